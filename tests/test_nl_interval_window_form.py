"""nl-interval's window-centred form (src/ivobs/estimators/nonlinear/window.py): every box holds
the true state, floating-point rounding included, and boxes do not wrap on stable plants that
rotate or couple their states (``ρ(A) < 1 < ρ(|A|)``).

The linear plants are simulated exactly (tests/vertexsim.py, ``exact_linear``): each state and
output is a double, and the disturbance that makes it exact (``x+ - (A x + B u)``, ``y - C x``
in rational arithmetic) lies in its bounds, on a vertex up to the rounding of that double. The
Hénon map and the pendulum use the rigorous interval simulator of tests/exactsim.py (60 digits,
every parameter and signal on a vertex). Neither is ivobs' own simulator.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import ivobs
from exactsim import simulate as exact_record
from nlsystems import HENON_X0, henon_record
from randsys import random_nonlinear
from vertexsim import exact_linear as _simulate
from vertexsim import wrapping_plant as _plant


def _contained(res: ivobs.Result, X: np.ndarray) -> list[int]:
    """The steps whose box misses the true state."""
    bad = (res.lower > X) | (X > res.upper)
    return np.flatnonzero(bad.any(axis=1)).tolist()


@pytest.mark.parametrize("seed,n,offset,zono", [(0, 4, 0.0, 0.55), (2, 6, 1e6, 1.34)])
def test_random_stable_plants_are_contained_and_stay_bounded(seed, n, offset, zono):
    """``zono``: nl-zonotope's mean width on the same record (steps 20..80)."""
    sys, xe = _plant(seed, n, offset)
    U, X, Y = _simulate(sys, xe + 0.5, 80, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no wrapping warning
        res = ivobs.make_estimator("nl-interval", sys, x0=ivobs.Box(xe - 1.0, xe + 1.0)).run(U, Y)
    assert _contained(res, X) == []
    assert not res.inconsistent.any()
    # bounded, about as tight as a zonotope, where the box form alone grows without bound
    assert (res.upper - res.lower)[20:].mean() < 1.25 * zono


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_random_stable_plants_are_contained_over_long_runs(seed):
    n = 4 + seed
    for offset, lag, window in ((0.0, 1, 10), (1e6, 0, 3), (1e6, 2, 20)):
        sys, xe = _plant(seed, n, offset)
        U, X, Y = _simulate(sys, xe - 0.7, 200, seed)
        res = ivobs.make_estimator(
            "nl-interval", sys, x0=ivobs.Box(xe - 1.0, xe + 1.0), lag=lag, window=window
        ).run(U, Y)
        assert _contained(res, X) == [], (offset, lag, window)
        assert np.all(np.isfinite(res.upper - res.lower))


@pytest.mark.slow
@pytest.mark.parametrize("seed,n", [(0, 4), (3, 4)])
def test_within_a_few_times_the_exact_hull(seed, n):
    """The ratio of the mean widths (steps 40..300, and the last 100 steps: no drift) to the
    exact hull's: at most 5 (measured 1.16 and 1.34; over 400 steps of eight plants of 4-6
    states: BENCHMARKS.md, "nl-interval: the window-centred form")."""
    sys, _ = _plant(seed, n)
    x0 = ivobs.Box(-np.ones(n), np.ones(n))
    U, X, Y = _simulate(sys, np.zeros(n), 300, seed)
    exact = ivobs.make_estimator("exact", sys, x0=x0).run(U, Y)
    res = ivobs.make_estimator("nl-interval", sys, x0=x0).run(U, Y)
    assert _contained(res, X) == []
    we, w = (exact.upper - exact.lower)[40:], (res.upper - res.lower)[40:]
    assert np.all(w >= we - 1e-9)  # the exact hull is inside every sound box
    assert w.mean() / we.mean() <= 5.0
    assert w[-100:].mean() / we[-100:].mean() <= 5.0


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_random_nonlinear_systems_are_contained_with_the_window(seed):
    """The form forced on (``window=10``) on the random nonlinear maps of tests/randsys.py
    (polynomial and transcendental terms, uncertain parameters, nonlinear outputs), every
    unknown on a vertex at every step: contained, never inconsistent, never wider."""
    case = random_nonlinear(seed, 300)
    rec = exact_record(case.system, case.x_true0, 300, case.u, seed=seed)
    res = ivobs.make_estimator("nl-interval", case.system, x0=case.x0, window=10).run(case.u, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    assert not res.inconsistent.any()
    box = ivobs.make_estimator("nl-interval", case.system, x0=case.x0, window=0).run(case.u, rec.Y)
    assert np.all((res.upper - res.lower) <= (box.upper - box.lower) * (1 + 1e-9) + 1e-12)


def test_henon_is_contained_and_no_wider_than_the_box_form():
    sys, rec = henon_record(300, seed=4)
    res = ivobs.make_estimator("nl-interval", sys, x0=HENON_X0).run(None, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    box = ivobs.make_estimator("nl-interval", sys, x0=HENON_X0, window=0).run(None, rec.Y)
    w, wb = res.upper - res.lower, box.upper - box.lower
    assert np.all(w <= wb * (1 + 1e-9) + 1e-12)  # it only intersects


def test_pendulum_is_contained_at_every_step():
    sc = ivobs.scenarios.get("pendulum-nl", horizon=150)
    U = sc.simulate("vertex", 0).u
    rec = exact_record(sc.system, sc.x_true0, 150, U, seed=5)
    res = ivobs.make_estimator("nl-interval", sc.system, x0=sc.x0).run(U, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    box = ivobs.make_estimator("nl-interval", sc.system, x0=sc.x0, window=0).run(U, rec.Y)
    assert (res.upper - res.lower)[20:].mean() < (box.upper - box.lower)[20:].mean()


def test_an_unstable_unobserved_state_still_grows_and_is_warned_about():
    """The form does not invent what the outputs cannot see: ``x1`` grows like ``1.2^k``, the
    warning fires once, and the box still holds the true state."""
    sys = ivobs.NonlinearSystem(
        states=["x1", "x2"], f=["1.2*x1 + w1", "0.5*x2 + w2"], h=["x2 + v"],
        d={"w1": (-0.1, 0.1), "w2": (-0.1, 0.1), "v": (-0.1, 0.1)},
    )  # fmt: skip
    rec = exact_record(sys, [0.5, 0.5], 120, seed=1)
    est = ivobs.make_estimator("nl-interval", sys, x0=ivobs.Box([-1, -1], [1, 1]))
    with pytest.warns(UserWarning, match="outputs do not bound") as caught:
        res = est.run(None, rec.Y)
    assert sum("grew" in str(w.message) for w in caught) == 1
    assert rec.misses(res.lower, res.upper).tolist() == []
    assert (res.upper - res.lower)[-1, 0] > 1e6


def test_the_window_option_is_checked_and_in_the_state():
    sys, _ = _plant(0, 4)
    x0 = ivobs.Box(-np.ones(4), np.ones(4))
    with pytest.raises(ivobs.IvobsError, match="window: expected 0 to 100"):
        ivobs.make_estimator("nl-interval", sys, x0=x0, window=101)
    kink = ivobs.NonlinearSystem(f=["-abs(x)"], h=["x"], states=["x"], dt=0).discretize(
        0.5, order=2
    )
    with pytest.raises(ivobs.IvobsError, match="window: the window-centred form linearises f"):
        ivobs.make_estimator("nl-interval", kink, x0=ivobs.Box([-1.0], [1.0]), window=3)
    assert ivobs.make_estimator("nl-interval", kink, x0=ivobs.Box([-1.0], [1.0])).design.window == 0
    U, _, Y = _simulate(sys, np.zeros(4), 30, 0)
    est = ivobs.make_estimator("nl-interval", sys, x0=x0, window=5)
    for k in range(12):
        est.step(U[k], Y[k])
    saved = json.loads(json.dumps(est.state()))
    assert saved["state"]["win_F"]["shape"] == [5, 4, 4]
    full = ivobs.make_estimator("nl-interval", sys, x0=x0, window=5).run(U, Y)
    other = ivobs.make_estimator("nl-interval", sys, x0=x0, window=5)
    other.restore(saved)
    boxes = [other.step(U[k], Y[k]) for k in range(12, 30)]
    np.testing.assert_array_equal(np.array([b.lo for b in boxes]), full.lower[12:])
    np.testing.assert_array_equal(np.array([b.hi for b in boxes]), full.upper[12:])
    with pytest.raises(ivobs.IvobsError, match="another design"):
        ivobs.make_estimator("nl-interval", sys, x0=x0).restore(saved)
