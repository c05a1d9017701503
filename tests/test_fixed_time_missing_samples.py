"""Missing samples never destabilise the fixed-time estimator [Wang2020].

Random stable plants (tests/randsys.py, and plants whose ``|A|`` is not Schur although ``A`` is,
where an interval prediction through a gap grows), 10 % of the output components missing at
random over 3,000 steps: every box contains the true state (simulated exactly here), and the
widths stay within 20 times those with complete data. The box of a window with missing samples
comes from the shortest window (up to ``2 s + 2`` samples) whose available samples determine the
state, intersected with the prediction from the previous box; it never depends on a long chain
of predictions.
"""

from __future__ import annotations

import math
import warnings
from fractions import Fraction

import numpy as np
import pytest

import ivobs
from ivobs import LinearSystem
from randsys import random_interval_linear

T = 3000


def inward(q: Fraction, up: bool) -> float:
    """The double nearest to ``q`` on the side of ``q`` towards ``-inf`` (``up=False``: at most
    ``q``) or ``+inf`` (``up=True``: at least ``q``)."""
    f = float(q)
    if up and Fraction(f) < q:
        f = math.nextafter(f, math.inf)
    if not up and Fraction(f) > q:
        f = math.nextafter(f, -math.inf)
    return f


def absorbed_run(
    sys: LinearSystem, x0: np.ndarray, u: np.ndarray, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """An exact trajectory of ``x+ = A x + B u + w``, ``y = C x + D u + v`` (``E = [I 0]``,
    ``F = [0 I]``), ``w``, ``v`` on vertices of their bounds: each new state is the double next
    to ``A x + B u + w`` on the side of the bound's centre, so the exact disturbance that makes it
    exact lies within its bounds, and the states stay doubles; ``y`` is the double nearest to the
    exact output (as a logger records it)."""
    A, B, C, D, E, F = sys.matrices_at(0)
    nx, ny = sys.nx, sys.ny
    assert np.array_equal(E, np.hstack([np.eye(nx), np.zeros((nx, ny))]))
    assert np.array_equal(F, np.hstack([np.zeros((ny, nx)), np.eye(ny)]))
    box = sys.d_at(0)
    w_hi, v_hi = box.hi[:nx], box.hi[nx:]
    assert np.array_equal(box.lo, -box.hi)

    A, B, C, D = ([[Fraction(float(a)) for a in row] for row in M] for M in (A, B, C, D))

    def dot(row: list[Fraction], v: list[Fraction]) -> Fraction:
        return sum((a * b for a, b in zip(row, v) if a), Fraction(0))

    x = [Fraction(float(v)) for v in x0]
    X, Y = np.empty((len(u), nx)), np.empty((len(u), ny))
    for k in range(len(u)):
        uk = [Fraction(float(v)) for v in u[k]]
        X[k] = [float(v) for v in x]  # doubles
        side = rng.random(nx + ny) < 0.5
        for j in range(ny):
            vj = v_hi[j] if side[nx + j] else -v_hi[j]
            Y[k, j] = float(dot(C[j], x) + dot(D[j], uk) + Fraction(float(vj)))
        x = [
            Fraction(
                inward(dot(A[i], x) + dot(B[i], uk) + Fraction(float(w_hi[i] * (1 if s else -1))),
                       up=not s)
            )
            for i, s in enumerate(side[:nx])
        ]  # fmt: skip
    return X, Y


def hard_plant(seed: int, nx: int, ny: int) -> LinearSystem:
    """A stable plant (``ρ(A) = 0.85``) whose ``|A|`` is not Schur (``ρ(|A|) > 1.2``): the
    interval prediction ``|A|ᵏ`` through a run of missing samples grows."""
    rng = np.random.default_rng(seed)
    while True:
        A = rng.normal(size=(nx, nx))
        A *= 0.85 / np.max(np.abs(np.linalg.eigvals(A)))
        if np.max(np.abs(np.linalg.eigvals(np.abs(A)))) > 1.2:
            break
    return LinearSystem.from_process_measurement(
        A,
        rng.normal(size=(nx, 1)),
        rng.normal(size=(ny, nx)),
        np.eye(nx),
        np.eye(ny),
        np.full(nx, 0.02),
        np.full(ny, 0.05),
    )


PLANTS = [("randsys", seed) for seed in (0, 1, 2, 3)] + [("hard", seed) for seed in (4, 5, 6, 7)]


@pytest.mark.parametrize(("kind", "seed"), PLANTS)
def test_widths_stay_bounded_and_boxes_contain_the_state(kind, seed):
    if kind == "randsys":
        sys = random_interval_linear(seed).system.nominal()
    else:
        sys = hard_plant(seed, 4, 2 if seed % 2 else 1)
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, (T, sys.nu))
    X, y = absorbed_run(sys, rng.uniform(-0.5, 0.5, sys.nx), u, rng)
    y_miss = y.copy()
    y_miss[rng.random(y.shape) < 0.1] = np.nan
    x0 = ivobs.Box(-np.ones(sys.nx), np.ones(sys.nx))
    est = ivobs.make_estimator("fixed-time", sys, x0=x0)
    vf, m = est.valid_from, est.memory
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no admissible sample flagged
        full = est.run(u, y)
        runs = [est.run(u, y_miss), est.run(u, y_miss, vectorize=False)]
    ref = full.width[vf:].sum(axis=1).mean()
    for res in [full, *runs]:
        assert np.all(res.lower[vf:] <= X[vf:]) and np.all(X[vf:] <= res.upper[vf:])
    np.testing.assert_allclose(runs[0].width[vf:], runs[1].width[vf:], rtol=1e-9)
    widths = runs[0].width.sum(axis=1)
    assert widths[vf:].mean() <= 20 * ref
    assert widths[m:].max() <= 20 * ref  # after the start (no window before step 0)
    assert np.isnan(y_miss).any(axis=1).mean() > 0.09
