"""What users look at: tables comparing methods and figures of estimates.

- :mod:`~ivobs.report.comparison`: :func:`compare` (several methods on one record) and
  :func:`markdown_table` (widths, containment, timings);
- :mod:`~ivobs.report.plot`: bands of estimates over the true trajectory, figure files;
- :mod:`~ivobs.report.figures`: the papers' figures, one module per paper (``ivobs figures``).

This is the top of the library's layers below the command line: it imports estimators,
results and scenarios; none of them imports it (``Estimate.plot`` reaches :mod:`.plot`, which
imports :class:`~ivobs.Estimate` for its annotations only).
"""

from __future__ import annotations

from .comparison import POINT_TOL, MethodResult, compare, markdown_table

__all__ = ["POINT_TOL", "MethodResult", "compare", "markdown_table"]
