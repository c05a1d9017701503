"""Resume: the online state of every estimator and of the monitor is JSON-serialisable, and a
restored (or restarted) monitor continues with the same boxes as if it had never stopped."""

import json
import os
import signal
import subprocess
import sys
from functools import cache

import numpy as np
import pytest

import ivobs
from ivobs import DesignError, IvobsError, scenarios
from ivobs.cli import main
from ivobs.io import save_system, write_log
from ivobs.monitor import Monitor
from ivobs.testing import adversarial_run

METHODS = ivobs.methods()
SLOW = {"exact", "constrained-zonotope"}
LP = {"exact", "dual-window"}  # LPs (HiGHS, warm-started): other optimal multipliers after
# a restore give the same bounds within rounding


def _close(a, b):
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12)


@cache
def _build(method):
    sc = scenarios.get("servo-motor")
    try:
        return ivobs.make_estimator(method, sc.system, x0=sc.x0), None
    except DesignError as exc:
        return None, str(exc)


def estimator(method):
    est, why = _build(method)
    if est is None:
        pytest.skip(f"{method} cannot be designed for the servo motor: {why}")
    return est


@pytest.mark.parametrize("method", METHODS)
def test_state_survives_json_and_continues_identically(method):
    est = estimator(method)
    sc = scenarios.get("servo-motor")
    T, cut = (24, 12) if method in SLOW else (80, 37)
    tr = adversarial_run(sc.system, sc.x0, T, seed=4)
    y = tr.y.copy()
    y[cut - 3 : cut + 2, 0] = np.nan  # missing samples around the cut
    mon = Monitor(sc.system, est, x0=sc.x0)
    straight = mon.run(tr.u, y)
    mon.reset()
    mon.run(tr.u[:cut], y[:cut])
    saved = json.loads(json.dumps(mon.state()))  # what `ivobs monitor --state` keeps on disk
    # the monitor keeps the estimator's online state itself (the estimator's own is untouched)
    est_saved = json.loads(json.dumps(est.save_state(mon.estimator_state)))
    assert est_saved["method"] == method
    mon.reset()  # forget everything, then continue from the saved state
    mon.restore(saved)
    assert mon.k == cut
    rest = mon.run(tr.u[cut:], y[cut:])
    # bit for bit, except through an LP solver whose warm start differs after a restart
    same = np.testing.assert_array_equal if method not in LP else _close
    same(rest.lower, straight.lower[cut:])
    same(rest.upper, straight.upper[cut:])
    same(rest.band_lower, straight.band_lower[cut:])
    np.testing.assert_array_equal(rest.alarm, straight.alarm[cut:])
    # the estimator alone, restored from its own state
    est.reset()
    est.restore(est_saved)
    box = est.step(tr.u[cut], y[cut])
    same(box.lo, straight.lower[cut])


def test_restore_refuses_another_method_or_a_broken_state():
    sc = scenarios.get("servo-motor")
    a = Monitor(sc.system, estimator("interval-split"), x0=sc.x0)
    b = Monitor(sc.system, estimator("zonotope"), x0=sc.x0)
    with pytest.raises(IvobsError, match="saved by method 'interval-split'"):
        b.restore(a.state())
    with pytest.raises(IvobsError, match="Monitor.state"):
        a.restore({"k": 3})


# -- ivobs monitor --state ------------------------------------------------------------------
@pytest.fixture
def plant(tmp_path):
    sc = scenarios.get("servo-motor", horizon=160)
    tr = sc.simulate("vertex", seed=6)
    y = tr.y.copy()
    y[40:50, 1] = np.nan
    y[120:, 1] += 0.6  # speed sensor offset: alarms in the second half
    save_system(tmp_path / "servo.toml", sc, method="interval-split")
    write_log(tmp_path / "log.csv", tr.u, y)
    return tmp_path


def _monitor(capsys, *args):
    code = main(["monitor", *map(str, args)])
    return code, capsys.readouterr().out.splitlines()


@pytest.mark.parametrize("step_column", [True, False])
def test_cli_restart_with_state_continues_where_it_stopped(plant, capsys, step_column):
    sc = scenarios.get("servo-motor", horizon=160)
    tr = sc.simulate("vertex", seed=6)
    log, part = plant / "log.csv", plant / "part.csv"
    if not step_column:  # positions, not steps, say where to resume (--input only)
        write_log(log, tr.u, tr.y, steps=False)
    lines = log.read_text().splitlines(keepends=True)
    part.write_text("".join(lines[:91]))  # header + 90 rows
    system = plant / "servo.toml"
    _, full = _monitor(capsys, "--system", system, "--input", log)
    state = plant / "state.json"
    _, first = _monitor(capsys, "--system", system, "--input", part, "--state", state)
    assert json.loads(state.read_text())["stream"]["rows"] == 90
    _, second = _monitor(capsys, "--system", system, "--input", log, "--state", state)
    assert first + second == full
    assert len(full) == 161


def test_cli_state_saved_every_n_steps_and_at_the_end(plant, capsys):
    state = plant / "state.json"
    code, _ = _monitor(
        capsys,
        "--system",
        plant / "servo.toml",
        "--input",
        plant / "log.csv",
        "--state",
        state,
        "--save-every",
        "7",
    )
    saved = json.loads(state.read_text())
    assert code == 1 and saved["monitor"]["k"] == 160 and saved["stream"]["step"] == 159
    assert sorted(p.name for p in plant.iterdir()) == ["log.csv", "servo.toml", "state.json"]


def test_cli_rejects_a_state_of_another_kind(plant, capsys):
    state = plant / "state.json"
    state.write_text('{"hello": 1}')
    code = main(
        [
            "monitor",
            "--system",
            str(plant / "servo.toml"),
            "--input",
            str(plant / "log.csv"),
            "--state",
            str(state),
        ]
    )
    assert code == 2 and "not an ivobs monitor state" in capsys.readouterr().err


def test_monitor_killed_and_restarted_prints_the_same_bounds(plant, capsys):
    """A real process, killed (SIGKILL) mid-stream and restarted with --state on the whole
    stream: the union of both outputs is the uninterrupted output (a step printed just before
    the kill may be printed again, identically)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "ivobs.cli", "monitor", "--system", str(plant / "servo.toml")]
    data = (plant / "log.csv").read_text()
    _, full = _monitor(capsys, "--system", plant / "servo.toml", "--input", plant / "log.csv")
    state = [*cmd, "--state", str(plant / "state.json")]
    proc = subprocess.Popen(
        state, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env
    )
    lines = data.splitlines(keepends=True)
    proc.stdin.write("".join(lines[:101]))  # header + 100 rows; the rest never comes
    proc.stdin.flush()
    first = [proc.stdout.readline() for _ in range(61)]  # header + 60 steps printed
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait(timeout=60)
    first = "".join([*first, proc.stdout.read()]).splitlines()  # and whatever it printed since
    proc.stdout.close()
    second = subprocess.run(
        state, input=data, capture_output=True, text=True, env=env, timeout=300
    ).stdout.splitlines()
    assert first[0] == full[0] and not second[0].startswith("step")  # no second header
    assert 61 <= len(first) <= 101 and len(second) >= 60
    merged = {}
    for line in first[1:] + second:
        k = int(line.split(",", 1)[0])
        assert merged.setdefault(k, line) == line  # a repeated step is the same line
    assert [merged[k] for k in sorted(merged)] == full[1:]


def test_cli_restart_with_the_state_of_a_typed_state_method(plant, capsys):
    """A method whose online state is a dataclass (zonotope) resumes from its state file like
    one with a dict state."""
    log, part = plant / "log.csv", plant / "part.csv"
    lines = log.read_text().splitlines(keepends=True)
    part.write_text("".join(lines[:61]))  # header + 60 rows
    system, state = plant / "servo.toml", plant / "state.json"
    _, full = _monitor(capsys, "--system", system, "--method", "zonotope", "--input", log)
    _, first = _monitor(
        capsys, "--system", system, "--method", "zonotope", "--input", part, "--state", state
    )
    _, second = _monitor(
        capsys, "--system", system, "--method", "zonotope", "--input", log, "--state", state
    )
    assert first + second == full and len(full) == 161
