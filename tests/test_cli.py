"""The ivobs command."""

import functools
import subprocess
import sys

import numpy as np
import pytest

import ivobs
from ivobs.cli import main


def test_help_lists_commands(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for cmd in ["demo", "run", "scenarios", "methods"]:
        assert cmd in out


def test_scenarios_and_methods(capsys):
    assert main(["scenarios"]) == 0
    assert "servo-motor" in capsys.readouterr().out
    assert main(["methods"]) == 0


def test_unknown_scenario_is_a_clean_error(capsys):
    assert main(["run", "nope", "--method", "interval"]) == 2
    assert "unknown scenario 'nope'" in capsys.readouterr().err


def test_demo_writes_figure_and_table(tmp_path, capsys):
    import ivobs

    code = main(["demo", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert "| method |" in out
    if [m for m in ivobs.methods() if m != "intersect"]:
        assert code == 0 and (tmp_path / "servo-motor.png").stat().st_size > 1000
        assert "**NO**" not in out


def test_console_entry_point_runs():
    r = subprocess.run(
        [sys.executable, "-m", "ivobs.cli", "scenarios"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0 and "henon" in r.stdout


# -- your own plant on compare / run ---------------------------------------------------------
def _servo_files(tmp_path):
    sc = ivobs.scenarios.get("servo-motor")
    ivobs.save_system(tmp_path / "servo.toml", sc)
    tr = sc.simulate("vertex", seed=1)
    ivobs.io.write_log(tmp_path / "log.csv", tr.u[:60], tr.y[:60])
    return sc, tr


def test_compare_takes_a_system_file_and_a_log(tmp_path, capsys):
    import json

    sc, tr = _servo_files(tmp_path)
    argv = ["compare", "--system", str(tmp_path / "servo.toml"), "--log", str(tmp_path / "log.csv")]
    argv += ["--methods", "interval-split,exact", "--json", str(tmp_path / "cmp.json")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "| interval-split |" in out and "60 steps" in out
    doc = json.loads((tmp_path / "cmp.json").read_text())
    assert [m["method"] for m in doc["methods"]] == ["interval-split", "exact"]
    assert doc["horizon"] == 60 and doc["methods"][0]["contains_truth"] is None  # a log: no truth
    # the same numbers as the Python API on the log's data
    # compare's default: the measurement strips
    ref = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, strips=True)
    ref = ref.run(tr.u[:60], tr.y[:60])
    burn = 6
    assert doc["methods"][0]["mean_width"] == pytest.approx(ref.mean_width(burn).tolist())


def test_compare_simulates_a_system_file_and_refuses_mixtures(tmp_path, capsys):
    _servo_files(tmp_path)
    system = str(tmp_path / "servo.toml")
    assert main(["compare", "--system", system, "--horizon", "40", "--methods", "exact"]) == 0
    assert "40 steps, vertex disturbances" in capsys.readouterr().out
    assert main(["compare", "servo-motor", "--log", str(tmp_path / "log.csv")]) == 2
    assert "need --system FILE" in capsys.readouterr().err
    assert main(["compare", "--system", system]) == 2
    assert "give --log FILE" in capsys.readouterr().err
    assert main(["compare", "servo-motor", "--system", system]) == 2


def test_run_discretizes_a_continuous_system_file(tmp_path, capsys):
    ct = ivobs.LinearSystem(
        [[-1.0, 1.0], [0.0, -2.0]], [[0.0], [1.0]], [[1.0, 0.0]],
        E=[[0.1], [0.0]], d=ivobs.Box([-1.0], [1.0]), dt=0,
    )  # fmt: skip
    ivobs.save_system(tmp_path / "ct.toml", ct, x0=ivobs.Box([-1.0, -1.0], [1.0, 1.0]))
    sd = ct.discretize(0.1, disturbances="held")
    x, ys = np.zeros(2), []
    for k in range(30):  # the test's own simulator, disturbance on a vertex
        ys.append(sd.C @ x)
        x = sd.A @ x + sd.B[:, 0] + sd.E[:, 0] * (-1) ** k
    ivobs.io.write_log(tmp_path / "log.csv", np.ones((30, 1)), np.array(ys), t=0.1 * np.arange(30))
    base = ["run", "--system", str(tmp_path / "ct.toml"), "--log", str(tmp_path / "log.csv")]
    assert main([*base, "--method", "interval-split"]) == 2
    assert "give --discretize TS" in capsys.readouterr().err
    assert main([*base, "--method", "interval-split", "--discretize", "0.1"]) == 0
    assert "alarms: none" in capsys.readouterr().out
    held = [*base, "--method", "interval-split", "--discretize", "0.1", "--held-disturbances"]
    assert main(held) == 0
    assert "alarms: none" in capsys.readouterr().out
    assert main([*base, "--method", "interval-split", "--held-disturbances"]) == 2
    assert "only with --discretize" in capsys.readouterr().err
    assert main([*base, "--method", "interval-split", "--discretize", "0.2"]) == 2
    assert "not sampled every --discretize 0.2" in capsys.readouterr().err


def test_options_on_the_command_line_and_from_the_system_file(tmp_path, capsys):
    """``--option`` gives a method's design options as the API takes them; ``compare
    --system`` honours the file's ``[method.options]`` (the numbers of ``run`` and of the API
    with the same options)."""
    sc = ivobs.scenarios.get("servo-motor")
    path = tmp_path / "servo.toml"
    ivobs.save_system(path, sc.system, x0=sc.x0, method="zonotope", options={"order": 8})
    # the API with the file's options, then with other ones, on the record compare simulates
    from ivobs.io.plant import file_scenario

    plant = file_scenario(path, horizon=200)
    tr = plant.simulate("vertex", seed=0)
    zono = functools.partial(ivobs.make_estimator, "zonotope", sc.system, x0=sc.x0, strips=True)
    api4, api60 = zono(order=8).run(tr.u, tr.y), zono(order=60).run(tr.u, tr.y)
    burn = 200 // 10
    widths = {}
    for extra, key in (([], 4), (["--option", "zonotope.order=60"], 60)):
        args = ["compare", "--system", str(path), "--horizon", "200", "--methods", "zonotope"]
        assert main(args + extra + ["--json", "-"]) == 0
        out = capsys.readouterr().out
        import json

        rows = json.loads(out[out.index("[") : out.rindex("]") + 1])
        widths[key] = np.array(rows[0]["mean_width"])
    np.testing.assert_allclose(widths[4], api4.mean_width(burn), rtol=1e-12)
    np.testing.assert_allclose(widths[60], api60.mean_width(burn), rtol=1e-12)
    assert not np.allclose(widths[4], widths[60])
    # run takes KEY=VALUE for its one method; bad items are clear errors
    assert main(["run", "servo-motor", "-m", "zonotope", "--option", "order=60"]) == 0
    capsys.readouterr()
    assert main(["run", "servo-motor", "-m", "zonotope", "--option", "order"]) == 2
    assert "expected [METHOD.]KEY=VALUE" in capsys.readouterr().err
    two = ["compare", "servo-motor", "--methods", "zonotope,reachability"]
    assert main([*two, "--option", "order=3"]) == 2
    assert "names no method" in capsys.readouterr().err
    assert main(["compare", "servo-motor", "--methods", "zonotope", "--option", "exact.x=1"]) == 2
    assert "which this command does not run" in capsys.readouterr().err
