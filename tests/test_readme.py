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
