"""The ivobs command."""

import subprocess
import sys

import pytest

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
