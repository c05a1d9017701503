"""The comparison figure: every method's band stays visible on every state.

Overlaying bands on the raw state hides them when the state moves far more than the bands are
wide (the servo's angle runs over 0–37 rad, its bands are 0.1 wide). So each state gets two
panels: the bounds minus a reference (the true state when known, else the centre of the
tightest method's box), and the widths over time on a log scale.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import IvobsError

if TYPE_CHECKING:
    from ..result import Estimate

__all__ = ["check_states", "comparison_figure", "reference_trajectory"]

_STYLES = ["-", "--", "-.", ":"]


def check_states(states: Sequence[int] | None, nx: int) -> list[int]:
    """0-based state indices, each in ``0..nx-1`` (an :class:`IvobsError` otherwise)."""
    if states is None:
        return list(range(nx))
    out = []
    for s in states:
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or not 0 <= s < nx:
            raise IvobsError(
                f"states: expected 0-based state indices in 0..{nx - 1} (the CLI's --states "
                f"counts from 1), got {s!r}"
            )
        out.append(int(s))
    return out


def reference_trajectory(
    estimates: Mapping[str, Estimate], truth: Any = None
) -> tuple[np.ndarray, str]:
    """The curve the bands are drawn around: the truth, or the centre of the box of the method
    with the smallest mean width (over the steps where it is finite)."""
    if truth is not None:
        return np.asarray(truth, dtype=float), "true state"
    best, best_w = None, np.inf
    for name, est in estimates.items():
        w = est.width
        finite = np.isfinite(w).all(axis=1)
        if finite.any() and float(np.mean(w[finite])) < best_w:
            best, best_w = name, float(np.mean(w[finite]))
    if best is None:
        raise IvobsError("comparison figure: no method has a finite box to draw around")
    est = estimates[best]
    return 0.5 * (est.lower + est.upper), f"centre of {best}"


def comparison_figure(
    estimates: Mapping[str, Estimate],
    truth: Any = None,
    states: Sequence[int] | None = None,
    *,
    t: Any = None,
    state_names: Sequence[str] | None = None,
    title: str | None = None,
) -> Any:
    """Per state: bounds minus the reference (left), widths on a log scale (right)."""
    import matplotlib.pyplot as plt

    if not estimates:
        raise IvobsError("comparison figure: nothing to plot")
    first = next(iter(estimates.values()))
    idx = check_states(states, first.nx)
    ref, ref_name = reference_trajectory(estimates, truth)
    time = np.asarray(first.t if t is None and first.t is not None else
                      np.arange(first.T) if t is None else t, dtype=float)  # fmt: skip
    fig, axes = plt.subplots(
        len(idx), 2, figsize=(11, 2.3 * len(idx) + 0.7), sharex=True, squeeze=False
    )
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for row, i in enumerate(idx):
        left, right = axes[row]
        for m, (name, est) in enumerate(estimates.items()):
            style = {"color": colors[m % len(colors)], "ls": _STYLES[m % 4], "lw": 1.1}
            label = name if row == 0 else None
            left.plot(time, est.upper[:, i] - ref[:, i], label=label, **style)
            left.plot(time, est.lower[:, i] - ref[:, i], **style)
            width = est.width[:, i]
            right.plot(time, np.where(width > 0, width, np.nan), **style)
        left.axhline(0.0, color="k", lw=0.6)
        name = state_names[i] if state_names is not None else f"$x_{{{i + 1}}}$"
        left.set_ylabel(f"bounds − {ref_name}\n({name})", fontsize=8)
        right.set_ylabel(f"width of {name}", fontsize=8)
        right.set_yscale("log")
        for ax in (left, right):
            ax.grid(True, alpha=0.3)
    xlabel = "t (s)" if (t is not None or first.t is not None) else "step k"
    axes[-1, 0].set_xlabel(xlabel)
    axes[-1, 1].set_xlabel(xlabel)
    axes[0, 0].legend(loc="best", fontsize=7, ncol=min(3, len(estimates)))
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    return fig
