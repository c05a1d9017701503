"""The benchmark command runs end to end on a small setting (smoke test)."""

import runpy
from pathlib import Path

import ivobs

ROOT = Path(__file__).resolve().parent.parent


def test_suite_runs_end_to_end(tmp_path):
    suite = runpy.run_path(str(ROOT / "benchmarks" / "suite.py"))
    md, csvf = tmp_path / "B.md", tmp_path / "r.csv"
    md.write_text("# Benchmarks\n\nkept text\n")
    methods = [m for m in ("reachability", "interval-split", "exact") if m in ivobs.methods()]
    args = ["--scenarios", "dinh2019", "--out", str(md), "--csv", str(csvf)]
    if methods:
        args += ["--methods", ",".join(methods)]
    assert suite["main"](args) == 0
    text = md.read_text()
    assert "kept text" in text and "<!-- suite:start -->" in text and "### dinh2019" in text
    lines = csvf.read_text().splitlines()
    assert lines[0].startswith("scenario,disturbance,method,mean_width,ratio_to_exact")
    assert len(lines) >= 1 + max(1, len(methods))
    # running twice replaces the section instead of appending
    suite["main"](args)
    assert md.read_text().count("<!-- suite:start -->") == 1
