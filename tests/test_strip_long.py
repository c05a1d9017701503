"""The strip method [Alamo2005] over long runs: the CORA benchmarks of [Althoff2021] (their
recorded trajectories, vertex disturbances, every order bounded, CORA FRad-A's saved radii),
random systems over 300 steps, and the reductions it uses."""

from __future__ import annotations

from importlib import resources

import numpy as np
import pytest

import ivobs
from ivobs import Box, scenarios
from ivobs.testing import random_system

CORA = ["cora-2dim", "cora-vehicle6", "cora-pedestrian4", "cora-slip4", "cora-tank30"]
# CORA's pedestrian record leaves its own noise bound at k = 217 (by 3.2e-3, CORA_README): the
# one sample a guaranteed method may miss; (step, state)
KNOWN_OUTSIDE = {"cora-pedestrian4": {(217, 1)}}


def vertex_run(sys: ivobs.LinearSystem, x0: np.ndarray, u: np.ndarray, seed: int):
    """x+ = A x + B u + E d, y = C x + D u + F d with d on the vertices of its box (a
    simulator written here, not ivobs.simulate)."""
    rng = np.random.default_rng(seed)
    A, B, C, D, E, F = (np.asarray(M, float) for M in sys.matrices_at(0))
    lo, hi = sys.d.lo, sys.d.hi
    T = u.shape[0]
    xs, ys, x = np.empty((T, sys.nx)), np.empty((T, sys.ny)), np.asarray(x0, float)
    for k in range(T):
        d = np.where(rng.integers(0, 2, lo.shape[0]).astype(bool), hi, lo)
        xs[k], ys[k] = x, C @ x + D @ u[k] + F @ d
        x = A @ x + B @ u[k] + E @ d
    return xs, ys


def outside(res: ivobs.Estimate, x: np.ndarray) -> set[tuple[int, int]]:
    ks, js = np.nonzero((res.lower > x) | (x > res.upper))
    return set(zip(ks.tolist(), js.tolist()))


@pytest.mark.parametrize("name", [n for n in CORA if n != "cora-2dim"])
def test_contains_the_recorded_trajectory(name: str) -> None:
    if name == "cora-tank30":
        pytest.importorskip("scipy")
    sc = scenarios.get(name)
    tr = sc.recorded
    res = ivobs.make_estimator("strip", sc.system, x0=sc.x0).run(tr.u, tr.y)
    assert outside(res, tr.x) <= KNOWN_OUTSIDE.get(name, set())
    assert not res.inconsistent.any()


@pytest.mark.slow
@pytest.mark.parametrize("name", CORA)
def test_vertex_disturbances_contained_at_every_step_for_300_steps(name: str) -> None:
    sc = scenarios.get(name)
    sys = sc.system
    T = 300 if sys.nx < 30 else 120
    rng = np.random.default_rng(3)
    u = sc.u[np.arange(T) % sc.u.shape[0]]
    x0 = np.where(rng.integers(0, 2, sys.nx).astype(bool), sc.x0.hi, sc.x0.lo)
    x, y = vertex_run(sys, x0, u, seed=4)
    for order in (sys.nx, 10 * sys.nx):
        res = ivobs.make_estimator("strip", sys, x0=sc.x0, order=order).run(u, y)
        assert not outside(res, x), (name, order)
        assert np.all(np.isfinite(res.lower)) and not res.inconsistent.any()


@pytest.mark.slow
@pytest.mark.parametrize("name", CORA)
@pytest.mark.parametrize("reduction", ["parallelotope", "girard"])
def test_every_order_stays_bounded(name: str, reduction: str) -> None:
    """The largest mean radius over the whole record, for orders from the smallest accepted
    (nx) up: a few times the prior's at most (it was 10⁷ times on tank30 at order 60 with the
    unchecked parallelotope basis). Measured at worst (parallelotope): 0.77, 7.45, 2.10, 0.30,
    0.86 times the prior's on 2dim, vehicle6, pedestrian4, slip4, tank30; Girard's box 16.4
    (pedestrian4, order 2 nx)."""
    sc = scenarios.get(name)
    tr = sc.recorded
    nx = sc.system.nx
    r0 = float(np.mean(0.5 * (sc.x0.hi - sc.x0.lo)))
    orders = [nx, nx + 1, 2 * nx, 3 * nx, 10 * nx] if nx < 30 else [nx, 2 * nx, 5 * nx]
    if reduction != "parallelotope":  # order < 2 nx is refused
        orders = [q for q in orders if q >= 2 * nx]
    limit = 10.0 if reduction == "parallelotope" else 100.0
    for order in orders:
        est = ivobs.make_estimator("strip", sc.system, x0=sc.x0, order=order, reduction=reduction)
        res = est.run(tr.u, tr.y)
        r = 0.5 * (res.upper - res.lower)
        assert np.all(np.isfinite(r))
        assert r.mean(axis=1).max() <= limit * r0, (order, r.mean(axis=1).max() / r0)


def _cora_radius(key: str) -> float:
    with resources.files("ivobs.data").joinpath("cora_tank30_results.npz").open("rb") as fh:
        z = np.load(fh)
        return float(np.mean(0.5 * (z[key + "_hi"] - z[key + "_lo"])))


@pytest.mark.slow
def test_tank30_default_is_tighter_than_cora_frad_a() -> None:
    """CORA FRad-A (the same strips [Alamo2005], Girard's/PCA reduction at 100 nx generators)
    has mean radius 1.0103 at time point 20 and 0.6109 at 235; the default strip (10 nx
    generators, conditioned parallelotope): 0.864 and 0.579 (measured)."""
    sc = scenarios.get("cora-tank30")
    tr = sc.recorded
    res = ivobs.make_estimator("strip", sc.system, x0=sc.x0).run(tr.u, tr.y)
    r = 0.5 * (res.upper - res.lower)
    assert r[19].mean() <= _cora_radius("cora_k20_FRadA")
    assert r[234].mean() <= _cora_radius("cora_k235_FRadA")
    assert r[19].mean() >= _cora_radius("exact_k20") and r[234].mean() >= _cora_radius("exact_k235")


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_systems_300_steps_low_order(seed: int) -> None:
    """Vertex disturbances at every step, every reduction, at the smallest orders it accepts
    (the reduction works hardest). Measured widths (parallelotope, rows 150-299): at most 3.0,
    4.5, 8.7 at order nx; Girard's box reached 1e11 and 1e82 at order nx, now refused."""
    nx = 4 + seed
    sys = random_system(seed + 20, nx=nx, ny=2, nu=1, feedthrough=bool(seed % 2))
    x0 = Box(-np.ones(nx), np.ones(nx))
    u = np.random.default_rng(seed).normal(size=(300, 1))
    x, y = vertex_run(sys, -np.ones(nx), u, seed=seed)
    for reduction, order in (("parallelotope", nx), ("parallelotope", 3 * nx),
                             ("girard", 2 * nx), ("box", 3 * nx)):  # fmt: skip
        est = ivobs.make_estimator("strip", sys, x0=x0, order=order, reduction=reduction)
        res = est.run(u, y)
        assert not outside(res, x), (reduction, order)
        assert np.all(np.isfinite(res.upper))
        if reduction == "parallelotope":  # the boxes may diverge on such systems (docs)
            assert res.width[150:].max() < 1e2


def test_box_reductions_refuse_the_orders_where_they_diverge() -> None:
    sc = scenarios.get("cora-vehicle6")
    for reduction in ("girard", "box"):
        for q in (6, 7, 11):
            with pytest.raises(ivobs.IvobsError, match=f"order.*2 nx = 12, got {q}"):
                ivobs.make_estimator("strip", sc.system, x0=sc.x0, order=q, reduction=reduction)
        ivobs.make_estimator("strip", sc.system, x0=sc.x0, order=12, reduction=reduction)
