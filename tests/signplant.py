"""A random stable plant whose state changes sign at every step, simulated exactly (rational
arithmetic): a box placed one step early or late misses its state, so it tests that readers
and commands put every row of a log on its own step. Shared by tests/test_log_integrity.py and
benchmarks/bad_inputs.py."""

from __future__ import annotations

from fractions import Fraction
from typing import Any

import numpy as np

import ivobs


def plant(seed: int) -> tuple[ivobs.LinearSystem, ivobs.Box]:
    """2 states, 1 output, no input; ``A`` close to ``-0.9 I``; the prior box."""
    rng = np.random.default_rng(seed)
    A = -0.9 * np.eye(2) + rng.uniform(-0.05, 0.05, (2, 2))
    C = np.array([[1.0, rng.uniform(-0.5, 0.5)]])
    E = np.hstack([np.eye(2), np.zeros((2, 1))])
    F = np.array([[0.0, 0.0, 1.0]])
    d = ivobs.Box(np.full(3, -0.05), np.full(3, 0.05))
    return ivobs.LinearSystem(A, None, C, E=E, F=F, d=d), ivobs.Box([3.0, -3.0], [4.0, -2.0])


def simulate(
    sys: ivobs.LinearSystem, seed: int, T: int, x_true0: Any = (3.5, -2.5)
) -> tuple[list[list[Fraction]], np.ndarray]:
    """The true states (exact rationals) and the measurements (floats: the exact ``y``
    rounded; the disturbances stay inside their bounds by more than that rounding)."""
    rng = np.random.default_rng(seed + 100)
    A = [[Fraction(v) for v in row] for row in sys.A]
    C = [[Fraction(v) for v in row] for row in sys.C]
    x = [Fraction(v) for v in x_true0]
    xs, ys = [], []
    for _ in range(T):
        w = [Fraction(float(v)) for v in rng.choice([-0.049, 0.049], 3)]  # vertices, inside
        xs.append(x)
        ys.append([float(sum(c * xi for c, xi in zip(row, x)) + w[2]) for row in C])
        x = [sum(a * xi for a, xi in zip(row, x)) + w[i] for i, row in enumerate(A)]
    return xs, np.array(ys)


def contains(
    lo: np.ndarray, hi: np.ndarray, xs: list[list[Fraction]], steps: Any, missing_ok: bool = False
) -> bool:
    """Whether the box of every row (the log's step ``steps[i]``) holds the true state there.
    A missing bound (NaN) fails unless ``missing_ok`` (then it claims nothing)."""
    return all(
        (missing_ok and np.isnan(lo[i, j]))
        or Fraction(float(lo[i, j])) <= xs[k][j] <= Fraction(float(hi[i, j]))
        for i, k in enumerate(steps)
        for j in range(len(xs[0]))
    )
