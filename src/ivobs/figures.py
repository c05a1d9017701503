"""The papers' figures: ``ivobs.figures.generate(...)``, ``ivobs figures --out DIR``.

The code lives in :mod:`ivobs.report.figures` (one module per paper); this module keeps the
name ``ivobs.figures`` for scripts and the documentation.
"""

from __future__ import annotations

from .report.figures import (
    DPI,
    PAPERS,
    ErrorSets,
    FigureCheckError,
    FigureSpec,
    error_sets,
    figure_specs,
    generate,
    paper001_fig1,
    paper001_fig2,
    paper002_fig1,
    paper002_fig2,
    paper002_fig3,
    paper002_fig4,
    paper002_fig5,
    paper003_fig1,
    paper003_fig2,
    paper004_fig1,
    paper004_fig4,
    paper004_fig5,
    zonotope_polygon,
)

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
