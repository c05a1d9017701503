"""`reachability` and `zonotope` contain the exact state at every magnitude, their rounding
included, and never flag an admissible measurement.

The records come from tests/exactsim.py (the model simulated in exact arithmetic, every
disturbance on a vertex of its bounds, every state and measurement an exact value of the model
with admissible unknowns, stored as doubles), so the check relies on no margin of the
estimators. Every run path is checked: the loop of ``run()``, the vectorised ``run()``, ``step()``
with state round trips through JSON, and records with missing outputs (the window and the gains
of the outputs present).
"""

from __future__ import annotations

import json
import warnings
from functools import cache
from pathlib import Path

import numpy as np
import pytest

import ivobs
from exactsim import Record, simulate_linear

DATA = Path(__file__).parent / "data" / "observer_large_states.npz"


def _with_private_noise(A, B, C, D, E0, F0, lo0, hi0, w, v):
    """The plant with a process noise of its own on every state (bound ``w``) and a measurement
    noise of its own on every output (``v``), as tests/exactsim.py needs."""
    nx, ny = A.shape[0], C.shape[0]
    E = np.hstack([E0, np.eye(nx), np.zeros((nx, ny))])
    F = np.hstack([F0, np.zeros((ny, nx)), np.eye(ny)])
    lo = np.concatenate([lo0, -w, -v])
    hi = np.concatenate([hi0, w, v])
    return ivobs.LinearSystem(A, B, C, D, E=E, F=F, d=ivobs.Box(lo, hi))


@cache
def _large_states() -> tuple[ivobs.LinearSystem, ivobs.Box, np.ndarray, Record]:
    """The unstable 6-state plant whose states reach 1e7-1e10 (rho(A) = 1.05) with the radius
    gain of its two shared disturbances (max |L| = 220, rho(A - LC) = 0.67, ||A - LC|| = 1e3),
    plus private noises of 2e-6 (about one ulp of the states). With this record the margin of
    the earlier code missed the state at 3 steps and flagged 4 admissible samples."""
    z = np.load(DATA)
    nx, ny = 6, 3
    sys = _with_private_noise(
        z["A"], z["B"], z["C"], z["D"], z["E"], z["F"], z["dlo"], z["dhi"],
        np.full(nx, 2e-6), np.full(ny, 2e-6),
    )  # fmt: skip
    rec = simulate_linear(sys, z["x0"], 120, z["U"], seed=2)
    return sys, ivobs.Box(z["x0l"], z["x0h"]), z["L"], rec


def _check(est: ivobs.Estimator, rec: Record, *, missing: float = 0.1) -> None:
    """0 misses and 0 inconsistency flags on every run path."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an inconsistency report is a UserWarning
        for vec in (False, True):
            res = est.run(rec.U, rec.Y, vectorize=vec)
            assert not res.inconsistent.any()
            assert rec.misses(res.lower, res.upper).size == 0, f"vectorize={vec}"
        est.reset()
        lo, hi = [], []
        for k in range(rec.Y.shape[0]):
            if k % 25 == 24:  # continue from a state that went through JSON
                saved = json.loads(json.dumps(est.state()))
                est.reset()
                est.restore(saved)
            box = est.step(rec.U[k], rec.Y[k])
            lo.append(box.lo)
            hi.append(box.hi)
        assert rec.misses(np.array(lo), np.array(hi)).size == 0
        y = rec.Y.copy()
        y[np.random.default_rng(0).random(y.shape) < missing] = np.nan
        res = est.run(rec.U, y)
        assert not res.inconsistent.any()
        assert rec.misses(res.lower, res.upper).size == 0


def test_reachability_contains_states_of_1e10_with_a_gain_of_220():
    sys, x0, L, rec = _large_states()
    assert np.abs(rec.X_lo).max() > 7e9 and np.abs(rec.X_lo[0]).min() > 1e6
    est = ivobs.make_estimator("reachability", sys, x0=x0, L=L)
    _check(est, rec)
    # the rounding at 1e10 (1e-16 relative) through ||A - LC|| = 1e3 dominates the widths
    res = est.run(rec.U, rec.Y)
    assert (res.upper - res.lower).mean() < 0.5


def test_the_designed_gain_keeps_states_of_1e10_tight():
    """With the plant's own radius gain the widths are 1e-4 at states of 1e10: the rounding is
    proven at 1e-14 of the state, no margin relative to it."""
    sys, x0, _, rec = _large_states()
    for method in ("reachability", "zonotope"):
        est = ivobs.make_estimator(method, sys, x0=x0)
        res = est.run(rec.U, rec.Y)
        assert rec.misses(res.lower, res.upper).size == 0
        assert (res.upper - res.lower).mean() < 1e-3


def _scaled_plant(seed: int, scale: float) -> tuple[ivobs.LinearSystem, np.ndarray, ivobs.Box]:
    """A random unstable plant (rho(A) = 1.02) whose states are ``scale`` to ``100 scale`` in
    magnitude, measured weakly (|C| ~ 1e-2 before scaling: gains of 1e3 and more), with
    disturbances of 1e-12 of the states: the rounding is what the bounds must cover."""
    rng = np.random.default_rng(seed)
    nx, ny = 3, 2
    A = rng.normal(size=(nx, nx))
    A *= 1.02 / np.abs(np.linalg.eigvals(A)).max()
    S = scale * 10.0 ** rng.integers(0, 3, nx)  # x' = S x: badly scaled states
    A = A * S[:, None] / S[None, :]
    B = rng.normal(size=(nx, 1)) * S[:, None]
    C = rng.normal(size=(ny, nx)) * 1e-2 * scale / S[None, :]
    D = rng.normal(size=(ny, 1)) * 1e-2 * scale
    E0 = rng.normal(size=(nx, 1)) * S[:, None] * 1e-12
    F0 = rng.normal(size=(ny, 1)) * 1e-14 * scale
    w, v = 1e-12 * S, 1e-14 * scale * np.ones(ny)
    sys = _with_private_noise(A, B, C, D, E0, F0, np.array([-1.0]), np.array([0.5]), w, v)
    x_true = S * rng.normal(size=nx)
    return sys, x_true, ivobs.Box(x_true - 1e-9 * S, x_true + 2e-9 * S)


@cache
def _scaled(seed: int, scale: float) -> tuple[ivobs.LinearSystem, ivobs.Box, Record]:
    sys, x_true, x0 = _scaled_plant(seed, scale)
    u = np.random.default_rng(seed).normal(size=(100, 1))
    return sys, x0, simulate_linear(sys, x_true, 100, u, seed=seed)


@pytest.mark.parametrize("method", ["reachability", "zonotope"])
@pytest.mark.parametrize(("seed", "scale"), [(1, 1e-6), (2, 1e-2), (3, 1e3), (4, 1e7), (5, 1e10)])
def test_random_plants_from_1e_6_to_1e10_with_large_gains(method, seed, scale):
    sys, x0, rec = _scaled(seed, scale)
    est = ivobs.make_estimator(method, sys, x0=x0)
    assert np.abs(est.design.L).max() > 400.0  # a large gain
    _check(est, rec)
    # the proven rounding is a few ulps of the state per step: widths of about 1e-11 of the
    # state (the disturbances are 1e-12 of it), where a margin relative to 1 + |x| is not
    res = est.run(rec.U, rec.Y)
    assert np.mean((res.upper - res.lower) / np.abs(rec.X_lo).mean(axis=0)) < 1e-9
