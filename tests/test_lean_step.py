"""The lean path of ``step()`` (issue 17): one step's float vectors are checked cheaply and its
bounds rounded in Python floats; the numbers are the full path's bit for bit, and every input the
cheap test does not vouch for goes through the full checks (the same errors as before)."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem
from ivobs.estimators._inputs import lean_u_y
from ivobs.estimators.rounding import lean_outward, outward
from ivobs.estimators.scale import DataScale

RECURSIVE = [
    "reachability",
    "zonotope",
    "interval",
    "interval-split",
    "interval-transformed",
    "fixed-time",
    "kkl",
    "strip",
]


def _servo(T: int = 300):
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    return sc, sc.simulate("vertex", seed=3)


@pytest.mark.parametrize("method", RECURSIVE)
def test_lean_step_equals_the_checked_step_and_run_bit_for_bit(method):
    sc, tr = _servo()
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    res = est.run(tr.u, tr.y, vectorize=False)  # the loop, rounded by outward() over the record
    est.reset()
    lean = [est.step(tr.u[k], tr.y[k]) for k in range(len(tr.y))]
    est.reset()  # lists are not vouched for by the cheap test: the full checks
    full = [est.step(tr.u[k].tolist(), tr.y[k].tolist()) for k in range(len(tr.y))]
    for k, (a, b) in enumerate(zip(lean, full, strict=True)):
        assert a.lo.tobytes() == b.lo.tobytes() and a.hi.tobytes() == b.hi.tobytes(), k
        if k >= est.valid_from:
            assert a.lo.tobytes() == res.lower[k].tobytes(), k
            assert a.hi.tobytes() == res.upper[k].tobytes(), k
    ok = res.contains(tr.x)[est.valid_from :]
    assert ok.all()


def test_lean_outward_is_outward_bit_for_bit():
    rng = np.random.default_rng(0)
    for n in (1, 3, 7, 32):
        for mag in (1e-300, 1e-8, 1.0, 1e8, 1e300):
            lo = rng.standard_normal(n) * mag
            hi = lo + np.abs(rng.standard_normal(n)) * mag
            lo[0] = -0.0
            for scale in (0.0, 3.7, 1e12):
                got = lean_outward(lo, hi, scale)
                assert got is not None
                ref = outward(lo.copy(), hi.copy(), scale)
                assert got[0].tobytes() == ref[0].tobytes()
                assert got[1].tobytes() == ref[1].tobytes()


@pytest.mark.parametrize(
    "lo, hi",
    [
        ([np.nan, 0.0], [1.0, 1.0]),
        ([0.0, 0.0], [np.inf, 1.0]),
        ([-1e308, -1e308], [1e308, 1e308]),  # finite bounds whose sum overflows
        ([1.0, 2.0, 3.0], [4.0, 5.0]),  # shapes differ
    ],
)
def test_lean_outward_leaves_the_unusual_to_the_full_path(lo, hi):
    assert lean_outward(np.array(lo), np.array(hi), 0.0) is None
    assert lean_outward(np.zeros(40), np.ones(40), 0.0) is None  # long: NumPy
    assert lean_outward(np.zeros(3, dtype=np.float32), np.ones(3), 0.0) is None


def test_short_data_scale_equals_the_array_path():
    sys = LinearSystem(
        [[0.5, 0.1], [0.0, 0.3]],
        [[1.0, -2.0], [0.5, 0.0]],
        [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
        D=[[0.0, 3.0], [0.0, 0.0], [1.0, 0.0]],
        E=np.eye(2),
        F=np.ones((3, 2)) * 0.1,
        d=Box([-1.0, -2.0], [1.0, 0.5]),
    )
    rng = np.random.default_rng(1)
    scales = DataScale(sys)
    scales.terms(0)  # caches the constant terms: of_step takes the float path from now on
    assert scales._steady_list is not None
    for _ in range(200):
        u = rng.standard_normal(2) * 10.0 ** rng.integers(-5, 9)
        y = rng.standard_normal(3) * 10.0 ** rng.integers(-5, 9)
        y[rng.random(3) < 0.3] = np.nan
        g, c = scales.terms(0)
        ref = c
        m = np.fmax.reduce(np.abs(y))
        if m == m:
            ref = max(ref, float(m))
        ref = max(ref, float(np.max(np.abs(u) * g)))
        assert scales.of_step(0, u, y, None) == ref


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
