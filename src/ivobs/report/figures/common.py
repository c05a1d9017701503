"""What every figure module shares: the containment check, a checked run, pyplot.

Every figure checks that the bounds it draws contain the true state at every step and raises
:class:`FigureCheckError` otherwise (a figure of a broken guarantee is a bug, never a picture).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ... import scenarios
from ...estimators import make_estimator
from ...result import Estimate

__all__ = ["DPI", "FigureCheckError", "check_contains", "legend_below", "pyplot", "run_checked"]


DPI = 100
"""Resolution of the written PNG files."""


class FigureCheckError(RuntimeError):
    """A figure's bounds miss the true state (or a set relation the figure illustrates fails).

    Raised instead of drawing: it means a bug in ivobs, not bad input."""


def pyplot() -> Any:
    """``matplotlib.pyplot``, imported when a figure is drawn (not when ivobs is imported)."""
    import matplotlib.pyplot as plt

    return plt


def check_contains(label: str, res: Estimate, x: np.ndarray) -> None:
    """Raise :class:`FigureCheckError` unless ``res`` contains ``x`` at every valid step."""
    ok = res.contains(x)
    if not ok.all():
        bad = np.argwhere(~ok)
        raise FigureCheckError(
            f"{label}: the true state leaves the bounds at {len(bad)} step(s), first at "
            f"{tuple(int(v) for v in bad[0])} (a bug in ivobs; please report it)"
        )


_INTERVAL_FAMILY = ("interval", "interval-split", "interval-transformed")


def run_checked(
    method: str, sc: scenarios.Scenario, traj: Any, label: str, **options: Any
) -> Estimate:
    """Run ``method`` on the scenario's trajectory and check containment: the papers' boxes
    (without the measurement strips of :mod:`ivobs.estimators.measured`, which the papers'
    methods do not take, and the interval observers without the finite-memory bound, which
    the papers' observers do not meet: :mod:`ivobs.estimators.interval.window`)."""
    options.setdefault("strips", False)
    if method in _INTERVAL_FAMILY:
        options.setdefault("finite_memory", False)
    est = make_estimator(method, sc.system, x0=sc.x0, **options)
    res = est.run(traj.u, traj.y)
    check_contains(label, res, traj.x)
    return res


def legend_below(fig: Any, ax: Any, ncol: int = 4) -> None:
    """Move ``ax``'s legend below the panels of ``fig`` (a wide legend inside a panel squeezes
    the others when ``tight_layout`` makes room for it)."""
    handles, labels = ax.get_legend_handles_labels()
    if ax.get_legend() is not None:
        ax.get_legend().remove()
    rows = -(-len(labels) // ncol)
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.035 * rows + 0.01, 1, 1))
