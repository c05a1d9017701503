"""Self-contained interactive HTML reports (``ivobs run/compare ... --html FILE``).

One zoomable figure per state (every method's bounds minus a reference — the true state, or
the centre of the tightest box — and the widths on a log scale), the method table, and the
alarms. Drawn with plotly (``pip install "ivobs[html]"``); plotly's JavaScript is embedded
once, so the page works offline. The bounds are written as plain JSON numbers (not plotly's
binary encoding), so that the page can be checked against the CSV.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import IvobsError
from ..frames import _import
from .compare_figure import reference_trajectory

if TYPE_CHECKING:
    from ..result import Estimate

__all__ = ["html_report"]


def _values(a: np.ndarray) -> list[float | None]:
    """JSON numbers (NaN: a gap)."""
    return [None if not np.isfinite(v) else float(v) for v in np.asarray(a, dtype=float)]


def _state_figure(
    go: Any,
    estimates: Mapping[str, Estimate],
    i: int,
    time: np.ndarray,
    ref: np.ndarray,
    ref_name: str,
    label: str,
) -> Any:
    from plotly.subplots import make_subplots

    fig = make_subplots(
        rows=2, cols=1, shared_xaxes=True, vertical_spacing=0.08, row_heights=[0.6, 0.4]
    )
    x = time.tolist()
    for m, (name, est) in enumerate(estimates.items()):
        color = _COLORS[m % len(_COLORS)]
        for bound, arr in (("upper", est.upper), ("lower", est.lower)):
            fig.add_trace(
                go.Scatter(
                    x=x, y=_values(arr[:, i] - ref[:, i]), mode="lines", name=name,
                    legendgroup=name, showlegend=bound == "upper",
                    line={"color": color, "width": 1.2},
                    meta={"method": name, "bound": bound, "state": i},
                ),
                row=1, col=1,
            )  # fmt: skip
        fig.add_trace(
            go.Scatter(
                x=x, y=_values(est.width[:, i]), mode="lines", name=name, legendgroup=name,
                showlegend=False, line={"color": color, "width": 1.0, "dash": "dot"},
                meta={"method": name, "bound": "width", "state": i},
            ),
            row=2, col=1,
        )  # fmt: skip
    fig.update_yaxes(title_text=f"bounds − {ref_name}", row=1, col=1)
    fig.update_yaxes(title_text="width", type="log", row=2, col=1)
    fig.update_layout(title=label, height=480, margin={"l": 60, "r": 20, "t": 40, "b": 30})
    return fig


_COLORS = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2"]


def html_report(
    path: str | Path,
    estimates: Mapping[str, Estimate],
    *,
    title: str,
    truth: Any = None,
    t: Any = None,
    state_names: Sequence[str] | None = None,
    table: str = "",
    alarms: Sequence[int] = (),
    notes: Sequence[str] = (),
    episodes: Sequence[str] = (),
) -> Path:
    """Write the report to ``path`` (atomically) and return it. ``table``: an HTML table of the
    methods; ``alarms``: steps flagged inconsistent; ``notes``: lines printed under the title;
    ``episodes``: one line per fault episode (its steps, the outputs blamed and isolated, the
    estimated bias), listed under the alarms."""
    _import("plotly", "html")  # refused with the extra to install
    import plotly.graph_objects as go

    if not estimates:
        raise IvobsError("html report: no estimate to show")
    first = next(iter(estimates.values()))
    ref, ref_name = reference_trajectory(estimates, truth)
    time = np.asarray(np.arange(first.T) if t is None else t, dtype=float)
    parts = [f"<h1>{html.escape(title)}</h1>"]
    parts += [f"<p>{html.escape(n)}</p>" for n in notes]
    if table:
        parts.append(table)
    if alarms:
        shown = ", ".join(str(int(k)) for k in alarms[:50]) + (" …" if len(alarms) > 50 else "")
        parts.append(f"<p class='alarms'><b>Alarms</b> ({len(alarms)} steps): {shown}</p>")
    if episodes:
        items = "".join(f"<li>{html.escape(e)}</li>" for e in episodes)
        parts.append(f"<p class='faults'><b>Fault episodes</b></p><ul class='faults'>{items}</ul>")
    for i in range(first.nx):
        label = state_names[i] if state_names is not None else f"x{i + 1}"
        fig = _state_figure(go, estimates, i, time, ref, ref_name, label)
        parts.append(
            fig.to_html(full_html=False, include_plotlyjs=(i == 0), div_id=f"state-{i + 1}")
        )
    page = (
        "<!DOCTYPE html><html><head><meta charset='utf-8'>"
        f"<title>{html.escape(title)}</title>"
        "<style>body{font-family:sans-serif;max-width:1100px;margin:auto}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 6px}"
        "</style></head><body>" + "\n".join(parts) + "</body></html>"
    )
    from ..io.atomic import write_text_atomic

    out = Path(path)
    write_text_atomic(out, page)
    return out


def results_table(results: Sequence[Any], state_names: Sequence[str] | None = None) -> str:
    """The comparison as an HTML table (mean widths, containment, timings, reasons)."""
    if not results:
        return ""
    nx = next((r.estimate.nx for r in results if r.estimate is not None), 0)
    names = list(state_names) if state_names is not None else [f"x{i + 1}" for i in range(nx)]
    head = "".join(f"<th>width {html.escape(n)}</th>" for n in names)
    rows = []
    for r in results:
        if r.estimate is None:
            cells = f"<td colspan='{nx + 4}'>{html.escape(str(r.error))}</td>"
        else:
            widths = "".join(f"<td>{w:.4g}</td>" for w in np.ravel(r.mean_width))
            seen = {True: "yes", False: "NO", None: "n/a"}[r.contains]
            times = (r.design_time, r.run_time, r.cpu_time)
            cells = f"{widths}<td>{seen}</td>" + "".join(f"<td>{v:.3g}</td>" for v in times)
        label = r.method if r.guaranteed else f"{r.method} (NOT guaranteed)"
        rows.append(f"<tr><td>{html.escape(label)}</td>{cells}</tr>")
    return (
        f"<table class='methods'><tr><th>method</th>{head}<th>contains truth</th>"
        "<th>design (s)</th><th>run (s)</th><th>CPU design + run (s)</th></tr>"
        f"{''.join(rows)}</table>"
    )
