"""The papers' figures, regenerated with ivobs' methods: ``ivobs figures --out DIR``.

One function per figure of [Wang2020], [Tang2019], [Efimov2013] and [Dinh2024]
(``tang2019_fig5()``, ...; the papers are named by their reference keys, as in
``ivobs figures --paper Tang2019``), each returning a matplotlib figure drawn from a fresh run
of the paper's scenario (:mod:`ivobs.scenarios`), one module per paper. Besides the papers,
one figure per nonlinear or uncertain scenario (:mod:`.scenario_figures`: truth and every
capable method's bounds, ``ivobs figures --scenario cstr``) and the Hénon map's two models on
one record (:mod:`.henon`, ``--scenario henon``). Every function checks that the bounds it
draws contain the true state at every step and raises :class:`FigureCheckError` otherwise (a
figure of a broken guarantee is a bug, never a picture). :func:`generate` writes them all (or
those of some papers or scenarios) as PNG files.

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
from .henon import henon_compare_fig
from .scenario_figures import SCENARIO_FIGURES, scenario_figure
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
    "SCENARIOS",
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
    "henon_compare_fig",
    "scenario_figure",
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

SCENARIOS = (*SCENARIO_FIGURES, "henon")
"""The scenarios with a figure of their own (``henon``: its Remark-1 observer against the
nonlinear methods on ``henon-nl``'s record, :func:`henon_compare_fig`)."""


@dataclass(frozen=True)
class FigureSpec:
    """One output file: ``paper`` (a key of :data:`PAPERS`, ``""`` for a scenario's figure),
    file ``stem`` (``<stem>.png``), the function drawing it and ``scenario`` (a name of
    :data:`SCENARIOS` for a scenario's figure, else ``""``)."""

    paper: str
    stem: str
    make: Callable[[], Any]
    scenario: str = ""


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

_SCENARIO_SPECS = (
    *(
        FigureSpec("", f"scenario_{name.replace('-', '_')}", partial(scenario_figure, name), name)
        for name in SCENARIO_FIGURES
    ),
    FigureSpec("", "henon_remark1_vs_nl", henon_compare_fig, "henon"),
)


def _select(wanted: str | Iterable[str], known: tuple[str, ...], name: str) -> list[str]:
    """The items of ``wanted`` (a comma-separated string or a list) as spelled in ``known``
    (any case); an unknown or empty selection raises :class:`IvobsError` naming ``name``."""
    if isinstance(wanted, str):
        wanted = wanted.split(",")
    keys = {k.lower(): k for k in known}
    expected = f"expected some of {', '.join(known)} (any case)"
    out = []
    for p in wanted:
        key = keys.get(str(p).strip().lower())
        if key is None:
            raise IvobsError(f"{name}: {expected}, got {p!r}")
        out.append(key)
    if not out:
        raise IvobsError(f"{name}: {expected}, got none")
    return out


def figure_specs(
    papers: str | Iterable[str] | None = None,
    *,
    name: str = "papers",
    scenarios: str | Iterable[str] | None = None,
    scenarios_name: str = "scenarios",
) -> list[FigureSpec]:
    """The figures of the given papers, by reference key in any case (``"Tang2019"``,
    ``"dinh2024"``, a comma-separated string or a list), then those of the given ``scenarios``
    (names of :data:`SCENARIOS`, any case). With neither, every figure; with one of them, only
    its figures. An unknown key raises :class:`IvobsError` naming ``name`` (or
    ``scenarios_name``: the argument as the caller knows it, e.g. ``--paper``)."""
    if papers is None and scenarios is None:
        return [*_SPECS, *_SCENARIO_SPECS]
    out: list[FigureSpec] = []
    if papers is not None:
        wanted = _select(papers, PAPERS, name)
        out += [s for s in _SPECS if s.paper in wanted]
    if scenarios is not None:
        chosen = _select(scenarios, SCENARIOS, scenarios_name)
        out += [s for s in _SCENARIO_SPECS if s.scenario in chosen]
    return out


def generate(
    out_dir: str | os.PathLike[str],
    papers: str | Iterable[str] | None = None,
    *,
    scenarios: str | Iterable[str] | None = None,
    verbose: bool = False,
) -> list[Path]:
    """Draw the figures of ``papers`` and ``scenarios`` (all with neither, see
    :func:`figure_specs`) into ``out_dir`` as ``<stem>.png``; return the paths written
    (``verbose``: print each path and its time). Each figure is closed once written; the
    command line (``ivobs figures``) selects the non-interactive Agg backend."""
    plt = pyplot()
    specs = figure_specs(papers, scenarios=scenarios)
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
