"""The interval observers meet every box with the finite-memory bound of the ``N`` complete steps
before it (:mod:`ivobs.estimators.interval.window`, option ``finite_memory``): the truth stays
inside with the rounding included, also when disturbances put it on the bound (an exact
simulator, tests/exactsim.py); ``run()`` (vectorised and loop) and ``step()`` with saved states
give the same boxes; on the servo the width with complete data drops to the window's."""

from __future__ import annotations

import json

import numpy as np
import pytest

import ivobs
from exactsim import simulate_linear
from ivobs import Box, IvobsError, LinearSystem
from vertexsim import simulate_vertex

FAMILY = ("interval", "interval-split", "interval-transformed")


def _window_kd(sys: LinearSystem, est) -> np.ndarray:
    """``K_d = P_d − M T_d`` of the estimator's window bound: how the window's disturbances
    move ``x[s+N]`` away from ``M Y + K_u U`` (ivobs.design.finite_memory), computed here."""
    A, _, C, _, E, F = sys.matrices_at(0)
    bound = est.operators.window
    (ny, n), nd, N = C.shape, E.shape[1], bound.N
    M = bound.Mw.reshape(n, N, -1)[:, :, :ny].reshape(n, N * ny)
    power = np.linalg.matrix_power
    Pd = np.hstack([power(A, N - 1 - i) @ E for i in range(N)])
    Td = np.zeros((N * ny, N * nd))
    for j in range(N):
        Td[j * ny : (j + 1) * ny, j * nd : (j + 1) * nd] = F
        for i in range(j):
            Td[j * ny : (j + 1) * ny, i * nd : (i + 1) * nd] = C @ power(A, j - 1 - i) @ E
    return Pd - M @ Td


def _on_the_bound(Kd: np.ndarray, N: int, nd: int, T: int):
    """Disturbance vertices in blocks of ``N`` steps, each block driving one component of the
    state at its end to one end of the window's bound (``d = d_c ± sign(K_d[i]) d_r``), the
    components and ends in turn: ``(vertices, [(k, i, sign), ...])``."""
    n = Kd.shape[0]
    V = np.zeros((T, nd), dtype=bool)
    targets = []
    for b in range(T // N):
        i, s = b % n, 1.0 if (b // n) % 2 == 0 else -1.0
        V[b * N : (b + 1) * N] = (s * Kd[i].reshape(N, nd)) > 0
        targets.append(((b + 1) * N, i, s))
    return V, [t for t in targets if t[0] < T]


def _paths(est, u, y):
    """The boxes of the loop, the vectorised path and ``step()`` (the state saved to JSON and
    restored into a fresh estimator every 23 steps)."""
    loop, vec = est.run(u, y, vectorize=False), est.run(u, y, vectorize=True)
    est.reset()
    lo, hi = np.empty_like(loop.lower), np.empty_like(loop.upper)
    for k in range(y.shape[0]):
        box = est.step(u[k], y[k])
        lo[k], hi[k] = box.lo, box.hi
        if k % 23 == 0:
            est.restore(json.loads(json.dumps(est.state())))
    return {"loop": (loop.lower, loop.upper), "vectorised": (vec.lower, vec.upper),
            "step": (lo, hi)}  # fmt: skip


def _agree(paths, rtol=1e-7):
    """The same boxes within rounding: relative to the state's magnitude at that step (the
    rounding terms scale with ``‖x‖``, in every component), and to the vectorised path's own
    rounding bound (``c / (1 − λ)`` times the data's rounding: larger than the loop's)."""
    lo, hi = paths["loop"]
    scale = 1.0 + np.max(np.abs(lo) + np.abs(hi), axis=-1, keepdims=True)
    for other in ("vectorised", "step"):
        olo, ohi = paths[other]
        assert np.max(np.abs(olo - lo) / scale) < rtol, other
        assert np.max(np.abs(ohi - hi) / scale) < rtol, other


@pytest.mark.parametrize("scale", [0.0, 1e6])
@pytest.mark.parametrize("method", FAMILY)
def test_the_truth_on_the_window_bound_stays_inside(method, scale):
    """The servo of [Tang2019], its position offset by ``scale``, every window's disturbances
    on the vertex that puts one component of the state on the window's bound (exact
    trajectory): no box misses it on any path, the three paths agree, and the boxes do touch
    the truth (the bound is attained up to its rounding terms, ~1e-13 of the state)."""
    sc = ivobs.scenarios.get("servo-motor")
    sys = sc.system
    x_true0 = np.asarray(sc.x_true0, dtype=float) + np.array([scale, 0.0, 0.0])
    est = ivobs.make_estimator(method, sys, x0=Box(x_true0 - 1.0, x_true0 + 1.0))
    N, T = est.operators.window.N, 160
    V, targets = _on_the_bound(_window_kd(sys, est), N, sys.nd, T)
    u = np.full((T, 1), 2.0)
    rec = simulate_linear(sys, x_true0, T, u, vertices=V)
    paths = _paths(est, u, rec.Y)
    for name, (lo, hi) in paths.items():
        assert len(rec.misses(lo, hi)) == 0, name
    _agree(paths)
    lo, hi = paths["vectorised"]
    gaps = [
        hi[k, i] - rec.X_hi[k, i] if s > 0 else rec.X_lo[k, i] - lo[k, i]
        for k, i, s in targets
        if k >= 40
    ]
    assert np.median(gaps) < 1e-9 + 1e-12 * scale


@pytest.mark.parametrize("method", FAMILY)
def test_servo_width_with_complete_data_is_the_windows(method):
    """Complete data: the boxes are never wider than the observer's own (``finite_memory=False``),
    equal to them before the first window (``k < N``), and on the servo the summed width
    settles below 1.3 (the observer alone: 254 in steady state, its current unobserved)."""
    sc = ivobs.scenarios.get("servo-motor", horizon=3000)
    tr = sc.simulate("vertex", seed=2)
    on = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    off = ivobs.make_estimator(method, sc.system, x0=sc.x0, finite_memory=False)
    a, b = on.run(tr.u, tr.y), off.run(tr.u, tr.y)
    assert a.contains(tr.x).all()
    N = on.operators.window.N
    np.testing.assert_array_equal(a.lower[:N], b.lower[:N])
    assert np.all(a.lower >= b.lower) and np.all(a.upper <= b.upper)
    w = a.width.sum(axis=-1)
    assert w[1000:].max() < 1.3
    if method != "interval-transformed":  # (its own observer reaches 1.44 on the servo)
        assert b.width.sum(axis=-1)[-1] > 100.0


def _plant(seed: int) -> LinearSystem:
    """A random stable 3-state plant with an input, feedthrough and noise, observable through
    its one output after 3 steps (a window of N = 3)."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(3, 3))
    A *= 0.9 / max(abs(np.linalg.eigvals(np.abs(A))))
    return LinearSystem(
        A,
        rng.normal(size=(3, 1)),
        rng.normal(size=(1, 3)),
        D=rng.normal(size=(1, 1)),
        E=np.hstack([rng.normal(size=(3, 2)), np.zeros((3, 1))]),
        F=np.hstack([np.zeros((1, 2)), rng.normal(size=(1, 1))]),
        d=Box(-rng.random(3), rng.random(3)),
    )


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("method", ["interval-split", "interval-transformed"])
def test_random_plants_complete_and_missing(method, seed):
    """Vertex disturbances (a float simulator of the tests, tests/vertexsim.py): containment
    with complete data (three paths agreeing) and with 10 % of the samples missing, and the
    boxes no wider than without the bound."""
    sys = _plant(seed)
    x0 = Box(-np.ones(3), np.ones(3))
    opts = {"L": np.zeros((3, 1))} if method == "interval-split" else {}
    est = ivobs.make_estimator(method, sys, x0=x0, **opts)
    assert est.operators.window is not None and est.operators.window.N == 3
    T = 300
    u = np.random.default_rng(seed).uniform(-1.0, 1.0, (T, 1))
    x, y = simulate_vertex(sys, x0, u, seed)
    paths = _paths(est, u, y)
    for lo, hi in paths.values():
        assert np.all(lo <= x) and np.all(x <= hi)
    _agree(paths)
    y[np.random.default_rng(seed + 1).random(T) < 0.1] = np.nan
    res = est.run(u, y)
    assert res.contains(x).all() and not res.inconsistent.any()
    off = ivobs.make_estimator(method, sys, x0=x0, finite_memory=False, **opts).run(u, y)
    assert np.all(res.lower >= off.lower) and np.all(res.upper <= off.upper)


def test_batch_with_an_inconsistent_stream_matches_the_loop():
    """A batch of streams on the vectorised path, one of them with a faulty sample (that stream
    goes through the loop, which does not use the windows holding it): each stream's boxes are
    those of its own record."""
    sc = ivobs.scenarios.get("servo-motor")
    est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0)
    T = 200
    u = np.full((T, 1), 2.0)
    ys = [simulate_vertex(sc.system, Box(sc.x_true0, sc.x_true0), u, seed)[1] for seed in range(3)]
    ys[1][120, 0] += 50.0  # far outside the model's prediction
    batch = est.run(u, np.stack(ys))
    assert batch.inconsistent[1, 120] and not batch.inconsistent[[0, 2]].any()
    for b, y in enumerate(ys):
        ref = est.run(u, y, vectorize=False)
        np.testing.assert_allclose(batch.lower[b], ref.lower, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(batch.upper[b], ref.upper, rtol=1e-12, atol=1e-12)


def test_a_state_saved_while_a_window_is_pending_without_filled_restores():
    """States saved before ``filled`` existed count a pending window's rows in ``fresh``: such
    a state continues exactly as the uninterrupted run."""
    sc = ivobs.scenarios.get("servo-motor")
    est = ivobs.make_estimator("interval", sc.system, x0=sc.x0)
    T = 80
    u = np.full((T, 1), 2.0)
    _, y = simulate_vertex(sc.system, Box(sc.x_true0, sc.x_true0), u, 4)
    y[30:40] = np.nan
    ref = est.run(u, y)
    for k in range(41):  # the gap ends at 40: the window holds step 40 only
        est.step(u[k], y[k])
    assert est._state.fresh == 1 and est._state.filled == 1
    saved = est.state()
    del saved["state"]["filled"]
    other = ivobs.make_estimator("interval", sc.system, x0=sc.x0)
    other.restore(saved)
    for k in range(41, T):
        box = other.step(u[k], y[k])
        np.testing.assert_array_equal(box.lo, ref.lower[k])
        np.testing.assert_array_equal(box.hi, ref.upper[k])


def test_the_option_is_checked():
    sc = ivobs.scenarios.get("servo-motor")
    with pytest.raises(IvobsError, match="finite_memory"):
        ivobs.make_estimator("interval", sc.system, x0=sc.x0, finite_memory="no")
