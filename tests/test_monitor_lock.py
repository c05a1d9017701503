"""A monitor's state file belongs to one running monitor, one model and one stream: it is
locked while a monitor runs (a second one is refused, naming the holder), refused when written
for another model (matrices, bounds, prior, settings; the same gains are not enough) or another
stream, or edited by hand; and the exit status reports the alarms of the whole stream, the part
before a restart included."""

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError, scenarios
from ivobs.cli import main
from ivobs.io import save_system, write_log
from ivobs.monitor import Monitor

T = 80
L = np.array([[1.0, 0.1], [0.0, 0.8495], [0.0, -0.0357]])  # one gain for both plants


@pytest.fixture
def plant(tmp_path):
    """The servo with a fixed gain, a log with a speed-sensor fault in steps 15..24, and a
    second system file with the same matrices and gain but other disturbance bounds."""
    sc = scenarios.get("servo-motor", horizon=T)
    tr = sc.simulate("vertex", seed=6)
    y = tr.y.copy()
    y[15:25, 1] += 0.6
    save_system(tmp_path / "servo.toml", sc, method="interval-split", options={"L": L})
    wider = ivobs.LinearSystem(
        sc.system.A, sc.system.B, sc.system.C, D=sc.system.D, E=sc.system.E, F=sc.system.F,
        d=ivobs.Box(2 * sc.system.d.lo, 2 * sc.system.d.hi),
    )  # fmt: skip
    save_system(tmp_path / "wider.toml", wider, x0=sc.x0, method="interval-split",
                options={"L": L})  # fmt: skip
    write_log(tmp_path / "log.csv", tr.u, y)
    lines = (tmp_path / "log.csv").read_text().splitlines(keepends=True)
    (tmp_path / "head.csv").write_text("".join(lines[:41]))  # header + steps 0..39
    return tmp_path


def _monitor(capsys, folder, *args, system="servo.toml"):
    argv = ["monitor", "-s", str(folder / system), "--state", str(folder / "state.json")]
    code = main([*argv, *map(str, args)])
    out, err = capsys.readouterr()
    return code, out.splitlines(), err


def test_a_second_monitor_on_a_locked_state_is_refused_naming_the_holder(plant, capsys):
    from ivobs.io.statefile import StateLock

    with StateLock(plant / "state.json"):
        code, out, err = _monitor(capsys, plant, "-i", plant / "log.csv")
    assert code == 2 and out == []
    assert f"in use by another monitor (process {os.getpid()} on " in err
    assert not (plant / "state.json").exists()
    code, out, err = _monitor(capsys, plant, "-i", plant / "log.csv")  # released: runs
    assert code == 1 and len(out) == T + 1
    assert not (plant / "state.json.lock").exists()  # removed with the lock


@pytest.mark.slow  # two processes importing ivobs
def test_two_monitor_processes_never_share_a_state(plant):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    cmd = [sys.executable, "-m", "ivobs.cli", "monitor", "-s", str(plant / "servo.toml"),
           "--state", str(plant / "state.json")]  # fmt: skip
    first = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)
    try:
        first.stdin.write("k,u1,y1,y2\n")
        first.stdin.flush()
        assert first.stdout.readline().startswith("k,")  # running, the lock held
        for _ in range(100):
            if (plant / "state.json.lock").read_text():
                break
            time.sleep(0.05)
        second = subprocess.run(
            cmd, input=(plant / "log.csv").read_text(), capture_output=True, text=True, env=env,
            timeout=120,
        )  # fmt: skip
        assert second.returncode == 2 and second.stdout == ""
        assert f"in use by another monitor (process {first.pid} on" in second.stderr
    finally:
        first.stdin.close()
        first.wait(timeout=60)
        first.stdout.close()


def test_a_state_of_another_plant_with_the_same_gain_is_refused(plant, capsys):
    assert _monitor(capsys, plant, "-i", plant / "head.csv")[0] == 1
    code, out, err = _monitor(capsys, plant, "-i", plant / "log.csv", system="wider.toml")
    assert code == 2 and out == [] and "the disturbance bounds d differ" in err
    text = (plant / "servo.toml").read_text().replace("upper = [0.2, 0.2, 0.2]",
                                                      "upper = [0.2, 0.2, 0.25]")  # fmt: skip
    (plant / "other-prior.toml").write_text(text)
    code, out, err = _monitor(capsys, plant, "-i", plant / "log.csv", system="other-prior.toml")
    assert code == 2 and "the prior box x0 differ" in err
    code, _, err = _monitor(capsys, plant, "-i", plant / "log.csv", "--clear-after", 3)
    assert code == 2 and "the monitor's settings" in err


def test_the_api_refuses_another_plant_too():
    sc = scenarios.get("servo-motor", horizon=20)
    tr = sc.simulate("vertex", seed=1)
    mon = Monitor(sc.system, "interval-split", x0=sc.x0, L=L)
    mon.run(tr.u, tr.y)
    state = json.loads(json.dumps(mon.state()))
    wider = ivobs.LinearSystem(sc.system.A, sc.system.B, sc.system.C, D=sc.system.D,
                               E=sc.system.E, F=sc.system.F,
                               d=ivobs.Box(2 * sc.system.d.lo, 2 * sc.system.d.hi))  # fmt: skip
    with pytest.raises(IvobsError, match="the disturbance bounds d differ"):
        Monitor(wider, "interval-split", x0=sc.x0, L=L).restore(state)
    Monitor(sc.system, "interval-split", x0=sc.x0, L=L).restore(state)  # its own: accepted


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d.pop("stream"), "checksum"),
        (lambda d: d["stream"].update(step=10**9), "checksum"),
        (lambda d: d["stream"].update(rows=0), "checksum"),
        (lambda d: d["monitor"].update(alarms=0), "checksum"),
    ],
)
def test_an_edited_state_file_is_refused(plant, capsys, edit, message):
    assert _monitor(capsys, plant, "-i", plant / "head.csv")[0] == 1
    data = json.loads((plant / "state.json").read_text())
    edit(data)
    (plant / "state.json").write_text(json.dumps(data))
    code, out, err = _monitor(capsys, plant, "-i", plant / "log.csv")
    assert code == 2 and out == [] and message in err, err


def test_a_consistent_but_wrong_stream_entry_is_refused(plant, capsys):
    """A stream entry rewritten with its checksum recomputed (by a program, not a typo) is
    still checked against the monitor's step count."""
    from ivobs.io import statefile

    assert _monitor(capsys, plant, "-i", plant / "head.csv")[0] == 1
    data = json.loads((plant / "state.json").read_text())
    data["stream"]["step"] = 10**9
    statefile.write_state_file(plant / "state.json", data["method"], data["monitor"],
                               data["stream"])  # fmt: skip
    code, out, err = _monitor(capsys, plant, "-i", plant / "log.csv")
    assert code == 2 and out == [] and "stream.step: 1000000000, but 40 steps" in err


def test_a_state_resumed_on_another_stream_is_refused(plant, capsys):
    assert _monitor(capsys, plant, "-i", plant / "head.csv")[0] == 1
    other = plant / "other.csv"
    sc = scenarios.get("servo-motor", horizon=T)
    tr = sc.simulate("vertex", seed=7)
    write_log(other, tr.u, tr.y)
    code, out, err = _monitor(capsys, plant, "-i", other)
    assert code == 2 and out == [] and "was built from another stream" in err
    write_log(other, tr.u, tr.y, steps=False)  # other columns
    code, out, err = _monitor(capsys, plant, "-i", other)
    assert code == 2 and "columns u1,y1,y2, but the state" in err


def test_the_exit_status_counts_the_alarms_before_a_restart(plant, capsys):
    assert _monitor(capsys, plant, "-i", plant / "head.csv")[0] == 1  # the fault: 15..24
    code, out, _ = _monitor(capsys, plant, "-i", plant / "log.csv")  # 40..79: no new alarm
    assert len(out) == T - 40 and all(line.split(",")[7] == "0" for line in out)
    assert code == 1
    state = json.loads((plant / "state.json").read_text())
    assert state["monitor"]["alarms"] >= 10 and state["stream"]["step"] == T - 1
