"""Interactive HTML reports: parsed back, every state is plotted and the numbers are the CSV's."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import ivobs
from ivobs.cli import main

pytest.importorskip("plotly")


def _figures(page: str) -> dict[str, list[dict]]:
    """The traces of every plotly figure in the page, by div id (parsed from the page's
    ``Plotly.newPlot("id", [traces], ...)`` calls)."""
    out = {}
    for m in re.finditer(r'Plotly\.newPlot\(\s*"([^"]+)",\s*(\[.*?\])\s*,\s*\{', page, re.S):
        out[m.group(1)] = json.loads(m.group(2))
    return out


def test_run_html_matches_the_csv(tmp_path, capsys):
    sc = ivobs.scenarios.get("servo-motor")
    ivobs.save_system(tmp_path / "servo.toml", sc)
    tr = sc.simulate("vertex", seed=2)
    y = tr.y[:50].copy()
    y[30] += 5.0  # a fault: an alarm in the report
    ivobs.io.write_log(tmp_path / "log.csv", tr.u[:50], y)
    argv = ["run", "--system", str(tmp_path / "servo.toml"), "--log", str(tmp_path / "log.csv")]
    argv += ["--method", "strip", "--csv", str(tmp_path / "b.csv")]
    argv += ["--html", str(tmp_path / "r.html")]
    assert main(argv) == 1  # the alarm
    page = (tmp_path / "r.html").read_text()
    figs = _figures(page)
    assert sorted(figs) == ["state-1", "state-2", "state-3"]
    assert "Alarms</b> (1 steps): 30" in page
    est = ivobs.Estimate.from_csv(tmp_path / "b.csv")
    ref = 0.5 * (est.lower + est.upper)  # no truth: bands around the tightest box's centre
    for i in range(3):
        traces = {(t["meta"]["bound"]): t for t in figs[f"state-{i + 1}"]}
        np.testing.assert_allclose(traces["upper"]["y"], est.upper[:, i] - ref[:, i], atol=1e-12)
        np.testing.assert_allclose(traces["lower"]["y"], est.lower[:, i] - ref[:, i], atol=1e-12)
        np.testing.assert_allclose(traces["width"]["y"], est.width[:, i], rtol=1e-12)
    assert not re.search(r"<script[^>]*src=", page)  # plotly.js embedded: works offline


def test_compare_html_has_every_method_and_state(tmp_path, capsys):
    argv = ["compare", "servo-motor", "--methods", "interval-split,zonotope,exact"]
    assert main([*argv, "--html", str(tmp_path / "c.html")]) == 0
    page = (tmp_path / "c.html").read_text()
    figs = _figures(page)
    assert len(figs) == 3
    for traces in figs.values():
        assert {t["meta"]["method"] for t in traces} == {"interval-split", "zonotope", "exact"}
    assert "<table class='methods'>" in page and "<td>exact</td>" in page
    sc = ivobs.scenarios.get("servo-motor")
    tr = sc.simulate("paper", 0)
    est = ivobs.make_estimator("zonotope", sc.system, x0=sc.x0, strips=True).run(tr.u, tr.y)
    z = next(t for t in figs["state-2"] if t["meta"] == {"method": "zonotope", "bound": "upper",
                                                          "state": 1})  # fmt: skip
    np.testing.assert_allclose(z["y"], est.upper[:, 1] - tr.x[:, 1], atol=1e-12)
