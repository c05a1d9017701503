"""One step's inputs: the cheap test of the common case (finite float vectors of the right
lengths) vouches for nothing else, and every other input gets the full checks' errors."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError
from ivobs.estimators._inputs import lean_u_y


def _servo(T: int = 300):
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    return sc, sc.simulate("vertex", seed=3)


def test_the_cheap_input_test_vouches_only_for_finite_float_vectors():
    sc, _ = _servo(10)
    sys = sc.system  # nu = 1, ny = 2
    u, y = np.array([0.5]), np.array([1.0, -2.0])
    assert lean_u_y(sys, u, y) is not None
    for bad_u, bad_y in [
        (np.array([np.nan]), y),
        (np.array([np.inf]), y),
        (u, np.array([np.nan, 1.0])),  # a missing sample: the full path handles it
        (u, np.array([np.inf, 1.0])),
        (u, np.array([1e308, 1e308])),  # finite, the sum overflows
        (u, np.array([1.0, 2.0, 3.0])),
        (u, np.array([[1.0, 2.0]])),
        (u, np.array([1, 2])),  # integers: converted by the full path
        ([0.5], y),
        (None, y),
    ]:
        assert lean_u_y(sys, bad_u, bad_y) is None


@pytest.mark.parametrize("method", ["reachability", "interval-split", "kkl"])
def test_bad_step_inputs_still_get_the_full_errors(method):
    sc, tr = _servo(10)
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, on_inconsistent="ignore")
    with pytest.raises(IvobsError, match="y_k: infinite measurement"):
        est.step(tr.u[0], np.array([np.inf, 0.0]))
    with pytest.raises(IvobsError, match="u_k"):
        est.step(np.array([np.nan]), tr.y[0])
    with pytest.raises(IvobsError, match="u_k"):
        est.step(np.array([np.inf]), tr.y[0])
    with pytest.raises(IvobsError, match="y_k: expected 2"):
        est.step(tr.u[0], np.zeros(3))
    with pytest.raises(IvobsError, match="t: this system is discrete-time"):
        est.step(tr.u[0], tr.y[0], t=0.1)
    assert est.k == 0  # no failed call moved the estimator on
    box = est.step(tr.u[0], np.array([np.nan, tr.y[0, 1]]))  # missing: the full path, then on
    assert np.isfinite(box.lo).all() and est.k == 1
    box2 = est.step(np.array([1], dtype=np.int64), np.array([1, 2], dtype=np.int64))
    assert np.isfinite(box2.hi).all() and est.k == 2
