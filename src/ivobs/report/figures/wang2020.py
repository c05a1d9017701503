"""[Wang2020, Section 4], Figs. 1-2: the fixed-time estimator with ``s = 2`` on [Dinh2019]."""

from __future__ import annotations

from typing import Any

from ... import scenarios
from ..plot import plot_estimates
from .common import run_checked

__all__ = ["wang2020_fig1", "wang2020_fig2"]


def _fixed_time_figure(state: int, horizon: int) -> Any:
    sc = scenarios.get("dinh2019", horizon=horizon)
    traj = sc.simulate("paper")
    res = run_checked("fixed-time", sc, traj, "[Wang2020] fixed-time (s = 2)", s=sc.reference["s"])
    fig = plot_estimates(
        {"fixed-time, s = 2, T of Theorem 1 (eq. 13)": res},
        truth=traj.x,
        states=[state],
        fill=False,
        title=f"[Wang2020] Fig. {state + 1}: $x_{{{state + 1}}}$ and its interval estimate",
    )
    fig.set_size_inches(8, 3.4)
    fig.tight_layout()
    return fig


def wang2020_fig1(horizon: int = 50) -> Any:
    """[Wang2020, Fig. 1]: bounds of ``x1`` by the fixed-time estimator (s = 2, the paper's T),
    truth."""
    return _fixed_time_figure(0, horizon)


def wang2020_fig2(horizon: int = 50) -> Any:
    """[Wang2020, Fig. 2]: bounds of ``x2`` by the fixed-time estimator (s = 2, the paper's T),
    truth."""
    return _fixed_time_figure(1, horizon)
