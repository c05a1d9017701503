"""Data at a large scale carrying a small state (|D u| = 1e8, |x| ~ 1): step equals run within
rounding, state round trips, no false alarm, sound."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import Box, LinearSystem


def _feedthrough():
    """|D u| = 1e8 carries a state of size 1: y is only known to eps * 1e8."""
    sys = LinearSystem(
        [[0.5]], [[0.0]], [[1.0]], D=[[1e8]], E=[[1e-3]], F=[[0.0]], d=Box(-1.0, 1.0)
    )
    T = 30
    u = np.ones((T, 1))
    u[T // 2 :] = -1.0
    tr = ivobs.simulate(sys, [1.0], u=u, d=np.ones((T, 1)))
    return sys, tr


@pytest.mark.parametrize("method", ["reachability", "interval-split", "kkl", "intersect"])
def test_step_equals_run_at_a_large_data_scale(method):
    sys, tr = _feedthrough()
    opts = {"methods": ["reachability", "interval-split"]} if method == "intersect" else {}
    est = ivobs.make_estimator(method, sys, x0=Box(-1.0, 1.0), **opts)
    res = est.run(tr.u, tr.y)
    assert not res.inconsistent.any()
    est.reset()
    for k in range(10):
        box = est.step(tr.u[k], tr.y[k])
        np.testing.assert_array_equal(box.lo, res.lower[k])
        np.testing.assert_array_equal(box.hi, res.upper[k])
    saved = json.loads(json.dumps(est.state()))
    est2 = ivobs.make_estimator(method, sys, x0=Box(-1.0, 1.0), **opts)
    est2.restore(saved)
    for k in range(10, 30):
        box = est2.step(tr.u[k], tr.y[k])
        np.testing.assert_array_equal(box.lo, res.lower[k])
    assert res.contains(tr.x).all()


@pytest.mark.parametrize("method", sorted(ivobs.methods()))
def test_no_false_alarm_at_a_large_data_scale(method):
    """|D u| = 1e8 carries a state of size 1: every method's consistency test must allow for the
    rounding of y at that scale (no valid sample reported inconsistent), and stay sound."""
    sys, tr = _feedthrough()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an inconsistency report is a UserWarning
        res = ivobs.make_estimator(method, sys, x0=Box(-1.0, 1.0)).run(tr.u, tr.y)
    assert not res.inconsistent.any()
    assert res.contains(tr.x).all()
    # the state is known to the disturbance (|E d| = 1e-3) plus a margin at the scale of y
    assert np.nanmax(res.width[5:]) < 1e3
