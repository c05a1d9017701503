"""[Efimov2013, Section IV], Figs. 1-2: the planar system and the Hénon map."""

from __future__ import annotations

from typing import Any

from ... import scenarios
from ..plot import plot_estimates
from .common import pyplot, run_checked

__all__ = ["efimov2013_fig1", "efimov2013_fig2"]


def efimov2013_fig1(horizon: int = 50) -> Any:
    """[Efimov2013, Fig. 1]: ``x2`` by observer (4) (``interval-transformed``, automatic design: the
    paper's ``R`` is not nonnegative) in (a) and by observer (5) (``interval-split``,
    ``L = (0.3, 0.6)``) in (b)."""
    sc = scenarios.get("efimov-planar", horizon=horizon)
    traj = sc.simulate("paper")
    r4 = run_checked("interval-transformed", sc, traj, "[Efimov2013] observer (4)")
    r5 = run_checked("interval-split", sc, traj, "[Efimov2013] observer (5)", L=sc.reference["L"])
    fig, axes = pyplot().subplots(2, 1, figsize=(8, 5.6), sharex=True)
    panels = [
        (
            "observer (4), $z = Sx$ (ivobs' design)",
            r4,
            "[Efimov2013] Fig. 1 (a): $x_2$ by observer (4)",
        ),
        ("observer (5), $L = (0.3, 0.6)$", r5, "(b): $x_2$ by observer (5)"),
    ]
    for ax, (label, res, title) in zip(axes, panels):
        plot_estimates({label: res}, truth=traj.x, states=[1], axes=[ax], title=title)
    axes[0].set_xlabel("")
    fig.tight_layout()
    return fig


def efimov2013_fig2(horizon: int = 100) -> Any:
    """[Efimov2013, Fig. 2]: the Hénon map, interval observer (3) with ``L = (−0.1, 0.1)``,
    bounds of the nonlinear term from the measurement [Efimov2013, Remark 1]."""
    sc = scenarios.get("henon", horizon=horizon)
    traj = sc.simulate("paper")
    res = run_checked("interval", sc, traj, "[Efimov2013] Hénon observer (3)", L=sc.reference["L"])
    return plot_estimates(
        {"observer (3), $L = (-0.1, 0.1)$": res},
        truth=traj.x,
        title="[Efimov2013] Fig. 2: Hénon map with uncertain $a(t)$",
    )
