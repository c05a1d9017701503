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
    dinh2024_fig1,
    dinh2024_fig4,
    dinh2024_fig5,
    efimov2013_fig1,
    efimov2013_fig2,
    error_sets,
    figure_specs,
    generate,
    tang2019_fig1,
    tang2019_fig2,
    tang2019_fig3,
    tang2019_fig4,
    tang2019_fig5,
    wang2020_fig1,
    wang2020_fig2,
    zonotope_polygon,
)

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
