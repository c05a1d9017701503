"""The papers' figures, regenerated with ivobs' methods: ``ivobs figures --out DIR``.

One function per figure of papers 001-004 (``paper002_fig5()``, ...), each returning a matplotlib
figure drawn from a fresh run of the paper's scenario (:mod:`ivobs.scenarios`). Every function
checks that the bounds it draws contain the true state at every step and raises
:class:`FigureCheckError` otherwise (a figure of a broken guarantee is a bug, never a picture).
:func:`generate` writes them all (or those of some papers) as PNG files.

What each figure shows, and what differs from the paper and why: ``docs/figures.md``.
Paper 002's Fig. 5 is built from :func:`error_sets` (the sets Ω_k, P̃ of Theorem 8 and sampled
errors), which tests can check numerically.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from . import scenarios
from .errors import IvobsError
from .estimators import make_estimator
from .model import LinearSystem
from .plot import plot_estimates
from .result import Estimate
from .sets import Box, Zonotope, image_bounds, neg, pos
from .simulate import simulate

__all__ = [
    "PAPERS",
    "ErrorSets",
    "FigureCheckError",
    "FigureSpec",
    "error_sets",
    "figure_specs",
    "generate",
    "paper001_fig1",
    "paper001_fig2",
    "paper002_fig1",
    "paper002_fig2",
    "paper002_fig3",
    "paper002_fig4",
    "paper002_fig5",
    "paper003_fig1",
    "paper003_fig2",
    "paper004_fig1",
    "paper004_fig4",
    "paper004_fig5",
    "zonotope_polygon",
]

PAPERS = ("001", "002", "003", "004")
"""The papers whose figures :func:`generate` can draw."""

DPI = 100
"""Resolution of the written PNG files."""


class FigureCheckError(RuntimeError):
    """A figure's bounds miss the true state (or a set relation the figure illustrates fails).

    Raised instead of drawing: it means a bug in ivobs, not bad input."""


def _pyplot() -> Any:
    import matplotlib.pyplot as plt

    return plt


def _check(label: str, res: Estimate, x: np.ndarray) -> None:
    """Raise :class:`FigureCheckError` unless ``res`` contains ``x`` at every valid step."""
    ok = res.contains(x)
    if not ok.all():
        bad = np.argwhere(~ok)
        raise FigureCheckError(
            f"{label}: the true state leaves the bounds at {len(bad)} step(s), first at "
            f"{tuple(int(v) for v in bad[0])} (a bug in ivobs; please report it)"
        )


def _run(method: str, sc: scenarios.Scenario, traj: Any, label: str, **options: Any) -> Estimate:
    """Run ``method`` on the scenario's trajectory and check containment."""
    est = make_estimator(method, sc.system, x0=sc.x0, **options)
    res = est.run(traj.u, traj.y)
    _check(label, res, traj.x)
    return res


# ---------------------------------------------------------------------------------------------
# Paper 001 (Wang et al., IFAC 2020), Section 4, Figs. 1-2: fixed-time estimator with s = 2
# ---------------------------------------------------------------------------------------------
def _paper001(state: int, horizon: int) -> Any:
    sc = scenarios.get("dinh2019", horizon=horizon)
    traj = sc.simulate("paper")
    res = _run("fixed-time", sc, traj, "001 fixed-time (s = 2)", s=sc.reference["s"])
    fig = plot_estimates(
        {"fixed-time, s = 2, T of Theorem 1 (eq. 13)": res},
        truth=traj.x,
        states=[state],
        fill=False,
        title=f"Paper 001, Fig. {state + 1}: $x_{{{state + 1}}}$ and its interval estimate",
    )
    fig.set_size_inches(8, 3.4)
    fig.tight_layout()
    return fig


def paper001_fig1(horizon: int = 50) -> Any:
    """001 Fig. 1: bounds of ``x1`` by the fixed-time estimator (s = 2, the paper's T), truth."""
    return _paper001(0, horizon)


def paper001_fig2(horizon: int = 50) -> Any:
    """001 Fig. 2: bounds of ``x2`` by the fixed-time estimator (s = 2, the paper's T), truth."""
    return _paper001(1, horizon)


# ---------------------------------------------------------------------------------------------
# Paper 002 (Tang et al., IEEE TAC 2019), Section VII
# ---------------------------------------------------------------------------------------------
def _servo_runs(horizon: int) -> tuple[dict[str, Estimate], Any, scenarios.Scenario]:
    """Example 1: Algorithm 1 vs zonotope (34) with ``L1``; Algorithm 1 vs (36) with ``L2``.

    Line styles are the paper's: solid Algorithm 1/L1, dash-dotted zonotope/L1, dashed
    Algorithm 1/L2, dotted interval observer/L2."""
    sc = scenarios.get("servo-motor", horizon=horizon)
    traj = sc.simulate("paper")
    L1, L2 = sc.reference["L1"], sc.reference["L2"]
    runs = {
        "Algorithm 1, $L_1$": ("reachability", L1),
        "zonotope (34), $L_1$": ("zonotope", L1),
        "Algorithm 1, $L_2$": ("reachability", L2),
        "interval observer (36), $L_2$": ("interval", L2),
    }
    out = {
        name: _run(m, sc, traj, f"002 servo motor, {name}", L=L) for name, (m, L) in runs.items()
    }
    return out, traj, sc


def _compare(
    ax: Any, res: dict[str, tuple[Estimate, dict[str, Any]]], truth: np.ndarray, i: int
) -> None:
    """Upper and lower bounds of state ``i`` for each method with its own line style (the
    papers' legends distinguish methods by line style), the truth as asterisks."""
    t = np.arange(truth.shape[0])
    for name, (est, style) in res.items():
        ax.plot(t, est.upper[:, i], label=name, **style)
        ax.plot(t, est.lower[:, i], **style)
    ax.plot(t, truth[:, i], "k*", ms=3.5, label="true state", zorder=5)
    ax.grid(True, alpha=0.3)


_SERVO_STYLES = {  # 002 Section VII: solid, dash-dotted (L1); dashed, dotted (L2); the
    # comparison methods thicker, underneath: they nearly coincide with Algorithm 1
    "Algorithm 1, $L_1$": {"ls": "-", "color": "C0", "lw": 1.5, "zorder": 4},
    "zonotope (34), $L_1$": {"ls": "-.", "color": "C2", "lw": 2.6, "alpha": 0.8, "zorder": 3},
    "Algorithm 1, $L_2$": {"ls": "--", "color": "C1", "lw": 1.5, "zorder": 4},
    "interval observer (36), $L_2$": {"ls": ":", "color": "C3", "lw": 2.4, "zorder": 3},
}


def _paper002_servo(state: int, horizon: int) -> Any:
    res, traj, sc = _servo_runs(horizon)
    names = sc.state_names or ("θ", "n", "i")
    what = ("Motor position θ", "Motor speed n", "Armature current i")[state]
    fig, ax = _pyplot().subplots(figsize=(8, 4))
    _compare(ax, {k: (v, _SERVO_STYLES[k]) for k, v in res.items()}, traj.x, state)
    ax.set_ylabel(names[state])
    ax.set_xlabel("step k (Ts = 0.1 s)")
    ax.legend(fontsize=8, ncol=3)
    ax.set_title(f"Paper 002, Fig. {state + 1}: {what} and its interval estimations")
    fig.tight_layout()
    return fig


def paper002_fig1(horizon: int = 100) -> Any:
    """002 Fig. 1: servo-motor position θ: Algorithm 1 vs zonotope (L1), vs (36) (L2)."""
    return _paper002_servo(0, horizon)


def paper002_fig2(horizon: int = 100) -> Any:
    """002 Fig. 2: servo-motor speed n: Algorithm 1 vs zonotope (L1), vs (36) (L2)."""
    return _paper002_servo(1, horizon)


def paper002_fig3(horizon: int = 100) -> Any:
    """002 Fig. 3: armature current i: Algorithm 1 vs zonotope (L1), vs (36) (L2)."""
    return _paper002_servo(2, horizon)


def _tang2_options(sc: scenarios.Scenario) -> dict[str, Any]:
    """The paper's design of (42): its ``L``, ``R``, ``e1``, ``e2`` (``S`` by eq. (48))."""
    ref = sc.reference
    return {"L": ref["L"], "R": ref["R"], "e1": ref["e1"], "e2": ref["e2"]}


def paper002_fig4(horizon: int = 25) -> Any:
    """002 Fig. 4 (Example 2): Algorithm 1 (H∞ gain) vs the transformed observer (42), with the
    paper's ``L``, ``R``, ``e1``, ``e2``. ``A`` is unstable (``|λ| = 1.118``) and ``u = 0``: the
    state grows like ``1.118^k``, so a short horizon keeps the bounds' widths visible."""
    sc = scenarios.get("tang-example2", horizon=horizon)
    traj = sc.simulate("paper")
    res = {
        "Algorithm 1 (H∞ gain $L$)": (
            _run("reachability", sc, traj, "002 Ex. 2 Algorithm 1", L=sc.reference["L"]),
            {"ls": "--", "color": "C0", "lw": 1.4, "zorder": 4},
        ),
        "interval observer (42), $z = Sx$": (
            _run("interval-transformed", sc, traj, "002 Ex. 2 (42)", **_tang2_options(sc)),
            {"ls": "-.", "color": "C3", "lw": 1.3, "zorder": 3},
        ),
    }
    fig, axes = _pyplot().subplots(2, 1, figsize=(8, 5.6), sharex=True)
    for i, ax in enumerate(axes):
        _compare(ax, res, traj.x, i)
        ax.set_ylabel(f"$x_{{{i + 1}}}$")
    axes[0].legend(fontsize=8, ncol=3)
    axes[-1].set_xlabel("step k")
    axes[0].set_title(
        "Paper 002, Fig. 4: $x_k$ and its interval estimations by Algorithm 1 and (42)"
    )
    fig.tight_layout()
    return fig


@dataclass(frozen=True)
class ErrorSets:
    """The sets of 002 Fig. 5 (Theorem 8) at step ``k``, in error coordinates ``e = x − x̂``.

    ``omega``: the reachable set Ω_k of the H∞ observer's error (a zonotope, eq. (25));
    ``box_reach``: ``[e̲_k, ē_k]`` of Algorithm 1 (its box minus ``x̂_k``; ``= Box(Ω_k)``);
    ``S``, ``pz_lo``, ``pz_hi``: the parallelotope P̃ = {e : e̲ᶻ_k <= S e <= ẽᶻ_k} of (72);
    ``box_transformed``: the box of observer (42) minus ``x̂_k`` (``= Box(P̃)``, eq. (79));
    ``samples``: ``e_k`` of independent runs (uniform initial state and disturbances)."""

    k: int
    omega: Zonotope
    box_reach: Box
    S: np.ndarray
    pz_lo: np.ndarray
    pz_hi: np.ndarray
    box_transformed: Box
    samples: np.ndarray

    def parallelotope(self) -> np.ndarray:
        """The four vertices of P̃ (counter-clockwise order of the z-box corners)."""
        corners = [
            (self.pz_lo[0], self.pz_lo[1]),
            (self.pz_hi[0], self.pz_lo[1]),
            (self.pz_hi[0], self.pz_hi[1]),
            (self.pz_lo[0], self.pz_hi[1]),
        ]
        return np.linalg.solve(self.S, np.array(corners).T).T


def zonotope_polygon(Z: Zonotope) -> np.ndarray:
    """Vertices ``(m, 2)`` of a planar zonotope, counter-clockwise (its generators sorted by
    angle, each walked once forwards and once backwards)."""
    if Z.dim != 2:
        raise IvobsError(f"zonotope_polygon: expected a planar zonotope, got dimension {Z.dim}")
    G = Z.generators[:, np.any(Z.generators != 0.0, axis=0)]
    if G.shape[1] == 0:
        return Z.center[None, :].copy()
    up = (G[1] > 0) | ((G[1] == 0) & (G[0] > 0))
    G = np.where(up, G, -G)  # all generators in the upper half-plane: angles in [0, π)
    G = G[:, np.argsort(np.arctan2(G[1], G[0]), kind="stable")]
    start = Z.center - G.sum(axis=1)
    steps = np.hstack([2 * G, -2 * G])
    return start + np.cumsum(steps, axis=1).T  # the last vertex is ``start`` again


def _in_planar_zonotope(Z: Zonotope, pts: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
    """Exact membership in a planar zonotope: its facets are normal to its generators."""
    G = Z.generators[:, np.any(Z.generators != 0.0, axis=0)]
    N = np.vstack([-G[1], G[0]])  # normals (2, m)
    h = np.abs(N.T @ G).sum(axis=1)  # support in each normal direction
    v = np.abs((pts - Z.center) @ N)
    return np.all(v <= h * (1 + rtol) + 1e-15, axis=1)


def error_sets(k: int = 40, runs: int = 1000, seed: int = 0) -> ErrorSets:
    """The sets of 002 Fig. 5 on Example 2 at step ``k``, with ``runs`` independent runs.

    Algorithm 1 and observer (42) both use the paper's ``L`` (Theorem 8: same gain, same prior
    box ``x0 = <p0, H0>``). With ``M = A − LC``, ``G = E − LF``, ``d = c + diag(r) δ``:

        Ω_k = M^k <0, H0> ⊕ ⊕_{i<k} M^i G <0, diag r>                         (25)
        ẽᶻ+ = R⁺ ẽᶻ − R⁻ e̲ᶻ + (SG)⁺ d̄ − (SG)⁻ d̲ − S G c   (and e̲ᶻ+ symmetrically),
        ẽᶻ_0 = −e̲ᶻ_0 = |S| h0                                                 (70)

    (``R = S M S⁻¹`` as propagated by the estimator). The function runs both estimators on the
    ``runs`` trajectories as one batch and raises :class:`FigureCheckError` unless: every run
    stays in both estimators' boxes at every step; Algorithm 1's box at ``k`` is Box(Ω_k) and
    (42)'s is Box(P̃) (eq. 79), both to 1e-9; every sampled ``e_k`` lies in Ω_k; Ω_k ⊆ P̃ (74).
    """
    sc = scenarios.get("tang-example2", horizon=k + 1)
    sys = sc.system
    rng = np.random.default_rng(seed)
    x0s = sc.x0.sample(runs, rng)
    trajs = [simulate(sys, x0s[j], sc.u, sc.disturbance("uniform", seed=rng)) for j in range(runs)]
    X = np.stack([tr.x for tr in trajs])
    Y = np.stack([tr.y for tr in trajs])
    U = np.broadcast_to(sc.u, (runs, *sc.u.shape))
    L = sc.reference["L"]
    reach = make_estimator("reachability", sys, x0=sc.x0, L=L)
    trans = make_estimator("interval-transformed", sys, x0=sc.x0, **_tang2_options(sc))
    r_res, t_res = reach.run(U, Y), trans.run(U, Y)
    _check("002 Fig. 5 Algorithm 1 (batch)", r_res, X)
    _check("002 Fig. 5 observer (42) (batch)", t_res, X)
    xhat = 0.5 * (r_res.lower[:, k] + r_res.upper[:, k])  # Algorithm 1's box is x̂_k ± ρ_k

    A, _, C, _, E, F = sys.matrices_at(0)
    M, G = A - L @ C, E - L @ F
    d = sys.d_at(0)
    H = np.diag(sc.x0.radius)  # M^k H0
    Gi = [G * d.radius]  # M^i G diag r, i < k
    for _ in range(k):
        H = M @ H
    for _ in range(k - 1):
        Gi.append(M @ Gi[-1])
    omega = Zonotope(np.zeros(2), np.hstack([H, *Gi]))

    S, R = trans.design.S, trans.design.R
    SG = S @ G
    shift = SG @ d.center
    ghi = pos(SG) @ d.hi - neg(SG) @ d.lo - shift
    glo = pos(SG) @ d.lo - neg(SG) @ d.hi - shift
    zlo, zhi = image_bounds(S, -sc.x0.radius, sc.x0.radius)
    for _ in range(k):
        zlo, zhi = pos(R) @ zlo - neg(R) @ zhi + glo, pos(R) @ zhi - neg(R) @ zlo + ghi

    sets = ErrorSets(
        k=k,
        omega=omega,
        box_reach=Box(r_res.lower[0, k] - xhat[0], r_res.upper[0, k] - xhat[0]),
        S=S,
        pz_lo=zlo,
        pz_hi=zhi,
        box_transformed=Box(t_res.lower[0, k] - xhat[0], t_res.upper[0, k] - xhat[0]),
        samples=X[:, k] - xhat,
    )
    _check_error_sets(sets, r_res, t_res, xhat)
    return sets


def _check_error_sets(sets: ErrorSets, r_res: Estimate, t_res: Estimate, xhat: np.ndarray) -> None:
    """The relations 002 Fig. 5 illustrates (Theorem 8); see :func:`error_sets`."""
    k = sets.k
    hull = sets.omega.interval_hull()
    p_lo, p_hi = image_bounds(np.linalg.inv(sets.S), sets.pz_lo, sets.pz_hi)  # Box(P̃)
    scale = 1e-9 * (1.0 + np.abs(t_res.upper[:, k]).max())
    Sv = zonotope_polygon(sets.omega) @ sets.S.T  # S times the vertices of Ω_k
    checks = {
        "Algorithm 1's box is Box(Ω_k) (eq. 26)": np.allclose(
            np.stack([r_res.lower[:, k] - xhat, r_res.upper[:, k] - xhat]),
            np.stack([np.broadcast_to(hull.lo, xhat.shape), np.broadcast_to(hull.hi, xhat.shape)]),
            rtol=0.0,
            atol=scale,
        ),
        "observer (42)'s box is Box(P̃) (eq. 79)": np.allclose(
            np.stack([t_res.lower[:, k] - xhat, t_res.upper[:, k] - xhat]),
            np.stack([np.broadcast_to(p_lo, xhat.shape), np.broadcast_to(p_hi, xhat.shape)]),
            rtol=0.0,
            atol=scale,
        ),
        "every sampled e_k lies in Ω_k": bool(_in_planar_zonotope(sets.omega, sets.samples).all()),
        "Ω_k ⊆ P̃ (eq. 74)": bool(np.all((Sv >= sets.pz_lo - scale) & (Sv <= sets.pz_hi + scale))),
    }
    failed = [name for name, ok in checks.items() if not ok]
    if failed:
        raise FigureCheckError(f"002 Fig. 5: failed: {'; '.join(failed)} (a bug in ivobs)")


def _box_xy(b: Box) -> tuple[list[float], list[float]]:
    return (
        [b.lo[0], b.hi[0], b.hi[0], b.lo[0], b.lo[0]],
        [b.lo[1], b.lo[1], b.hi[1], b.hi[1], b.lo[1]],
    )


def paper002_fig5(k: int = 40, runs: int = 1000, seed: int = 0) -> Any:
    """002 Fig. 5: at step ``k``, Ω_k (solid polygon), P̃ of (72) (dash-dotted), ``[e̲_k, ē_k]``
    (dashed), the box of (42) (dotted) and ``e_k`` of ``runs`` independent runs (dots)."""
    s = error_sets(k, runs, seed)
    fig, ax = _pyplot().subplots(figsize=(6.4, 5.4))
    ax.plot(*s.samples.T, ".", color="0.45", ms=2, label=f"$e_k$, {len(s.samples)} runs")
    poly = zonotope_polygon(s.omega)
    ax.plot(*np.vstack([poly, poly[:1]]).T, "-", color="C0", lw=1.6, label=r"$\Omega_k$")
    par = s.parallelotope()
    ax.plot(*np.vstack([par, par[:1]]).T, "-.", color="C3", lw=1.3, label=r"$\tilde P$ (72)")
    ax.plot(*_box_xy(s.box_reach), "--", color="C0", lw=1.1, label=r"$[\underline{e}_k, \bar e_k]$")
    ax.plot(
        *_box_xy(s.box_transformed),
        ":",
        color="C3",
        lw=1.4,
        label=r"$[\underline{e}^t_k, \bar e^t_k]$ of (42)",
    )
    ax.set_xlabel("$e_1$")
    ax.set_ylabel("$e_2$")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(f"Paper 002, Fig. 5: reachability analysis of the error $e_k$, k = {s.k}")
    fig.tight_layout()
    return fig


# ---------------------------------------------------------------------------------------------
# Paper 003 (Efimov et al.), Section IV
# ---------------------------------------------------------------------------------------------
def paper003_fig1(horizon: int = 50) -> Any:
    """003 Fig. 1: ``x2`` by observer (4) (``interval-transformed``, automatic design: the
    paper's ``R`` is not nonnegative) in (a) and by observer (5) (``interval-split``,
    ``L = (0.3, 0.6)``) in (b)."""
    sc = scenarios.get("efimov-planar", horizon=horizon)
    traj = sc.simulate("paper")
    r4 = _run("interval-transformed", sc, traj, "003 observer (4)")
    r5 = _run("interval-split", sc, traj, "003 observer (5)", L=sc.reference["L"])
    fig, axes = _pyplot().subplots(2, 1, figsize=(8, 5.6), sharex=True)
    plot_estimates(
        {"observer (4), $z = Sx$ (ivobs' design)": r4},
        truth=traj.x,
        states=[1],
        axes=axes[:1],
        title="Paper 003, Fig. 1 (a): $x_2$ by observer (4)",
    )
    plot_estimates(
        {"observer (5), $L = (0.3, 0.6)$": r5},
        truth=traj.x,
        states=[1],
        axes=axes[1:],
        title="(b): $x_2$ by observer (5)",
    )
    axes[0].set_xlabel("")
    fig.tight_layout()
    return fig


def paper003_fig2(horizon: int = 100) -> Any:
    """003 Fig. 2: the Hénon map, interval observer (3) with ``L = (−0.1, 0.1)``, bounds of the
    nonlinear term from the measurement (Remark 1)."""
    sc = scenarios.get("henon", horizon=horizon)
    traj = sc.simulate("paper")
    res = _run("interval", sc, traj, "003 Hénon observer (3)", L=sc.reference["L"])
    return plot_estimates(
        {"observer (3), $L = (-0.1, 0.1)$": res},
        truth=traj.x,
        title="Paper 003, Fig. 2: Hénon map with uncertain $a(t)$",
    )


# ---------------------------------------------------------------------------------------------
# Paper 004 (Dinh & Tran, arXiv 2405.06445): KKL observers, with and without disturbances
# ---------------------------------------------------------------------------------------------
def _quiet(sysm: LinearSystem) -> LinearSystem:
    """The same system with zero disturbance bounds (the paper's "absence of d and w")."""
    zero = Box(np.zeros(sysm.nd), np.zeros(sysm.nd))
    return LinearSystem(sysm.A, sysm.B, sysm.C, D=sysm.D, E=sysm.E, F=sysm.F, d=zero, dt=sysm.dt)


def _kkl_run(sc: scenarios.Scenario, disturbed: bool, **options: Any) -> tuple[Estimate, Any, Any]:
    """The ``kkl`` method on the scenario, disturbed (paper signals, bounds known) or not (zero
    signals and the observer told so); returns the estimate, trajectory and design."""
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
    est = make_estimator("kkl", system, x0=sc.x0, **options)
    res = est.run(traj.u, traj.y, t=traj.t if system.is_continuous else None)
    what = "with" if disturbed else "without"
    _check(f"004 {sc.name} kkl {what} disturbances", res, traj.x)
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
    """004's style: the state (solid black), upper bound red dashed, lower bound blue dashed."""
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


def paper004_fig1(
    continuous: bool = True, t_final: float = 10.0, dt: float = 0.02, horizon: int = 60
) -> Any:
    """004 Fig. 1 (Example 1): all 8 states of the random system, observer (3) in ``z``
    (equivalent to (6)); absence (top) and presence (bottom) of disturbances. ``continuous``:
    the paper's continuous-time system (``t_final``, samples every ``dt``), else ivobs'
    discrete-time version (``horizon`` steps)."""
    if continuous:
        sc = scenarios.get("kkl-random8", continuous=True, t_final=t_final, dt=dt)
    else:
        sc = scenarios.get("kkl-random8", horizon=horizon)
    fig, axes = _pyplot().subplots(4, 4, figsize=(13, 8.5), sharex=True)
    for block, (res, traj) in enumerate(_kkl_pair(sc)):
        for i in range(8):
            ax = axes[2 * block + i // 4, i % 4]
            _kkl_panel(ax, res, traj, i, legend=(block, i) == (0, 0))
        axes[2 * block, 0].set_title(
            ("absence" if block == 0 else "presence") + " of $(d, w)$", loc="left", fontsize=9
        )
    for ax in axes[-1]:
        ax.set_xlabel("t" if continuous else "k")
    kind = "continuous time" if continuous else "discrete time (ivobs' version)"
    fig.suptitle(f"Paper 004, Fig. 1: Example 1, {kind}, observer (3)")
    fig.tight_layout()
    return fig


def _paper004_x2(sc: scenarios.Scenario, title: str) -> Any:
    fig, axes = _pyplot().subplots(2, 1, figsize=(7.5, 5.2), sharex=True)
    for block, (res, traj) in enumerate(_kkl_pair(sc)):
        _kkl_panel(axes[block], res, traj, 1, legend=block == 0)
        axes[block].set_title(
            ("absence" if block == 0 else "presence") + " of disturbances/noise",
            loc="left",
            fontsize=9,
        )
    axes[-1].set_xlabel("k" if sc.t is None else "t")
    fig.suptitle(title)
    fig.tight_layout()
    return fig


def paper004_fig4(t_final: float = 15.0, dt: float = 0.02) -> Any:
    """004 Fig. 4 (Example 2): the pendulum with varying length (CT LTV), state ``x2 = θ'``,
    observer (10) with ``Ã = diag(−1, −2)``, ``B̃ = (1, 1)``, ``ℓ = 2``; measurements every
    ``dt`` (the sampled-data form of (10), see :mod:`ivobs.estimators.kkl`)."""
    sc = scenarios.get("pendulum", t_final=t_final, dt=dt)
    return _paper004_x2(sc, "Paper 004, Fig. 4: pendulum (CT LTV), $x_2$, observer (10)")


def paper004_fig5(horizon: int = 30) -> Any:
    """004 Fig. 5 (Example 3): the discrete-time LTV system, state ``x2``, observer (15) with
    ``Ã = diag(0.1, 0.2)``, ``B̃ = (1, 1)``, ``γ = 1`` (bounds from ``k* = 2``)."""
    sc = scenarios.get("kkl-ltv-dt", horizon=horizon)
    return _paper004_x2(sc, "Paper 004, Fig. 5: DT LTV system, $x_2$, observer (15)")


# ---------------------------------------------------------------------------------------------
# All of them
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class FigureSpec:
    """One output file: ``paper``, file ``stem`` (``<stem>.png``) and the function drawing it."""

    paper: str
    stem: str
    make: Callable[[], Any]


_SPECS = (
    FigureSpec("001", "paper001_fig1", paper001_fig1),
    FigureSpec("001", "paper001_fig2", paper001_fig2),
    FigureSpec("002", "paper002_fig1", paper002_fig1),
    FigureSpec("002", "paper002_fig2", paper002_fig2),
    FigureSpec("002", "paper002_fig3", paper002_fig3),
    FigureSpec("002", "paper002_fig4", paper002_fig4),
    FigureSpec("002", "paper002_fig5", paper002_fig5),
    FigureSpec("003", "paper003_fig1", paper003_fig1),
    FigureSpec("003", "paper003_fig2", paper003_fig2),
    FigureSpec("004", "paper004_fig1_ct", partial(paper004_fig1, continuous=True)),
    FigureSpec("004", "paper004_fig1_dt", partial(paper004_fig1, continuous=False)),
    FigureSpec("004", "paper004_fig4", paper004_fig4),
    FigureSpec("004", "paper004_fig5", paper004_fig5),
)


def figure_specs(papers: str | Iterable[str] | None = None) -> list[FigureSpec]:
    """The figures of the given papers (``"001"``, ``"2"``, ``"paper003"`` ...; all by default)."""
    if papers is None:
        return list(_SPECS)
    if isinstance(papers, str):
        papers = papers.split(",")
    wanted = []
    for p in papers:
        digits = str(p).strip().lower().removeprefix("paper")
        if not digits.isdigit() or f"{int(digits):03d}" not in PAPERS:
            raise IvobsError(f"papers: expected some of {', '.join(PAPERS)}, got {p!r}")
        wanted.append(f"{int(digits):03d}")
    if not wanted:
        raise IvobsError(f"papers: expected some of {', '.join(PAPERS)}, got none")
    return [s for s in _SPECS if s.paper in wanted]


def generate(
    out_dir: str | os.PathLike[str],
    papers: str | Iterable[str] | None = None,
    *,
    verbose: bool = False,
) -> list[Path]:
    """Draw the figures of ``papers`` (all by default) into ``out_dir`` as ``<stem>.png``;
    return the paths written (``verbose``: print each path and its time). Each figure is closed
    once written; the command line (``ivobs figures``) selects the non-interactive Agg backend."""
    plt = _pyplot()
    specs = figure_specs(papers)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for spec in specs:
        t0 = time.perf_counter()
        fig = spec.make()
        path = out / f"{spec.stem}.png"
        try:
            fig.savefig(path, dpi=DPI)
        finally:
            plt.close(fig)
        paths.append(path)
        if verbose:
            print(f"{path}  ({time.perf_counter() - t0:.1f} s)", flush=True)
    return paths
