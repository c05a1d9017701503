"""[Tang2019, Section VII], Figs. 1-5: the servo motor (Example 1) and Example 2.

Fig. 5 is built from :func:`error_sets` (the sets Ω_k, P̃ of [Tang2019, Theorem 8] and sampled
errors), which tests can check numerically.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, cast

import numpy as np

from ... import scenarios
from ...errors import IvobsError
from ...estimators import make_estimator
from ...model import LinearSystem
from ...result import Estimate
from ...sets import Box, Zonotope, image_bounds, neg, pos
from ...simulate import simulate
from .common import FigureCheckError, check_contains, pyplot, run_checked

__all__ = [
    "ErrorSets",
    "error_sets",
    "in_planar_zonotope",
    "tang2019_fig1",
    "tang2019_fig2",
    "tang2019_fig3",
    "tang2019_fig4",
    "tang2019_fig5",
    "zonotope_polygon",
]


class _TransformedDesign(Protocol):
    """What Fig. 5 reads of ``interval-transformed``'s design: ``z = S x``, ``R = S M S⁻¹``."""

    S: np.ndarray
    R: np.ndarray


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
        name: run_checked(m, sc, traj, f"[Tang2019] servo motor, {name}", L=L)
        for name, (m, L) in runs.items()
    }
    return out, traj, sc


def _compare(
    ax: Any,
    res: dict[str, tuple[Estimate, dict[str, Any]]],
    truth: np.ndarray,
    i: int,
    shift: Any = 0.0,
) -> None:
    """Upper and lower bounds of state ``i`` for each method with its own line style (the
    papers' legends distinguish methods by line style), the truth as asterisks; everything
    minus ``shift``."""
    t = np.arange(truth.shape[0])
    for name, (est, style) in res.items():
        ax.plot(t, est.upper[:, i] - shift, label=name, **style)
        ax.plot(t, est.lower[:, i] - shift, **style)
    ax.plot(t, truth[:, i] - shift, "k*", ms=3.5, label="true state", zorder=5)
    ax.grid(True, alpha=0.3)


_SERVO_STYLES = {  # [Tang2019, Section VII]: solid, dash-dotted (L1); dashed, dotted (L2); the
    # comparison methods thicker, underneath: they nearly coincide with Algorithm 1
    "Algorithm 1, $L_1$": {"ls": "-", "color": "C0", "lw": 1.5, "zorder": 4},
    "zonotope (34), $L_1$": {"ls": "-.", "color": "C2", "lw": 2.6, "alpha": 0.8, "zorder": 3},
    "Algorithm 1, $L_2$": {"ls": "--", "color": "C1", "lw": 1.5, "zorder": 4},
    "interval observer (36), $L_2$": {"ls": ":", "color": "C3", "lw": 2.4, "zorder": 3},
}


def _servo_figure(state: int, horizon: int) -> Any:
    res, traj, sc = _servo_runs(horizon)
    names = sc.state_names or ("θ", "n", "i")
    what = ("Motor position θ", "Motor speed n", "Armature current i")[state]
    fig, ax = pyplot().subplots(figsize=(8, 4))
    _compare(ax, {k: (v, _SERVO_STYLES[k]) for k, v in res.items()}, traj.x, state)
    ax.set_ylabel(names[state])
    ax.set_xlabel("step k (Ts = 0.1 s)")
    ax.legend(fontsize=8, ncol=3)
    ax.set_title(f"[Tang2019] Fig. {state + 1}: {what} and its interval estimations")
    fig.tight_layout()
    return fig


def tang2019_fig1(horizon: int = 100, zoom: tuple[int, int] = (60, 64)) -> Any:
    """[Tang2019, Fig. 1]: servo-motor position θ: Algorithm 1 vs zonotope (L1), vs (36) (L2).

    θ grows to about 37 rad while the bands are 0.17–0.31 rad wide, so drawn like Figs. 2–3
    they collapse onto one line. Top: θ and its interval estimations as in the paper, with an
    inset magnifying steps ``zoom``; bottom: the same bounds minus the true θ (``θ̄_k − θ_k >= 0``
    and ``θ̲_k − θ_k <= 0``), where the bands are as wide as the estimates are, on a scale of
    tenths of a radian. The bottom axes carry the label ``"bounds minus θ"``."""
    res, traj, sc = _servo_runs(horizon)
    styled = {k: (v, _SERVO_STYLES[k]) for k, v in res.items()}
    name = (sc.state_names or ("θ",))[0]
    fig, (top, err) = pyplot().subplots(
        2, 1, figsize=(8, 6.4), sharex=True, gridspec_kw={"height_ratios": [1.0, 1.4]}
    )
    _compare(top, styled, traj.x, 0)
    top.set_ylabel(name)
    top.legend(fontsize=8, ncol=2, loc="upper left")
    top.set_title("[Tang2019] Fig. 1: Motor position θ and its interval estimations")
    k0, k1 = zoom
    if 0 <= k0 < k1 < traj.x.shape[0]:
        ins = top.inset_axes((0.6, 0.13, 0.38, 0.36))
        _compare(ins, styled, traj.x, 0)
        lo = min(float(est.lower[k0 : k1 + 1, 0].min()) for est in res.values())
        hi = max(float(est.upper[k0 : k1 + 1, 0].max()) for est in res.values())
        pad = 0.05 * (hi - lo)
        ins.set_xlim(k0 - 0.3, k1 + 0.3)
        ins.set_ylim(lo - pad, hi + pad)
        ins.tick_params(labelsize=7)
        top.indicate_inset_zoom(ins, edgecolor="0.3")
    _compare(err, styled, traj.x, 0, shift=traj.x[:, 0])
    err.set_ylabel(f"bounds minus {name}")
    err.set_xlabel("step k (Ts = 0.1 s)")
    err.set_title("the same bounds minus the true θ (estimation error bounds)", fontsize=10)
    fig.tight_layout()
    return fig


def tang2019_fig2(horizon: int = 100) -> Any:
    """[Tang2019, Fig. 2]: servo-motor speed n: Algorithm 1 vs zonotope (L1), vs (36) (L2)."""
    return _servo_figure(1, horizon)


def tang2019_fig3(horizon: int = 100) -> Any:
    """[Tang2019, Fig. 3]: armature current i: Algorithm 1 vs zonotope (L1), vs (36) (L2)."""
    return _servo_figure(2, horizon)


def _tang2_options(sc: scenarios.Scenario) -> dict[str, Any]:
    """The paper's design of (42): its ``L``, ``R``, ``e1``, ``e2`` (``S`` by eq. (48))."""
    ref = sc.reference
    return {"L": ref["L"], "R": ref["R"], "e1": ref["e1"], "e2": ref["e2"]}


def tang2019_fig4(horizon: int = 25) -> Any:
    """[Tang2019, Fig. 4] (Example 2): Algorithm 1 (H∞ gain) vs the transformed observer (42),
    with the paper's ``L``, ``R``, ``e1``, ``e2``. ``A`` is unstable (``|λ| = 1.118``) and
    ``u = 0``: the state grows like ``1.118^k``, so a short horizon keeps the bounds' widths
    visible."""
    sc = scenarios.get("tang-example2", horizon=horizon)
    traj = sc.simulate("paper")
    res = {
        "Algorithm 1 (H∞ gain $L$)": (
            run_checked(
                "reachability", sc, traj, "[Tang2019] Ex. 2 Algorithm 1", L=sc.reference["L"]
            ),
            {"ls": "--", "color": "C0", "lw": 1.4, "zorder": 4},
        ),
        "interval observer (42), $z = Sx$": (
            run_checked(
                "interval-transformed", sc, traj, "[Tang2019] Ex. 2 (42)", **_tang2_options(sc)
            ),
            {"ls": "-.", "color": "C3", "lw": 1.3, "zorder": 3},
        ),
    }
    fig, axes = pyplot().subplots(2, 1, figsize=(8, 5.6), sharex=True)
    for i, ax in enumerate(axes):
        _compare(ax, res, traj.x, i)
        ax.set_ylabel(f"$x_{{{i + 1}}}$")
    axes[0].legend(fontsize=8, ncol=3)
    axes[-1].set_xlabel("step k")
    axes[0].set_title(
        "[Tang2019] Fig. 4: $x_k$ and its interval estimations by Algorithm 1 and (42)"
    )
    fig.tight_layout()
    return fig


@dataclass(frozen=True)
class ErrorSets:
    """The sets of [Tang2019, Fig. 5] ([Tang2019, Theorem 8]) at step ``k``, in error
    coordinates ``e = x − x̂``.

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
    vertices: np.ndarray = start + np.cumsum(steps, axis=1).T  # the last one is ``start`` again
    return vertices


def in_planar_zonotope(Z: Zonotope, pts: np.ndarray, rtol: float = 1e-9) -> np.ndarray:
    """Exact membership in a planar zonotope: its facets are normal to its generators."""
    G = Z.generators[:, np.any(Z.generators != 0.0, axis=0)]
    N = np.vstack([-G[1], G[0]])  # normals (2, m)
    h = np.abs(N.T @ G).sum(axis=1)  # support in each normal direction
    v = np.abs((pts - Z.center) @ N)
    inside: np.ndarray = np.all(v <= h * (1 + rtol) + 1e-15, axis=1)
    return inside


def error_sets(k: int = 40, runs: int = 1000, seed: int = 0) -> ErrorSets:
    """The sets of [Tang2019, Fig. 5] on Example 2 at step ``k``, with ``runs`` independent runs.

    Algorithm 1 and observer (42) both use the paper's ``L`` (Theorem 8: same gain, same prior
    box ``x0 = <p0, H0>``). With ``M = A − LC``, ``G = E − LF``, ``d = c + diag(r) δ``::

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
    assert isinstance(sys, LinearSystem)
    rng = np.random.default_rng(seed)
    x0s = sc.x0.sample(runs, rng)
    trajs = [simulate(sys, x0s[j], sc.u, sc.disturbance("uniform", seed=rng)) for j in range(runs)]
    X = np.stack([tr.x for tr in trajs])
    Y = np.stack([tr.y for tr in trajs])
    U = np.broadcast_to(sc.u, (runs, *sc.u.shape))
    L = sc.reference["L"]
    reach = make_estimator("reachability", sys, x0=sc.x0, L=L)
    trans = make_estimator(  # observer (42) as in the paper: no finite-memory bound
        "interval-transformed", sys, x0=sc.x0, finite_memory=False, **_tang2_options(sc)
    )
    r_res, t_res = reach.run(U, Y), trans.run(U, Y)
    check_contains("[Tang2019, Fig. 5] Algorithm 1 (batch)", r_res, X)
    check_contains("[Tang2019, Fig. 5] observer (42) (batch)", t_res, X)
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

    design = cast(_TransformedDesign, trans.design)
    S, R = design.S, design.R
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
    """The relations [Tang2019, Fig. 5] illustrates ([Tang2019, Theorem 8]); see
    :func:`error_sets`."""
    k = sets.k
    hull = sets.omega.interval_hull()
    p_lo, p_hi = image_bounds(np.linalg.inv(sets.S), sets.pz_lo, sets.pz_hi)  # Box(P̃)
    scale = 1e-9 * (1.0 + np.abs(t_res.upper[:, k]).max())
    Sv = zonotope_polygon(sets.omega) @ sets.S.T  # S times the vertices of Ω_k

    def is_box(res: Estimate, lo: np.ndarray, hi: np.ndarray) -> bool:
        """Whether every run's box at step ``k``, minus ``x̂_k``, is ``[lo, hi]``."""
        got = np.stack([res.lower[:, k] - xhat, res.upper[:, k] - xhat])
        want = np.stack([np.broadcast_to(lo, xhat.shape), np.broadcast_to(hi, xhat.shape)])
        return bool(np.allclose(got, want, rtol=0.0, atol=scale))

    checks = {
        "Algorithm 1's box is Box(Ω_k) (eq. 26)": is_box(r_res, hull.lo, hull.hi),
        "observer (42)'s box is Box(P̃) (eq. 79)": is_box(t_res, p_lo, p_hi),
        "every sampled e_k lies in Ω_k": bool(in_planar_zonotope(sets.omega, sets.samples).all()),
        "Ω_k ⊆ P̃ (eq. 74)": bool(np.all((Sv >= sets.pz_lo - scale) & (Sv <= sets.pz_hi + scale))),
    }
    failed = [name for name, ok in checks.items() if not ok]
    if failed:
        raise FigureCheckError(f"[Tang2019, Fig. 5]: failed: {'; '.join(failed)} (a bug in ivobs)")


def _box_xy(b: Box) -> tuple[list[float], list[float]]:
    return (
        [b.lo[0], b.hi[0], b.hi[0], b.lo[0], b.lo[0]],
        [b.lo[1], b.lo[1], b.hi[1], b.hi[1], b.lo[1]],
    )


def tang2019_fig5(k: int = 40, runs: int = 1000, seed: int = 0) -> Any:
    """[Tang2019, Fig. 5]: at step ``k``, Ω_k (solid polygon), P̃ of (72) (dash-dotted),
    ``[e̲_k, ē_k]`` (dashed), the box of (42) (dotted) and ``e_k`` of ``runs`` independent runs
    (dots)."""
    s = error_sets(k, runs, seed)
    fig, ax = pyplot().subplots(figsize=(6.4, 5.4))
    ax.plot(*s.samples.T, ".", color="0.45", ms=2, label=f"$e_k$, {len(s.samples)} runs")
    poly = zonotope_polygon(s.omega)
    ax.plot(*np.vstack([poly, poly[:1]]).T, "-", color="C0", lw=1.6, label=r"$\Omega_k$")
    par = s.parallelotope()
    ax.plot(*np.vstack([par, par[:1]]).T, "-.", color="C3", lw=1.3, label=r"$\tilde P$ (72)")
    ax.plot(*_box_xy(s.box_reach), "--", color="C0", lw=1.1, label=r"$[\underline{e}_k, \bar e_k]$")
    label = r"$[\underline{e}^t_k, \bar e^t_k]$ of (42)"
    ax.plot(*_box_xy(s.box_transformed), ":", color="C3", lw=1.4, label=label)
    ax.set_xlabel("$e_1$")
    ax.set_ylabel("$e_2$")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(f"[Tang2019] Fig. 5: reachability analysis of the error $e_k$, k = {s.k}")
    fig.tight_layout()
    return fig
