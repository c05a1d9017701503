"""Boxes never wider than the data (:mod:`ivobs.estimators.measured`): every box of ``x[k]``
met with the measurement strips of ``y[k]``. The servo of [Tang2019] measures its angle and
speed directly (noise ±0.0564): no method's box of those states may be wider than the sensor's
band, and every box still contains the true state of a float64 simulation written here, with
the disturbances on the vertices of their box."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from vertexsim import servo_vertex

T = 120
# every linear method, but the two that solve programs each step (tested at length elsewhere)
METHODS = [
    m
    for m in ivobs.methods()
    if not m.startswith("nl-") and m not in ("constrained-zonotope", "exact")
]


def _servo(seed: int = 0):
    return servo_vertex(T, seed)


@pytest.mark.parametrize("method", METHODS)
def test_no_measured_state_is_wider_than_its_sensor(method: str) -> None:
    sc, u, x, y = _servo()
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, strips=True)
    res = est.run(u, y)
    vf = est.valid_from
    band = 2 * 0.0564  # the noise on each measured state
    assert np.all(res.width[vf:, :2] <= band * (1 + 1e-9)), res.width[vf:, :2].max(axis=0)
    tol = 1e-12 * (1 + np.abs(x[vf:]))
    assert np.all((res.lower[vf:] <= x[vf:] + tol) & (x[vf:] - tol <= res.upper[vf:]))
    assert not res.inconsistent.any()


def test_defaults_follow_the_data_used() -> None:
    sc = ivobs.scenarios.get("servo-motor")
    assert ivobs.make_estimator("kkl", sc.system, x0=sc.x0).strips  # filter form
    assert not ivobs.make_estimator("reachability", sc.system, x0=sc.x0).strips  # the paper's
    with pytest.raises(ivobs.IvobsError, match="strips: expected True, False or None"):
        ivobs.make_estimator("kkl", sc.system, x0=sc.x0, strips="yes")


def test_the_strips_narrow_a_prediction_observer_and_keep_the_truth() -> None:
    sc, u, _, y = _servo(1)
    paper = ivobs.make_estimator("reachability", sc.system, x0=sc.x0).run(u, y)
    met = ivobs.make_estimator("reachability", sc.system, x0=sc.x0, strips=True).run(u, y)
    assert np.all(met.lower >= paper.lower) and np.all(met.upper <= paper.upper)
    assert met.mean_width(10)[0] < 0.7 * paper.mean_width(10)[0]
    np.testing.assert_array_equal(met.width[:, 2], paper.width[:, 2])  # unmeasured: unchanged


def test_step_loop_and_vectorised_run_agree() -> None:
    sc, u, _, y = _servo(2)
    y[30:35, 0] = np.nan  # missing samples: no strip
    est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, strips=True)
    vec, loop = est.run(u, y, vectorize=True), est.run(u, y, vectorize=False)
    np.testing.assert_allclose(vec.lower, loop.lower, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(vec.upper, loop.upper, rtol=1e-9, atol=1e-12)
    est.reset()
    for k in (0, 1, 2):
        box = est.step(u[k], y[k])
        np.testing.assert_allclose(box.lo, loop.lower[k], rtol=1e-12)
    batch = est.run(np.stack([u, u]), np.stack([y, y]))
    np.testing.assert_allclose(batch.lower[1], vec.lower, rtol=1e-12)
    assert np.all(vec.width[30:35, 0] > loop.width[36:, 0].max())  # the gap: no angle strip


def test_a_sample_far_outside_its_strip_is_an_inconsistency() -> None:
    sc, u, x, y = _servo(3)
    y[50, 0] += 5.0
    est = ivobs.make_estimator("reachability", sc.system, x0=sc.x0, strips=True)
    est.on_inconsistent = "ignore"
    res = est.run(u, y)
    assert res.inconsistent[50] and res.inconsistent.sum() == 1
    assert np.all((res.lower[50] <= x[50]) & (x[50] <= res.upper[50]))  # left as it was


def test_interval_matrices_use_their_exact_rows() -> None:
    sc = ivobs.scenarios.get("servo-motor")
    s = sc.system
    A = np.asarray(s.A)
    sys = ivobs.LinearSystem(ivobs.Box(A - 0.01 * np.abs(A), A + 0.01 * np.abs(A)), s.B, s.C,
                             D=s.D, E=s.E, F=s.F, d=s.d)  # fmt: skip
    est = ivobs.make_estimator("reachability", sys, x0=sc.x0, strips=True)
    _, u, _, y = _servo(4)
    res = est.run(u, y)
    assert np.all(res.width[5:, :2] <= 2 * 0.0564 * (1 + 1e-9))
