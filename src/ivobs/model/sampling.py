"""Sampled-data models of a continuous-time :class:`~ivobs.LinearSystem` (docs/continuous.md).

The plant ``x' = A x + B u + E d``, ``y = C x + D u + F d`` is sampled every ``Ts``; the input
``u`` is held over each period (zero-order hold: it is commanded). Over one period

    x(t+Ts) = e^{A Ts} x(t) + ∫_0^Ts e^{A s} ds B u + ∫_0^Ts e^{A s} E d(t + Ts − s) ds.

**Held disturbances** (``disturbances="held"``): ``d`` constant over each period, the last term
is ``Γ E d`` with ``Γ = ∫_0^Ts e^{A s} ds`` — the classical model [VanLoan1978]. Physical
disturbances (wind, load torque, flow) are not held: a ``d(t)`` that switches sign inside a
period reaches states that no held value reaches, and an estimator built on the held model can
lose the true state.

**Varying disturbances** (the default): the last term ranges over the Aumann integral
``S = {∫_0^Ts e^{A s} E d(s) ds : d measurable, d(s) ∈ [d]}``, a convex set ([Aubin1984],
the reachable set of one period from ``0``). ``[0, Ts]`` is cut into ``N`` pieces
``P_k = [k h, (k+1) h]``, ``h = Ts / N``; on each, with ``G_k = ∫_{P_k} e^{A s} ds E`` and the
mean ``d̄_k = (1/h) ∫_{P_k} d(s) ds ∈ [d]`` (the box is convex),

    ∫_{P_k} e^{A s} E d(s) ds = Ĝ_k d̄_k + (G_k − Ĝ_k) c + ∫_{P_k} (e^{A s} E − Ĝ_k / h) δ(s) ds

for any matrix ``Ĝ_k`` (the double nearest ``G_k``), ``d = c + δ``, ``|δ| <= r`` (centre and
radius of ``[d]``): the last two terms are at most ``ρ_k = |G_k − Ĝ_k| |c| + K_k r`` with
``K_k = ∫_{P_k} |e^{A s} E − Ĝ_k / h| ds`` (elementwise). So ``S ⊆ Σ_k Ĝ_k [d] ⊕ [−ρ, ρ]``,
``ρ = Σ_k ρ_k``: the discrete model has one disturbance per piece and per process disturbance
(the mean of ``d`` over the piece, in ``[d]``) and one per state (the remainder, in
``[−ρ, ρ]``). ``K_k`` is bounded by cutting ``P_k`` into ``S`` intervals ``J`` and enclosing
``e^{A J} E`` by validated exponentials of interval matrices (:mod:`ivobs.sets.expm`):
``∫_J |X − g| <= |J| max_{X ∈ [X]} |X − g|``. The remainder shrinks as ``h²``.

**First moments.** The same identity holds with a second generator per piece, ``Ĥ_k μ_k`` for
the first moment ``μ_k = (1/h) ∫_{P_k} P₁ d`` (``P₁ = 2σ/h − 1`` on the piece, so
``|μ_k| <= r/2``): the remainder is then ``∫ |e^{A s} E − Ĝ_k/h − (Ĥ_k/h) P₁|`` (any ``Ĥ_k``
keeps the bound; the projection of ``e^{A s} E`` on ``P₁`` makes it third order). It helps
where the effect of ``d`` turns fast within a period (an unstable plant at a slow rate).

**The automatic choice** (``pieces=None``) takes, among ``N`` = 1, 2, 4, 8 pieces with and
without moments, the one with the fewest disturbances whose set is within
:data:`SUPPORT_EXCESS` of the exact set in every direction tried (support functions against a
fine quadrature of ``∫ |ℓ e^{A s} E| r``), else the tightest.

The measurement sees ``d`` at the sampling instant, which the integral does not constrain: a
disturbance that enters both ``E`` and ``F`` gets separate columns for its means and its sample.
``e^{A Ts}`` and ``Γ B`` are the doubles nearest their validated enclosures (relative error
within a few units of rounding); ``interval_matrices=True`` makes them interval matrices that
contain the exact ones, for the methods that accept interval matrices (docs/uncertain.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_bool
from ..errors import IvobsError
from ..sets import Box
from ..sets.expm import expm, expm_integral, interval_product, scaled
from ..sets.rounding import UNIT_ROUNDOFF, down, mid_rad, product_error, up, upper

__all__ = [
    "DISTURBANCES",
    "MAX_PIECES",
    "SUPPORT_EXCESS",
    "Sampled",
    "check_options",
    "period_hull",
    "sample",
]

DISTURBANCES = ("varying", "held")
"""How disturbances behave between samples: any measurable signal in the box, or held."""
MAX_PIECES = 8
"""Most pieces chosen automatically (each adds one disturbance per process disturbance)."""
SUPPORT_EXCESS = 0.15
"""Largest excess of the model's disturbance set over the exact one (support functions)
accepted by the automatic choice of pieces."""
SUBINTERVALS = 16
"""Intervals per piece over which the remainder's integral is bounded."""


@dataclass
class Sampled:
    """The matrices and bounds of a sampled model (``x+ = A x + B u + E d``, ``y = C x + D u +
    F d``, ``d ∈ d``; ``A``, ``B`` interval matrices as Boxes when asked), the names of its
    disturbances (None: those of the continuous system) and how it was sampled."""

    A: Any
    B: Any
    E: np.ndarray | None
    F: np.ndarray | None
    d: Any
    disturbance_names: tuple[str, ...] | None
    sampling: dict[str, Any]


def check_options(Ts: Any, disturbances: Any, pieces: Any, interval_matrices: Any) -> float:
    """``Ts`` as a float, after checking the options of ``discretize``."""
    if isinstance(Ts, bool) or not isinstance(Ts, (int, float)) or not 0 < Ts < math.inf:
        raise IvobsError(f"Ts: expected a sampling period > 0, got {Ts!r}")
    if disturbances not in DISTURBANCES:
        raise IvobsError(
            f"disturbances: expected 'varying' (any signal in the box between samples) or "
            f"'held' (constant over each period), got {disturbances!r}"
        )
    as_bool("interval_matrices", interval_matrices)
    if pieces is not None and (
        isinstance(pieces, bool)
        or not isinstance(pieces, (int, np.integer))
        or not 1 <= pieces <= 64
        or pieces & (pieces - 1)
    ):
        raise IvobsError(f"pieces: expected None or a power of two in [1, 64], got {pieces!r}")
    return float(Ts)


def sample(
    A: np.ndarray,
    B: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    d: Any,
    Ts: float,
    disturbances: str,
    pieces: int | None,
    interval_matrices: bool,
    names: Any,
) -> Sampled:
    """The sampled model of ``x' = A x + B u + E d`` (module docstring); ``names``: the
    continuous system's :class:`~ivobs.model.statespace.SignalNames`."""
    nx, nd = A.shape[0], E.shape[1]
    if disturbances == "held" or nd == 0:
        (Ad, RA), (BE, RBE) = expm_integral(A, np.hstack([B, E]), Ts)
        nu = B.shape[1]
        A_m, B_m = _matrices(Ad, RA, BE[:, :nu], RBE[:, :nu], interval_matrices)
        info = {"Ts": Ts, "disturbances": disturbances, "pieces": 1, "moments": False}
        return Sampled(A_m, B_m, BE[:, nu:] if nd else None, F if nd else None, d, None, info)
    if not isinstance(d, Box):
        raise IvobsError(
            "d: disturbances that vary between samples need their bounds as a Box (constant "
            "or per step); bounds computed from the measurement hold only at the samples: "
            "discretize(Ts, disturbances='held')"
        )
    if not d.is_bounded:
        raise IvobsError("d: varying disturbances need finite bounds")
    (Ad, RA), (GB, RB) = expm_integral(A, B, Ts)
    process = np.flatnonzero(np.any(E != 0.0, axis=0))
    n_pieces, moments, gens, K, RG = _choose(A, E[:, process], d, Ts, pieces, process)
    shared = [j for j in process if np.any(F[:, j] != 0.0)]
    own = [j for j in process if j not in shared]
    lo, hi = np.asarray(d.lo, dtype=float), np.asarray(d.hi, dtype=float)
    cols_E = [np.zeros(nx)] * nd
    cols_F = [F[:, j] for j in range(nd)]
    los, his = [lo[..., j] for j in range(nd)], [hi[..., j] for j in range(nd)]
    dnames = list(names.disturbances or [f"d{j + 1}" for j in range(nd)])
    pos = {j: i for i, j in enumerate(process)}
    c = 0.5 * lo[..., process] + 0.5 * hi[..., process]
    r = up(np.maximum(hi[..., process] - c, c - lo[..., process]))

    def add(col: np.ndarray, low: Any, high: Any, name: str) -> None:
        """A new disturbance of the sampled model: its column of ``E``, bounds and name."""
        cols_E.append(col)
        cols_F.append(np.zeros(F.shape[0]))
        los.append(low)
        his.append(high)
        dnames.append(name)

    for j in own:
        cols_E[j] = gens[0][0][:, pos[j]]
    for k in range(n_pieces):
        for j in process:
            if not (k == 0 and j in own):
                add(gens[k][0][:, pos[j]], lo[..., j], hi[..., j],
                    f"{dnames[j]} (mean over piece {k + 1})")  # fmt: skip
        for j in process if moments else ():  # the first moment of d over the piece: ±r/2
            half = up(0.5 * r[..., pos[j]])
            add(gens[k][1][:, pos[j]], -half, half, f"{dnames[j]} (moment over piece {k + 1})")
    rho = upper(r @ K.T + np.abs(c) @ RG.T, 2 * len(process) + 2)
    keep = np.flatnonzero(np.any(rho > 0.0, axis=0) if rho.ndim == 2 else rho > 0.0)
    for i in keep:
        state = f"x{i + 1}" if names.states is None else names.states[i]
        add(np.eye(nx)[:, i], -rho[..., i], rho[..., i], f"remainder {state}")
    box = Box(np.stack(los, axis=-1), np.stack(his, axis=-1))
    A_m, B_m = _matrices(Ad, RA, GB, RB, interval_matrices)
    info = {"Ts": Ts, "disturbances": "varying", "pieces": n_pieces, "moments": moments}
    E_d, F_d = np.column_stack(cols_E), np.column_stack(cols_F)
    return Sampled(A_m, B_m, E_d, F_d, box, tuple(dnames), info)


def _matrices(Ad: Any, RA: Any, GB: Any, RB: Any, interval: bool) -> tuple[Any, Any]:
    if not interval:
        return Ad, GB
    Bm = Box(GB - RB, GB + RB) if GB.size and np.any(RB > 0.0) else GB
    return Box(Ad - RA, Ad + RA), Bm


def _choose(
    A: np.ndarray, E: np.ndarray, d: Box, Ts: float, pieces: Any, process: np.ndarray
) -> tuple[int, bool, list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
    """``(N, moments, [(Ĝ_k, Ĥ_k)], K, R_G)``: the pieces, whether their first moments are
    generators, the generators, ``K = Σ_k K_k`` and ``R_G = Σ_k |G_k − Ĝ_k|`` bounds (module
    docstring). ``pieces`` given: those pieces, their means only. Else the candidate with the
    fewest disturbances whose set is within :data:`SUPPORT_EXCESS` of the exact one in every
    direction tried (:func:`_excess`), or the tightest."""
    lo, hi = np.asarray(d.lo, dtype=float), np.asarray(d.hi, dtype=float)
    lo, hi = lo[..., process], hi[..., process]
    r = np.max(np.atleast_2d(0.5 * hi - 0.5 * lo), axis=0)
    c = np.max(np.atleast_2d(np.abs(0.5 * hi + 0.5 * lo)), axis=0)
    if pieces is not None:
        return (int(pieces), False, *_pieces(A, E, Ts, int(pieces), False))
    candidates = sorted(
        ((n, mom) for n in (1, 2, 4, 8) for mom in (False, True)),
        key=lambda nm: (nm[0] * (1 + nm[1]), not nm[1]),
    )
    kernel = _kernel(A, E, Ts)
    best: Any = None
    for n, mom in candidates:
        gens, K, RG = _pieces(A, E, Ts, n, mom)
        excess = _excess(gens, K @ r + RG @ c, r, kernel, Ts)
        if best is None or excess < best[0]:
            best = (excess, n, mom, gens, K, RG)
        if excess <= SUPPORT_EXCESS:
            return n, mom, gens, K, RG
    return best[1], best[2], best[3], best[4], best[5]


def _kernel(A: np.ndarray, E: np.ndarray, Ts: float) -> np.ndarray:
    """``e^{A s} E`` at the midpoints of 128 intervals of ``[0, Ts]`` (floats: the choice of
    pieces only, not a bound)."""
    from scipy.linalg import expm as _expm

    n = 128
    step = _expm(A * (Ts / n))
    K = _expm(A * (Ts / (2 * n))) @ E
    out = [K]
    for _ in range(n - 1):
        out.append(step @ out[-1])
    return np.array(out)


def _excess(
    gens: list[tuple[np.ndarray, np.ndarray]],
    rho: np.ndarray,
    r: np.ndarray,
    kernel: np.ndarray,
    Ts: float,
) -> float:
    """How much the model's set of one period's disturbance effect exceeds the exact one: the
    largest ratio of support functions, ``Σ_k |ℓ Ĝ_k| r + |ℓ Ĥ_k| r/2 + |ℓ|₁ ρ`` against
    ``∫ |ℓ e^{As} E| r ds``, over the coordinate axes and 32 fixed directions, minus 1. A thin
    direction of the set counts as much as a wide one: the measurements often pin the wide
    ones, and the estimates then live in the thin ones."""
    n = rho.shape[0]
    rng = np.random.default_rng(0)
    dirs = np.vstack([np.eye(n), rng.normal(size=(32, n))])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    model = np.zeros(len(dirs))
    for G, H in gens:
        model += np.abs(dirs @ G) @ r + 0.5 * np.abs(dirs @ H) @ r
    model += np.abs(dirs) @ rho
    exact = np.abs(np.einsum("dn,snm->dsm", dirs, kernel)).sum(axis=1) @ r * (Ts / len(kernel))
    keep = exact > 1e-300 * max(1.0, float(np.max(exact)))
    return float(np.max(model[keep] / exact[keep]) - 1.0) if keep.any() else 0.0


def _pieces(
    A: np.ndarray, E: np.ndarray, Ts: float, N: int, moments: bool
) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray]:
    """For ``N`` pieces of ``[0, Ts]``: the generators ``(Ĝ_k, Ĥ_k)`` of the mean and of the
    first moment, ``Σ_k K_k`` and ``Σ_k |G_k − Ĝ_k|`` (upper bounds; module docstring)."""
    n, m = E.shape
    h = Ts / N  # exact: N is a power of two (an underflow is caught below)
    s = h / SUBINTERVALS
    if h * N != Ts or s * SUBINTERVALS != h or s == 0.0:
        raise IvobsError(f"Ts: {Ts!r} is too small to be cut into {N} pieces")
    (Ph, RPh), (Gh, RGh) = expm_integral(A, E, h)  # e^{A h}, ∫_0^h e^{A s} ds E
    Ps, RPs = expm(*scaled(A, s))
    W, RW = interval_product(*expm(*scaled(A, (0.0, s))), E, None)  # e^{A [0, s]} E
    V, RV = [W], [RW]  # e^{A j s} e^{A [0, s]} E, j < SUBINTERVALS
    for _ in range(SUBINTERVALS - 1):
        Vj, RVj = interval_product(Ps, RPs, V[-1], RV[-1])
        V.append(Vj)
        RV.append(RVj)
    # P1 = 2 σ / h − 1 on interval j of a piece: centre p_j, radius 1 / SUBINTERVALS (exact)
    p1 = -1.0 + (2.0 * np.arange(SUBINTERVALS) + 1.0) / SUBINTERVALS
    p1_rad = 1.0 / SUBINTERVALS
    P, RP = np.eye(n), np.zeros((n, n))  # e^{A k h}
    gens: list[tuple[np.ndarray, np.ndarray]] = []
    K = np.zeros((n, m))
    RG = np.zeros((n, m))
    for _ in range(N):
        G, RGk = interval_product(P, RP, Gh, RGh)
        RG = up(RG + RGk)
        X = [interval_product(P, RP, Vj, RVj) for Vj, RVj in zip(V, RV)]  # e^{A (k h + J)} E
        g = G / h  # within one rounding of the exact G / h
        # K1: the L2 projection of e^{A s} E on P1 (any matrix keeps the bound sound)
        k1 = 3.0 / SUBINTERVALS * sum(Xj * pj for (Xj, _), pj in zip(X, p1))
        k1 = k1 if moments else np.zeros_like(k1)
        gens.append((G, k1 * h))
        slack = (np.abs(g) + np.abs(k1)) * 2.0**-50
        total = np.zeros((n, m))
        for (Xj, RXj), pj in zip(X, p1):
            total = total + (up(np.abs(Xj - g - k1 * pj)) + RXj + np.abs(k1) * p1_rad + slack)
        K = up(K + up(upper(total, SUBINTERVALS * 4) * s))
        P, RP = interval_product(P, RP, Ph, RPh)
    if not (np.all(np.isfinite(K)) and np.all(np.isfinite(RG))):
        raise IvobsError(
            "discretize: the disturbance's effect over one period could not be bounded "
            "(the exponential overflowed); use a smaller Ts"
        )
    return gens, K, RG


def period_hull(
    A: np.ndarray,
    B: np.ndarray,
    E: np.ndarray,
    d: Any,
    Ts: float,
    lo: np.ndarray,
    hi: np.ndarray,
    u: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Boxes ``(lo, hi)`` (shape ``(T, nx)``) containing ``x(t_k + τ)`` for every ``τ`` in
    ``[0, Ts]`` and every path from ``x(t_k) ∈ [lo_k, hi_k]`` with ``u_k`` held and ``d(t)``
    anywhere in its box (``d``: a Box, constant or per step, or None without disturbances).

    On each of :data:`SUBINTERVALS` intervals ``J`` of ``[0, Ts]``, with ``τ ∈ J``:
    ``x(t_k + τ) = e^{A τ} x_k + Γ(τ) B u_k + Γ(τ) E c + ∫_0^τ e^{A s} E δ(τ − s) ds``
    (``d = c + δ``, ``|δ| <= r``), whose first three terms lie in validated enclosures over
    ``J`` (:func:`~ivobs.sets.expm.expm_integral` with ``t = J``) applied to the boxes, and the
    last within ``∫_0^{max J} |e^{A s} E| ds r``; the hull of the ``J`` boxes is returned."""
    n = A.shape[0]
    T = lo.shape[0]
    c, rx = mid_rad(lo, hi)
    nd = E.shape[1] if d is not None else 0
    if nd:
        dl = np.broadcast_to(np.asarray(d.lo, dtype=float)[:T], (T, nd))
        dh = np.broadcast_to(np.asarray(d.hi, dtype=float)[:T], (T, nd))
        cd, rd = mid_rad(dl, dh)
    M = np.hstack([B, E]) if nd else B
    step = Ts / SUBINTERVALS
    out_lo = np.full((T, n), np.inf)
    out_hi = np.full((T, n), -np.inf)
    spread = np.zeros((n, nd))  # ∫_0^{end of J} |e^{A s} E| ds, rounded up
    for j in range(SUBINTERVALS):
        a, b = j * step, (Ts if j == SUBINTERVALS - 1 else (j + 1) * step)
        (P, RP), (G, RG) = expm_integral(A, M, (down(a) if a else 0.0, up(b)))
        if nd:
            W, RW = interval_product(*expm(*scaled(A, (down(a) if a else 0.0, up(b)))), E, None)
            spread = up(spread + up(upper(np.abs(W) + RW, 2) * up(b - a)))
        # e^{A τ} x: |P c − e^{Aτ} x| <= |P| r + RP (|c| + r) + rounding of P c
        mid = c @ P.T
        rad = np.abs(c) @ RP.T + rx @ up(np.abs(P) + RP).T
        rad = rad + product_error(np.abs(c) @ np.abs(P).T, n)
        GB, RGB = G[:, : B.shape[1]], RG[:, : B.shape[1]]
        if GB.size:
            mid = mid + u @ GB.T
            rad = rad + np.abs(u) @ RGB.T + product_error(np.abs(u) @ np.abs(GB).T, GB.shape[1])
        if nd:
            GE, RGE = G[:, B.shape[1] :], RG[:, B.shape[1] :]
            mid = mid + cd @ GE.T
            rad = rad + np.abs(cd) @ RGE.T + product_error(np.abs(cd) @ np.abs(GE).T, nd)
            rad = rad + rd @ spread.T
        rad = upper(rad, 4 * n + 2 * nd + 8) + 8 * np.abs(mid) * UNIT_ROUNDOFF  # the sums
        out_lo = np.minimum(out_lo, down(mid - rad))
        out_hi = np.maximum(out_hi, up(mid + rad))
    return out_lo, out_hi
