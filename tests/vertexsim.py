"""Simulators written for the tests (not the library's own): every disturbance on a random
vertex of its box, the adversarial case of the containment tests. Float64, except
:func:`exact_linear` (rational arithmetic: exact trajectories of the model)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np

import ivobs


def simulate_vertex(
    sys: ivobs.LinearSystem, x0: ivobs.Box, u: np.ndarray, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """``x+ = A x + B u + E d``, ``y = C x + D u + F d``, every ``d[k]`` on a random vertex of
    the model's box, from a random vertex of ``x0``: the states and outputs."""
    rng = np.random.default_rng(seed)
    A, B, C, D, E, F = sys.matrices_at(0)
    d = sys.d_at(0)
    x = np.where(rng.integers(0, 2, sys.nx).astype(bool), x0.hi, x0.lo)
    xs, ys = [], []
    for k in range(u.shape[0]):
        dk = np.where(rng.integers(0, 2, sys.nd).astype(bool), d.hi, d.lo)
        xs.append(x)
        ys.append(C @ x + D @ u[k] + F @ dk)
        x = A @ x + B @ u[k] + E @ dk
    return np.array(xs), np.array(ys)


def servo_vertex(T: int, seed: int = 0):
    """The servo of [Tang2019] under a constant 2 V from its true initial state, every
    disturbance on a vertex: ``(scenario, u, x, y)``."""
    sc = ivobs.scenarios.get("servo-motor")
    s = sc.system
    A, B, C, E, F = (np.asarray(m, dtype=float) for m in (s.A, s.B, s.C, s.E, s.F))
    rng = np.random.default_rng(seed)
    d = np.where(rng.random((T, s.nd)) < 0.5, s.d.lo, s.d.hi)
    u = np.full((T, 1), 2.0)
    x = np.zeros((T, s.nx))
    x[0] = sc.x_true0
    for k in range(T - 1):
        x[k + 1] = A @ x[k] + B @ u[k] + E @ d[k]
    return sc, u, x, x @ C.T + d @ F.T


D = 0.1
"""Half-width of every disturbance of :func:`wrapping_plant`."""


def wrapping_plant(seed: int, n: int, offset: float = 0.0) -> tuple[ivobs.LinearSystem, np.ndarray]:
    """A stable plant whose boxes wrap: ``ρ(A) = 0.95 < 1 < ρ(|A|)``, one output, process
    noise on every state and measurement noise, all ``±0.1``; with ``offset``, a constant
    input ``u = 1`` holds the equilibrium at about ``offset`` in every state. Returns the
    system and the equilibrium."""
    rng = np.random.default_rng(seed)
    while True:
        A = rng.normal(size=(n, n))
        A *= 0.95 / max(abs(np.linalg.eigvals(A)))
        if max(abs(np.linalg.eigvals(abs(A)))) > 1.05:
            break
    C = rng.normal(size=(1, n))
    B = (np.eye(n) - A) @ np.full((n, 1), offset)
    E = np.hstack([np.eye(n), np.zeros((n, 1))])
    F = np.hstack([np.zeros((1, n)), np.ones((1, 1))])
    d = ivobs.Box(np.full(n + 1, -D), np.full(n + 1, D))
    sys = ivobs.LinearSystem(A=A, B=B, C=C, E=E, F=F, d=d)
    return sys, np.linalg.solve(np.eye(n) - A, B[:, 0])


def _absorb_rational(g: Fraction, up_side: bool) -> float:
    """The double ``z`` next to ``g ± D`` with ``z - g`` in ``[-D, D]`` (the doubles ``±0.1``
    as the exact bounds of the model)."""
    lo, hi = Fraction(-D), Fraction(D)
    z = float(g + (hi if up_side else lo))
    while Fraction(z) - g > hi:
        z = math.nextafter(z, -math.inf)
    while Fraction(z) - g < lo:
        z = math.nextafter(z, math.inf)
    return z


def exact_linear(
    sys: ivobs.LinearSystem, x0: np.ndarray, T: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``T`` exact steps of ``x+ = A x + B u + w``, ``y = C x + v`` from the doubles ``x0``,
    ``u = 1`` when the plant has an input, every ``w``, ``v`` on a random vertex: ``(U, X, Y)``
    with the true states and outputs as doubles."""
    rng = np.random.default_rng(seed + 1000)
    A = [[Fraction(a) for a in row] for row in sys.A]
    B = [[Fraction(b) for b in row] for row in sys.B]
    C = [Fraction(c) for c in sys.C[0]]
    n = sys.nx
    x = [float(v) for v in x0]
    U = np.ones((T, sys.nu))
    X, Y = np.empty((T, n)), np.empty((T, 1))
    for k in range(T):
        side = rng.integers(0, 2, n + 1).astype(bool)
        X[k] = x
        xf = [Fraction(v) for v in x]
        Y[k, 0] = _absorb_rational(sum(c * v for c, v in zip(C, xf)), bool(side[n]))
        inputs = [sum(b for b in row) for row in B]  # B u with u = 1
        x = [
            _absorb_rational(sum(a * v for a, v in zip(A[i], xf)) + inputs[i], bool(side[i]))
            for i in range(n)
        ]
    return U, X, Y
