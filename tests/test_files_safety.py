"""Files are safe to use: no output ever overwrites an input (also through links), loading a
system file or a campaign spec runs no code and a spec writes only into its folder unless the
user opts in, a discrete-time system refuses a sample time, and a bad option value in a system
file names its file and line."""

import os
import sys

import numpy as np
import pytest

from ivobs import IvobsError, campaign, make_estimator, scenarios
from ivobs.cli import main
from ivobs.io import dumps_system, load_system, loads_system, save_system, write_log


@pytest.fixture
def plant(tmp_path):
    """A servo system file (with bounds from a CSV file) and a log of 40 steps."""
    sc = scenarios.get("servo-motor", horizon=40)
    tr = sc.simulate("vertex", seed=3)
    save_system(tmp_path / "s.toml", sc, method="interval-split")
    text = (tmp_path / "s.toml").read_text()
    lo = ", ".join(repr(float(v)) for v in np.atleast_1d(sc.system.d.lo))
    hi = ", ".join(repr(float(v)) for v in np.atleast_1d(sc.system.d.hi))
    head = ",".join(f"h{i}" for i in range(sc.system.nd))
    (tmp_path / "bounds.csv").write_text(f"{head}\n" + f"{hi}\n" * 40)
    cols = ", ".join(f'"h{i}"' for i in range(sc.system.nd))
    text = text.replace(f"upper = [{hi}]", f'csv = "bounds.csv"\nupper = [{cols}]')
    assert f"lower = [{lo}]" in text and 'csv = "bounds.csv"' in text
    (tmp_path / "s.toml").write_text(text)
    write_log(tmp_path / "log.csv", tr.u, tr.y)
    return tmp_path


def _snapshot(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


# -- 1. no output overwrites an input ------------------------------------------------------


def test_same_file_sees_through_symbolic_and_hard_links(tmp_path):
    from ivobs.io.atomic import check_distinct, same_file

    a = tmp_path / "a.csv"
    a.write_text("x\n")
    os.symlink(a, tmp_path / "sym.csv")
    os.link(a, tmp_path / "hard.csv")
    os.symlink(tmp_path, tmp_path / "dir")
    assert same_file(a, tmp_path / "sym.csv") and same_file(a, tmp_path / "hard.csv")
    assert same_file(a, tmp_path / "dir" / "a.csv") and same_file(a, f"{tmp_path}/./a.csv")
    assert same_file(tmp_path / "new.csv", tmp_path / "dir" / "new.csv")  # neither exists
    assert not same_file(a, tmp_path / "b.csv")
    with pytest.raises(IvobsError, match=r"--out, --log: .* is the input --log"):
        check_distinct({"--out": tmp_path / "hard.csv"}, {"--log": a})
    check_distinct({"--out": tmp_path / "b.csv", "--plot": None}, {"--log": a, "--x": None})


@pytest.mark.parametrize(
    "out, clash",
    [
        ("log.csv", "--log"),
        ("s.toml", "--system"),
        ("sym-log.csv", "--log"),  # a symbolic link to the log
        ("hard-log.csv", "--log"),  # a hard link to the log
        ("bounds.csv", "--system's [disturbance] csv"),
    ],
)
@pytest.mark.parametrize("option", ["--out", "--csv"])
def test_run_refuses_to_overwrite_an_input(plant, capsys, out, clash, option):
    os.symlink(plant / "log.csv", plant / "sym-log.csv")
    os.link(plant / "log.csv", plant / "hard-log.csv")
    before = _snapshot(plant)
    argv = ["run", "--system", str(plant / "s.toml"), "--log", str(plant / "log.csv")]
    code = main([*argv, option, str(plant / out)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"--csv, {clash}: " in err and "would overwrite it" in err, err
    assert _snapshot(plant) == before  # nothing written, the input intact


def test_run_refuses_a_figure_over_an_input(plant, capsys):
    (plant / "log.png").write_bytes(b"not really a figure, but an input here")
    before = _snapshot(plant)
    argv = ["run", "--system", str(plant / "s.toml"), "--log", str(plant / "log.png")]
    assert main([*argv, "--plot", str(plant / "log.png")]) == 2
    assert "--plot, --log: " in capsys.readouterr().err
    assert _snapshot(plant) == before


def test_run_refuses_two_outputs_in_one_file_through_a_link(plant, capsys):
    os.symlink(plant / "r.png", plant / "link.png")
    argv = ["run", "--system", str(plant / "s.toml"), "--log", str(plant / "log.csv")]
    code = main([*argv, "--csv", str(plant / "r.png"), "--plot", str(plant / "link.png")])
    assert code == 2 and "--csv, --plot: both write" in capsys.readouterr().err


def test_monitor_state_cannot_be_an_input(plant, capsys, monkeypatch):
    before = _snapshot(plant)
    argv = ["monitor", "--system", str(plant / "s.toml"), "--input", str(plant / "log.csv")]
    for state, clash in (("log.csv", "--input"), ("s.toml", "--system"),
                         ("bounds.csv", "--system's [disturbance] csv")):  # fmt: skip
        assert main([*argv, "--state", str(plant / state)]) == 2
        captured = capsys.readouterr()
        assert f"--state, {clash}: " in captured.err and captured.out == ""
    assert _snapshot(plant) == before


SPEC = 'scenarios = ["servo-motor"]\nmethods = ["interval-split"]\nhorizon = 30\n'


def test_campaign_outputs_cannot_be_the_spec_or_one_file(tmp_path, capsys):
    spec = tmp_path / "spec.toml"
    spec.write_text(SPEC + 'summary = "spec.toml"\n')
    before = spec.read_text()
    assert main(["campaign", str(spec), "--workers", "0"]) == 2
    assert "summary, the spec: " in capsys.readouterr().err and spec.read_text() == before
    with pytest.raises(IvobsError, match="summary, the spec"):
        campaign.run_campaign(spec, workers=0)
    spec.write_text(SPEC)
    for extra, needle in (
        (["--output", str(spec)], "--output, the spec: "),
        (["--summary", str(tmp_path / "spec.csv")], "output, --summary: both write"),
        (["--output", str(tmp_path / "r.csv"), "--summary", str(tmp_path / "r.csv")],
         "--output, --summary: both write"),
    ):  # fmt: skip
        assert main(["campaign", str(spec), "--workers", "0", *extra]) == 2
        assert needle in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["spec.toml"]
    with pytest.raises(IvobsError, match="output, the spec"):
        campaign.run_campaign(spec, workers=0, output=spec)


# -- 2. loading runs no code unless trusted ------------------------------------------------

PAYLOAD = """\
import pathlib
pathlib.Path({marker!r}).write_text("the module ran")

def A_of_k(k):
    return [[0.5, 0.0], [0.0, 0.5]]
"""

SYSTEM = """\
[system]
A = {{ python = "{path}" }}
C = [[1.0, 0.0]]
"""


@pytest.fixture
def payload(tmp_path, monkeypatch):
    """An importable module that leaves a file behind when it is imported."""
    marker = tmp_path / "ran.txt"
    (tmp_path / "untrusted_payload.py").write_text(PAYLOAD.format(marker=str(marker)))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield marker
    sys.modules.pop("untrusted_payload", None)


def test_a_system_file_runs_no_code_unless_allowed(tmp_path, payload, capsys):
    path = tmp_path / "s.toml"
    path.write_text(SYSTEM.format(path="untrusted_payload:A_of_k"))
    with pytest.raises(IvobsError) as err:
        load_system(path)
    assert str(err.value) == (
        f"{path}, line 2: system.A.python: refers to Python code untrusted_payload:A_of_k; "
        "loading it would run that code: pass --allow-code (CLI) or allow_code=True (API) if "
        "you trust this file"
    )
    with pytest.raises(IvobsError, match="allow_code=True"):
        loads_system(path.read_text())
    assert not payload.exists() and "untrusted_payload" not in sys.modules
    (tmp_path / "log.csv").write_text("k,y1\n0,0.1\n1,0.05\n")
    run = ["run", "--system", str(path), "--log", str(tmp_path / "log.csv"), "-m", "interval"]
    assert main(run) == 2
    assert "--allow-code" in capsys.readouterr().err and not payload.exists()
    assert main(["monitor", "--system", str(path), "-m", "interval"]) == 2
    assert "--allow-code" in capsys.readouterr().err and not payload.exists()
    # trusted: the module is imported and its function is the matrix
    f = load_system(path, allow_code=True)
    assert payload.read_text() == "the module ran"
    np.testing.assert_array_equal(f.system.A_at(3), 0.5 * np.eye(2))
    with pytest.raises(IvobsError, match="allow_code: expected True or False, got 'yes'"):
        load_system(path, allow_code="yes")


def test_a_system_file_may_name_ivobs_scenario_functions_only_by_default():
    for name in ("henon", "pendulum"):  # bounds / a matrix of t by an ivobs.scenarios callable
        sc = scenarios.get(name)
        text = dumps_system(sc.system, x0=sc.x0)
        assert 'python = "ivobs.scenarios:' in text
        back = loads_system(text).system
        np.testing.assert_array_equal(back.A_at(0.3), sc.system.A_at(0.3))
    # a name reached through ivobs.scenarios but defined elsewhere is not ivobs' own function
    for path in (
        "ivobs.scenarios.efimov2013:np.eye",
        "ivobs.scenarios.efimov2013:np.linalg.inv",
        "ivobs.io.atomic:write_text_atomic",
        "ivobs:load_system",
        "os:system",
    ):
        with pytest.raises(IvobsError, match=f"refers to Python code {path}"):
            loads_system(SYSTEM.format(path=path))


def test_a_spec_imports_nothing_and_writes_in_its_folder_unless_allowed(tmp_path, payload):
    folder = tmp_path / "c"
    folder.mkdir()
    spec = folder / "spec.toml"
    spec.write_text(SPEC + 'imports = ["untrusted_payload"]\n')
    with pytest.raises(IvobsError, match=r"line 4: imports: imports Python module "):
        campaign.load_spec(spec)
    with pytest.raises(IvobsError, match="allow_code=True"):
        campaign.run_campaign(spec, workers=0)
    assert not payload.exists() and "untrusted_payload" not in sys.modules
    assert campaign.load_spec(spec, allow_code=True).imports == ["untrusted_payload"]
    assert payload.exists()

    os.symlink(tmp_path, folder / "up")
    for output in ("../r.csv", str(tmp_path / "r.csv"), "up/r.csv", "sub/../../r.csv"):
        for key in ("output", "summary"):
            spec.write_text(SPEC + f"{key} = {output!r}\n")
            with pytest.raises(IvobsError) as err:
                campaign.load_spec(spec)
            assert f"line 4: {key}: {output!r} is outside the spec's folder" in str(err.value)
            assert "--allow-outside (CLI) or allow_outside=True (API)" in str(err.value)
            got = campaign.load_spec(spec, allow_outside=True)
            assert (got.output if key == "output" else got.summary) == folder / output
    spec.write_text(SPEC + 'output = "sub/r.csv"\nsummary = "./s.md"\n')
    got = campaign.load_spec(spec)
    assert got.output == folder / "sub/r.csv" and got.summary == folder / "s.md"


def test_campaign_cli_opt_ins(tmp_path, capsys):
    folder = tmp_path / "c"
    folder.mkdir()
    spec = folder / "spec.toml"
    spec.write_text(SPEC + 'output = "../r.csv"\n')
    assert main(["campaign", str(spec), "--workers", "0", "-q"]) == 2
    assert "--allow-outside" in capsys.readouterr().err and not (tmp_path / "r.csv").exists()
    # an output given on the command line is the user's choice, not the spec's
    assert main(["campaign", str(spec), "-j", "0", "-q", "-o", str(tmp_path / "x.csv")]) == 2
    capsys.readouterr()
    assert main(["campaign", str(spec), "--workers", "0", "-q", "--allow-outside"]) == 0
    assert len(campaign.read_results(tmp_path / "r.csv")) == 1


# -- 3. a sample time on a discrete-time system, option values of a file ------------------


def test_discrete_time_refuses_a_sample_time():
    sc = scenarios.get("servo-motor", horizon=5)
    tr = sc.simulate("vertex", seed=0)
    est = make_estimator("interval-split", sc.system, x0=sc.x0)
    with pytest.raises(IvobsError) as err:
        est.step(tr.u[0], tr.y[0], t=0.5)
    assert str(err.value) == (
        "t: this system is discrete-time: its steps are counted by k, and t, the "
        "sample time of the step, applies to continuous-time systems (dt = 0) only; leave t out"
    )
    assert est.k == 0
    # a record's times label the result (the steps stay k); a step carries no label
    labelled = est.run(tr.u, tr.y, t=np.arange(5) * 0.1)
    assert np.array_equal(labelled.t, np.arange(5) * 0.1)
    assert labelled.equals(est.run(tr.u, tr.y))
    with pytest.raises(IvobsError, match="sample time of the step"):
        est.predict(tr.u[0], 0.5)
    est.step(tr.u[0], tr.y[0])  # without t: step 0
    assert est.k == 1


def test_a_bad_option_value_in_a_system_file_names_file_and_line(tmp_path):
    sc = scenarios.get("servo-motor")
    text = dumps_system(sc.system, x0=sc.x0)
    n = text.count("\n")
    for method, options, line, msg in (
        (
            "zonotope",
            '[method.options]\norder = "six"\n',
            n + 5,
            "order: expected an integer, got 'six'",
        ),
        (
            "zonotope",
            "options = { weight = 6, order = 6.5 }\n",
            n + 4,
            "order: expected an integer",
        ),
        ("interval", "options = { L = [[1.0]] }\n", n + 4, "L: expected shape (3, 2), got (1, 1)"),
    ):
        path = tmp_path / "s.toml"
        path.write_text(text + f'\n[method]\nname = "{method}"\n' + options)
        f = load_system(path)
        with pytest.raises(IvobsError) as err:
            f.make_estimator()
        assert str(err.value).startswith(f"{path}, line {line}: method.options.{msg}"), err
    # an option given in Python is the caller's: no file line
    f = load_system(path)
    with pytest.raises(IvobsError, match=r"^order: expected an integer"):
        f.make_estimator("zonotope", order="x")
