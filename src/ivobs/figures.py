"""The papers' figures: ``ivobs.figures.generate(...)``, ``ivobs figures --out DIR``.

The code lives in :mod:`ivobs.report.figures` (one module per paper); this module keeps the
name ``ivobs.figures`` for scripts and the documentation, with the same public names.
"""

from __future__ import annotations

from .report.figures import *  # noqa: F403  (the same public names, listed there)
from .report.figures import __all__ as __all__
