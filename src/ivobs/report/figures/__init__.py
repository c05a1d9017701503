"""The papers' figures, regenerated with ivobs' methods: ``ivobs figures --out DIR``.

One function per figure of [Wang2020], [Tang2019], [Efimov2013] and [Dinh2024]
(``paper002_fig5()``, ...; the numbers 001-004 name the papers in that order, as in
``ivobs figures --paper 002``), each returning a matplotlib figure drawn from a fresh run of the
paper's scenario (:mod:`ivobs.scenarios`), one module per paper. Every function checks that the
bounds it draws contain the true state at every step and raises :class:`FigureCheckError`
otherwise (a figure of a broken guarantee is a bug, never a picture). :func:`generate` writes
them all (or those of some papers) as PNG files.

What each figure shows, and what differs from the paper and why: ``docs/figures.md``.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

from ...errors import IvobsError
from .common import DPI, FigureCheckError, pyplot
from .dinh2024 import paper004_fig1, paper004_fig4, paper004_fig5
from .efimov2013 import paper003_fig1, paper003_fig2
from .tang2019 import (
    ErrorSets,
    error_sets,
    paper002_fig1,
    paper002_fig2,
    paper002_fig3,
    paper002_fig4,
    paper002_fig5,
    zonotope_polygon,
)
from .wang2020 import paper001_fig1, paper001_fig2

__all__ = [
    "DPI",
    "PAPERS",
    "ErrorSets",
    "FigureCheckError",
    "FigureSpec",
    "error_sets",
    "figure_specs",
    "generate",
    "paper001_fig1",
    "paper001_fig2",
    "paper002_fig1",
    "paper002_fig2",
    "paper002_fig3",
    "paper002_fig4",
    "paper002_fig5",
    "paper003_fig1",
    "paper003_fig2",
    "paper004_fig1",
    "paper004_fig4",
    "paper004_fig5",
    "zonotope_polygon",
]

PAPERS = ("001", "002", "003", "004")
"""The papers whose figures :func:`generate` can draw: [Wang2020], [Tang2019], [Efimov2013],
[Dinh2024]."""


@dataclass(frozen=True)
class FigureSpec:
    """One output file: ``paper``, file ``stem`` (``<stem>.png``) and the function drawing it."""

    paper: str
    stem: str
    make: Callable[[], Any]


_SPECS = (
    FigureSpec("001", "paper001_fig1", paper001_fig1),
    FigureSpec("001", "paper001_fig2", paper001_fig2),
    FigureSpec("002", "paper002_fig1", paper002_fig1),
    FigureSpec("002", "paper002_fig2", paper002_fig2),
    FigureSpec("002", "paper002_fig3", paper002_fig3),
    FigureSpec("002", "paper002_fig4", paper002_fig4),
    FigureSpec("002", "paper002_fig5", paper002_fig5),
    FigureSpec("003", "paper003_fig1", paper003_fig1),
    FigureSpec("003", "paper003_fig2", paper003_fig2),
    FigureSpec("004", "paper004_fig1_ct", partial(paper004_fig1, continuous=True)),
    FigureSpec("004", "paper004_fig1_dt", partial(paper004_fig1, continuous=False)),
    FigureSpec("004", "paper004_fig4", paper004_fig4),
    FigureSpec("004", "paper004_fig5", paper004_fig5),
)


def figure_specs(papers: str | Iterable[str] | None = None) -> list[FigureSpec]:
    """The figures of the given papers (``"001"``, ``"2"``, ``"paper003"`` ...; all by default)."""
    if papers is None:
        return list(_SPECS)
    if isinstance(papers, str):
        papers = papers.split(",")
    wanted = []
    for p in papers:
        digits = str(p).strip().lower().removeprefix("paper")
        if not digits.isdigit() or f"{int(digits):03d}" not in PAPERS:
            raise IvobsError(f"papers: expected some of {', '.join(PAPERS)}, got {p!r}")
        wanted.append(f"{int(digits):03d}")
    if not wanted:
        raise IvobsError(f"papers: expected some of {', '.join(PAPERS)}, got none")
    return [s for s in _SPECS if s.paper in wanted]


def generate(
    out_dir: str | os.PathLike[str],
    papers: str | Iterable[str] | None = None,
    *,
    verbose: bool = False,
) -> list[Path]:
    """Draw the figures of ``papers`` (all by default) into ``out_dir`` as ``<stem>.png``;
    return the paths written (``verbose``: print each path and its time). Each figure is closed
    once written; the command line (``ivobs figures``) selects the non-interactive Agg backend."""
    plt = pyplot()
    specs = figure_specs(papers)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for spec in specs:
        t0 = time.perf_counter()
        fig = spec.make()
        path = out / f"{spec.stem}.png"
        try:
            fig.savefig(path, dpi=DPI)
        finally:
            plt.close(fig)
        paths.append(path)
        if verbose:
            print(f"{path}  ({time.perf_counter() - t0:.1f} s)", flush=True)
    return paths
