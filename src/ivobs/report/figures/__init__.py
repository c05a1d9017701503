"""The papers' figures, regenerated with ivobs' methods: ``ivobs figures --out DIR``.

One function per figure of [Wang2020], [Tang2019], [Efimov2013] and [Dinh2024]
(``tang2019_fig5()``, ...; the papers are named by their reference keys, as in
``ivobs figures --paper Tang2019``), each returning a matplotlib figure drawn from a fresh run
of the paper's scenario (:mod:`ivobs.scenarios`), one module per paper. Every function checks
that the bounds it draws contain the true state at every step and raises
:class:`FigureCheckError` otherwise (a figure of a broken guarantee is a bug, never a picture).
:func:`generate` writes them all (or those of some papers) as PNG files.

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
from .dinh2024 import dinh2024_fig1, dinh2024_fig4, dinh2024_fig5
from .efimov2013 import efimov2013_fig1, efimov2013_fig2
from .tang2019 import (
    ErrorSets,
    error_sets,
    tang2019_fig1,
    tang2019_fig2,
    tang2019_fig3,
    tang2019_fig4,
    tang2019_fig5,
    zonotope_polygon,
)
from .wang2020 import wang2020_fig1, wang2020_fig2

__all__ = [
    "DPI",
    "PAPERS",
    "ErrorSets",
    "FigureCheckError",
    "FigureSpec",
    "dinh2024_fig1",
    "dinh2024_fig4",
    "dinh2024_fig5",
    "efimov2013_fig1",
    "efimov2013_fig2",
    "error_sets",
    "figure_specs",
    "generate",
    "tang2019_fig1",
    "tang2019_fig2",
    "tang2019_fig3",
    "tang2019_fig4",
    "tang2019_fig5",
    "wang2020_fig1",
    "wang2020_fig2",
    "zonotope_polygon",
]

PAPERS = ("Wang2020", "Tang2019", "Efimov2013", "Dinh2024")
"""The papers whose figures :func:`generate` can draw, by their keys in docs/references.md."""


@dataclass(frozen=True)
class FigureSpec:
    """One output file: ``paper`` (a key of :data:`PAPERS`), file ``stem`` (``<stem>.png``) and
    the function drawing it."""

    paper: str
    stem: str
    make: Callable[[], Any]


_SPECS = (
    FigureSpec("Wang2020", "wang2020_fig1", wang2020_fig1),
    FigureSpec("Wang2020", "wang2020_fig2", wang2020_fig2),
    FigureSpec("Tang2019", "tang2019_fig1", tang2019_fig1),
    FigureSpec("Tang2019", "tang2019_fig2", tang2019_fig2),
    FigureSpec("Tang2019", "tang2019_fig3", tang2019_fig3),
    FigureSpec("Tang2019", "tang2019_fig4", tang2019_fig4),
    FigureSpec("Tang2019", "tang2019_fig5", tang2019_fig5),
    FigureSpec("Efimov2013", "efimov2013_fig1", efimov2013_fig1),
    FigureSpec("Efimov2013", "efimov2013_fig2", efimov2013_fig2),
    FigureSpec("Dinh2024", "dinh2024_fig1_ct", partial(dinh2024_fig1, continuous=True)),
    FigureSpec("Dinh2024", "dinh2024_fig1_dt", partial(dinh2024_fig1, continuous=False)),
    FigureSpec("Dinh2024", "dinh2024_fig4", dinh2024_fig4),
    FigureSpec("Dinh2024", "dinh2024_fig5", dinh2024_fig5),
)


def figure_specs(
    papers: str | Iterable[str] | None = None, *, name: str = "papers"
) -> list[FigureSpec]:
    """The figures of the given papers, by reference key in any case (``"Tang2019"``,
    ``"dinh2024"``, a comma-separated string or a list; all by default). An unknown key raises
    :class:`IvobsError` naming ``name`` (the argument as the caller knows it, e.g. ``--paper``)."""
    if papers is None:
        return list(_SPECS)
    if isinstance(papers, str):
        papers = papers.split(",")
    keys = {p.lower(): p for p in PAPERS}
    expected = f"expected some of {', '.join(PAPERS)} (any case)"
    wanted = []
    for p in papers:
        key = keys.get(str(p).strip().lower())
        if key is None:
            raise IvobsError(f"{name}: {expected}, got {p!r}")
        wanted.append(key)
    if not wanted:
        raise IvobsError(f"{name}: {expected}, got none")
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
