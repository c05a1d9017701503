"""Fault isolation (:mod:`ivobs.monitor.isolate`): the faulty outputs named by the consistency
of the recent data with each output removed, not by which band a sample left. The servo of
[Tang2019] (angle ``y1``, speed ``y2``), a plant whose two outputs measure one state, and the
unicycle's ranges. Simulators written here and in ``vertexsim``."""

from __future__ import annotations

import json

import numpy as np
import pytest

import ivobs
from ivobs.cli import main
from ivobs.monitor import Monitor
from ivobs.monitor.isolate import History, Isolation
from vertexsim import servo_vertex

ONSET = 40


def _servo(T: int, seed: int = 0):
    sc, u, x, y = servo_vertex(T, seed)
    return sc.system, sc.x0, u, x, y


def _missed(out, x) -> np.ndarray:
    """The steps whose box misses the true state."""
    tol = 1e-9 * (1.0 + np.abs(x))
    return np.flatnonzero(~np.all((out.lower <= x + tol) & (x - tol <= out.upper), axis=1))


def test_an_angle_bias_is_isolated_to_the_angle() -> None:
    s, x0, u, x, y = _servo(60)
    y[ONSET:, 0] += 0.5  # 9 noise bounds
    out = Monitor(s, "interval-split", x0=x0).run(u, y)
    assert not out.alarm[:ONSET].any() and out.alarm[ONSET:].all()
    [f] = out.faults
    assert (f.start, f.outputs, f.isolated, f.isolation) == (ONSET, (0,), ((0,),), "y1")
    assert "isolated to y1: steps 20..40 fit the model without it" in out.reasons[ONSET]
    assert _missed(out, x).size == 0


@pytest.mark.parametrize("method", ["interval-split", "reachability"])
def test_a_speed_bias_is_isolated_to_the_speed(method: str) -> None:
    """+0.3 on the speed (5 noise bounds). ``interval-split``'s loose band lets the biased
    speed into its estimate for 4 steps; the first sample the band rejects is then the healthy
    angle's. Without isolation it blamed ``y1`` and its boxes missed the true state from there
    on; the window finds that only removing ``y2`` explains the data, and the estimate is
    recomputed over the window without ``y2``."""
    s, x0, u, x, y = _servo(60)
    y[ONSET:, 1] += 0.3
    out = Monitor(s, method, x0=x0).run(u, y)
    first = out.first_alarm
    assert first is not None and ONSET <= first <= ONSET + 5 and out.alarm[first:].all()
    [f] = out.faults
    assert (f.outputs, f.isolated, f.isolation) == ((1,), ((1,),), "y2")
    assert "isolated to y2" in out.reasons[first]
    assert f.bias_lower[1] <= 0.3 <= f.bias_upper[1] and f.bias_lower[1] > 0
    assert np.isnan(f.bias_lower[0])
    # before its detection the fault is inside the band: interval-split's boxes of those
    # steps took the biased speed in (they were printed before anything was known)
    missed = _missed(out, x)
    assert missed.size == 0 or (method == "interval-split" and missed.max() < first)


def _twin(T: int, onset: int, bias: float, seed: int = 3):
    """Two sensors of one state that moves by up to 1 a step: ``x+ = x + w``,
    ``y_i = x + v_i``, ``|v_i| <= 0.05`` on the vertices, ``w`` drawn in half its bounds (so
    that a jump of ``bias`` on either sensor fits a trajectory)."""
    s = ivobs.LinearSystem(
        [[1.0]],
        np.zeros((1, 0)),
        [[1.0], [1.0]],
        E=[[1.0, 0.0, 0.0]],
        F=[[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        d=ivobs.Box([-1.0, -0.05, -0.05], [1.0, 0.05, 0.05]),
    )
    rng = np.random.default_rng(seed)
    w = rng.uniform(-0.5, 0.5, T)
    v = np.where(rng.random((T, 2)) < 0.5, -0.05, 0.05)
    x = np.concatenate([[0.0], np.cumsum(w[:-1])])[:, None]
    y = x + v
    y[onset:, 1] += bias
    return s, ivobs.Box([-1.0], [1.0]), x, y


def test_two_sensors_of_one_state_cannot_be_told_apart() -> None:
    s, x0, x, y = _twin(45, 30, 0.4)
    out = Monitor(s, "reachability", x0=x0).run(None, y)
    assert not out.alarm[:30].any() and out.alarm[30:].all()
    [f] = out.faults
    assert f.isolated == ((0,), (1,)) and f.isolation == "y1 or y2 (cannot be told apart)"
    assert f.outputs == (0, 1)  # one of them is faulty: both are held out
    assert "y1 or y2: steps 10..30 fit the model without either" in out.reasons[30]
    assert _missed(out, x).size == 0


@pytest.mark.parametrize("output", [1, 3])
def test_a_bias_on_a_nonlinear_plant_is_isolated_to_that_output(output: int) -> None:
    """The unicycle's second range, or its compass: +0.5 from step 20. The window is the
    constrained zonotope of the nonlinear model over 10 steps (5 runs, one per hypothesis: the
    costly part)."""
    sc = ivobs.scenarios.get("unicycle-range")
    tr = sc.simulate("vertex", seed=1)
    y = tr.y[:30].copy()
    y[20:, output] += 0.5
    out = Monitor(sc.system, "nl-interval", x0=sc.x0, window=10).run(tr.u[:30], y)
    assert not out.alarm[:20].any() and out.alarm[20:].all()
    [f] = out.faults
    assert (f.outputs, f.isolated) == ((output,), ((output,),))
    assert f.isolation == f"y{output + 1}"
    assert f.bias_lower[output] <= 0.5 <= f.bias_upper[output]
    assert _missed(out, tr.x[:30]).size == 0


def test_the_history_and_the_isolation_are_saved_and_resumed() -> None:
    """Saved before the fault (the window's anchors and rows) and during it (the isolation):
    the resumed monitor gives the same steps as one that never stopped."""
    s, x0, u, _, y = _servo(55)
    y[ONSET:, 1] += 0.3
    whole = Monitor(s, "interval-split", x0=x0).run(u, y)
    for cut in (37, 47):
        mon = Monitor(s, "interval-split", x0=x0)
        mon.run(u[:cut], y[:cut])
        saved = json.loads(json.dumps(mon.state()))
        again = Monitor(s, "interval-split", x0=x0)
        again.restore(saved)
        rest = again.run(u[cut:], y[cut:])
        assert np.array_equal(rest.lower, whole.lower[cut:])
        assert rest.reasons == whole.reasons[cut:]
        assert rest.faults[0].isolated == ((1,),)
    assert saved["isolation"]["candidates"] == [[1]]
    bad = json.loads(json.dumps(saved))
    bad["isolation"]["candidates"] = [[5]]
    with pytest.raises(ivobs.IvobsError, match="state: isolation"):
        Monitor(s, "interval-split", x0=x0).restore(bad)
    bad = json.loads(json.dumps(saved))
    bad["history"]["rows"][0][2] = [1.0]
    with pytest.raises(ivobs.IvobsError, match="state: history"):
        Monitor(s, "interval-split", x0=x0).restore(bad)
    # a state written before isolation (no history) continues, its next windows shorter
    old = json.loads(json.dumps(saved))
    del old["history"], old["isolation"]
    mon = Monitor(s, "interval-split", x0=x0)
    mon.restore(old)
    assert mon.run(u[47:], y[47:]).alarm.all()
    # another window is another setting: the state is refused
    with pytest.raises(ivobs.IvobsError, match="written for another model"):
        Monitor(s, "interval-split", x0=x0, window=30).restore(saved)


def test_bad_arguments_are_named() -> None:
    s, x0, *_ = _servo(2)
    for window in (1, 2.5, True, "20"):
        with pytest.raises(ivobs.IvobsError, match="window: expected an integer >= 2"):
            Monitor(s, "interval-split", x0=x0, window=window)


def test_the_window_and_the_texts() -> None:
    h = History(20)
    assert [h.first(k) for k in (0, 19, 20, 29, 30, 39)] == [0, 0, 0, 10, 10, 20]
    assert Isolation(((1,),), 20, 44, "isolated").text == "y2"
    assert Isolation(((0, 1),), 20, 44, "isolated").text == "y1;y2"
    assert Isolation((), 20, 44, "consistent").text == "not isolated: steps 20..44 fit the model"
    assert "no output set explains" in Isolation((), 20, 44, "unexplained").text


def test_cli_monitor_and_run_name_the_isolated_output(tmp_path, capsys) -> None:
    """``ivobs monitor``'s ``fault_isolated`` column, ``ivobs run``'s episode line and its HTML
    report."""
    sc = ivobs.scenarios.get("servo-motor")
    ivobs.save_system(tmp_path / "servo.toml", sc)
    _, _, u, _, y = _servo(60)
    y[ONSET:, 1] += 0.3
    ivobs.io.write_log(tmp_path / "log.csv", u, y)
    argv = ["--system", str(tmp_path / "servo.toml"), "--method", "interval-split"]
    assert main(["monitor", *argv, "--input", str(tmp_path / "log.csv")]) == 1
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].endswith(",bias_upper_2,fault_isolated")
    assert lines[-1].endswith(",y2") and lines[ONSET].endswith(",")
    argv += ["--log", str(tmp_path / "log.csv")]
    html = pytest.importorskip("plotly") and ["--html", str(tmp_path / "r.html")]
    assert main(["run", *argv, *html]) == 1
    out = capsys.readouterr().out
    assert ": y2; isolated: y2; bias y2 in [" in out
    page = (tmp_path / "r.html").read_text()
    assert "<b>Fault episodes</b>" in page and "isolated: y2" in page


def test_the_worked_nonlinear_example_of_the_guide_runs_as_written():
    """docs/operating.md's worked example (detection, isolation, estimation on the unicycle):
    its code runs and its results are the ones the comments state."""
    import pathlib
    import re

    text = (pathlib.Path(__file__).parents[1] / "docs" / "operating.md").read_text()
    start = text.index("**Worked example: detection, isolation and estimation")
    code = re.search(r"```python\n(.*?)```", text[start:], re.S)
    assert code is not None
    scope: dict[str, object] = {}
    exec(compile(code.group(1), "operating.md", "exec"), scope)  # the guide's own code
    out, f, traj = scope["out"], scope["f"], scope["traj"]
    assert out.first_alarm == 80 and bool(out.alarm[80:].all())
    assert (f.start, f.end, f.outputs, f.isolation) == (80, None, (1,), "y2")
    assert f.bias_text == "y2 in [0.3, 0.3]"
    assert f.bias_lower[1] <= 0.3 <= f.bias_upper[1]  # y2, estimated (NaN for the others)
    tol = 1e-9 * (1.0 + np.abs(traj.x))
    assert np.all((out.lower <= traj.x + tol) & (traj.x - tol <= out.upper))
