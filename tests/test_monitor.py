"""The streaming monitor: no false alarm over long fault-free runs with vertex disturbances (for
every method), alarms within a few steps of realistic faults, method-agnostic plumbing, and the
``ivobs monitor`` command."""

import io
from dataclasses import dataclass, replace
from functools import cache
from typing import ClassVar

import numpy as np
import pytest

import ivobs
from ivobs import Box, DesignError, IvobsError, image_bounds, scenarios
from ivobs.cli import main
from ivobs.estimators import Estimator
from ivobs.estimators.state import OnlineState, Step
from ivobs.io import save_system, write_log
from ivobs.monitor import Monitor
from ivobs.simulate import simulate, vertex_disturbance
from ivobs.testing import adversarial_run, random_system

METHODS = ivobs.methods()
SLOW = {"exact", "constrained-zonotope", "nl-horizon"}  # optimisations per step: shorter records
# no vectorised run: shorter here; 10,000 online steps in bench_fault_detection.py --fault-free
ONLINE_STEPS = {"strip": 200, "intersect": 200, "exact": 40, "constrained-zonotope": 30,
                "nl-horizon": 30}  # fmt: skip
LONG_STEPS = {
    "strip": 1000,
    "intersect": 1000,
    "exact": 150,
    "constrained-zonotope": 60,
    "nl-constrained-zonotope": 1000,
    "nl-horizon": 150,
    "nl-zonotope": 3000,
    "nl-interval": 3000,
    "ellipsoid": 3000,
}
VBAR = 0.0564  # servo motor: bound of the measurement noise


@cache
def servo(T):
    return scenarios.get("servo-motor", horizon=T)


@cache
def _build(method, which):
    if which == "servo":
        sys, x0 = servo(100).system, servo(100).x0
    else:
        sys = random_system(7, nx=3, ny=2, nu=1, feedthrough=True, symmetric_bounds=False)
        x0 = Box(-np.ones(3), np.ones(3))
    try:
        return ivobs.make_estimator(method, sys, x0=x0), None
    except DesignError as exc:
        return None, str(exc)


def monitor(method, which="servo", **kw):
    est, why = _build(method, which)
    if est is None:
        pytest.skip(f"{method} cannot be designed for the {which} system: {why}")
    return Monitor(est.sys, est, x0=est.x0, **kw)


# -- no false alarm -------------------------------------------------------------------------------
@pytest.mark.parametrize("method", METHODS)
def test_no_false_alarm_in_10000_fault_free_steps(method):
    """Offline check (the estimator's vectorised run + the Lemma 1 band) over 10,000 steps of
    vertex disturbances (methods without a vectorised run: shorter records)."""
    T = LONG_STEPS.get(method, 10_000)
    mon = monitor(method)
    sc = servo(100)
    tr = simulate(
        sc.system, sc.x_true0, np.full((T, 1), 2.0), vertex_disturbance(sc.system.d, T, seed=1)
    )
    rec = mon.check(tr.u, tr.y)
    k = rec.first_alarm
    assert k is None, f"{method}: false alarm at step {k}: {rec.reasons[k]}"
    ok = (rec.lower <= tr.x) & (tr.x <= rec.upper) | np.isnan(rec.lower)
    assert ok.all()


@pytest.mark.parametrize("which", ["servo", "random"])
@pytest.mark.parametrize("method", METHODS)
def test_online_monitor_no_false_alarm_with_missing_samples(method, which):
    """The online monitor (band tightened by the estimator's own prediction), vertex
    disturbances, 10% of the samples missing: no alarm, finite sound boxes."""
    if method in SLOW and which == "random":
        pytest.skip("one optimisation per step: the servo system only")
    mon = monitor(method, which)
    T = ONLINE_STEPS.get(method, 300)
    tr = adversarial_run(mon.sys, mon.x0, T, seed=5)
    y = tr.y.copy()
    rng = np.random.default_rng(0)
    y[rng.random(y.shape) < 0.1] = np.nan
    rec = mon.run(tr.u, y)
    k = rec.first_alarm
    assert k is None, f"{method}: false alarm at step {k}: {rec.reasons[k]}"
    vf = mon.estimator.valid_from
    assert np.all(np.isfinite(rec.lower[vf:])) and np.all(np.isfinite(rec.upper[vf:]))
    assert np.all((rec.lower[vf:] <= tr.x[vf:]) & (tr.x[vf:] <= rec.upper[vf:]))
    # the band really is a band: finite once anything is known, containing every measurement
    meas = ~np.isnan(y)
    assert np.all(np.isfinite(rec.band_lower[1:]))
    assert np.all((rec.band_lower <= y) | ~meas) and np.all((y <= rec.band_upper) | ~meas)


def test_offline_check_is_the_online_test_with_a_wider_band():
    mon = monitor("zonotope", tight=False)
    tr = adversarial_run(mon.sys, mon.x0, 120, seed=2)
    y = tr.y.copy()
    y[60:, 1] += 0.5
    y[30:33] = np.nan
    off = mon.check(tr.u, y)
    on = mon.run(tr.u, y)
    # the same boxes until the fault; from step 60 on the online monitor leaves y2 out
    np.testing.assert_allclose(off.lower[:60], on.lower[:60], rtol=1e-12)
    tol = 1e-9 * (1 + np.abs(on.band_lower[:60]))
    assert np.all(off.band_lower[:60] <= on.band_lower[:60] + tol)
    assert np.all(on.band_upper[:60] <= off.band_upper[:60] + tol)
    assert np.all(on.alarm[off.alarm])  # every offline alarm is an online alarm
    assert off.first_alarm == on.first_alarm == 60 and "y2 = " in off.reasons[60]
    assert on.alarm[60:].all() and [(f.start, f.outputs, f.end) for f in on.faults] == [
        (60, (1,), None)
    ]
    assert mon.k == 120  # check() left the online state alone
    # at step 1 both bands are Lemma 1 of the same box (the estimate at 0 inside the prior)
    np.testing.assert_allclose(off.band_lower[:2], on.band_lower[:2], rtol=1e-9)


def test_the_estimator_prediction_tightens_the_band():
    tr = adversarial_run(servo(100).system, servo(100).x0, 200, seed=3)
    wide = monitor("interval-split", tight=False).run(tr.u, tr.y)
    tight = monitor("interval-split", tight=True).run(tr.u, tr.y)
    w_wide = (wide.band_upper - wide.band_lower)[20:].mean()
    w_tight = (tight.band_upper - tight.band_lower)[20:].mean()
    assert w_tight < w_wide
    np.testing.assert_array_equal(wide.lower, tight.lower)  # the bounds are the method's


@pytest.mark.parametrize(
    "name, method",
    [
        ("kkl-ltv-dt", "kkl"),
        ("kkl-ltv-dt", "fixed-time"),
        ("pendulum", "kkl"),
        ("henon", "interval-split"),
        ("henon", "zonotope"),
    ],
)
def test_time_varying_continuous_and_measured_bounds(name, method):
    """A(k) callable, continuous time (band from the estimator's prediction only), and bounds
    computed from y[k] (the estimator cannot predict through a missing sample there)."""
    sc = scenarios.get(name, t_final=1.0) if name == "pendulum" else scenarios.get(name)
    try:
        mon = Monitor(sc.system, method, x0=sc.x0)
    except IvobsError as exc:
        pytest.skip(f"{method} on {name}: {exc}")
    tr = sc.simulate("vertex", seed=2)
    t = tr.t if sc.system.is_continuous else None
    on, off = mon.run(tr.u, tr.y, t=t), mon.check(tr.u, tr.y, t=t)
    assert on.first_alarm is None and off.first_alarm is None
    vf = mon.estimator.valid_from
    assert np.all((on.lower[vf:] <= tr.x[vf:]) & (tr.x[vf:] <= on.upper[vf:]))
    assert np.isfinite(on.band_lower[vf + 1 :]).all()
    y = tr.y.copy()
    y[len(y) // 2 :, 0] += 50 * np.abs(tr.y[:, 0]).max() + 5  # a gross sensor fault
    mon.reset()
    assert mon.run(tr.u, y, t=t).first_alarm == len(y) // 2


# -- detection ------------------------------------------------------------------------------------
def faulty(kind, size, seed, onset):
    sc = servo(onset + 25)
    d = vertex_disturbance(sc.system.d, sc.horizon, seed=seed)
    if kind == "actuator":  # the motor receives u - size volts, the log says u
        applied = sc.u.copy()
        applied[onset:] -= size
        return sc.u, simulate(sc.system, sc.x_true0, applied, d).y
    y = simulate(sc.system, sc.x_true0, sc.u, d).y.copy()
    y[onset:, 1] += size * VBAR  # speed sensor bias
    return sc.u, y


def delays(method, kind, size):
    mon = monitor(method)
    onset = 30 if method in SLOW else 60
    out = []
    for seed in range(1 if method in SLOW else 2):
        u, y = faulty(kind, size, seed, onset)
        mon.reset()
        rec = mon.run(u, y)
        assert not rec.alarm[:onset].any(), f"false alarm before the fault: {rec.first_alarm}"
        hit = np.flatnonzero(rec.alarm[onset:])
        out.append(int(hit[0]) if hit.size else None)
    return out


# The ellipsoid's band is wide along the speed (ellipsoids cannot follow the observer's box):
# a bias of 5 noise bounds stays inside it for one seed; 10 noise bounds are seen at once.
SENSOR_BIAS = {"ellipsoid": 10.0}


@pytest.mark.parametrize("method", METHODS)
def test_speed_sensor_bias_of_five_noise_bounds_is_detected(method):
    d = delays(method, "sensor", SENSOR_BIAS.get(method, 5.0))
    assert None not in d and max(d) <= 20, f"{method}: detection delays {d}"


# Interval observers (A - LC >= 0 in the original or in split coordinates) carry wide boxes of
# the unmeasured current; a dead actuator stays inside their band (bench_fault_detection.py).
ACTUATOR_BLIND = {"interval", "interval-split"}


@pytest.mark.parametrize("method", METHODS)
def test_dead_actuator_is_detected(method):
    if method in ACTUATOR_BLIND:
        pytest.skip(f"{method}: boxes of the current too wide to see a 2 V actuator loss")
    d = delays(method, "actuator", 2.0)
    assert None not in d and max(d) <= 12, f"{method}: detection delays {d}"


# -- plumbing, with estimators defined here ----------------------------------------------------
@dataclass(frozen=True)
class BoxState(OnlineState):
    """The predicted box of ``x[k]``."""

    lo: np.ndarray
    hi: np.ndarray
    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"),)


class OpenLoop(Estimator):
    """x[k+1] ∈ A[x[k]] + B u[k] + E[d[k]]; flags y[k] as inconsistent at the steps in ``flag``
    and can return a box shifted by ``shift`` (to test the monitor, not a method)."""

    name = "open-loop-monitor-test"
    data_used = "prediction"  # uses no measurement: no strips of its own

    def __init__(self, sys, x0=None, *, flag=(), shift=0.0, on_inconsistent="warn"):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)
        self.flag, self.shift = set(flag), shift

    def _initial_state(self):
        return BoxState(lo=self.x0.lo.copy(), hi=self.x0.hi.copy())

    def _step(self, state, u_k, y_k, t_k):
        k, lo, hi = state.k, state.lo, state.hi
        A, B, _, _, E, _ = self.sys.matrices_at(k)
        d = self.sys.d_at(k, y_k)
        a_lo, a_hi = image_bounds(A, lo, hi)
        e_lo, e_hi = image_bounds(E, d.lo, d.hi)
        nxt = replace(state, lo=a_lo + B @ u_k + e_lo, hi=a_hi + B @ u_k + e_hi)
        flag = k in self.flag and not np.isnan(y_k).all()
        shift = self.shift if k == 5 else 0.0
        return Step(nxt, lo + shift, hi + shift, flag)


def test_estimator_inconsistency_is_an_alarm_and_not_a_warning(recwarn):
    sc = servo(100)
    tr = sc.simulate("vertex", seed=0)
    est = OpenLoop(sc.system, sc.x0, flag=[7])
    rec = Monitor(sc.system, est, clear_after=3).run(tr.u[:12], tr.y[:12])
    # raised at 7, held until both outputs have been consistent again for 3 steps (8, 9, 10)
    assert np.flatnonzero(rec.alarm).tolist() == [7, 8, 9]
    assert np.flatnonzero(rec.evidence).tolist() == [7]
    assert "measurement of y1;y2 inconsistent with the model" in rec.reasons[7]
    assert [(f.start, f.outputs, f.end, f.duration) for f in rec.faults] == [(7, (0, 1), 10, 3)]
    assert not [w for w in recwarn if "inconsistent" in str(w.message)]


def test_estimate_disjoint_from_the_prediction_is_an_alarm():
    sc = servo(100)
    tr = sc.simulate("vertex", seed=0)
    est = OpenLoop(sc.system, sc.x0, shift=50.0)
    rec = Monitor(sc.system, est, tight=False, clear_after=2).run(tr.u[:10], tr.y[:10])
    # step 5: the estimate jumps away from the prediction; step 6: back, away from the
    # prediction made from the step-5 box; held for 2 consistent steps (7, 8)
    assert np.flatnonzero(rec.evidence).tolist() == [5, 6]
    assert np.flatnonzero(rec.alarm).tolist() == [5, 6, 7]
    assert "estimate disjoint from the model's prediction in x1" in rec.reasons[5]
    tight = Monitor(sc.system, est, tight=True).run(tr.u[:8], tr.y[:8])
    assert "the estimator's prediction disjoint from the model's" in tight.reasons[5]
    off = Monitor(sc.system, OpenLoop(sc.system, sc.x0, shift=50.0)).check(tr.u[:8], tr.y[:8])
    assert np.flatnonzero(off.alarm).tolist() == [5, 6]


def test_band_is_exactly_lemma_one_of_the_previous_box():
    sc = servo(100)
    tr = sc.simulate("vertex", seed=0)
    mon = Monitor(sc.system, OpenLoop(sc.system, sc.x0), tight=False, margin=0.0)
    s0, s1 = mon.update(tr.u[0], tr.y[0]), mon.update(tr.u[1], tr.y[1])
    A, B, C, _, E, F = sc.system.matrices_at(0)
    d = sc.system.d
    lo, hi = image_bounds(C, sc.x0.lo, sc.x0.hi)
    f_lo, f_hi = image_bounds(F, d.lo, d.hi)
    np.testing.assert_allclose(s0.band_lower, lo + f_lo)
    np.testing.assert_allclose(s0.band_upper, hi + f_hi)
    # step 1: the prediction from the step-0 box (intersected with the prior) through A, B, E
    prev_lo, prev_hi = np.maximum(s0.lower, sc.x0.lo), np.minimum(s0.upper, sc.x0.hi)
    p_lo, p_hi = image_bounds(A, prev_lo, prev_hi)
    e_lo, e_hi = image_bounds(E, d.lo, d.hi)
    p_lo, p_hi = p_lo + B @ tr.u[0] + e_lo, p_hi + B @ tr.u[0] + e_hi
    c_lo, c_hi = image_bounds(C, np.maximum(p_lo, s1.lower), np.minimum(p_hi, s1.upper))
    np.testing.assert_allclose(s1.band_lower, c_lo + f_lo, rtol=1e-9)
    np.testing.assert_allclose(s1.band_upper, c_hi + f_hi, rtol=1e-9)


def test_monitor_rejects_bad_input():
    sc = servo(100)
    with pytest.raises(IvobsError, match="unknown method 'kalman'"):
        Monitor(sc.system, "kalman", x0=sc.x0)
    est = OpenLoop(sc.system, sc.x0)
    with pytest.raises(IvobsError, match="design options"):
        Monitor(sc.system, est, L=np.zeros((3, 2)))
    mon = Monitor(sc.system, est)
    with pytest.raises(IvobsError, match="expected 2 measurement value"):
        mon.update([2.0], [0.1, 0.2, 0.3])
    with pytest.raises(IvobsError, match="u_k"):
        mon.update([np.nan], [0.1, 0.2])
    with pytest.raises(IvobsError, match="infinite measurement"):
        mon.update([2.0], [np.inf, 0.2])
    assert mon.k == 0


# -- ivobs monitor -------------------------------------------------------------------------------
@pytest.fixture
def files(tmp_path):
    sc = servo(100)
    tr = sc.simulate("vertex", seed=9)
    y = tr.y.copy()
    y[20:25, 0] = np.nan
    y[70:, 1] += 1.0  # speed sensor offset of ~18 noise bounds
    save_system(tmp_path / "servo.toml", sc, method="interval-split")
    write_log(tmp_path / "log.csv", tr.u, y)
    return tmp_path, tr.u, y


def test_cli_monitor_reads_stdin_and_prints_one_line_per_step(files, monkeypatch, capsys):
    tmp, u, y = files
    monkeypatch.setattr("sys.stdin", io.StringIO((tmp / "log.csv").read_text()))
    code = main(["monitor", "--system", str(tmp / "servo.toml")])
    lines = capsys.readouterr().out.splitlines()
    assert code == 1  # alarms were raised
    assert lines[0] == (
        "k,lower_1,lower_2,lower_3,upper_1,upper_2,upper_3,alarm,reason,"
        "fault_start,fault_duration,fault_outputs,"
        "bias_lower_1,bias_lower_2,bias_upper_1,bias_upper_2,fault_isolated"
    )
    assert len(lines) == 101
    rows = [ln.split(",", 8) for ln in lines[1:]]
    alarms = [int(r[0]) for r in rows if r[7] == "1"]
    assert 70 <= alarms[0] <= 75 and "outside the predicted band" in rows[alarms[0]][8]
    mon = Monitor(servo(100).system, "interval-split", x0=servo(100).x0).run(u, y)
    np.testing.assert_array_equal(
        [[float(v) for v in r[1:7]] for r in rows], np.hstack([mon.lower, mon.upper])
    )


def test_cli_monitor_input_file_and_a_malformed_row(files, capsys):
    tmp, _, _ = files
    log = tmp / "log.csv"
    text = log.read_text().splitlines()
    text[31] = "30,2.0,abc,0.1"
    log.write_text("\n".join(text) + "\n")
    code = main(["monitor", "--system", str(tmp / "servo.toml"), "--input", str(log)])
    out, err = capsys.readouterr()
    assert code == 2 and "line 32: column 'y1': expected a number, got 'abc'" in err
    assert len(out.splitlines()) == 31  # header + steps 0..29, printed as they came
