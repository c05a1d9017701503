"""Missing samples never destabilise an estimator on a detectable stable plant: with 10 % of the
output components missing at random, every linear method's mean width stays within 20 times its
width with complete data, and every box contains the exact state (random stable plants,
disturbances on the vertices of their bounds, exact trajectories)."""

from __future__ import annotations

import functools
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import Box, DesignError, IvobsError, LinearSystem
from ivobs.testing import ExactStates, exact_misses, exact_run

pytestmark = pytest.mark.slow

STEPS = {"exact": 150, "constrained-zonotope": 150, "dual-window": 600, "intersect": 600}
"""Steps per record for the methods with a program per step (the others: 1,500)."""


def _plant(seed: int) -> tuple[LinearSystem, Box]:
    """A random stable 4-state plant with 2 outputs (ρ(A) = 0.8), observable from each output
    alone and from both."""
    rng = np.random.default_rng(seed)
    nx, ny = 4, 2
    for _ in range(500):
        A = rng.normal(size=(nx, nx))
        A *= 0.8 / max(np.abs(np.linalg.eigvals(A)))
        C = rng.normal(size=(ny, nx))
        ok = all(
            np.linalg.matrix_rank(np.vstack([c @ np.linalg.matrix_power(A, i) for i in range(nx)]))
            == nx
            for c in (C, C[:1], C[1:])
        )
        if ok:
            break
    E = np.hstack([0.1 * np.eye(nx), np.zeros((nx, ny))])
    F = np.hstack([np.zeros((ny, nx)), 0.05 * np.eye(ny)])
    sys = LinearSystem(A, rng.normal(size=(nx, 1)), C, E=E, F=F, d=Box.symmetric(np.ones(nx + ny)))
    return sys, Box.symmetric(np.ones(nx))


@functools.cache
def _record(seed: int, T: int) -> tuple[np.ndarray, np.ndarray, ExactStates, np.ndarray]:
    """``T`` steps of plant ``seed`` (the methods with the same record length share it): the
    inputs, the measurements, the exact states and the measurements with 10 % missing."""
    sys, _ = _plant(seed)
    rng = np.random.default_rng(seed + 100)
    U = rng.uniform(-1, 1, size=(T, 1))
    D = np.where(rng.integers(0, 2, size=(T, sys.nd)).astype(bool), sys.d.hi, sys.d.lo)
    Y, X = exact_run(sys, np.where(rng.integers(0, 2, 4).astype(bool), 1.0, -1.0), U, D)
    return U, Y, X, np.where(rng.uniform(size=Y.shape) < 0.1, np.nan, Y)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("method", [m for m in ivobs.methods() if not m.startswith("nl-")])
def test_ten_percent_missing_keeps_widths_within_20x_of_complete_data(method, seed):
    sys, x0 = _plant(seed)
    T = STEPS.get(method, 1500)
    U, Y, X, Ym = _record(seed, T)
    try:
        est = ivobs.make_estimator(method, sys, x0=x0)
    except (DesignError, IvobsError) as exc:
        pytest.skip(f"{method} refuses the plant: {str(exc)[:80]}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        full, part = est.run(U, Y), est.run(U, Ym)
    for res in (full, part):
        assert exact_misses(res.lower, res.upper, X).size == 0
    burn = T // 5
    ratio = part.mean_width(burn) / full.mean_width(burn)
    assert np.all(np.isfinite(ratio)) and np.max(ratio) <= 20.0, (method, ratio)
