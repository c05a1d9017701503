"""Nonlinear systems in system files: the same expression strings in TOML, read without running
code, errors with file and line, save/load round trips, and ``ivobs run --system --log``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import ivobs
from ivobs.cli import main
from ivobs.io.logs import write_log
from nlsystems import HENON_X0, henon, henon_record

HENON_TOML = """\
format = 1
name = "henon"

[system]
states = ["x1", "x2"]
f = ["1 - a*x1**2 + x2 + w1", "b*x1"]
h = ["x2 + v1"]

[system.params]
a = [1.39, 1.41]
b = 0.3

[system.d]
w1 = [-0.005, 0.005]
v1 = [-0.02, 0.02]

[x0]
lower = [0.2, 0.0]
upper = [0.4, 0.2]

[method]
name = "nl-interval"
"""


def test_a_nonlinear_system_file_loads_and_round_trips(tmp_path: Path) -> None:
    spec = ivobs.io.loads_system(HENON_TOML)
    assert isinstance(spec.system, ivobs.NonlinearSystem)
    assert spec.system.spec() == henon("x2").spec()
    assert spec.x0 == HENON_X0 and spec.method == "nl-interval"
    path = tmp_path / "henon.toml"
    ivobs.save_system(path, spec)
    again = ivobs.load_system(path)
    assert ivobs.equal_systems(again.system, spec.system)
    assert again.x0 == spec.x0 and again.method == "nl-interval"
    # units beside the model's own names, kept by a round trip
    ivobs.io.save_system(
        path, ivobs.io.loads_system(HENON_TOML + '\n[names]\nunits = ["m", "m"]\n')
    )
    labelled = ivobs.load_system(path).system
    assert labelled.names.state_labels() == ("x1 (m)", "x2 (m)")
    assert labelled.names.outputs == ("y1",)
    # a callable model is written as its expressions
    made = ivobs.NonlinearSystem(
        f=lambda x, u, p, d: [x[0] * u[0] + 0.25 * ivobs.nlmath.sin(x[0])],
        h=["abs(x1) + max(x1, 0)"],
        states=["x1"],
        inputs=["u1"],
    )
    ivobs.save_system(path, made, x0=ivobs.Box([0.0], [1.0]))
    back = ivobs.load_system(path).system
    assert ivobs.equal_systems(back, made) and not ivobs.equal_systems(back, spec.system)
    box = ([0.1], [0.4], [2.0], [], [])
    np.testing.assert_array_equal(back.f_tight_box(*box)[0], made.f_tight_box(*box)[0])


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (("b*x1", "b*q"), r"line 6: system.f: f\[1\] = 'b\*q': unknown name 'q' at column 3"),
        (("a = [1.39, 1.41]", "a = [1.41, 1.39]"), r"line 10: system.params.a: params\['a'\]"),
        (("w1 = [-0.005, 0.005]", 'w1 = "x"'), r"line 14: system.d.w1: d\['w1'\]: expected a"),
        (('h = ["x2 + v1"]', 'h = "x2"'), r"line 7: system.h: expected a list of expressions"),
        (("[system]\n", "[system]\nA = [[1.0]]\n"), r"system.A: a nonlinear system .* no matrix"),
        (('f = ["1 - a*x1**2 + x2 + w1", "b*x1"]\n', ""), r"missing f = \[...\]"),
        (("b*x1", "__import__('os').getcwd()"), r"only calls of the listed functions"),
    ],
)
def test_errors_name_the_file_line_and_key(edit: tuple[str, str], match: str) -> None:
    text = HENON_TOML.replace(*edit)
    with pytest.raises(ivobs.IvobsError, match=match):
        ivobs.io.loads_system(text, source="henon.toml")


def test_ivobs_run_estimates_a_nonlinear_system_from_a_log(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "henon.toml").write_text(HENON_TOML)
    Y = henon_record(400, seed=4, output="x2")[1].Y.copy()
    write_log(tmp_path / "log.csv", None, Y)
    out = tmp_path / "bounds.csv"
    code = main(
        [
            "run",
            "--system",
            str(tmp_path / "henon.toml"),
            "--log",
            str(tmp_path / "log.csv"),
            "--out",
            str(out),
        ]
    )
    text = capsys.readouterr().out
    assert code == 0, text
    assert "nl-interval on henon" in text and "alarms: none" in text
    Y[200, 0] = 3.0  # a fault
    write_log(tmp_path / "log.csv", None, Y)
    code = main(
        ["run", "--system", str(tmp_path / "henon.toml"), "--log", str(tmp_path / "log.csv")]
    )
    text = capsys.readouterr().out
    assert code == 1 and "ALARMS: 1 step(s)" in text and "first: step 200" in text
