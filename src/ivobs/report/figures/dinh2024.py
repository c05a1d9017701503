"""[Dinh2024], Figs. 1, 4 and 5: KKL interval observers, with and without disturbances."""

from __future__ import annotations

from typing import Any

import numpy as np

from ... import scenarios
from ...estimators import make_estimator
from ...model import LinearSystem
from ...result import Estimate
from ...sets import Box
from ...simulate import simulate
from .common import check_contains, pyplot

__all__ = ["dinh2024_fig1", "dinh2024_fig4", "dinh2024_fig5"]


def _quiet(sysm: LinearSystem) -> LinearSystem:
    """The same system with zero disturbance bounds (the paper's "absence of d and w")."""
    zero = Box(np.zeros(sysm.nd), np.zeros(sysm.nd))
    return LinearSystem(sysm.A, sysm.B, sysm.C, D=sysm.D, E=sysm.E, F=sysm.F, d=zero, dt=sysm.dt)


def _kkl_run(sc: scenarios.Scenario, disturbed: bool, **options: Any) -> tuple[Estimate, Any, Any]:
    """The ``kkl`` method on the scenario, disturbed (paper signals, bounds known) or not (zero
    signals and the observer told so); returns the estimate, trajectory and design."""
    assert isinstance(sc.system, LinearSystem)
    system = sc.system if disturbed else _quiet(sc.system)
    if system.is_continuous:
        u = sc.u_fn if sc.u_fn is not None else sc.u
        d = sc.disturbance("paper") if disturbed else None
        traj = simulate(system, sc.x_true0, u, d, t=sc.t)
        if sc.u_fn is not None:
            options.setdefault("input_hold", sc.u_fn)  # the known input between samples
    else:
        d = sc.disturbance("paper") if disturbed else np.zeros((sc.horizon, system.nd))
        traj = simulate(system, sc.x_true0, sc.u, d)
    options.setdefault("strips", False)  # the paper's observer, as published
    est = make_estimator("kkl", system, x0=sc.x0, **options)
    res = est.run(traj.u, traj.y, t=traj.t if system.is_continuous else None)
    what = "with" if disturbed else "without"
    check_contains(f"[Dinh2024] {sc.name} kkl {what} disturbances", res, traj.x)
    return res, traj, est.design


def _kkl_pair(sc: scenarios.Scenario, **options: Any) -> list[tuple[Estimate, Any]]:
    """Runs without and with disturbances, sharing one observer design (time-invariant: the
    disturbed design's ``A_z, B_z, T``, so that the two rows show the same observer)."""
    res_d, traj_d, design = _kkl_run(sc, True, **options)
    if not design.time_varying:
        options = {**options, "A_z": design.A_z, "B_z": design.B_z, "T": design.T}
    res_c, traj_c, _ = _kkl_run(sc, False, **options)
    return [(res_c, traj_c), (res_d, traj_d)]


def _zoom(x: np.ndarray, res: Estimate, i: int) -> tuple[float, float]:
    """Y-limits showing the truth and the converged bounds (the first steps are wide)."""
    k0 = res.valid_from + max(1, res.T // 10)
    lo = min(x.min(), np.nanmin(res.lower[k0:, i]))
    hi = max(x.max(), np.nanmax(res.upper[k0:, i]))
    pad = 0.15 * (hi - lo + 1e-9)
    return lo - pad, hi + pad


def _kkl_panel(ax: Any, res: Estimate, traj: Any, i: int, legend: bool = False) -> None:
    """The style of [Dinh2024]: the state solid black, upper bound red dashed, lower bound blue
    dashed."""
    t = traj.t  # sample times; the step numbers in discrete time
    ax.plot(t, traj.x[:, i], "k-", lw=1.2, label="$x$")
    ax.plot(t, res.upper[:, i], "r--", lw=1.0, label=r"$\overline{x}$")
    ax.plot(t, res.lower[:, i], "b--", lw=1.0, label=r"$\underline{x}$")
    if res.valid_from:
        ax.axvline(t[res.valid_from], color="0.6", lw=0.8, ls=":")
    ax.set_ylim(*_zoom(traj.x[:, i], res, i))
    ax.set_ylabel(f"$x_{{{i + 1}}}$")
    ax.grid(True, alpha=0.3)
    if legend:
        ax.legend(fontsize=7, ncol=3, loc="upper right")


def dinh2024_fig1(
    continuous: bool = True, t_final: float = 10.0, dt: float = 0.02, horizon: int = 60
) -> Any:
    """[Dinh2024, Fig. 1] (Example 1): all 8 states of the random system, observer (3) in ``z``
    (equivalent to (6)); absence (top) and presence (bottom) of disturbances. ``continuous``:
    the paper's continuous-time system (``t_final``, samples every ``dt``), else ivobs'
    discrete-time version (``horizon`` steps)."""
    if continuous:
        sc = scenarios.get("kkl-random8", continuous=True, t_final=t_final, dt=dt)
    else:
        sc = scenarios.get("kkl-random8", horizon=horizon)
    kind = "continuous time" if continuous else "discrete time (ivobs' version)"
    title = f"[Dinh2024] Fig. 1: Example 1, {kind}, observer (3)"
    return _pair_figure(sc, range(8), 4, (13, 8.5), "$(d, w)$", title)


def _pair_figure(
    sc: scenarios.Scenario, states: Any, ncols: int, size: Any, what: str, title: str
) -> Any:
    """The ``states`` without (top rows) and with (bottom rows) disturbances, ``ncols`` panels
    a row."""
    per = -(-len(states) // ncols)  # rows of one block
    fig, axes = pyplot().subplots(2 * per, ncols, figsize=size, sharex=True, squeeze=False)
    for block, (res, traj) in enumerate(_kkl_pair(sc)):
        for n, i in enumerate(states):
            ax = axes[block * per + n // ncols, n % ncols]
            _kkl_panel(ax, res, traj, i, legend=(block, n) == (0, 0))
        axes[block * per, 0].set_title(
            ("absence" if block == 0 else "presence") + f" of {what}", loc="left", fontsize=9
        )
    for ax in axes[-1]:
        ax.set_xlabel("k" if sc.t is None else "t")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def dinh2024_fig4(t_final: float = 15.0, dt: float = 0.02) -> Any:
    """[Dinh2024, Fig. 4] (Example 2): the pendulum with varying length (CT LTV), state ``x2 = θ'``,
    observer (10) with ``Ã = diag(−1, −2)``, ``B̃ = (1, 1)``, ``ℓ = 2``; measurements every
    ``dt`` (the sampled-data form of (10), see :mod:`ivobs.estimators.kkl`)."""
    sc = scenarios.get("pendulum", t_final=t_final, dt=dt)
    title = "[Dinh2024] Fig. 4: pendulum (CT LTV), $x_2$, observer (10)"
    return _pair_figure(sc, [1], 1, (7.5, 5.2), "disturbances/noise", title)


def dinh2024_fig5(horizon: int = 30) -> Any:
    """[Dinh2024, Fig. 5] (Example 3): the discrete-time LTV system, state ``x2``, observer (15)
    with ``Ã = diag(0.1, 0.2)``, ``B̃ = (1, 1)``, ``γ = 1`` (bounds from ``k* = 2``)."""
    sc = scenarios.get("kkl-ltv-dt", horizon=horizon)
    title = "[Dinh2024] Fig. 5: DT LTV system, $x_2$, observer (15)"
    return _pair_figure(sc, [1], 1, (7.5, 5.2), "disturbances/noise", title)
