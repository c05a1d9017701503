"""nl-horizon: containment on range-only, never wider than its inner nl-constrained-zonotope,
tighter late in the run, within a stated ratio of the linearised exact hull over 320 steps, state
round trip, options, and the rows' inequalities themselves."""

from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest

import ivobs
from ivobs.errors import IvobsError
from ivobs.estimators.nonlinear.horizon import dynamics_row, measurement_row
from ivobs.scenarios import registry
from ivobs.scenarios.nonlinear import RANGE_BEACONS, RANGE_STEP
from linearised import linearised_along

H = RANGE_STEP


def _f(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """range-only's map, written out (w = (om, w1, w2, r1, r2, c))."""
    px, py, v, th = x
    return np.array(
        [px + H * v * np.cos(th), py + H * v * np.sin(th), v + w[1], th + H * w[0] + w[2]]
    )


def _h(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    ranges = [np.hypot(x[0] - bx, x[1] - by) + w[3 + i] for i, (bx, by) in enumerate(RANGE_BEACONS)]
    return np.array([*ranges, x[3] + w[5]])


def _simulate(T: int, seed: int = 0) -> tuple[ivobs.NonlinearSystem, ivobs.Box, np.ndarray, ...]:
    """range-only with every unknown on a vertex of its bounds at every step."""
    sc = registry.get("range-only", horizon=T)
    W = sc.system.w_box
    rng = np.random.default_rng(seed)
    x = np.array([0.0, 0.0, 1.0, 0.0])
    xs, ys = [], []
    for _ in range(T):
        w = np.where(rng.random(W.lo.size) < 0.5, W.lo, W.hi)
        xs.append(x)
        ys.append(_h(x, w))
        x = _f(x, w)
    return sc.system, sc.x0, np.array(xs), np.array(ys)


@pytest.fixture(scope="module")
def run120() -> tuple[np.ndarray, ...]:
    sys, x0, x, y = _simulate(120)
    u = np.zeros((120, 0))
    res = ivobs.make_estimator("nl-horizon", sys, x0, window=10).run(u, y)
    cz = ivobs.make_estimator("nl-constrained-zonotope", sys, x0).run(u, y)
    return x, res.lower, res.upper, cz.lower, cz.upper


def test_contains_the_state_at_every_step_with_disturbances_on_vertices(run120):
    x, lo, hi, _, _ = run120
    assert np.all(lo <= x) and np.all(x <= hi)


def test_never_wider_than_the_inner_constrained_zonotope_filter(run120):
    _, lo, hi, cz_lo, cz_hi = run120
    assert np.all(lo >= cz_lo) and np.all(hi <= cz_hi)


def test_tighter_than_nl_constrained_zonotope_late_in_the_run(run120):
    # measured (window 10, mean widths over steps 60-119, relative to nl-constrained-zonotope):
    # px 0.44, py 0.60, v 0.81, th 0.76
    _, lo, hi, cz_lo, cz_hi = run120
    late = slice(60, None)
    ratio = (hi - lo)[late].mean(axis=0) / (cz_hi - cz_lo)[late].mean(axis=0)
    assert ratio[0] < 0.5
    assert np.all(ratio < 0.85)


@pytest.mark.parametrize("kind", ["vertex", "uniform"])
def test_late_widths_within_a_stated_ratio_of_the_linearised_exact_hull(kind):
    """Over 320 steps (window 20), the mean width of every state over the second half is at most
    1.25 times that of the exact hull of the model linearised along the true trajectory
    (measured 1.00-1.15), and the boxes contain the state throughout."""
    T = 320
    sc = registry.get("range-only", horizon=T)
    tr = sc.simulate(kind, seed=1)
    res = ivobs.make_estimator("nl-horizon", sc.system, x0=sc.x0).run(tr.u, tr.y)
    assert res.contains(tr.x).all()
    lin, u_lin = linearised_along(sc.system, tr)
    ref = ivobs.make_estimator("exact", lin, x0=sc.x0, window=20).run(u_lin, tr.y)
    late = slice(T // 2, None)
    ratio = res.width[late].mean(axis=0) / ref.width[late].mean(axis=0)
    assert np.all(ratio <= 1.25), ratio


def test_state_round_trip_through_json_continues_identically():
    sys, x0, _, y = _simulate(40, seed=3)
    a = ivobs.make_estimator("nl-horizon", sys, x0, window=6)
    boxes = [a.step(None, y[k]) for k in range(25)]
    saved = json.loads(json.dumps(a.state()))
    b = ivobs.make_estimator("nl-horizon", sys, x0, window=6)
    b.restore(saved)
    for k in range(25, 40):
        ba, bb = a.step(None, y[k]), b.step(None, y[k])
        assert np.array_equal(ba.lo, bb.lo) and np.array_equal(ba.hi, bb.hi)
    assert len(boxes) == 25


@pytest.mark.parametrize(
    ("options", "name"),
    [({"window": 0}, "window"), ({"window": "ten"}, "window"), ({"passes": -1}, "passes"),
     ({"passes": 1.5}, "passes")],
)  # fmt: skip
def test_bad_options_raise_naming_the_argument(options, name):
    sc = registry.get("range-only", horizon=5)
    with pytest.raises(IvobsError, match=name):
        ivobs.make_estimator("nl-horizon", sc.system, sc.x0, **options)


def _exact(v: np.ndarray) -> list[Fraction]:
    return [Fraction(float(a)) for a in v]


def test_the_rows_hold_at_every_point_of_their_boxes():
    """(D) and (M) of the module docstring at random points of random boxes, the linear part
    evaluated exactly (fractions); the maps in floats (their rounding is far below the
    record margin the rows carry)."""
    sys = registry.get("range-only", horizon=5).system
    W = sys.w_box
    rng = np.random.default_rng(7)
    for _ in range(20):
        c = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(0.5, 1.5),
                      rng.uniform(-3, 3)])  # fmt: skip
        r = rng.uniform(0.0, 0.3, 4)
        lo, hi = c - r, c + r
        dyn = dynamics_row(sys, lo, hi, np.zeros(0), W.lo, W.hi)
        for _ in range(10):
            x = rng.uniform(lo, hi)
            w = rng.uniform(W.lo, W.hi)
            f = _f(x, w)
            y = _h(x, w)
            meas = measurement_row(sys, lo, hi, np.zeros(0), y, W.lo, W.hi)
            xe, we = _exact(x), _exact(w)
            for i in range(4):
                lin = sum(Fraction(float(a)) * b for a, b in zip(dyn.A[i], xe)) + sum(
                    Fraction(float(a)) * b for a, b in zip(dyn.E[i], we)
                )
                gap = Fraction(float(f[i])) - lin - Fraction(float(dyn.bu[i]))
                assert abs(gap) <= Fraction(float(dyn.tau[i]))
            for i in range(y.size):
                lin = sum(Fraction(float(a)) * b for a, b in zip(meas.C[i], xe)) + sum(
                    Fraction(float(a)) * b for a, b in zip(meas.F[i], we)
                )
                assert abs(lin - Fraction(float(meas.rhs[i]))) <= Fraction(float(meas.tau[i]))


def test_missing_components_are_free_rows():
    sys = registry.get("range-only", horizon=5).system
    W = sys.w_box
    y = np.array([np.nan, 9.0, 0.1])
    meas = measurement_row(sys, np.full(4, -0.1), np.full(4, 0.1), np.zeros(0), y, W.lo, W.hi)
    assert np.isnan(meas.rhs[0]) and not np.isnan(meas.rhs[1:]).any()


SCENARIO_STEPS = {"henon-nl": 80, "pendulum-nl": 80, "cora-tank6-nl": 15, "cstr": 80,
                  "unicycle-range": 60, "range-only": 60, "chain10-nl": 10}  # fmt: skip
"""Short runs (the long ones: benchmarks/bench_nl_sound.py, BENCHMARKS.md)."""


@pytest.mark.parametrize("name", list(SCENARIO_STEPS))
def test_contains_the_exact_vertex_trajectory_of_every_nonlinear_scenario(name):
    from nlsystems import simulate

    T = SCENARIO_STEPS[name]
    sc = ivobs.scenarios.get(name, horizon=T)
    rec = simulate(sc.system, sc.x_true0, T, sc.u if sc.system.nu else None, seed=7)
    res = ivobs.make_estimator("nl-horizon", sc.system, x0=sc.x0).run(sc.u, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    assert not res.inconsistent.any()
