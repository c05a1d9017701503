"""``interval`` / ``interval-split`` after missing samples: the width returns to the complete
observer's within ``N`` complete steps (the observability index) after a gap of any length, and
stays bounded when single outputs go missing at random; the truth stays inside at every step
(disturbances on the vertices of their bounds). Module :mod:`ivobs.estimators.interval.window`."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import Box, LinearSystem
from ivobs.testing import adversarial_run, assert_contains

FAMILY = ["interval", "interval-split"]


def servo(method):
    sc = ivobs.scenarios.get("servo-motor")
    return sc, ivobs.make_estimator(method, sc.system, x0=sc.x0)


def summed(res):
    return res.width.sum(axis=-1)


@pytest.mark.slow
@pytest.mark.parametrize(("method", "T"), [("interval", 100_000), ("interval-split", 20_000)])
def test_one_output_missing_at_random_stays_bounded(method, T):
    """3 % of the speed measurement missing at random: the summed width used to grow without
    bound (3,380 at k = 20,000, 1.25e8 at 200,000); now it stays below the complete observer's
    steady width (254.4) over 10⁵ steps. (interval-split runs the same recursion with the same
    gain here: a shorter record keeps the test short.)"""
    sc, est = servo(method)
    steady = float(est.design.steady_width.sum())
    assert steady == pytest.approx(254.4006, abs=1e-3)
    tr = adversarial_run(sc.system, sc.x0, T, seed=3)
    y = tr.y.copy()
    y[np.random.default_rng(5).random(T) < 0.03, 1] = np.nan
    res = est.run(tr.u, y)
    assert_contains(res, tr.x)
    assert not res.inconsistent.any()
    w = summed(res)
    assert w[-1] < 2.0 * steady
    assert w.max() < 0.5 * steady  # measured: 52.7 (interval, 10⁵ steps)


@pytest.mark.parametrize("method", FAMILY)
@pytest.mark.parametrize("length", [1, 50, 500])
def test_a_gap_of_any_length_returns_within_two_steps(method, length):
    """A gap of the speed sensor (and of both sensors) of 1, 50 or 500 steps: the width grows in
    the gap (1.077 per step, 2.9e18 after 500 steps) and used to come back at 0.9995 per step
    (a 50-step gap: 29,000, still 894 after 10,000 steps). Two complete steps after the gap
    (N = 2, the observability index of the servo) the summed width is within 10 % of the
    complete record's, and stays there."""
    sc, est = servo(method)
    T, start = 1200, 600
    end = start + length
    tr = adversarial_run(sc.system, sc.x0, T, seed=4)
    full = summed(est.run(tr.u, tr.y))
    for comp in (1, slice(None)):
        y = tr.y.copy()
        y[start:end, comp] = np.nan
        res = est.run(tr.u, y)
        assert_contains(res, tr.x)
        w = summed(res)
        if length >= 50:
            assert w[end] > 20.0 * full[end]  # the gap did widen the bounds
        assert np.all(w[end + 2 :] <= 1.1 * full[end + 2 :])
    assert est.operators.window.N == 2


def test_restore_inside_the_window_continues_identically():
    """A state saved between a gap and the window's intersection restores to the same
    continuation."""
    sc, est = servo("interval")
    tr = adversarial_run(sc.system, sc.x0, 120, seed=6)
    y = tr.y.copy()
    y[50:60, 1] = np.nan
    ref = est.run(tr.u, y)
    run = ivobs.make_estimator("interval", sc.system, x0=sc.x0)
    for k in range(61):  # the gap ends at 60: the window holds step 60 only
        run.step(tr.u[k], y[k])
    assert run._state.fresh == 1
    saved = run.state()
    other = ivobs.make_estimator("interval", sc.system, x0=sc.x0)
    other.restore(saved)
    for k in range(61, 120):
        box = other.step(tr.u[k], y[k])
        np.testing.assert_array_equal(box.lo, ref.lower[k])
        np.testing.assert_array_equal(box.hi, ref.upper[k])


def _random_system(seed):
    """Observable through one output only after nx steps (N = nx), with feedthrough and
    measurement noise; |A| Schur so that L = 0 is an admissible interval-split gain."""
    rng = np.random.default_rng(seed)
    n = 3
    A = rng.normal(size=(n, n))
    A *= 0.9 / max(abs(np.linalg.eigvals(np.abs(A))))
    C = rng.normal(size=(1, n))
    return LinearSystem(
        A,
        rng.normal(size=(n, 1)),
        C,
        D=rng.normal(size=(1, 1)),
        E=np.hstack([rng.normal(size=(n, 2)), np.zeros((n, 1))]),
        F=np.hstack([np.zeros((1, 2)), rng.normal(size=(1, 1))]),
        d=Box(-rng.random(3), rng.random(3)),
    )


@pytest.mark.parametrize("seed", range(6))
def test_window_bound_contains_the_truth_on_random_systems(seed):
    """Soundness of the finite-memory bound (longer windows, feedthrough, noise): containment
    at every step with 20 % of the samples missing and vertex disturbances."""
    sys = _random_system(seed)
    x0 = Box(-np.ones(3), np.ones(3))
    est = ivobs.make_estimator("interval-split", sys, x0=x0, L=np.zeros((3, 1)))
    assert est.operators.window is not None and est.operators.window.N == 3
    tr = adversarial_run(sys, x0, 400, seed=seed)
    y = tr.y.copy()
    y[np.random.default_rng(seed).random(400) < 0.2] = np.nan
    res = est.run(tr.u, y)
    assert_contains(res, tr.x)
    assert not res.inconsistent.any()
    # the window's intersection did tighten the open-loop bounds
    assert summed(res)[-1] < summed(est.run(tr.u, np.full_like(y, np.nan)))[-1]


def test_a_state_saved_without_the_window_entries_restores():
    """States saved before the window existed (no ``window``/``fresh`` entries) restore with
    no window pending."""
    sc, est = servo("interval-split")
    tr = adversarial_run(sc.system, sc.x0, 30, seed=7)
    for k in range(10):
        est.step(tr.u[k], tr.y[k])
    saved = est.state()
    del saved["state"]["window"], saved["state"]["fresh"]
    other = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0)
    other.restore(saved)
    assert other._state.fresh == -1 and other._state.window.shape == (2, 3)
    np.testing.assert_array_equal(
        other.step(tr.u[10], tr.y[10]).hi, est.step(tr.u[10], tr.y[10]).hi
    )
