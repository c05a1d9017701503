"""Proven rounding of ``nl-interval`` and ``nl-zonotope``: no margin is added to their bounds, so
these check what the proofs promise at every magnitude.

* A sample within rounding of its bound is consistent: ``y = -0.1 + -0.005`` is
  ``-0.10500000000000001`` in doubles, 4e-18 beyond the exact set's end ``-0.105``; a sample
  a few ulps further is a fault.
* The same plant written at scales 1e-6 to 1e10: every box contains the exact state
  (tests/exactsim.py), no sample is flagged, and the widths divided by the scale are the same at
  every scale up to rounding (a margin relative to ``1 + |bound|`` would not be).
* Coefficients up to 1e3; saved states of magnitude 1e10 round-trip through JSON.
"""

from __future__ import annotations

import json
import math
import warnings

import numpy as np
import pytest

import ivobs
from nlsystems import simulate

METHODS = ["nl-interval", "nl-zonotope"]


def _one_state(kind: str) -> ivobs.NonlinearSystem | ivobs.LinearSystem:
    """``x+ = 0.5 x + w``, ``y = x + v``, ``|w| <= 0.01``, ``|v| <= 0.005``."""
    if kind == "nonlinear":
        return ivobs.NonlinearSystem(
            f=["0.5*x1 + w1"],
            h=["x1 + v1"],
            states=["x1"],
            d={"w1": (-0.01, 0.01), "v1": (-0.005, 0.005)},
        )
    d = ivobs.Box([-0.01, -0.005], [0.01, 0.005])
    return ivobs.LinearSystem(
        [[0.5]], np.zeros((1, 0)), [[1.0]], E=[[1.0, 0.0]], F=[[0.0, 1.0]], d=d
    )


@pytest.mark.parametrize("kind", ["nonlinear", "linear"])
@pytest.mark.parametrize("method", METHODS)
def test_a_sample_within_rounding_of_its_bound_is_consistent(method: str, kind: str) -> None:
    """The state starts on a corner of the prior box and the noise sits on its bound (one
    state, two samples, each the double of a float computation)."""
    sys = _one_state(kind)
    x = np.array([[-0.1], [0.5 * -0.1 + -0.01]])
    y = x + -0.005
    assert y[0, 0] == -0.10500000000000001
    est = ivobs.make_estimator(method, sys, x0=ivobs.Box([-0.1], [0.1]), on_inconsistent="raise")
    res = est.run(np.zeros((2, 0)), y)
    assert not res.inconsistent.any()
    assert np.all(res.lower <= x) and np.all(x <= res.upper)
    beyond = y.copy()
    beyond[0, 0] = -0.105 - 8 * math.ulp(0.105)  # no rounding of an admissible sample
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        flagged = ivobs.make_estimator(method, sys, x0=ivobs.Box([-0.1], [0.1])).run(None, beyond)
    assert flagged.inconsistent.tolist() == [True, False]


def _plant(scale: float) -> ivobs.NonlinearSystem:
    """A contracting map with an uncertain parameter, written for states of magnitude
    ``scale``: ``x1+ = 0.6 x1 - a x2²/s + w1``, ``x2+ = 0.5 x2 + 0.3 x1 + w2``,
    ``y = x1 + v``, the bounds of ``w`` and ``v`` proportional to ``s``."""
    s = repr(scale)
    return ivobs.NonlinearSystem(
        f=[f"0.6*x1 - a*x2**2/{s} + w1", "0.5*x2 + 0.3*x1 + w2"],
        h=["x1 + v1"],
        states=["x1", "x2"],
        params={"a": (0.1, 0.2)},
        d={
            "w1": (-0.01 * scale, 0.01 * scale),
            "w2": (-0.01 * scale, 0.01 * scale),
            "v1": (-0.02 * scale, 0.02 * scale),
        },
    )


@pytest.mark.parametrize("method", METHODS)
def test_containment_and_relative_widths_at_every_scale(method: str) -> None:
    T = 400
    widths = {}
    for scale in (1e-6, 1.0, 1e6, 1e10):
        sys = _plant(scale)
        rec = simulate(sys, [0.3 * scale, 0.1 * scale], T, seed=4)
        x0 = ivobs.Box([-scale, -scale], [scale, scale])
        res = ivobs.make_estimator(method, sys, x0=x0).run(None, rec.Y)
        assert rec.misses(res.lower, res.upper).tolist() == [], scale
        assert not res.inconsistent.any(), scale
        widths[scale] = (res.upper - res.lower).mean(axis=0) / scale
    for scale, w in widths.items():
        np.testing.assert_allclose(w, widths[1.0], rtol=1e-9, err_msg=f"scale {scale}")
    assert np.all(widths[1.0] < [0.02, 0.06])  # the noise band on x1, x2 through the map


@pytest.mark.parametrize("method", METHODS)
def test_coefficients_up_to_1e3_are_contained(method: str) -> None:
    sys = ivobs.NonlinearSystem(
        f=["0.5*x1 + 1000*sin(x2) + w1", "0.8*x2 + 0.0001*x1 + w2"],
        h=["x1 + v1", "x2 + 0.001*x1**2/1000 + v2"],
        states=["x1", "x2"],
        d={"w1": (-1.0, 1.0), "w2": (-0.01, 0.01), "v1": (-2.0, 2.0), "v2": (-0.02, 0.02)},
    )
    rec = simulate(sys, [500.0, 0.5], 400, seed=6)
    res = ivobs.make_estimator(method, sys, x0=ivobs.Box([0, -1], [1000, 1])).run(None, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    assert not res.inconsistent.any()
    assert (res.upper - res.lower)[20:, 0].max() < 4.0 + 1e-9  # the measurement band of x1


@pytest.mark.parametrize("method", METHODS)
def test_a_state_of_magnitude_1e10_round_trips(method: str) -> None:
    sys = _plant(1e10)
    rec = simulate(sys, [3e9, 1e9], 40, seed=2)
    x0 = ivobs.Box([-1e10, -1e10], [1e10, 1e10])
    ref = ivobs.make_estimator(method, sys, x0=x0).run(None, rec.Y)
    est = ivobs.make_estimator(method, sys, x0=x0)
    boxes = [est.step(None, rec.Y[k]) for k in range(20)]
    saved = json.loads(json.dumps(est.state()))
    other = ivobs.make_estimator(method, _plant(1e10), x0=x0)
    other.restore(saved)
    boxes += [other.step(None, rec.Y[k]) for k in range(20, 40)]
    lo, hi = np.array([b.lo for b in boxes]), np.array([b.hi for b in boxes])
    np.testing.assert_array_equal(lo, ref.lower)
    np.testing.assert_array_equal(hi, ref.upper)
    assert np.all(lo <= hi) and rec.misses(lo, hi).tolist() == []
