"""``dual-window``: the moving-window exact hull certified from cached LP multipliers.

Containment is checked against a simulator written here (the model's equations with
vertex disturbances, in floating point), on the quadruple tank [Johansson2000] and the DC servo
of [Tang2019, Section VII] at every step; tightness against ``exact`` with the same window; the
protocol (``step()`` equals ``run()``, a saved and restored state continues identically); and
the refusals.
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem
from vertexsim import simulate_vertex


def quadtank(T):
    sc = ivobs.scenarios.get("quadruple-tank", horizon=T)
    return sc.system, sc.x0, sc.u


def servo(T):
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    u = np.random.default_rng(1).normal(size=(T, sc.system.nu))
    return sc.system, sc.x0, u


@pytest.mark.parametrize("plant", [quadtank, servo])
def test_every_box_contains_the_true_state(plant):
    """600 steps (six refreshes of the cache after the window fills), two disturbance records:
    every box, at every step, contains the simulated state."""
    sys, x0, u = plant(600)
    est = ivobs.make_estimator("dual-window", sys, x0=x0, window=40, refresh=100)
    for seed in (0, 1):
        x, y = simulate_vertex(sys, x0, u, seed)
        res = est.run(u, y)
        inside = (res.lower <= x) & (x <= res.upper)
        assert inside.all(), np.argwhere(~inside)[:5]
        assert not res.inconsistent.any()


def test_random_multipliers_give_sound_bounds():
    """The certificate holds for any multipliers, not only the LP's: a cache filled with random
    ones (and no solve: ``refresh`` beyond the record) still contains the true state."""
    sys, x0, u = quadtank(200)
    x, y = simulate_vertex(sys, x0, u, 3)
    est = ivobs.make_estimator("dual-window", sys, x0=x0, window=20, cache=4, refresh=10**6)
    st = est.initial_state()
    rng = np.random.default_rng(0)
    st = type(st)(**{**st.__dict__, "mu": rng.normal(scale=3.0, size=st.mu.shape), "since": -5})
    for k in range(200):
        st, box = est.advance(st, u[k], y[k])
        assert np.all(box.lo <= x[k]) and np.all(x[k] <= box.hi), k


def test_within_a_few_percent_of_the_exact_hull_of_the_same_window():
    """300 steps of the quadruple tank, window 30 for both, the cache refreshed every 5 steps:
    the mean width of every level from step 100 on is within 1.1x the exact hull's (and not
    below it by more than the solver's tolerances)."""
    sys, x0, u = quadtank(300)
    x, y = simulate_vertex(sys, x0, u, 0)
    dual = ivobs.make_estimator("dual-window", sys, x0=x0, window=30, refresh=5).run(u, y)
    exact = ivobs.make_estimator("exact", sys, x0=x0, window=30).run(u, y)
    assert dual.contains(x).all()
    ratio = dual.width[100:].mean(axis=0) / exact.width[100:].mean(axis=0)
    assert np.all(ratio <= 1.1), ratio
    assert np.all(ratio >= 0.999), ratio


def test_step_equals_run_and_a_restored_state_continues_identically():
    """``step()`` through 160 steps (solves at warm-up and every 25 steps) gives ``run()``'s boxes
    exactly; a state saved at step 90 (through JSON) and restored into a new estimator
    continues with the same boxes."""
    sys, x0, u = quadtank(160)
    _, y = simulate_vertex(sys, x0, u, 5)
    est = ivobs.make_estimator("dual-window", sys, x0=x0, window=20, refresh=25)
    res = est.run(u, y)
    est.reset()
    saved = None
    for k in range(160):
        box = est.step(u[k], y[k])
        assert np.array_equal(box.lo, res.lower[k]) and np.array_equal(box.hi, res.upper[k]), k
        if k == 89:
            saved = json.dumps(est.state())
    other = ivobs.make_estimator("dual-window", sys, x0=x0, window=20, refresh=25)
    other.restore(json.loads(saved))
    for k in range(90, 160):
        box = other.step(u[k], y[k])
        assert np.array_equal(box.lo, res.lower[k]) and np.array_equal(box.hi, res.upper[k]), k


def test_a_gross_fault_is_reported_and_a_missing_component_is_used_around():
    """A sensor reading 5 V off at step 150 is reported inconsistent and not used; with ``h1``'s
    sensor missing for 30 steps the boxes stay sound and ``h2``'s sensor still narrows ``h2``
    (less than half as wide as with both missing)."""
    sys, x0, u = quadtank(300)
    x, y = simulate_vertex(sys, x0, u, 7)
    est = ivobs.make_estimator("dual-window", sys, x0=x0, window=30, on_inconsistent="ignore")
    faulty = y.copy()
    faulty[150, 0] += 5.0
    res = est.run(u, faulty)
    assert np.flatnonzero(res.inconsistent).tolist() == [150]
    assert res.contains(x).all()
    one, both = y.copy(), y.copy()
    one[200:230, 0] = np.nan
    both[200:230] = np.nan
    r_one, r_both = est.run(u, one), est.run(u, both)
    assert r_one.contains(x).all() and r_both.contains(x).all()
    assert r_one.width[200:230, 1].mean() < 0.5 * r_both.width[200:230, 1].mean()


def test_refuses_what_it_cannot_certify():
    """Time-varying matrices, interval matrices and disturbance bounds that vary with ``k``
    are refused with an error naming ``sys``; so are bad options."""
    sys, x0, _ = quadtank(10)
    A, B, C, D, E, F = sys.matrices_at(0)
    tv = LinearSystem(lambda k: A, B, C, D, E, F, d=sys.d_at(0))
    unc = LinearSystem(Box(A - 1e-3, A + 1e-3), B, C, D, E, F, d=sys.d_at(0))
    lo = np.tile(sys.d_at(0).lo, (10, 1))
    tvd = LinearSystem(A, B, C, D, E, F, d=Box(lo, -lo))
    for bad in (tv, unc, tvd):
        with pytest.raises(IvobsError, match="sys"):
            ivobs.make_estimator("dual-window", bad, x0=x0)
    for opt in ({"window": 0}, {"cache": 1.5}, {"refresh": "often"}):
        with pytest.raises(IvobsError, match=next(iter(opt))):
            ivobs.make_estimator("dual-window", sys, x0=x0, **opt)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ivobs.make_estimator("dual-window", sys, x0=x0)


def test_the_adaptive_interval_keeps_the_default_within_a_few_percent_of_the_hull():
    """Disturbances on the vertices of their box change the optimal multipliers at nearly every
    step: with the default (adaptive) interval between solves the mean width over 300 steps of
    a rotating 2-state system is within 1.05x the full-horizon exact hull (measured: 1.03; 1.48
    with a solve every 60 steps), every box holds the simulated state, and a saved state
    carries the interval."""
    A = np.array([[0.9, 0.4], [-0.4, 0.85]])
    sys = LinearSystem(A, np.zeros((2, 1)), [[1.0, 0.0]], E=[[0.3, 0.0], [0.1, 0.0]],
                       F=[[0.0, 1.0]], d=Box([-0.1, -0.05], [0.1, 0.05]))  # fmt: skip
    x0 = Box([-1.0, -1.0], [1.0, 1.0])
    u = np.zeros((300, 1))
    x, y = simulate_vertex(sys, x0, u, 2)
    exact = ivobs.make_estimator("exact", sys, x0=x0).run(u, y)
    adaptive = ivobs.make_estimator("dual-window", sys, x0=x0, window=20).run(u, y)
    fixed = ivobs.make_estimator("dual-window", sys, x0=x0, window=20, refresh_tol=None)
    stale = fixed.run(u, y)
    assert adaptive.contains(x).all() and stale.contains(x).all()
    ratio = adaptive.width.mean() / exact.width.mean()
    assert 0.999 <= ratio <= 1.05, ratio
    assert stale.width.mean() > 1.2 * adaptive.width.mean()  # what the fixed interval costs
    est = ivobs.make_estimator("dual-window", sys, x0=x0, window=20)
    for k in range(150):
        est.step(u[k], y[k])
    saved = json.loads(json.dumps(est.state()))
    assert 1 <= saved["state"]["period"] <= est.design.refresh
