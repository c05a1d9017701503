"""System files (TOML), logs (CSV), `ivobs run --system`: round trips and a catalogue of
malformed inputs, each rejected with the line and the key, leaving no output file behind."""

import functools
import re
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import Box, Estimate, IvobsError, LinearSystem, scenarios
from ivobs.cli import main
from ivobs.io import (
    atomic_path,
    callable_ref,
    dumps_system,
    equal_systems,
    load_system,
    loads_system,
    read_log,
    save_system,
    write_log,
)

SERVO = """\
name = "servo"

[system]
dt = 0.1
A = [[1.0, 0.1, 0.0], [0.0, 0.8495, 0.4977], [0.0, -0.0357, 0.9995]]
B = [[0.0], [0.0], [0.0729]]
C = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
E = [[1.0, 0.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0, 0.0]]
F = [[0.0, 0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 0.0, 1.0]]

[disturbance]
lower = [-0.0225, -0.0225, -0.0404, -0.0564, -0.0564]
upper = [0.0225, 0.0225, 0.0404, 0.0564, 0.0564]

[x0]
lower = [-0.2, -0.2, -0.2]
upper = [0.2, 0.2, 0.2]

[method]
name = "zonotope"
"""

LOG = "k,u1,y1,y2\n0,2.0,0.01,0.02\n1,2.0,0.03,\n2,2.0,NaN,0.05\n3,2.0,0.07,0.08\n"


def line_of(text, needle):
    """1-based line of the first line containing ``needle``."""
    return next(i for i, ln in enumerate(text.splitlines(), 1) if needle in ln)


# -- round trips ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", scenarios.names())
def test_every_scenario_round_trips_through_toml(name, tmp_path):
    sc = scenarios.get(name)
    path = tmp_path / f"{name}.toml"
    save_system(path, sc)
    back = load_system(path)
    assert equal_systems(sc.system, back.system)
    assert back.x0 == sc.x0 and back.name == sc.name and back.description == sc.description
    # the same numbers at a few steps, including callables (matrices of t / bounds from y)
    for k in (0, 1, 7) if isinstance(sc.system, LinearSystem) else ():  # nonlinear: no matrices
        for a, b in zip(sc.system.matrices_at(k), back.system.matrices_at(k)):
            np.testing.assert_array_equal(a, b)
    y0 = np.full(sc.system.ny, 0.3)
    assert sc.system.d_at(3, y0) == back.system.d_at(3, y0)
    assert dumps_system(back) == path.read_text()  # writing again gives the same text


def test_stacked_matrices_feedthrough_and_asymmetric_bounds_round_trip():
    from ivobs.testing import random_system

    sys = random_system(3, nx=3, ny=2, nu=2, feedthrough=True, symmetric_bounds=False)
    A = np.stack([sys.A * (1 + 0.1 * k) for k in range(4)])
    stacked = LinearSystem(A, sys.B, sys.C, D=sys.D, E=sys.E, F=sys.F, d=sys.d, dt=0.25)
    for s in (sys, stacked):
        back = loads_system(dumps_system(s, x0=Box(-np.ones(3), np.ones(3)))).system
        assert equal_systems(s, back)
    assert not equal_systems(sys, stacked)
    assert not equal_systems(
        sys, LinearSystem(sys.A, sys.B, sys.C, D=sys.D, E=sys.E, F=sys.F, d=sys.d, dt=1.0)
    )  # dt=True is not dt=1.0


def test_callables_are_written_by_import_path_and_params():
    text = dumps_system(scenarios.get("pendulum", L0=2.0, L1=0.25, omega=3.0))
    assert 'A = { python = "ivobs.scenarios:pendulum_A", params = { L0 = 2.0, L1 = 0.25' in text
    back = loads_system(text)
    np.testing.assert_array_equal(
        back.system.A_at(0.7), [[0.0, 1.0], [-9.8 / (2.0 + 0.25 * np.sin(3.0 * 0.7)), -1.0]]
    )
    assert not equal_systems(back.system, scenarios.get("pendulum").system)  # params differ
    assert callable_ref(scenarios.kkl_ltv_A) == ("ivobs.scenarios:kkl_ltv_A", {})
    assert callable_ref(lambda k: np.eye(2)) is None
    assert callable_ref(functools.partial(scenarios.pendulum_A, 1.0)) is None  # positional


def test_a_closure_cannot_be_saved(tmp_path):
    sys = LinearSystem(lambda k: np.eye(2) * 0.5, None, np.eye(2))
    with pytest.raises(IvobsError, match="module-level function"):
        save_system(tmp_path / "s.toml", sys)
    assert not list(tmp_path.iterdir())


def test_method_and_options_round_trip(tmp_path):
    sc = scenarios.get("servo-motor")
    L = sc.reference["L1"]
    save_system(tmp_path / "s.toml", sc, method="zonotope", options={"L": L, "order": 12})
    back = load_system(tmp_path / "s.toml")
    assert back.method == "zonotope" and back.options["order"] == 12
    np.testing.assert_array_equal(back.options["L"], L)
    est = back.make_estimator()
    np.testing.assert_array_equal(est.design.L, L)
    assert est.name == "zonotope"


def test_time_varying_bounds_inline_and_from_csv(tmp_path):
    T = 6
    lo = -np.linspace(0.1, 0.6, T)[:, None] * np.ones((T, 2))
    sys = LinearSystem([[0.5]], None, [[1.0]], E=[[1.0, 0.0]], F=[[0.0, 1.0]], d=Box(lo, -lo))
    back = loads_system(dumps_system(sys))
    assert equal_systems(sys, back.system) and back.system.d.is_time_varying
    (tmp_path / "bounds.csv").write_text(
        "w_lo,w_hi\n" + "".join(f"{float(a)!r},{-float(a)!r}\n" for a in lo[:, 0])
    )
    text = """
[system]
A = [[0.5]]
C = [[1.0]]
E = [[1.0, 0.0]]
F = [[0.0, 1.0]]
[disturbance]
csv = "bounds.csv"
lower = ["w_lo", -0.1]
upper = ["w_hi", 0.1]
"""
    (tmp_path / "s.toml").write_text(text)
    d = load_system(tmp_path / "s.toml").system.d
    np.testing.assert_array_equal(d.lo[:, 0], lo[:, 0])
    np.testing.assert_array_equal(d.hi[:, 1], 0.1)


def test_estimate_round_trips_through_csv(tmp_path):
    sc = scenarios.get("servo-motor")
    tr = sc.simulate("vertex", seed=2)
    y = tr.y.copy()
    y[10:13] = np.nan
    res = Estimate(
        lower=tr.x - np.abs(np.sin(np.arange(tr.T)))[:, None] / 3,
        upper=tr.x + 1 / 7,
        valid_from=2,
        method="reachability",
        missing=np.isnan(y).any(1),
    )
    res.lower[:2] = res.upper[:2] = np.nan
    res.to_csv(tmp_path / "r.csv")
    back = Estimate.from_csv(tmp_path / "r.csv")
    assert back.equals(res)
    np.testing.assert_array_equal(back.missing, res.missing)


def test_log_round_trip_keeps_missing_samples(tmp_path):
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=(50, 1)), rng.normal(size=(50, 2)) / 3
    y[rng.random(y.shape) < 0.1] = np.nan
    write_log(tmp_path / "log.csv", u, y)
    sys = scenarios.get("servo-motor").system
    log = read_log(tmp_path / "log.csv", sys)
    np.testing.assert_array_equal(log.u, u)
    np.testing.assert_array_equal(log.y, y)  # NaN positions included
    np.testing.assert_array_equal(log.steps, np.arange(50))
    assert log.missing.sum() == np.isnan(y).any(1).sum()


def test_log_with_time_column_empty_cells_and_comments(tmp_path):
    (tmp_path / "l.csv").write_text(
        "# plant 3, 2024-05-01\nTime, U1, Y_theta, y_speed\n0.0, 2, 0.1, \n\n0.1, 2, nan, 0.3\n"
    )
    log = read_log(tmp_path / "l.csv", scenarios.get("servo-motor").system)
    np.testing.assert_array_equal(log.t, [0.0, 0.1])
    assert np.isnan(log.y[0, 1]) and np.isnan(log.y[1, 0]) and log.y[1, 1] == 0.3


# -- ivobs run --system -------------------------------------------------------------------------
def test_run_system_log_writes_bounds_and_figure(tmp_path, capsys):
    sc = scenarios.get("servo-motor", horizon=120)
    tr = sc.simulate("vertex", seed=4)
    y = tr.y.copy()
    y[30:50, 1] = np.nan
    save_system(tmp_path / "s.toml", sc, method="zonotope")
    write_log(tmp_path / "log.csv", tr.u, y)
    out = tmp_path / "r.csv"
    code = main(
        [
            "run",
            "--system",
            str(tmp_path / "s.toml"),
            "--log",
            str(tmp_path / "log.csv"),
            "--out",
            str(out),
            "--plot",
            str(tmp_path / "p.png"),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    assert "missing samples: 20 step(s)" in text and "alarms: none" in text
    res = Estimate.from_csv(out)
    assert res.method == "zonotope" and res.T == 120 and res.contains(tr.x).all()
    expected = load_system(tmp_path / "s.toml").make_estimator().run(tr.u, y)
    assert res.equals(expected)
    assert (tmp_path / "p.png").stat().st_size > 1000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "p.png", "r.csv", "s.toml"]


def test_run_system_reports_alarms_of_a_faulty_log(tmp_path, capsys):
    sc = scenarios.get("servo-motor", horizon=80)
    tr = sc.simulate("vertex", seed=1)
    y = tr.y.copy()
    y[40:, 1] += 1.0  # a speed sensor offset of ~18 noise bounds
    save_system(tmp_path / "s.toml", sc)
    write_log(tmp_path / "log.csv", tr.u, y)
    args = ["run", "--system", str(tmp_path / "s.toml"), "--log", str(tmp_path / "log.csv")]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main([*args, "--method", "interval-split"])
    text = capsys.readouterr().out
    assert code == 1 and "ALARMS" in text and "first: step 40:" in text
    # one episode from step 40 to the end, isolated to y2, its bias (+1.0 on y2) estimated
    line = re.search(r"from step 40, 40 step\(s\), open at the end of the log: y2; isolated: y2; "
                     r"bias y2 in \[([-\d.e]+), ([-\d.e]+)\]", text)  # fmt: skip
    assert line is not None, text
    assert 0 < float(line[1]) <= 1.0 <= float(line[2])
    assert not caught, "the alarms are reported once, by the command, not also as warnings"


def test_run_needs_a_scenario_or_a_system(capsys):
    assert main(["run", "--method", "interval"]) == 2
    assert "give a scenario name" in capsys.readouterr().err
    assert main(["run", "servo-motor"]) == 2
    assert "--method: required" in capsys.readouterr().err


def test_atomic_path_leaves_nothing_on_error(tmp_path):
    with pytest.raises(RuntimeError), atomic_path(tmp_path / "x.csv") as tmp:
        tmp.write_text("half")
        raise RuntimeError("boom")
    assert not list(tmp_path.iterdir())


# -- malformed system files ---------------------------------------------------------------------
def _edit(old, new, count=1):
    assert old in SERVO
    return SERVO.replace(old, new, count)


BAD_SYSTEMS = {
    "toml syntax": (
        _edit("[0.0, 0.8495, 0.4977]", "[0.0, 0.8495 0.4977]"),
        "A = ",
        "not valid TOML",
    ),
    "missing [system]": (SERVO.replace("[system]", "[plant]"), "[plant]", "unknown key 'plant'"),
    "missing matrix A": (
        _edit("A = [[1.0, 0.1, 0.0], [0.0, 0.8495, 0.4977], [0.0, -0.0357, 0.9995]]\n", ""),
        "[system]",
        "missing matrix A",
    ),
    "missing matrix C": (
        _edit("C = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]\n", ""),
        "[system]",
        "missing matrix C",
    ),
    "A not square": (_edit("[0.0, -0.0357, 0.9995]]", "]"), "A = ", "square"),
    "B wrong rows": (
        _edit("[[0.0], [0.0], [0.0729]]", "[[0.0], [0.0729]]"),
        "B = ",
        r"expected shape \(3, any\)",
    ),
    "C wrong columns": (
        _edit("[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]", "[[1.0, 0.0], [0.0, 1.0]]"),
        "C = ",
        r"expected shape \(any, 3\)",
    ),
    "non-numeric entry": (
        _edit("[0.0, 0.8495, 0.4977]", '[0.0, "0.8495", 0.4977]'),
        "A = ",
        r"entry \[1\]\[1\]: expected a number, got '0.8495'",
    ),
    "boolean entry": (
        _edit("B = [[0.0], [0.0], [0.0729]]", "B = [[0.0], [false], [0.0729]]"),
        "B = ",
        r"entry \[1\]\[0\]: expected a number",
    ),
    "ragged matrix": (_edit("[0.0, 1.0, 0.0]]", "[0.0, 1.0]]"), "C = ", "ragged"),
    "infinite entry": (
        _edit("[0.0, -0.0357, 0.9995]", "[0.0, -0.0357, inf]"),
        "A = ",
        "must be finite",
    ),
    "vector instead of matrix": (
        _edit("B = [[0.0], [0.0], [0.0729]]", "B = [0.0, 0.0, 0.0729]"),
        "B = ",
        "array of rows",
    ),
    "disturbance lower > upper": (
        _edit("upper = [0.0225, 0.0225, 0.0404", "upper = [0.0225, -0.03, 0.0404"),
        "lower = [-0.0225",
        r"lower > upper at component 1: -0.0225 > -0.03",
    ),
    "x0 lower > upper": (
        _edit("lower = [-0.2, -0.2, -0.2]", "lower = [-0.2, 0.3, -0.2]"),
        "lower = [-0.2",
        "lower > upper in component 1: 0.3 > 0.2",
    ),
    "unknown key in [system]": (
        _edit("dt = 0.1", "dt = 0.1\nG = [[1.0]]"),
        "G = ",
        "unknown key 'G' in \\[system\\]; allowed keys: dt, A, B",
    ),
    "unknown table": (
        SERVO + "\n[observer]\ngain = 3\n",
        "[observer]",
        "unknown key 'observer' in the top level",
    ),
    "unknown method": (
        _edit('name = "zonotope"', 'name = "kalman"'),
        'name = "kalman"',
        "unknown method 'kalman'",
    ),
    "unknown option": (
        SERVO + "[method.options]\nordr = 3\n",
        "ordr = 3",
        "zonotope has no option 'ordr'; accepted: L, order",
    ),
    "E without bounds": (SERVO.split("[disturbance]")[0], "E = ", "no \\[disturbance\\]"),
    "bounds of wrong length": (
        _edit(
            "lower = [-0.0225, -0.0225, -0.0404, -0.0564, -0.0564]",
            "lower = [-0.0225, -0.0225, -0.0404, -0.0564]",
        ),
        "lower = [-0.0225",
        "expected 5 bounds",
    ),
    "negative dt": (_edit("dt = 0.1", "dt = -0.1"), "dt = ", "expected true or a period"),
    "x0 wrong length": (
        _edit("upper = [0.2, 0.2, 0.2]", "upper = [0.2, 0.2]"),
        "upper = [0.2, 0.2]",
        "expected 3 values",
    ),
    "callable not importable": (
        _edit(
            "A = [[1.0, 0.1, 0.0], [0.0, 0.8495, 0.4977], [0.0, -0.0357, 0.9995]]",
            'A = { python = "ivobs.scenarios.nowhere:A_of_k" }',
        ),
        "A = ",
        "cannot import module 'ivobs.scenarios.nowhere'",
    ),
    "E and F columns differ": (
        _edit("[0.0, 0.0, 0.0, 0.0, 1.0]]", "[0.0, 0.0, 0.0, 1.0]]"),
        "F = ",
        "ragged|E has 5 columns, F has",
    ),
    "unsupported format": ("format = 7\n" + SERVO, "format = 7", "unsupported format 7"),
}


@pytest.mark.parametrize("case", list(BAD_SYSTEMS))
def test_malformed_system_file_names_line_and_key(case, tmp_path, capsys):
    text, needle, message = BAD_SYSTEMS[case]
    path = tmp_path / "s.toml"
    path.write_text(text)
    (tmp_path / "log.csv").write_text(LOG)
    with pytest.raises(IvobsError) as err:
        load_system(path)
    msg = str(err.value)
    assert re.search(message, msg), msg
    assert f"line {line_of(text, needle)}" in msg, msg
    assert str(path) in msg
    out = tmp_path / "r.csv"
    code = main(
        [
            "run",
            "--system",
            str(path),
            "--log",
            str(tmp_path / "log.csv"),
            "--out",
            str(out),
            "--plot",
            str(tmp_path / "p.png"),
        ]
    )
    assert code == 2 and "ivobs: error:" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "s.toml"]


# -- malformed logs ------------------------------------------------------------------------------
BAD_LOGS = {
    "wrong field count": ("k,u1,y1,y2\n0,2,0.1,0.2\n1,2,0.1\n", 3, "expected 4 fields"),
    "text in a number cell": (
        "k,u1,y1,y2\n0,2,0.1,0.2\n1,2,abc,0.2\n",
        3,
        "column 'y1': expected a number, got 'abc'",
    ),
    "missing input": (
        "k,u1,y1,y2\n0,2,0.1,0.2\n1,,0.1,0.2\n",
        3,
        "column 'u1' is missing \\(inputs must be known",
    ),
    "too few y columns": ("k,u1,y1\n0,2,0.1\n", 1, "needs 2 y-columns"),
    "unexpected column": ("k,u1,y1,y2,temp\n0,2,0.1,0.2,20\n", 1, "unexpected column 'temp'"),
    "duplicate column": ("k,u1,y1,y1\n0,2,0.1,0.2\n", 1, "duplicate column 'y1'"),
    "step not increasing": (
        "k,u1,y1,y2\n0,2,0.1,0.2\n1,2,0.1,0.2\n1,2,0.1,0.2\n",
        4,
        "step 1 does not increase",
    ),
    "infinite value": ("k,u1,y1,y2\n0,2,inf,0.2\n", 2, "infinite value"),
    "fractional step": ("k,u1,y1,y2\n0.5,2,0.1,0.2\n", 2, "expected an integer step"),
    "header only": ("k,u1,y1,y2\n", None, "no data rows"),
}


@pytest.mark.parametrize("case", list(BAD_LOGS))
def test_malformed_log_names_the_row(case, tmp_path, capsys):
    text, line, message = BAD_LOGS[case]
    (tmp_path / "s.toml").write_text(SERVO)
    log = tmp_path / "log.csv"
    log.write_text(text)
    with pytest.raises(IvobsError, match=message) as err:
        read_log(log, load_system(tmp_path / "s.toml").system)
    if line is not None:
        assert f"line {line}:" in str(err.value)
    out = tmp_path / "r.csv"
    code = main(["run", "--system", str(tmp_path / "s.toml"), "--log", str(log), "--out", str(out)])
    assert code == 2 and re.search(message, capsys.readouterr().err)
    assert not out.exists() and len(list(tmp_path.iterdir())) == 2


def test_catalogue_is_large_enough():
    assert len(BAD_SYSTEMS) + len(BAD_LOGS) >= 15
    assert isinstance(ivobs.IvobsError("x"), ValueError)


def test_names_and_units_in_a_system_file(tmp_path):
    text = """
[system]
A = [[1.0, 0.1], [0.0, 0.9]]
B = [[0.0], [0.1]]
C = [[1.0, 0.0]]

[names]
states = ["position", "speed"]
units = ["m", "m/s"]
inputs = ["force"]
outputs = ["odometer"]
"""
    spec = ivobs.io.loads_system(text)
    names = spec.system.names
    assert names.states == ("position", "speed") and names.inputs == ("force",)
    assert names.state_labels() == ("position (m)", "speed (m/s)")
    ivobs.save_system(tmp_path / "copy.toml", spec)
    again = ivobs.load_system(tmp_path / "copy.toml").system.names
    assert again == names
    bad = text.replace('units = ["m", "m/s"]', 'units = ["m"]')
    with pytest.raises(IvobsError, match=r"line 9: names.units: expected 2 names"):
        ivobs.io.loads_system(bad)
    with pytest.raises(IvobsError, match="unknown key 'colour'"):
        ivobs.io.loads_system(text + 'colour = ["red"]\n')
