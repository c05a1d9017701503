"""The kkl boxes contain the true state at every step, floating-point rounding included: plants
simulated exactly (tests/exactsim.py: every state and measurement an exact trajectory of the
model, disturbances on the vertices of their bounds), at ordinary and at large magnitudes
(states of 1e6-1e10, gains up to 1e3), through ``run()`` (loop and vectorised) and ``step()``
with a state round trip through JSON at every step."""

from __future__ import annotations

import json
import math
from fractions import Fraction

import numpy as np
import pytest

import ivobs
from exactsim import Record, simulate_linear
from ivobs import Box, LinearSystem
from ivobs.testing import random_system


def _plant(seed: int, nx: int, ny: int, rho: float, scale: float = 1.0) -> LinearSystem:
    """A random observable plant ``x+ = A x + B u + w``, ``y = C x + D u + v`` (each state and
    output with a disturbance of its own, as the exact simulator needs)."""
    rng = np.random.default_rng(seed)
    base = random_system(rng, nx=nx, ny=ny, nu=1, rho=rho, feedthrough=True)
    w = scale * rng.uniform(0.01, 0.1, nx)
    v = scale * rng.uniform(0.01, 0.1, ny)
    return LinearSystem.from_process_measurement(
        base.A, base.B, base.C, np.eye(nx), np.eye(ny), w, v, D=base.D
    )


def _exact(sys_: LinearSystem, x0: Box, T: int, seed: int, u_scale: float = 1.0):
    rng = np.random.default_rng(seed)
    start = np.where(rng.random(sys_.nx) < 0.5, x0.lo, x0.hi)
    u = u_scale * rng.normal(size=(T, sys_.nu))
    return simulate_linear(sys_, start, T, u, seed=seed)


def _assert_contains(lo: np.ndarray, hi: np.ndarray, rec, from_k: int = 0) -> None:
    miss = rec.misses(lo, hi)
    miss = miss[miss >= from_k]  # (NaN boxes before valid_from)
    assert miss.size == 0, f"first miss at step {miss[0]}"


@pytest.mark.parametrize("seed", range(4))
def test_random_plants_loop_and_vectorised_run_contain_the_exact_trajectory(seed):
    nx, ny = 2 + seed % 3, 1 + seed % 2
    sys_ = _plant(seed, nx, ny, rho=[0.8, 0.95, 1.05, 0.5][seed])
    x0 = Box(-np.ones(nx), np.ones(nx))
    rec = _exact(sys_, x0, 300, seed)
    est = ivobs.make_estimator("kkl", sys_, x0=x0)
    loop = est.run(rec.U, rec.Y, vectorize=False)
    vec = est.run(rec.U, rec.Y, vectorize=True)
    _assert_contains(loop.lower, loop.upper, rec)
    _assert_contains(vec.lower, vec.upper, rec)
    assert not loop.inconsistent.any() and not vec.inconsistent.any()
    # two algorithms, the same sets: the widths agree to rounding
    np.testing.assert_allclose(vec.width, loop.width, rtol=1e-5, atol=1e-8)  # np.allclose


@pytest.mark.parametrize(
    "level, gain", [(1e6, 1.0), (1e8, 1e3), (1e10, 1.0)], ids=["1e6", "1e8-gain1e3", "1e10"]
)
def test_large_states_and_gains_step_with_state_round_trips(level, gain):
    """States near ``level`` (a prior box and inputs of that size on an unstable plant), a
    target with ``B_z`` of size ``gain``: every box of ``step()``, continued from its own state
    saved through JSON at every step, and of ``run()`` contains the exact trajectory; no
    admissible measurement is flagged; every saved state is accepted."""
    nx = 3
    sys_ = _plant(7, nx, 2, rho=1.02, scale=level * 1e-9)
    x0 = Box(np.full(nx, level - 1.0), np.full(nx, level + 1.0))
    rec = _exact(sys_, x0, 120, 3, u_scale=level * 1e-3)
    ref = ivobs.make_estimator("kkl", sys_, x0=x0).design
    kw = {"A_z": ref.A_z, "B_z": gain * ref.B_z, "T": gain * ref.T}  # (4) is linear in B_z
    est = ivobs.make_estimator("kkl", sys_, x0=x0, on_inconsistent="raise", **kw)
    assert np.abs(rec.X_lo).max() > 0.5 * level
    vec = est.run(rec.U, rec.Y, vectorize=True)
    _assert_contains(vec.lower, vec.upper, rec)
    res = est.run(rec.U, rec.Y, vectorize=False)  # the loop: step()'s recursion
    _assert_contains(res.lower, res.upper, rec)
    # two algorithms: the same widths up to rounding at the states' magnitude
    np.testing.assert_allclose(vec.width, res.width, rtol=1e-6, atol=1e-12 * level)
    lo, hi = np.empty_like(res.lower), np.empty_like(res.upper)
    other = ivobs.make_estimator("kkl", sys_, x0=x0, on_inconsistent="raise", **kw)
    est.reset()
    for k in range(rec.Y.shape[0]):
        box = est.step(rec.U[k], rec.Y[k])
        lo[k], hi[k] = box.lo, box.hi
        other.restore(json.loads(json.dumps(est.state())))
        est, other = other, est
    _assert_contains(lo, hi, rec)
    np.testing.assert_allclose(hi - lo, res.width, rtol=1e-6)


def test_a_sample_within_rounding_of_its_bound_is_not_flagged():
    """Measurements exactly on the vertices of the noise bounds (the exact simulator puts them
    within one ulp of ``C x + v̄``): thousands of them, none flagged inconsistent."""
    sys_ = _plant(11, 2, 2, rho=0.9)
    x0 = Box(-np.ones(2), np.ones(2))
    rec = _exact(sys_, x0, 400, 5)
    est = ivobs.make_estimator("kkl", sys_, x0=x0, on_inconsistent="raise")
    est.run(rec.U, rec.Y, vectorize=False)
    est.run(rec.U, rec.Y, vectorize=True)


def _inward(exact: Fraction, vertex: Fraction, bound: Fraction) -> float:
    """A double ``z`` next to ``exact + vertex`` with ``|z - exact| <= bound``: the disturbance
    ``z - exact`` is admissible (rounded towards the inside of its bounds)."""
    z = float(exact + vertex)
    while abs(Fraction(z) - exact) > bound:
        z = math.nextafter(z, float(exact))
    return z


def _exact_ltv(sys_: LinearSystem, x0: Box, T: int, seed: int):
    """An exact trajectory of a time-varying ``x+ = A[k] x + B u + w``, ``y = C x + D u + v``
    (symmetric bounds of each ``w_i``, ``v_j``, on their vertices): every state and measurement
    a double, the disturbance that makes it exact admissible (checked in rationals)."""
    rng = np.random.default_rng(seed)
    nx, ny = sys_.nx, sys_.ny
    wb = [Fraction(v) for v in sys_.d.hi[:nx]]
    vb = [Fraction(v) for v in sys_.d.hi[nx:]]
    x = [float(v) for v in np.where(rng.random(nx) < 0.5, x0.lo, x0.hi)]
    u = rng.normal(size=(T, sys_.nu))
    X, Y = np.empty((T, nx)), np.empty((T, ny))

    def dot(row, vec):
        return sum((Fraction(float(a)) * Fraction(b) for a, b in zip(row, vec)), Fraction(0))

    for k in range(T):
        A, B, C, D, _, _ = sys_.matrices_at(k)
        X[k] = x
        for j in range(ny):
            g = dot(C[j], x) + dot(D[j], u[k])
            Y[k, j] = _inward(g, vb[j] * int(rng.choice([-1, 1])), vb[j])
        x = [
            _inward(dot(A[i], x) + dot(B[i], u[k]), wb[i] * int(rng.choice([-1, 1])), wb[i])
            for i in range(nx)
        ]
    return Record(X, X.copy(), Y, u)


def _ltv(seed: int, nx: int) -> LinearSystem:
    rng = np.random.default_rng(seed)
    base = _plant(seed, nx, 1, rho=1.0)
    A1 = 0.2 * rng.normal(size=(nx, nx))
    T = 200
    A = np.stack([base.A + np.sin(0.7 * k) * A1 for k in range(T)])
    return LinearSystem(A, base.B, base.C, D=base.D, E=base.E, F=base.F, d=base.d)


@pytest.mark.parametrize("seed", range(3))
@pytest.mark.parametrize("T0", ["zero", "sylvester"])
def test_time_varying_plants_contain_the_exact_trajectory(seed, T0):
    nx = 2 + seed % 2
    sys_ = _ltv(seed, nx)
    x0 = Box(-np.ones(nx), np.ones(nx))
    rec = _exact_ltv(sys_, x0, 150, seed)
    est = ivobs.make_estimator("kkl", sys_, x0=x0, T0=T0, on_inconsistent="raise")
    res = est.run(rec.U, rec.Y)
    _assert_contains(res.lower, res.upper, rec, est.valid_from)
    assert np.all(np.isfinite(res.lower[est.valid_from :]))
    # without a prior (T0 = 0: z[0] = 0 exactly) the same from valid_from on
    if T0 == "zero":
        free = ivobs.make_estimator("kkl", sys_, on_inconsistent="raise").run(rec.U, rec.Y)
        _assert_contains(free.lower, free.upper, rec, est.valid_from)


def test_missing_samples_and_gaps_contain_the_exact_trajectory():
    sys_ = _plant(4, 3, 2, rho=0.9)
    x0 = Box(-np.ones(3), np.ones(3))
    rec = _exact(sys_, x0, 300, 4)
    y = rec.Y.copy()
    rng = np.random.default_rng(0)
    y[rng.random(y.shape) < 0.15] = np.nan
    y[100:120] = np.nan
    est = ivobs.make_estimator("kkl", sys_, x0=x0, on_inconsistent="raise")
    res = est.run(rec.U, y)
    _assert_contains(res.lower, res.upper, rec)
    ltv = _ltv(1, 2)
    x0 = Box(-np.ones(2), np.ones(2))
    rec = _exact_ltv(ltv, x0, 120, 1)
    y = rec.Y.copy()
    y[rng.random(y.shape) < 0.15] = np.nan
    est = ivobs.make_estimator("kkl", ltv, x0=x0, on_inconsistent="raise")
    res = est.run(rec.U, y)
    _assert_contains(res.lower, res.upper, rec, est.valid_from)


def test_badly_scaled_plant_vectorised_run_contains_the_truth_and_matches_the_loop():
    """The 'scaled' conformance plant (states of 1e6, 1 and 1e-3) with vertex disturbances: the
    vectorised run bounds its rounding entry by entry (in a diagonally scaled norm), so it
    contains the exact states and its per-state mean widths are the loop's within 1e-6 (a
    scalar ∞-norm bound let the big state's residual widen the small ones some 60 times)."""
    from ivobs.testing.conformance import conformance_plants, exact_run, vertex_disturbance

    sys_, x0 = conformance_plants()["scaled"]
    rng = np.random.default_rng(0)
    T = 150
    start = np.where(rng.integers(0, 2, sys_.nx).astype(bool), x0.hi, x0.lo)
    U = rng.uniform(-1, 1, size=(T, sys_.nu))
    Y, X = exact_run(sys_, start, U, vertex_disturbance(sys_.d_at(0), T, rng))
    est = ivobs.make_estimator("kkl", sys_, x0=x0)
    vec = est.run(U, Y, vectorize=True)
    loop = est.run(U, Y, vectorize=False)
    for res in (vec, loop):
        assert np.all(res.lower <= X.lo) and np.all(res.upper >= X.hi)
    ratio = vec.width.mean(axis=0) / loop.width.mean(axis=0)
    np.testing.assert_allclose(ratio, 1.0, rtol=1e-6)
    # a batch of the same record and a shifted one: each stream contains its truth
    Y2, X2 = exact_run(sys_, -start, -U, vertex_disturbance(sys_.d_at(0), T, rng))
    batch = est.run(np.stack((U, -U)), np.stack((Y, Y2)), vectorize=True)
    for b, Xb in enumerate((X, X2)):
        assert np.all(batch.lower[b] <= Xb.lo) and np.all(batch.upper[b] >= Xb.hi)
    np.testing.assert_allclose(
        batch.width[0].mean(axis=0) / loop.width.mean(axis=0), 1.0, rtol=1e-6
    )
