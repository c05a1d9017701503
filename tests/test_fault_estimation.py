"""Fault estimation (:mod:`ivobs.monitor.bias`): a sensor fault estimated as a constant bias
jointly with the state, the alarm kept while the bias interval excludes 0, an output
re-admitted only when the data since the estimate's start are consistent with no bias. The
servo of [Tang2019] with a bias on its angle sensor: the angle integrates the speed, so after
its onset a constant offset is itself a model trajectory; only the bias estimate, which keeps
the onset in memory, can keep the fault flagged. Simulators written here."""

from __future__ import annotations

import json

import numpy as np
import pytest

import ivobs
from ivobs.monitor import Monitor
from ivobs.monitor.bias import augment_with_bias
from vertexsim import servo_vertex

ONSET = 40


def _servo(T: int, seed: int = 0):
    """The servo with vertex disturbances and noise: ``(sys, x0 box, u, x, y)``."""
    sc, u, x, y = servo_vertex(T, seed)
    return sc.system, sc.x0, u, x, y


def _contains(out, x) -> bool:
    tol = 1e-9 * (1.0 + np.abs(x))
    return bool(np.all((out.lower <= x + tol) & (x - tol <= out.upper)))


def test_the_augmented_model() -> None:
    s, *_ = _servo(2)
    aug = augment_with_bias(s, (0,))
    assert isinstance(aug, ivobs.LinearSystem) and (aug.nx, aug.ny, aug.nd) == (4, 2, 5)
    assert np.array_equal(aug.A[3], [0, 0, 0, 1]) and np.array_equal(aug.A[:3, :3], s.A)
    assert np.array_equal(aug.C, [[1, 0, 0, 1], [0, 1, 0, 0]])
    assert not np.any(aug.E[3]) and np.array_equal(aug.F, s.F)
    nl = ivobs.NonlinearSystem(
        states=["x"], f=["0.5*x + w"], h=["x**2", "x"], d={"w": (-1, 1)}, dt=True
    )
    naug = augment_with_bias(nl, (1,))
    assert naug.state_names == ["x", "bias_y2"] and naug.ny == 2
    assert naug.f_text[1] == "bias_y2" and "bias_y2" in naug.h_text[1]


@pytest.mark.parametrize("method", ["interval-split", "strip"])
def test_a_persistent_angle_bias_stays_flagged_with_its_estimate(method: str) -> None:
    """+0.5 on the angle (9 noise bounds) from step 40: before fault estimation the latch
    cleared after ~25 steps and the boxes then missed the true state."""
    s, x0, u, x, y = _servo(120)
    y[ONSET:, 0] += 0.5
    out = Monitor(s, method, x0=x0).run(u, y)
    assert not out.alarm[:ONSET].any() and out.alarm[ONSET:].all()
    assert [(f.start, f.end, f.outputs) for f in out.faults] == [(ONSET, None, (0,))]
    lo, hi = out.bias_lower[ONSET:, 0], out.bias_upper[ONSET:, 0]
    assert np.all((lo <= 0.5) & (0.5 <= hi) & (lo > 0))  # contains 0.5, excludes 0
    assert np.all(hi - lo < 0.3)
    assert np.isnan(out.bias_lower[:ONSET]).all() and np.isnan(out.bias_lower[:, 1]).all()
    assert _contains(out, x)


def test_a_transient_bias_clears_clear_after_steps_after_it_ends() -> None:
    s, x0, u, x, y = _servo(110)
    y[ONSET:70, 0] += 0.5
    out = Monitor(s, "interval-split", x0=x0, clear_after=10).run(u, y)
    # the end is a jump back, seen at step 70: the bias is re-estimated around 0 there, and
    # the output is readmitted after 10 consistent steps (70 to 79)
    assert [(f.start, f.end, f.outputs) for f in out.faults] == [(ONSET, 79, (0,))]
    assert out.alarm[ONSET:79].all() and not out.alarm[79:].any()
    assert "y1: the bias estimated since step 40 changed" in out.reasons[70]
    assert _contains(out, x)


def test_a_bias_that_jumps_stays_flagged_and_is_re_estimated() -> None:
    s, x0, u, x, y = _servo(140)
    y[ONSET:, 0] += 0.5
    y[90:, 0] += 0.5
    out = Monitor(s, "interval-split", x0=x0).run(u, y)
    assert out.alarm[ONSET:].all() and len(out.faults) == 1
    assert out.bias_lower[-1, 0] <= 1.0 <= out.bias_upper[-1, 0]
    assert out.bias_lower[-1, 0] > 0.5  # the second estimate started from the first's state
    assert _contains(out, x)


def test_a_speed_bias_is_estimated_and_blamed_alone() -> None:
    s, x0, u, x, y = _servo(100)
    y[ONSET:, 1] += 0.3  # 5 noise bounds on the speed
    # (interval-split's band is too wide to see it at once: the biased speed then enters its
    # estimate, and the position sensor is blamed; isolation is not solved there)
    out = Monitor(s, "strip", x0=x0).run(u, y)
    first = out.first_alarm
    assert first is not None and ONSET <= first <= ONSET + 5 and out.alarm[first:].all()
    assert [f.outputs for f in out.faults] == [(1,)]
    assert out.bias_lower[-1, 1] <= 0.3 <= out.bias_upper[-1, 1] and out.bias_lower[-1, 1] > 0
    assert _contains(out, x)


def test_the_bias_estimate_is_saved_and_resumed() -> None:
    s, x0, u, _, y = _servo(90)
    y[ONSET:, 0] += 0.5
    mon = Monitor(s, "interval-split", x0=x0)
    mon.run(u[:60], y[:60])
    saved = json.loads(json.dumps(mon.state()))
    assert saved["bias"]["outputs"] == [0] and saved["bias"]["start"] == ONSET
    again = Monitor(s, "interval-split", x0=x0)
    again.restore(saved)
    a, b = mon.run(u[60:], y[60:]), again.run(u[60:], y[60:])
    assert np.array_equal(a.bias_lower, b.bias_lower, equal_nan=True)
    assert np.array_equal(a.alarm, b.alarm)
    assert a.alarm.all()
    saved["bias"]["start"] = 75  # after the monitor's step: refused, named
    with pytest.raises(ivobs.IvobsError, match="state: bias"):
        Monitor(s, "interval-split", x0=x0).restore(saved)


def test_a_nonlinear_plant_bias_is_estimated() -> None:
    sc = ivobs.scenarios.get("unicycle-range")
    tr = sc.simulate("vertex", seed=1)
    y = tr.y.copy()
    y[80:, 0] += 0.5
    out = Monitor(sc.system, "nl-interval", x0=sc.x0).run(tr.u, y)
    assert out.alarm[80:].all() and [f.outputs for f in out.faults] == [(0,)]
    lo, hi = out.faults[0].bias_lower[0], out.faults[0].bias_upper[0]
    assert lo <= 0.5 <= hi and lo > 0.4 and hi < 0.6


def test_a_short_angle_bias_record() -> None:
    """The README suite's quick check of the above: 20 faulty steps."""
    s, x0, u, x, y = _servo(50)
    y[30:, 0] += 0.5
    out = Monitor(s, "interval-split", x0=x0).run(u, y)
    assert out.alarm[30:].all() and not out.alarm[:30].any()
    assert np.all((out.bias_lower[30:, 0] > 0) & (out.bias_upper[30:, 0] >= 0.5))
    assert _contains(out, x)


@pytest.mark.parametrize("kind", ["linear", "interval-matrix", "nonlinear"])
def test_no_false_alarm_in_10000_fault_free_steps(kind: str) -> None:
    """Vertex disturbances (and matrices on the vertices of their intervals)."""
    T = 10_000
    if kind == "nonlinear":
        sc = ivobs.scenarios.get("henon-nl", horizon=T)
        tr = sc.simulate("vertex", seed=11)
        out = Monitor(sc.system, "nl-interval", x0=sc.x0).run(tr.u, tr.y)
        assert not out.alarm.any() and out.faults == []
        return
    s, x0, u, x, y = _servo(T, seed=11)
    if kind == "linear":
        out = Monitor(s, "interval-split", x0=x0).run(u, y)
    else:
        A = np.asarray(s.A)
        R = 0.01 * np.abs(A)
        sys = ivobs.LinearSystem(ivobs.Box(A - R, A + R), s.B, s.C, D=s.D, E=s.E, F=s.F, d=s.d)
        rng = np.random.default_rng(12)
        d = np.where(rng.random((T, s.nd)) < 0.5, s.d.lo, s.d.hi)
        x = np.zeros((T, 3))
        x[0] = ivobs.scenarios.get("servo-motor").x_true0
        for k in range(T - 1):
            Ak = A + R * rng.choice([-1.0, 1.0], A.shape)
            x[k + 1] = Ak @ x[k] + np.asarray(s.B) @ u[k] + np.asarray(s.E) @ d[k]
        y = x @ np.asarray(s.C).T + d @ np.asarray(s.F).T
        out = Monitor(sys, "reachability", x0=x0).run(u, y)
    assert not out.alarm.any() and out.faults == []
    assert _contains(out, x)
