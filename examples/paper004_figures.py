"""Reproduce the figures of paper 004 (Dinh & Tran, arXiv 2405.06445) with ivobs' ``kkl`` method.

* Fig. 1 — Example 1: a random observable system with 8 states and 6 outputs, in continuous time
  (as in the paper) and in discrete time; all 8 states.
* Fig. 4 — Example 2: the pendulum with a varying length (continuous-time LTV); state ``x2``.
* Fig. 5 — Example 3: the discrete-time LTV system; state ``x2`` (bounds from ``k* = 2``).

Each figure is drawn in the absence of disturbances and noise (the observer is told so: zero
bounds) and in their presence (the paper's signals, bounds known), one PNG per case::

    python examples/paper004_figures.py OUTPUT_FOLDER

The systems are ivobs' scenarios (``ivobs.scenarios.get(...)``); where the paper does not give a
value (random matrices, initial state, prior box, pendulum length) the scenario's notes say what
ivobs chose, so the pictures match the paper's qualitatively, not point by point.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

import ivobs


def _quiet(sysm: ivobs.LinearSystem) -> ivobs.LinearSystem:
    """The same system with zero disturbance bounds (the paper's "absence of d and w")."""
    zero = ivobs.Box(np.zeros(sysm.nd), np.zeros(sysm.nd))
    return ivobs.LinearSystem(
        sysm.A, sysm.B, sysm.C, D=sysm.D, E=sysm.E, F=sysm.F, d=zero, dt=sysm.dt
    )


def _run(sc: Any, disturbed: bool, **options: Any) -> tuple[ivobs.Estimate, Any]:
    system = sc.system if disturbed else _quiet(sc.system)
    if system.is_continuous:
        u = sc.u_fn if sc.u_fn is not None else sc.u
        d = sc.disturbance("paper") if disturbed else None
        traj = ivobs.simulate(system, sc.x_true0, u, d, t=sc.t)
        if sc.u_fn is not None:
            options.setdefault("input_hold", sc.u_fn)  # the known input between samples
    else:
        d = sc.disturbance("paper") if disturbed else np.zeros((sc.horizon, system.nd))
        traj = ivobs.simulate(system, sc.x_true0, sc.u, d)
    est = ivobs.make_estimator("kkl", system, x0=sc.x0, **options)
    res = est.run(traj.u, traj.y, t=traj.t if system.is_continuous else None)
    if not res.contains(traj.x).all():
        raise AssertionError(f"{sc.name}: the true state left the bounds (a bug; please report)")
    return res, traj


def _panel(ax: Any, res: ivobs.Estimate, traj: Any, i: int, discrete: bool) -> None:
    t = np.arange(res.T) if discrete else traj.t
    style = {"drawstyle": "steps-post"} if discrete else {}
    ax.plot(t, traj.x[:, i], "k-", lw=1.2, label="$x$")
    ax.plot(t, res.upper[:, i], "r--", lw=1.0, label=r"$\overline{x}$", **style)
    ax.plot(t, res.lower[:, i], "b--", lw=1.0, label=r"$\underline{x}$", **style)
    if res.valid_from:
        ax.axvline(t[res.valid_from], color="0.6", lw=0.8, ls=":")
    ax.set_ylabel(f"$x_{{{i + 1}}}$")
    ax.grid(True, alpha=0.3)


def figure1(out: Path, continuous: bool) -> list[Path]:
    """Example 1: all 8 states, observer (3) in z (equivalent to (6))."""
    kind = "ct" if continuous else "dt"
    sc = ivobs.scenarios.get("kkl-random8", **({"continuous": True} if continuous else {}))
    paths = []
    for disturbed in (False, True):
        res, traj = _run(sc, disturbed)
        fig, axes = plt.subplots(4, 2, figsize=(10, 8), sharex=True)
        for i, ax in enumerate(axes.T.ravel()):
            _panel(ax, res, traj, i, not continuous)
            ax.set_ylim(*_zoom(traj.x[:, i], res, i))
        axes[0, 0].legend(fontsize=8, ncol=3)
        axes[-1, 0].set_xlabel("t" if continuous else "k")
        axes[-1, 1].set_xlabel("t" if continuous else "k")
        what = "presence" if disturbed else "absence"
        fig.suptitle(
            f"Example 1 ({'continuous' if continuous else 'discrete'} time): "
            f"KKL interval observer, {what} of disturbances/noise"
        )
        fig.tight_layout()
        path = out / f"fig1_example1_{kind}_{'disturbed' if disturbed else 'clean'}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def _zoom(x: np.ndarray, res: ivobs.Estimate, i: int) -> tuple[float, float]:
    """Y-limits showing the truth and the converged bounds (the first steps are wide)."""
    k0 = res.valid_from + max(1, res.T // 10)
    lo = min(x.min(), np.nanmin(res.lower[k0:, i]))
    hi = max(x.max(), np.nanmax(res.upper[k0:, i]))
    pad = 0.15 * (hi - lo + 1e-9)
    return lo - pad, hi + pad


def figure_x2(out: Path, name: str, fig_no: int, title: str, **options: Any) -> list[Path]:
    """Figs. 4 and 5: the unmeasured state x2, without and with disturbances."""
    sc = ivobs.scenarios.get(name)
    paths = []
    for disturbed in (False, True):
        res, traj = _run(sc, disturbed, **options)
        discrete = not sc.system.is_continuous
        fig, ax = plt.subplots(figsize=(7, 3.2))
        _panel(ax, res, traj, 1, discrete)
        ax.set_ylim(*_zoom(traj.x[:, 1], res, 1))
        ax.set_xlabel("k" if discrete else "t")
        ax.legend(fontsize=8, ncol=3)
        what = "presence" if disturbed else "absence"
        ax.set_title(f"{title}: $x_2$, {what} of disturbances/noise")
        fig.tight_layout()
        path = out / f"fig{fig_no}_{name}_x2_{'disturbed' if disturbed else 'clean'}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)
    return paths


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print(__doc__)
        return 2
    out = Path(argv[0])
    out.mkdir(parents=True, exist_ok=True)
    paths = figure1(out, continuous=True) + figure1(out, continuous=False)
    paths += figure_x2(out, "pendulum", 4, "Example 2 (pendulum, CT LTV, ell = 2)")
    paths += figure_x2(out, "kkl-ltv-dt", 5, "Example 3 (DT LTV, gamma = 1, k* = 2)")
    for p in paths:
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
