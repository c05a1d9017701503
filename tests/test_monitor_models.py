"""The monitor on every model class: nonlinear plants and linear plants with interval matrices
(the model's own prediction and band from :mod:`ivobs.monitor.bands`), with simulators written
here. A fault-free record raises no alarm; a persistent sensor bias stays flagged to the end,
is blamed on its output only, and the boxes keep the true state."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs.monitor import Monitor

BIAS_FROM = 80


def _unicycle_record(seed: int):
    sc = ivobs.scenarios.get("unicycle-range")
    return sc, sc.simulate("vertex", seed=seed)


@pytest.mark.parametrize("method", ["nl-interval", "nl-constrained-zonotope"])
def test_a_nonlinear_plant_keeps_a_persistent_bias_flagged(method: str) -> None:
    """Ranges to three beacons and a compass: +0.5 on the first range (10 noise bounds) from
    step 80."""
    sc, tr = _unicycle_record(1)
    clean = Monitor(sc.system, method, x0=sc.x0).run(tr.u, tr.y)
    assert not np.any(clean.alarm)
    y = tr.y.copy()
    y[BIAS_FROM:, 0] += 0.5
    out = Monitor(sc.system, method, x0=sc.x0).run(tr.u, y)
    assert not np.any(out.alarm[:BIAS_FROM])
    first = out.first_alarm
    assert first is not None and first <= BIAS_FROM + 2
    assert np.all(out.alarm[first:])  # to the end of the record
    assert [f.outputs for f in out.faults] == [(0,)] and out.faults[0].end is None
    tol = 1e-9 * (1.0 + np.abs(tr.x))
    assert np.all((out.lower <= tr.x + tol) & (tr.x - tol <= out.upper))


def test_no_false_alarm_on_a_nonlinear_plant() -> None:
    sc = ivobs.scenarios.get("henon-nl", horizon=2000)
    tr = sc.simulate("vertex", seed=3)
    out = Monitor(sc.system, "nl-interval", x0=sc.x0).run(tr.u, tr.y)
    assert not np.any(out.alarm)


def _interval_servo():
    """The servo motor of [Tang2019] with ±1 % on the nonzero entries of ``A``."""
    sc = ivobs.scenarios.get("servo-motor")
    s = sc.system
    A = np.asarray(s.A)
    R = 0.01 * np.abs(A)
    sys = ivobs.LinearSystem(ivobs.Box(A - R, A + R), s.B, s.C, D=s.D, E=s.E, F=s.F, d=s.d, dt=s.dt)
    return sc, sys, A, R


def _simulate_interval(A, R, sys, x0, T, seed, bias=None):
    """``x+ = A_k x + B u + E d`` with ``A_k`` and ``d`` on random vertices of their boxes."""
    rng = np.random.default_rng(seed)
    B, C, E, F = (np.asarray(m) for m in (sys.B, sys.C, sys.E, sys.F))
    lo, hi = sys.d.lo, sys.d.hi
    u = np.full((T, B.shape[1]), 2.0)
    x, xs, ys = np.array(x0, dtype=float), [], []
    for k in range(T):
        d = np.where(rng.random(lo.shape) < 0.5, lo, hi)
        y = C @ x + F @ d
        if bias is not None and k >= bias[0]:
            y[bias[1]] += bias[2]
        xs.append(x.copy())
        ys.append(y)
        Ak = A + R * rng.choice([-1.0, 1.0], A.shape)
        d2 = np.where(rng.random(lo.shape) < 0.5, lo, hi)
        x = Ak @ x + B @ u[k] + E @ d2
    return u, np.array(xs), np.array(ys)


def test_an_interval_matrix_plant() -> None:
    sc, sys, A, R = _interval_servo()
    u, xs, ys = _simulate_interval(A, R, sys, sc.x_true0, 1500, seed=4)
    out = Monitor(sys, "reachability", x0=sc.x0).run(u, ys)
    assert not np.any(out.alarm)
    assert np.all((out.lower <= xs + 1e-9) & (xs - 1e-9 <= out.upper))
    # a bias of 0.5 on the angle sensor from step 300 is detected at once (that it stays
    # flagged while the servo's only other sensor cannot tell is the re-admission problem of
    # the fault-diagnosis issue, not solved here: the alarm is up on 4 % of the faulty steps)
    u, xs, ys = _simulate_interval(A, R, sys, sc.x_true0, 600, seed=5, bias=(300, 0, 0.5))
    out = Monitor(sys, "reachability", x0=sc.x0).run(u, ys)
    assert not np.any(out.alarm[:300]) and out.first_alarm == 300
    assert out.faults[0].outputs == (0,)


def test_refusals_name_what_to_do() -> None:
    ct = ivobs.NonlinearSystem(states=["x"], f=["-x + d"], h=["x"], d={"d": (-1, 1)}, dt=0)
    with pytest.raises(ivobs.IvobsError, match=r"discretize\(Ts\)"):
        Monitor(ct, "nl-interval", x0=ivobs.Box([-1.0], [1.0]))
    sc, _ = _unicycle_record(0)
    mon = Monitor(sc.system, "nl-interval", x0=sc.x0)
    with pytest.raises(ivobs.IvobsError, match="use run"):
        mon.check(np.zeros((3, sc.system.nu)), np.zeros((3, sc.system.ny)))


def test_ivobs_monitor_runs_a_nonlinear_system_file_with_a_fault_in_its_log(tmp_path, capsys):
    """``ivobs monitor --system`` on a nonlinear system file: the log's biased range is flagged
    from its first step to the end, isolated, its bias estimated, one CSV row per step."""
    from ivobs.cli import main

    sc, tr = _unicycle_record(1)
    T = 120
    y = tr.y[:T].copy()
    y[BIAS_FROM:, 1] += 0.3
    ivobs.save_system(tmp_path / "unicycle.toml", sc)
    ivobs.io.write_log(tmp_path / "log.csv", tr.u[:T], y)
    argv = ["monitor", "--system", str(tmp_path / "unicycle.toml"), "--method", "nl-interval"]
    assert main([*argv, "--input", str(tmp_path / "log.csv")]) == 1
    import csv
    import io

    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))  # reasons hold commas
    assert len(rows) == T
    alarm = [r["alarm"] == "1" for r in rows]
    assert not any(alarm[:BIAS_FROM]) and all(alarm[BIAS_FROM:])
    assert rows[-1]["fault_isolated"] == "y2"
    assert float(rows[-1]["bias_lower_2"]) <= 0.3 <= float(rows[-1]["bias_upper_2"])
