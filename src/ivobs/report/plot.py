"""Figures: bands of one or several estimates over the true trajectory (the papers' figures)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import IvobsError

if TYPE_CHECKING:  # only for annotations: Estimate.plot() calls this module (no import cycle)
    from ..result import Estimate

__all__ = ["figure_path", "plot_estimates", "save_figure"]

_STYLES = ["-", "--", "-.", ":"]


def plot_estimates(
    estimates: Mapping[str, Estimate] | Sequence[Estimate],
    truth: Any = None,
    states: Sequence[int] | None = None,
    axes: Any = None,
    *,
    t: Any = None,
    state_names: Sequence[str] | None = None,
    title: str | None = None,
    fill: bool | None = None,
    relative: bool = False,
    layout: bool = True,
) -> Any:
    """One panel per state: each method's lower/upper bounds, and the truth as dots.

    Returns the matplotlib figure. ``states`` selects state indices (all by default).
    ``relative=True`` plots ``bound - truth`` (the error bands around zero): readable when the
    state itself moves far more than the bands are wide. ``layout=False`` skips the final
    ``tight_layout`` (for a caller that adds panels or a legend and lays the figure out once).
    """
    import matplotlib.pyplot as plt

    if not isinstance(estimates, Mapping):
        estimates = {e.method or f"estimate {i}": e for i, e in enumerate(estimates)}
    if not estimates:
        raise IvobsError("plot_estimates: nothing to plot")
    first = next(iter(estimates.values()))
    if first.is_batch:
        raise IvobsError("plot_estimates: batch estimates cannot be plotted; pick one stream")
    nx, T = first.nx, first.T
    from .compare_figure import check_states

    states = check_states(states, nx)
    if t is None:
        t = first.t if first.t is not None else np.arange(T)
    t = np.asarray(t, dtype=float)
    if state_names is None and first.names is not None:
        state_names = first.state_labels  # the model's names and units
    if axes is None:
        fig, axes = plt.subplots(
            len(states), 1, figsize=(8, 2.4 * len(states) + 0.6), sharex=True, squeeze=False
        )
        axes = axes[:, 0]
    else:
        axes = np.atleast_1d(axes)
        fig = axes[0].figure
    fill = len(estimates) == 1 if fill is None else fill
    # the true states: an array, or a Trajectory (its x)
    x = None if truth is None else np.asarray(getattr(truth, "x", truth), dtype=float)
    if relative and x is None:
        raise IvobsError("plot_estimates: relative=True needs the truth")
    shift = x if relative else 0.0
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for j, (ax, i) in enumerate(zip(axes, states)):
        for m, (name, est) in enumerate(estimates.items()):
            c = colors[m % len(colors)]
            ls = _STYLES[m % len(_STYLES)]
            lo, hi = (est.lower - shift)[:, i], (est.upper - shift)[:, i]
            label_m = name if j == 0 else None
            if fill:
                ax.fill_between(t, lo, hi, color=c, alpha=0.25, label=label_m)
            else:
                ax.plot(t, hi, ls, color=c, lw=1.2, label=label_m)
                ax.plot(t, lo, ls, color=c, lw=1.2)
        if x is not None:
            ax.plot(t, (x - shift)[:, i], "k.", ms=3, label="true state" if j == 0 else None)
        label = state_names[i] if state_names is not None else f"$x_{{{i + 1}}}$"
        if relative:
            label = f"bounds − {label}"
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("t" if first.t is not None else "step k")
    axes[0].legend(loc="best", fontsize=8, ncol=min(4, len(estimates) + 1))
    if title:
        axes[0].set_title(title)
    if layout:
        fig.tight_layout()
    return fig


def figure_path(path: str | os.PathLike[str], what: str | None = None) -> Path:
    """The file a figure for ``path`` is written to, checked before any work: ``.png`` is added
    when ``path`` has no extension; an unsupported extension or an unwritable place is an
    :class:`~ivobs.IvobsError` naming ``what`` (e.g. ``"--plot"``)."""
    from matplotlib.backend_bases import FigureCanvasBase

    from ..io.atomic import check_output_path

    path = Path(path)
    prefix = f"{what}: " if what else ""
    if path.is_dir():
        raise IvobsError(f"{prefix}{str(path)!r} is a directory; expected a file name such as "
                         f"{str(path / 'figure.png')!r}")  # fmt: skip
    if not path.suffix:
        path = path.with_name(path.name + ".png")
    fmt = path.suffix[1:].lower()
    formats = sorted(FigureCanvasBase.get_supported_filetypes())  # what matplotlib can write
    if fmt not in formats:
        raise IvobsError(
            f"{prefix}unsupported figure format {path.suffix!r} ({str(path)!r}); expected one "
            f"of {', '.join('.' + f for f in formats)}"
        )
    return check_output_path(path, what)


def save_figure(fig: Any, path: str | os.PathLike[str]) -> Path:
    """Save (atomically: a temporary file, renamed) and close a figure; returns the path written
    (``.png`` added when ``path`` has no extension, see :func:`figure_path`)."""
    import matplotlib.pyplot as plt

    from ..io.atomic import atomic_path

    try:
        target = figure_path(path)
        with atomic_path(target) as tmp:
            fig.savefig(tmp, dpi=120, format=target.suffix[1:].lower())
    finally:
        plt.close(fig)
    return target
