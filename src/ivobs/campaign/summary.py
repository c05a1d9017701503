"""The campaign summary: per scenario, disturbance, method and option set, the mean width over
seeds with its 95 % confidence half-width, containment counts and times."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from .job import canonical
from .spec import CampaignSpec

__all__ = ["SummaryRow", "summarize", "summary_markdown"]


@dataclass
class SummaryRow:
    """One scenario × disturbance × method × option set over its seeds."""

    scenario: str
    disturbance: str
    method: str
    options: dict[str, Any]
    scenario_options: dict[str, Any]
    jobs: int = 0
    ok: int = 0
    mean_width: float = math.nan
    ci95: float = math.nan
    contained: int = 0
    checked: int = 0
    design_time: float = math.nan
    run_time: float = math.nan
    note: str = ""


def summarize(rows: Iterable[dict[str, Any]]) -> list[SummaryRow]:
    """Group rows by scenario, disturbance, method and options (first-seen order): mean width
    over seeds with its 95 % confidence half-width ``t_{0.975, n-1} s / √n``, containment
    counts, mean design and run times, and the most frequent error of the failed jobs."""
    import numpy as np
    from scipy import stats

    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        key = canonical([r["scenario"], r["scenario_options"], r["disturbance"], r["method"],
                          r["options"]])  # fmt: skip
        groups.setdefault(key, []).append(r)
    out = []
    for rs in groups.values():
        r0 = rs[0]
        s = SummaryRow(r0["scenario"], r0["disturbance"], r0["method"], r0["options"] or {},
                       r0["scenario_options"] or {}, jobs=len(rs))  # fmt: skip
        ok = [r for r in rs if r["status"] == "ok"]
        s.ok = len(ok)
        w = np.array([r["mean_width"] for r in ok], dtype=float)
        if w.size:
            s.mean_width = float(w.mean())
            if w.size > 1:
                s.ci95 = float(stats.t.ppf(0.975, w.size - 1) * w.std(ddof=1) / np.sqrt(w.size))
            s.design_time = float(np.mean([r["design_time"] for r in ok]))
            s.run_time = float(np.mean([r["run_time"] for r in ok]))
        checked = [r["contains"] for r in ok if r["contains"] is not None]
        s.checked, s.contained = len(checked), sum(checked)
        errors = [r["error"] or r["status"] for r in rs if r["status"] != "ok"]
        if errors:
            top = max(set(errors), key=errors.count)
            s.note = top if len(top) <= 100 else top[:97] + "..."
        out.append(s)
    return out


def _fmt_options(opts: dict[str, Any]) -> str:
    return ", ".join(f"{k}={canonical(v) if not isinstance(v, str) else v}"
                     for k, v in opts.items()) or "—"  # fmt: skip


def summary_markdown(rows: Iterable[dict[str, Any]], spec: CampaignSpec | None = None) -> str:
    """The summary as a Markdown table (a disturbance column when there are several, an options
    column when any method has options)."""
    summ = summarize(rows)
    if not summ:
        return "(no results yet)"
    many_d = len({s.disturbance for s in summ}) > 1 or (spec and len(spec.disturbances) > 1)
    any_o = any(s.options for s in summ)
    head = ["scenario"] + (["disturbance"] if many_d else []) + ["method"]
    head += (["options"] if any_o else []) + ["ok/jobs", "mean width", "± 95 %", "contained",
                                               "design (s)", "run (s)", "note"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in summ:
        cells = [s.scenario] + ([s.disturbance] if many_d else []) + [s.method]
        cells += [_fmt_options(s.options)] if any_o else []
        contained = (
            "n/a"
            if not s.checked
            else f"{s.contained}/{s.checked}"
            if s.contained == s.checked
            else f"**{s.contained}/{s.checked}**"
        )
        cells += [
            f"{s.ok}/{s.jobs}",
            "—" if math.isnan(s.mean_width) else f"{s.mean_width:.4g}",
            "—" if math.isnan(s.ci95) else f"{s.ci95:.2g}",
            contained,
            "—" if math.isnan(s.design_time) else f"{s.design_time:.3f}",
            "—" if math.isnan(s.run_time) else f"{s.run_time:.4f}",
            s.note.replace("|", "\\|"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
