"""One figure per nonlinear or uncertain scenario: the true state and every capable method's
bounds, one panel per state (``ivobs figures --scenario henon-nl``).

The scenarios are those of docs/nonlinear.md (``henon-nl``, ``pendulum-nl``, ``cora-tank6-nl``,
``cstr``, ``unicycle-range``, ``range-only``, ``chain10-nl``) and docs/uncertain.md
(``servo-uncertain``). The methods drawn are those that accept the scenario's system: for a
:class:`~ivobs.NonlinearSystem` the methods with ``supports_nonlinear`` (``nl-interval``,
``nl-zonotope``, ``nl-constrained-zonotope``, ``nl-horizon``); for a linear system with
interval matrices those with ``supports_uncertain`` (docs/uncertain.md), ``intersect`` left out
(it combines other methods). Each run is checked to contain the true state
(:class:`FigureCheckError` otherwise).
"""

from __future__ import annotations

import math
from typing import Any

from ... import scenarios
from ...errors import IvobsError
from ...result import Estimate
from ..comparison import applicable_methods
from ..plot import plot_estimates
from .common import legend_below, pyplot, run_checked

__all__ = [
    "SCENARIO_FIGURES",
    "capable_methods",
    "draw_scenario",
    "scenario_figure",
    "scenario_runs",
]

SCENARIO_FIGURES: dict[str, int] = {
    "henon-nl": 100,
    "pendulum-nl": 150,
    "cora-tank6-nl": 20,
    "cstr": 150,
    "unicycle-range": 100,
    "range-only": 200,
    "chain10-nl": 40,
    "servo-uncertain": 100,
}
"""The scenarios drawn by :func:`scenario_figure`, with the horizon of their figure (steps):
long enough to show the transient and the steady widths (docs/figures.md has the CPU times)."""


def capable_methods(sys: Any) -> list[str]:
    """The methods that accept ``sys`` (:func:`~ivobs.report.comparison.applicable_methods`:
    ``supports_nonlinear`` for a nonlinear system, ``supports_uncertain`` for one with interval
    matrices, and the time base and time variation), in :func:`ivobs.estimators.methods` order,
    without ``intersect`` (it combines other methods); a method may still refuse a particular
    system at :func:`~ivobs.make_estimator` (e.g. the ``nl-*`` methods bounds that vary with
    ``y``)."""
    return [m for m in applicable_methods(sys)[0] if m != "intersect"]


def scenario_runs(
    name: str, horizon: int | None = None, methods: list[str] | None = None
) -> tuple[Any, Any, dict[str, Estimate]]:
    """``(scenario, trajectory, {method: estimate})``: the scenario's ``paper`` trajectory
    (seed 0) over ``horizon`` steps (default: :data:`SCENARIO_FIGURES`) and each method's run
    on it (default: :func:`capable_methods`), each checked to contain the true state."""
    if name not in SCENARIO_FIGURES:
        raise IvobsError(f"scenario: expected one of {', '.join(SCENARIO_FIGURES)}, got {name!r}")
    sc = scenarios.get(name, horizon=horizon or SCENARIO_FIGURES[name])
    traj = sc.simulate("paper", seed=0)
    names = capable_methods(sc.system) if methods is None else list(methods)
    runs = {m: run_checked(m, sc, traj, f"{name}: {m}") for m in names}
    return sc, traj, runs


def scenario_figure(name: str, horizon: int | None = None, methods: list[str] | None = None) -> Any:
    """The figure of scenario ``name``: :func:`draw_scenario` of :func:`scenario_runs`."""
    return draw_scenario(*scenario_runs(name, horizon, methods))


def draw_scenario(sc: Any, traj: Any, runs: dict[str, Estimate]) -> Any:
    """One panel per state of ``sc`` (a grid of two columns beyond three states): the true
    state of ``traj`` as dots and each run's upper and lower bounds as two lines (one colour and
    style per method), one legend below the panels."""
    name = sc.name
    nx = sc.system.nx
    ncols = 1 if nx <= 3 else 2
    nrows = math.ceil(nx / ncols)
    fig, axes = pyplot().subplots(
        nrows, ncols, figsize=(8 if ncols == 1 else 11, 1.9 * nrows + 1.0), squeeze=False,
        sharex=True,
    )  # fmt: skip
    flat = axes.ravel()
    for ax in flat[nx:]:  # an odd number of states in a grid: the last cell stays empty
        ax.set_visible(False)
    t = traj.t if sc.system.sampling_period != 1 else None
    plot_estimates(
        runs,
        truth=traj.x,
        axes=flat[:nx],
        t=t,
        fill=False,
        state_names=sc.state_names or getattr(sc.system, "state_names", None),
        title=f"{name}: bounds of each method and the true state ({sc.horizon} steps)",
        layout=False,  # laid out once, by legend_below
    )
    xlabel = "t" if t is not None else "step k"
    for ax in axes[-1]:
        ax.set_xlabel(xlabel)
    if nx % ncols:  # the cell above the empty one is the last of its column
        axes[-2, -1].set_xlabel(xlabel)
        axes[-2, -1].xaxis.set_tick_params(labelbottom=True)
    legend_below(fig, flat[0], ncol=min(4, len(runs) + 1))
    return fig
