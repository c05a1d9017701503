"""The README's promises: two set-up commands, CI runs the test one, the quickstart runs."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def _bash_blocks():
    return re.findall(r"```bash\n(.*?)```", README, flags=re.S)


def test_exactly_two_setup_commands_and_ci_runs_the_test_one():
    setup = README.split("## Set up", 1)[1].split("\n## ", 1)[0]
    cmds = [b.strip() for b in re.findall(r"```bash\n(.*?)```", setup, flags=re.S)]
    assert len(cmds) == 2
    assert cmds[0].endswith("ivobs demo")
    assert "pytest" in cmds[1]
    test_cmd = cmds[1].split("&&", 2)[-1].strip()  # what follows the venv set-up
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd in ci, f"{test_cmd!r} not in .ci/run"


def test_quickstart_runs():
    block = re.search(r"## Quickstart\n\n```python\n(.*?)```", README, flags=re.S).group(1)
    exec(compile(block, "README quickstart", "exec"), {})


def _readme_methods_table():
    section = README.split("## Methods", 1)[1].split("\n## ", 1)[0]
    lines = [ln for ln in section.splitlines() if ln.startswith("| `")]
    return [[c.strip() for c in ln.strip().strip("|").split(" | ")] for ln in lines]


def test_readme_methods_table_lists_the_methods_in_their_order():
    import ivobs
    from ivobs.cli.methods_cmd import rows

    table = _readme_methods_table()
    assert [cells[0].strip("`") for cells in table] == ivobs.methods()
    # data used, needs x0, time-varying, continuous: the classes' attributes
    assert [cells[3:] for cells in table] == [
        [r["data used"], r["needs x0"], r["time-varying"], r["continuous"]] for r in rows()
    ]


def test_methods_command_prints_every_method_with_its_metadata(capsys):
    import ivobs
    from ivobs.cli import main

    assert main(["methods"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[0].split() == [
        "method",
        "paper",
        "data",
        "used",
        "needs",
        "x0",
        "time-varying",
        "continuous",
    ]
    listed = [ln.split()[0] for ln in out.splitlines()[1:] if not ln.startswith(" ")]
    assert listed == ivobs.methods()
    assert main(["methods", "--markdown"]) == 0
    md = capsys.readouterr().out.splitlines()
    assert [ln.split(" | ")[0].strip("| `") for ln in md[2:]] == ivobs.methods()
