"""Short HTML summaries for Jupyter (``_repr_html_``) of systems and sets: a title and a table
of (label, value) rows, escaped. Estimates add a figure (:mod:`ivobs.frames`)."""

from __future__ import annotations

import html
from collections.abc import Iterable
from typing import Any

import numpy as np

__all__ = ["summary_html", "vector"]


def vector(v: Any, limit: int = 8) -> str:
    """A short text of a vector (the first ``limit`` entries, 4 significant digits)."""
    a = np.ravel(np.asarray(v, dtype=float))
    text = ", ".join(f"{x:.4g}" for x in a[:limit])
    return f"[{text}{', …' if a.size > limit else ''}]"


def summary_html(title: str, rows: Iterable[tuple[str, str]], extra: str = "") -> str:
    """``<b>title</b>`` and a two-column table of ``rows``, then the HTML ``extra`` (a figure)."""
    body = "".join(
        f"<tr><th style='text-align:left'>{html.escape(a)}</th><td>{html.escape(b)}</td></tr>"
        for a, b in rows
    )
    return f"<div><b>{html.escape(title)}</b><table>{body}</table>{extra}</div>"
