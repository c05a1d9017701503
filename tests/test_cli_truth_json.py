"""``--truth FILE`` on ``ivobs run`` and ``ivobs compare`` (the true state of a logged record),
``ivobs run --json`` (the summary ``compare --json`` writes), and ``compare --baseline
kalman``: a Kalman filter's band, shown as not guaranteed, whose misses are counted."""

import copy
import json

import numpy as np
import pytest

import ivobs
from ivobs.cli import main
from ivobs.io import read_log, save_system, write_log
from ivobs.io.truth import read_truth
from ivobs.model.statespace import SignalNames
from ivobs.report.baseline import kalman_baseline

T = 40
NAMES = ("theta", "n", "i")
ROW_KEYS = {
    "method", "guaranteed", "ok", "error", "options", "mean_width", "mean_width_by_state",
    "steps", "valid_from", "inconsistent_steps", "contains_truth", "misses", "design_time_s",
    "run_time_s", "cpu_time_s",
}  # fmt: skip


def _truth_csv(path, x, header=None, steps=True):
    header = header or [f"x{i + 1}" for i in range(x.shape[1])]
    lines = [",".join((["k"] if steps else []) + list(header))]
    for k, row in enumerate(x):
        lines.append(",".join(([str(k)] if steps else []) + [repr(float(v)) for v in row]))
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def plant(tmp_path_factory):
    """The servo (states named) with a log and its true state, under disturbances on the
    vertices of their bounds (the adversarial case: a Kalman band misses the state there)."""
    folder = tmp_path_factory.mktemp("plant")
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    tr = sc.simulate("vertex", seed=1)
    system = copy.copy(sc.system)
    system.names = SignalNames(states=NAMES)
    save_system(folder / "servo.toml", system, x0=sc.x0, method="interval-split")
    write_log(folder / "log.csv", tr.u, tr.y)
    _truth_csv(folder / "truth.csv", tr.x)
    return folder, sc, tr


def _json_after(text):
    return json.loads(text[text.index("{") :])


def test_run_truth_and_json_are_the_api_numbers(plant, capsys):
    folder, sc, tr = plant
    argv = ["run", "-s", str(folder / "servo.toml"), "-l", str(folder / "log.csv")]
    assert main([*argv, "--truth", str(folder / "truth.csv"), "--json", "-"]) == 0
    out = capsys.readouterr().out
    assert "contains the true state at every step: yes" in out
    doc = _json_after(out)
    assert doc["horizon"] == T and doc["first_step"] == 0 and len(doc["methods"]) == 1
    row = doc["methods"][0]
    assert set(row) == ROW_KEYS
    api = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0).run(tr.u, tr.y)
    np.testing.assert_allclose(row["mean_width"], api.mean_width(), rtol=1e-12)
    assert list(row["mean_width_by_state"]) == list(NAMES)
    assert row["contains_truth"] is True and row["misses"] == 0
    assert row["guaranteed"] is True and row["steps"] == T and row["inconsistent_steps"] == []
    assert row["cpu_time_s"] >= 0 and row["options"] == {}
    # without --truth: no containment claim, null in the JSON
    assert main([*argv, "--json", str(folder / "run.json")]) == 0
    assert "contains the true state" not in capsys.readouterr().out
    row = json.loads((folder / "run.json").read_text())["methods"][0]
    assert row["contains_truth"] is None and row["misses"] is None


def test_run_json_on_a_scenario(capsys):
    assert main(["run", "servo-motor", "-m", "interval-split", "--json", "-"]) == 0
    doc = _json_after(capsys.readouterr().out)
    row = doc["methods"][0]
    assert doc["scenario"] == "servo-motor" and doc["burn_in"] == 10
    assert row["method"] == "interval-split" and row["contains_truth"] is True
    assert row["misses"] == 0 and row["steps"] == 100


def test_compare_truth_and_the_kalman_baseline(plant, capsys):
    folder, sc, tr = plant
    argv = ["compare", "-s", str(folder / "servo.toml"), "-l", str(folder / "log.csv"),
            "--truth", str(folder / "truth.csv"), "--methods", "interval-split",
            "--baseline", "kalman", "--json", "-"]  # fmt: skip
    assert main(argv) == 0  # the baseline's misses are expected: not a failure
    out = capsys.readouterr().out
    assert "(NOT guaranteed)" in out
    guaranteed, kalman = _json_after(out)["methods"]
    assert set(guaranteed) == set(kalman) == ROW_KEYS
    burn = T // 10
    # compare's default: the measurement strips (its JSON lists the option)
    assert guaranteed["options"] == {"strips": True}
    api = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, strips=True)
    api = api.run(tr.u, tr.y)
    np.testing.assert_allclose(guaranteed["mean_width"], api.mean_width(burn), rtol=1e-12)
    assert guaranteed["contains_truth"] is True and guaranteed["misses"] == 0
    band = kalman_baseline(sc.system, sc.x0, tr.u, tr.y)
    assert kalman["guaranteed"] is False and kalman["method"] == band.method
    np.testing.assert_allclose(kalman["mean_width"], band.mean_width(burn), rtol=1e-12)
    # what the guarantee costs: the band is narrower, and misses the state on this record
    assert kalman["misses"] == int(np.sum(~band.contains(tr.x))) > 0
    assert kalman["contains_truth"] is False
    # (on the unmeasured current; the measured states' boxes are met with their sensors')
    assert kalman["mean_width"][2] < guaranteed["mean_width"][2]


def test_kalman_baseline_is_the_textbook_filter():
    """A scalar plant with separate process and measurement noise: the recursion by hand."""
    a, rw, rv = 0.9, 0.2, 0.5
    sys = ivobs.LinearSystem([[a]], np.zeros((1, 0)), [[1.0]], E=[[1.0, 0.0]], F=[[0.0, 1.0]],
                             d=ivobs.Box([-rw, -rv], [rw, rv]))  # fmt: skip
    y = np.array([[0.3], [np.nan], [-0.2], [0.1]])
    band = kalman_baseline(sys, ivobs.Box([-1.0], [1.0]), None, y)
    x, p, q, r = 0.0, 1.0 / 3.0, rw**2 / 3.0, rv**2 / 3.0
    for k in range(len(y)):
        if not np.isnan(y[k, 0]):
            gain = p / (p + r)
            x, p = x + gain * (y[k, 0] - x), (1.0 - gain) * p
        assert band.lower[k, 0] == pytest.approx(x - 3.0 * np.sqrt(p), rel=1e-12)
        assert band.upper[k, 0] == pytest.approx(x + 3.0 * np.sqrt(p), rel=1e-12)
        x, p = a * x, a * a * p + q
    assert band.info["guaranteed"] is False


def test_kalman_is_no_method_and_needs_a_linear_model(capsys):
    assert not any("kalman" in m for m in ivobs.estimators.methods())
    assert main(["compare", "servo-uncertain", "--baseline", "kalman"]) == 2
    err = capsys.readouterr().err
    assert "--baseline kalman: needs a linear model" in err and "interval matrices" in err
    nl = ivobs.NonlinearSystem(f=["0.5*x1 + d1"], h=["x1"], states=["x1"], d={"d1": (-1, 1)})
    x0 = ivobs.Box([-1.0], [1.0])
    sc = ivobs.scenarios.Scenario("nl", nl, x0, np.zeros(1), np.zeros((5, 0)), 5, source="")
    with pytest.raises(ivobs.IvobsError, match="got a NonlinearSystem"):
        ivobs.report.compare(sc, ["nl-interval"], disturbance="zero", baselines=["kalman"])


def test_truth_columns_by_name_or_number_in_any_order(plant, tmp_path):
    folder, _, tr = plant
    spec = ivobs.io.load_system(folder / "servo.toml")
    log = read_log(folder / "log.csv", spec)
    order = [2, 0, 1]
    _truth_csv(tmp_path / "named.csv", tr.x[:, order], header=[NAMES[j] for j in order])
    np.testing.assert_array_equal(read_truth(tmp_path / "named.csv", spec, log), tr.x)
    _truth_csv(tmp_path / "numbered.csv", tr.x[:, order], header=["x3", "x1", "x2"], steps=False)
    np.testing.assert_array_equal(read_truth(tmp_path / "numbered.csv", spec, log), tr.x)


def _edit(text, case):
    lines = text.splitlines()
    if case == "missing row":
        del lines[-1]
    elif case == "gap":
        del lines[5]
    elif case == "columns":
        lines[0] = lines[0].replace("x3", "x4")
    elif case == "two columns":
        lines = [line.rsplit(",", 1)[0] for line in lines]
    elif case == "extra row":
        lines.append(f"{T}," + lines[-1].split(",", 1)[1])
    elif case == "empty cell":
        lines[3] = lines[3].rsplit(",", 1)[0] + ","
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    "case, says",
    [
        ("missing row", f"39 rows (steps 0..38), but the log has {T} steps"),
        ("gap", "step 4 missing (k jumps to 5)"),
        ("columns", "expected 3 state columns named theta, n, i or x1..x3"),
        ("two columns", "got ['x1', 'x2']"),
        ("extra row", f"{T + 1} rows"),
        ("empty cell", "the true state at step 2 has an empty or NaN cell"),
    ],
)
@pytest.mark.parametrize("command", ["run", "compare"])
def test_a_truth_that_does_not_fit_the_log_is_refused(plant, tmp_path, capsys, case, says, command):
    folder, *_ = plant
    bad = tmp_path / "bad.csv"
    bad.write_text(_edit((folder / "truth.csv").read_text(), case))
    argv = [command, "-s", str(folder / "servo.toml"), "-l", str(folder / "log.csv")]
    argv += ["--truth", str(bad)] + (
        ["--methods", "interval-split"] if command == "compare" else []
    )
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"--truth {bad}" in err and says in err, err


def test_truth_needs_a_log_and_is_never_overwritten(plant, capsys):
    folder, *_ = plant
    truth = str(folder / "truth.csv")
    before = (folder / "truth.csv").read_bytes()
    assert main(["run", "servo-motor", "-m", "interval-split", "--truth", truth]) == 2
    assert "need --system FILE" in capsys.readouterr().err
    assert main(["compare", "servo-motor", "--truth", truth]) == 2
    assert "--truth: the true state of a measurement log" in capsys.readouterr().err
    system = str(folder / "servo.toml")
    assert main(["compare", "-s", system, "--horizon", "20", "--truth", truth]) == 2
    assert "--truth: the true state of a measurement log" in capsys.readouterr().err
    base = ["-s", system, "-l", str(folder / "log.csv"), "--truth", truth]
    for argv in (["run", *base, "--json", truth], ["run", *base, "--out", truth],
                 ["compare", *base, "--methods", "interval-split", "--json", truth]):  # fmt: skip
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert "--truth" in err and "would overwrite it" in err, err
    assert (folder / "truth.csv").read_bytes() == before


def test_compare_lists_only_the_methods_that_accept_the_model():
    from ivobs.cli.compare import applicable_methods, default_methods

    nl = ivobs.scenarios.get("pendulum-nl")
    names, left_out = default_methods(nl)
    assert names == ["nl-interval", "nl-zonotope", "nl-constrained-zonotope", "nl-horizon"]
    assert not left_out
    assert "reachability" in applicable_methods(nl.system)[1]
    ct = ivobs.scenarios.get("servo-motor").system
    ct = ivobs.LinearSystem(ct.A - np.eye(3), ct.B, ct.C, E=ct.E, F=ct.F, d=ct.d, dt=0)
    ok, refused = applicable_methods(ct)
    assert ok == ["kkl", "intersect"] and "strip" in refused
