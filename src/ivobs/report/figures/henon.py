"""The Hénon map two ways, on the same truth: [Efimov2013, Remark 1] against the full nonlinear
model (docs/nonlinear.md, "Hénon: full nonlinear model vs Remark 1").

*Remark 1* keeps the linear part ``x+ = A x + r b``, ``A = [[0, 1], [0.3, 0]]``, ``r = (1, 0)``,
and treats ``b = 1 - a x1^2 + w`` as a disturbance whose bounds come from the measurement at each
step: ``x1 ∈ [y - V, y + V]`` gives ``x1^2`` and hence ``b`` an interval
(:func:`~ivobs.scenarios.efimov2013.henon_bounds`). Every linear method then runs on it. The
*nonlinear model* (:func:`~ivobs.scenarios.nonlinear.henon_nl_system`) bounds ``1 - a x1^2``
over the method's own set of ``x1`` by inclusion functions (natural and mean-value forms), after
that set was contracted by the same measurement (``nl-interval``), or linearises it over the set
(``nl-zonotope``, ``nl-constrained-zonotope``).

Both models are built with the same numbers (``a``-range, ``|w|``, ``|v|``), the same initial
box and are run on the same record: :func:`henon_pair` takes a Hénon scenario's ``paper``
trajectory, ``henon-nl`` (its uniform signals, ``a ∈ [1.39, 1.41]``) or ``henon``
([Efimov2013]'s ``a ∈ [1, 1.4]``, sinusoidal signals), and builds the other model with the
scenario's numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ... import scenarios
from ...errors import IvobsError
from ...estimators import make_estimator
from ...model import LinearSystem, NonlinearSystem
from ...result import Estimate
from ...scenarios.efimov2013 import henon_remark1_system
from ...scenarios.nonlinear import henon_nl_system
from ...sets import Box
from ...simulate import Trajectory
from ..plot import plot_estimates
from .common import check_contains, legend_below, pyplot

__all__ = [
    "HENON_SETTINGS",
    "NL_METHODS",
    "PAPER_L",
    "REMARK1_METHODS",
    "HenonPair",
    "henon_compare_fig",
    "henon_pair",
    "henon_run",
]

HENON_SETTINGS: dict[str, tuple[tuple[float, float], float, float]] = {
    "henon-nl": ((1.39, 1.41), 0.005, 0.02),
    "henon": ((1.0, 1.4), 0.015, 0.1),
}
"""Per scenario: the ``a``-range, the bound of the disturbance ``w`` on ``x1`` and of the noise
``v`` on ``y = x1 + v`` (the scenarios' own values)."""

PAPER_L = np.array([[-0.1], [0.1]])
"""The gain of [Efimov2013]'s interval observer (3) for the Hénon map."""

REMARK1_METHODS = (
    "interval (3)",
    "interval",
    "interval-split",
    "interval-transformed",
    "reachability",
    "zonotope",
    "fixed-time",
    "kkl",
    "strip",
    "ellipsoid",
    "constrained-zonotope",
    "exact",
)
"""The methods run on the Remark-1 model: every linear method (``intersect`` combines others);
``"interval (3)"`` is ``interval`` with the paper's gain :data:`PAPER_L`, ``"interval"`` its
automatic design."""

NL_METHODS = ("nl-interval", "nl-zonotope", "nl-constrained-zonotope")
"""The methods run on the full nonlinear model."""


@dataclass(frozen=True)
class HenonPair:
    """The two models of one Hénon setting, its initial box and the record both are run on."""

    setting: str
    remark1: LinearSystem
    nonlinear: NonlinearSystem
    x0: Box
    traj: Trajectory


def henon_pair(setting: str = "henon-nl", horizon: int = 200) -> HenonPair:
    """Both models with the numbers of scenario ``setting`` (``"henon-nl"`` or ``"henon"``,
    :data:`HENON_SETTINGS`), its initial box and its ``paper`` trajectory over ``horizon``."""
    if setting not in HENON_SETTINGS:
        raise IvobsError(f"setting: expected one of {', '.join(HENON_SETTINGS)}, got {setting!r}")
    a, w, v = HENON_SETTINGS[setting]
    sc = scenarios.get(setting, horizon=horizon)
    return HenonPair(
        setting=setting,
        remark1=henon_remark1_system(a, V=v, delta=w),
        nonlinear=henon_nl_system(a, w=w, v=v),
        x0=sc.x0,
        traj=sc.simulate("paper", seed=0),
    )


def henon_run(pair: HenonPair, method: str) -> Estimate:
    """Run ``method`` (of :data:`REMARK1_METHODS` or :data:`NL_METHODS`) on the pair's record
    with its model, checked to contain the true state."""
    if method in NL_METHODS:
        est = make_estimator(method, pair.nonlinear, x0=pair.x0)
    elif method == "interval (3)":
        est = make_estimator("interval", pair.remark1, x0=pair.x0, L=PAPER_L)
    elif method in REMARK1_METHODS:
        est = make_estimator(method, pair.remark1, x0=pair.x0)
    else:
        raise IvobsError(
            f"method: expected one of {', '.join(REMARK1_METHODS + NL_METHODS)}, got {method!r}"
        )
    res = est.run(pair.traj.u, pair.traj.y)
    check_contains(f"{pair.setting}: {method}", res, pair.traj.x)
    return res


def henon_compare_fig(setting: str = "henon-nl", horizon: int = 100) -> Any:
    """Left: the bounds of [Efimov2013]'s interval observer (3) on the Remark-1 model and of
    ``nl-interval``, ``nl-zonotope``, ``nl-constrained-zonotope`` on the nonlinear model, with
    the true state; right: the same bounds minus the true state. One row per state."""
    pair = henon_pair(setting, horizon)
    runs = {
        "Remark 1: interval observer (3)": henon_run(pair, "interval (3)"),
        **{f"nonlinear: {m}": henon_run(pair, m) for m in NL_METHODS},
    }
    fig, axes = pyplot().subplots(2, 2, figsize=(12, 5.6), sharex=True)
    a, w, v = HENON_SETTINGS[setting]
    plot_estimates(
        runs,
        truth=pair.traj.x,
        axes=axes[:, 0],
        fill=False,
        layout=False,
        title="bounds and the true state",
    )
    plot_estimates(runs, truth=pair.traj.x, axes=axes[:, 1], fill=False, relative=True,
                   layout=False, title="bounds minus the true state")  # fmt: skip
    axes[0, 1].get_legend().remove()
    fig.suptitle(f"Hénon map, one record ({setting}: a ∈ [{a[0]}, {a[1]}], |w| ≤ {w}, |v| ≤ {v}): "
                 "Remark 1 vs the nonlinear model")  # fmt: skip
    legend_below(fig, axes[0, 0], ncol=5)
    return fig
