"""Questions to a constrained zonotope ``<c, G, A, b>`` answered by linear programs in its
factors ``ξ``: interval hull, emptiness and membership ([Scott2016]).

Every bound is certified by weak duality, so it holds whatever the solver returns: for any
multipliers ``μ``,

    min {gᵀξ : A ξ = b, ‖ξ‖∞ <= r}  >=  μᵀb − r ‖g − Aᵀμ‖₁                              (W)

evaluated with the proven bounds of its rounding (:mod:`ivobs.sets.rounding`) — safe bounds
from an approximate dual, as in [Neumaier2004]. The multipliers are HiGHS's row duals
(:class:`~ivobs.sets.lp.LinearProgram`). Emptiness is claimed only with a certificate checked
the same way. :class:`Certificates` keeps the multipliers of the hull's bounds, so that a
reduction can tell what it loosens.
"""

from __future__ import annotations

import threading
from functools import cache

import numpy as np

from ..lp import LinearProgram, csc
from ..rounding import down, product_error, up, upper
from .tolerances import EMPTY_TOL

__all__ = [
    "Certificates",
    "certified_empty",
    "dual_bounds",
    "hull_bounds",
    "hull_certificates",
    "radius_certificate",
    "reaches",
    "soften",
]


def dual_bounds(
    Gs: np.ndarray, A: np.ndarray, b: np.ndarray, mu: np.ndarray, radius: float = 1.0
) -> np.ndarray:
    """Lower bounds of ``min {g_iᵀξ : A ξ = b, ‖ξ‖∞ <= radius}`` for every row ``g_i`` of
    ``Gs`` from any multipliers ``μ_i`` (rows of ``mu``): (W) in exact arithmetic.

    Proof. ``r_i = g_i − Aᵀμ_i`` is a dot product of ``nc + 1`` terms, so its computed value is
    within ``ε_r = γ_{nc+1} (|g_i| + |A|ᵀ|μ_i|)`` of the exact one (:func:`product_error`);
    hence ``‖r_i‖₁ <= Σ_j (|fl(r_ij)| + ε_rj)``, a sum of nonnegative terms bounded by
    :func:`upper`. ``μ_iᵀb`` is within ``γ_{nc} |μ_i|ᵀ|b|`` of its computed value. The bound is
    ``fl(μᵀb) − (e_b + radius ‖r‖₁)``, the subtracted sum rounded up and the difference rounded
    down (:func:`up`, :func:`down`)."""
    nc, m = A.shape
    am = np.abs(mu)
    R = Gs - mu @ A
    err_r = product_error(np.abs(Gs) + am @ np.abs(A), nc + 1)
    l1 = upper(np.abs(R).sum(axis=1) + err_r.sum(axis=1), 2 * m)
    e_b = product_error(am @ np.abs(b), nc)
    out: np.ndarray = down(mu @ b - up(e_b + up(radius * l1)))
    return out


def reaches(A: np.ndarray, b: np.ndarray, tol: float) -> bool:
    """Whether ``A ξ = b`` has a solution with ``‖ξ‖∞ <= 1 + tol`` by HiGHS's optimum of
    :func:`radius_certificate` (the membership test of a point in a (constrained) zonotope: for
    checks, not a proof); with no column, whether ``|b| <= tol``."""
    if A.shape[1] == 0:
        return bool(np.all(np.abs(b) <= tol))
    return radius_certificate(A, b)[0] <= 1.0 + tol


def radius_certificate(A: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """``(r, r_low)``: HiGHS's value of ``r* = min {‖ξ‖∞ : A ξ = b}`` (``inf`` when it finds no
    solution, ``0`` on solver trouble) and a lower bound of ``r*`` proven in floating point.

    The set ``<c, G, A, b>`` is empty exactly when ``r* > 1``. Every ``μ`` gives
    ``r* >= μᵀb / ‖Aᵀμ‖₁`` (``μᵀb = μᵀA ξ <= ‖Aᵀμ‖₁ ‖ξ‖∞``); ``r_low`` is this ratio at the
    program's row duals (or, when ``A ξ = b`` has no solution at all, at the least-squares
    residual ``μ = b − A ξ_ls``, for which ``Aᵀμ ≈ 0``), the numerator rounded down and the
    denominator up with the bounds of their rounding. ``0`` when no certificate is found:
    emptiness is then never claimed."""
    nc, m = A.shape
    if nc == 0:
        return 0.0, 0.0
    if m == 0:
        return (0.0, 0.0) if bool(np.all(b == 0)) else (float("inf"), float("inf"))
    # variables (ξ, s): min s  s.t.  A ξ = b,  −s <= ξ_j <= s  (rows ξ_j − s <= 0, ξ_j + s >= 0)
    eye, ones = np.eye(m), np.ones((m, 1))
    M = np.block([[A, np.zeros((nc, 1))], [eye, -ones], [eye, ones]])
    inf = np.full(m, np.inf)
    row_lo = np.concatenate([b, -inf, np.zeros(m)])
    row_hi = np.concatenate([b, np.zeros(m), inf])
    lp = LinearProgram(presolve=True)
    lo, hi = np.concatenate([-inf, [0.0]]), np.concatenate([inf, [np.inf]])
    cost = np.zeros(m + 1)
    cost[-1] = 1.0
    lp.load(csc(M), M.shape[0], lo, hi, row_lo, row_hi, cost)
    status = lp.solve()
    if status == "infeasible":
        r = float("inf")
        mu = b - A @ np.linalg.lstsq(A, b, rcond=None)[0]
    elif status == "optimal":
        r = lp.objective()
        lam = lp.row_duals()
        if lam is None or not np.isfinite(lam[:nc]).all():
            return r, 0.0
        mu = lam[:nc]
    else:  # numerical trouble: do not claim emptiness
        return 0.0, 0.0
    am = np.abs(mu)
    num = float(down(mu @ b - product_error(am @ np.abs(b), nc)))
    den = float(upper(np.abs(A.T @ mu).sum() + product_error(np.abs(A).T @ am, nc).sum(), 2 * m))
    if not num > 0.0:
        return r, 0.0
    if den == 0.0:
        return r, float("inf")
    return r, float(down(num / den))


def certified_empty(A: np.ndarray, b: np.ndarray) -> bool:
    """Whether ``<c, G, A, b>`` is certainly empty, with a margin: even the set with the larger
    box ``‖ξ‖∞ <= 1 + EMPTY_TOL`` is empty (:func:`radius_certificate`)."""
    return radius_certificate(A, b)[1] > 1.0 + EMPTY_TOL


BLOCK_SIZE = 2000
"""Largest ``K m`` (objectives times factors) whose ``K`` programs :func:`_multipliers` solves
as one block program; larger ones are solved as warm-started chains. HiGHS has a fixed cost per
solve (tens of µs), which dominates small programs (one solve of the block pays it once); a
large block solved from scratch costs more than ``K`` warm-started solves."""

_LOCAL = threading.local()


def _solver(i: int) -> LinearProgram:
    """The ``i``-th reused program of this thread (its HiGHS object outlives the step)."""
    lps: list[LinearProgram] | None = getattr(_LOCAL, "lps", None)
    if lps is None:
        lps = _LOCAL.lps = [LinearProgram(), LinearProgram()]
    return lps[i]


def _load(
    lp: LinearProgram, A: np.ndarray, b: np.ndarray, radius: float, cost: np.ndarray, K: int = 1
) -> None:
    """``K`` copies of ``{A ξ = b, ‖ξ‖∞ <= radius}`` side by side (block diagonal)."""
    nc, m = A.shape
    start, index, value = csc(A)
    if K > 1:
        nnz = index.size
        start = np.concatenate([start[:-1] + i * nnz for i in range(K)] + [[K * nnz]])
        index = np.concatenate([index + i * nc for i in range(K)])
        value = np.tile(value, K)
        b = np.tile(b, K)
    r = np.full(K * m, radius)
    lp.load((start, index, value), K * nc, -r, r, b, b, cost)


def _multipliers(
    Gs: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    radius: float,
    chains: list[list[int]],
    warm: bool = False,
    points: bool = False,
) -> tuple[np.ndarray, np.ndarray] | None:
    """Row duals ``μ`` (K, nc) of the ``K`` programs ``min {g_iᵀξ : A ξ = b, ‖ξ‖∞ <= radius}``
    (zero where no solver finds them: the bound of the set without constraints, valid too)
    and, if ``points``, the solver's optimal points ``ξ`` (K, m; NaN where it has none or
    when not asked for: these are for estimates, never for bounds), or None when HiGHS calls
    the set infeasible.

    Small programs (``K m <=`` :data:`BLOCK_SIZE`) are solved as one block program,
    ``min Σ_i g_iᵀξ_i`` over ``K`` independent copies, whose row duals are those of the ``K``
    programs. Larger ones share one model per chain of objectives (``chains``), only the cost
    changing along a chain, each solve warm-started from the previous optimum by the primal
    simplex (that basis stays feasible; the dual simplex would first have to repair its dual
    infeasibility). ``warm``: the chains' models already hold this program (the chains just
    solved on it), and go on from their last optimum. A program the
    shared model fails on is retried from a cold start, then by :func:`_second_opinion`."""
    K, m = Gs.shape
    nc = A.shape[0]
    mu = np.zeros((K, nc))
    xs = np.full((K, m), np.nan)
    if K * m <= BLOCK_SIZE and not warm:
        lp = _solver(0)
        _load(lp, A, b, radius, Gs.ravel(), K)
        status = lp.solve()
        lam = lp.row_duals() if status == "optimal" else None
        if lam is not None and np.isfinite(lam).all():
            return lam.reshape(K, nc), lp.primal().reshape(K, m) if points else xs
        chains = [list(range(K))]
        shared = False
    else:
        shared = True
    cols = np.arange(m)
    for n_chain, rows in enumerate(chains):
        lp = _solver(n_chain % 2)
        if shared and not warm:
            _load(lp, A, b, radius, np.zeros(m))
        primal = True
        for i in rows:
            lam = None
            if shared:
                lp.set_cost(cols, Gs[i])
                # only the cost changed, so the last basis is still feasible: the primal
                # simplex from it is fastest when the next optimum is near (tank30: 6 iterations
                # a solve, against 10 for the dual simplex); when a solve after the chain's first
                # takes more than nc iterations, the optima are far apart (dense random systems:
                # 280 against 96) and the rest of the chain uses the dual simplex
                status = lp.solve(primal=primal)
                if primal and i != rows[0] and lp.iterations() > nc:
                    primal = False
                if status != "optimal":
                    lp.cold()
                    status = lp.solve()
                lam = lp.row_duals() if status == "optimal" else None
                if lam is not None and points:
                    xs[i] = lp.primal()
            if lam is None or not np.isfinite(lam).all():
                lam, infeasible = _second_opinion(Gs[i], A, b, radius)
                if infeasible:
                    return None
            if lam is not None:
                mu[i] = lam
    return mu, xs


_SECOND_OPINIONS: tuple[dict[str, bool], ...] = ({"presolve": True}, {}, {"ipm": True})
"""Fresh HiGHS models tried in turn for a program the shared one failed on: on the
ill-conditioned programs of a set pinned down by its constraints, a warm start can stall or
call a feasible program infeasible; presolve, a cold start or the interior point method usually
succeed. Any multipliers give a valid bound, so a failure only loosens that bound."""


def _second_opinion(
    g: np.ndarray, A: np.ndarray, b: np.ndarray, radius: float
) -> tuple[np.ndarray | None, bool]:
    """The multipliers of one program from fresh models (:data:`_SECOND_OPINIONS`), or None;
    and whether every model calls it infeasible."""
    infeasible = True
    for options in _SECOND_OPINIONS:
        lp = LinearProgram(**options)
        _load(lp, A, b, radius, g)
        status = lp.solve()
        lam = lp.row_duals() if status == "optimal" else None
        if lam is not None and np.isfinite(lam).all():
            return lam, False
        infeasible &= status == "infeasible"
    return None, infeasible


def _certified_mins(
    Gs: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    radius: float,
    chains: list[list[int]],
    warm: bool = False,
    points: bool = False,
) -> tuple[np.ndarray, np.ndarray, bool, np.ndarray]:
    """:func:`dual_bounds` of every row of ``Gs`` at the solver's multipliers: ``(bounds,
    μ (K, nc), feasible, ξ (K, m))``; ``feasible`` False when HiGHS calls the set infeasible;
    ``ξ`` the solver's optimal points (NaN where it has none; with no constraint, the
    minimisers over the box); ``warm`` and ``points`` as in :func:`_multipliers`."""
    K, nc = Gs.shape[0], A.shape[0]
    if nc == 0 or K == 0:
        return -radius * np.abs(Gs).sum(axis=1), np.zeros((K, nc)), True, -radius * np.sign(Gs)
    out = _multipliers(Gs, A, b, radius, chains, warm, points)
    if out is None:
        return np.full(K, np.nan), np.zeros((K, nc)), False, np.full(Gs.shape, np.nan)
    mu, xs = out
    return dual_bounds(Gs, A, b, mu, radius), mu, True, xs


@cache
def _hull_chains(n: int, k: int) -> list[list[int]]:
    """Two warm-start chains over the rows ``[G; -G; P; -P]`` (``G`` n rows, ``P`` k rows):
    the minima in order, the maxima in reverse order (neighbouring objectives have close optima,
    opposite ones do not)."""
    lo = list(range(n)) + list(range(2 * n, 2 * n + k))
    hi = list(range(2 * n - 1, n - 1, -1)) + list(range(2 * n + 2 * k - 1, 2 * n + k - 1, -1))
    return [lo, hi]


def hull_bounds(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Certified interval hull of ``<c, G, A, b>``, or ``None`` when the set is certainly
    empty. See :func:`hull_certificates`."""
    out = hull_certificates(c, G, A, b)
    return None if out is None else (out[0], out[1])


def hull_certificates(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    extra: np.ndarray | None = None,
    extra_map: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, Certificates] | None:
    """Certified interval hull ``[lo, hi]`` of ``<c, G, A, b>`` and the certificates of its
    ``2 n`` bounds (weighted by the inverse width of each coordinate, so that losses are
    relative), or ``None`` when the set is certainly empty (:func:`certified_empty`).

    ``lo = c + min_ξ G_iξ`` with both terms proven (:func:`dual_bounds`) and the sum rounded
    down; ``hi`` likewise, rounded up.

    ``extra`` (n', m): more objectives in the factors whose bounds the certificates should
    also keep (the rows ``P`` and ``-P`` are appended, weighted by the inverse widths of
    ``P ξ``); the filter passes the hull of its prediction, ``[A G, E R]``. With
    ``extra_map = M`` (n', n), ``P = M G + Q`` (``Q`` in the factors of no row of ``G``, as
    ``[A G, E R]`` is with ``M = A``), and a box too large for one block program
    (:data:`BLOCK_SIZE`, so that every bound is a solve of its own), the bounds of ``±P`` are
    first certified by combining the box's multipliers and solved only where that is far
    from their optimum (:func:`_combined_mins`).

    When HiGHS calls the set infeasible without a certificate of it (a set that is thin, or
    empty only by rounding), the bounds are those of a *softened* superset, so still sound:
    first each constraint relaxed by a slack factor (:data:`RELAXATIONS`; ``cert.slack``), else
    the box ``‖ξ‖∞ <= ρ``, ``ρ = max(1, r*) (1 + EMPTY_TOL)`` (``r*`` the smallest feasible
    radius found; ``cert.radius``). The caller keeps that larger set (:func:`soften`,
    :attr:`Certificates.softened`).
    """
    n = G.shape[0]
    P = np.zeros((0, G.shape[1])) if extra is None else extra
    k = P.shape[0]
    Gs = np.concatenate([G, -G, P, -P])
    chains = _hull_chains(n, k)
    if extra_map is not None and k and 2 * G.size > BLOCK_SIZE:
        vals, mu, ok = _combined_mins(Gs, A, b, n, extra_map)
    else:
        vals, mu, ok, _ = _certified_mins(Gs, A, b, 1.0, chains)
    radius, slack = 1.0, None
    if not ok:
        r, r_low = radius_certificate(A, b)
        if r_low > 1.0 + EMPTY_TOL:
            return None
        row_size = np.abs(b) + np.abs(A).sum(axis=1)
        for tol in RELAXATIONS:  # each row relaxed by a slack factor: a superset, still thin
            slack = up(tol * row_size)
            Gs_r, A_r = with_slacks(Gs, A, slack)
            vals, mu, ok, _ = _certified_mins(Gs_r, A_r, b, 1.0, chains)
            if ok:
                Gs = Gs_r
                break
    if not ok:  # the box of the factors widened until HiGHS finds the set feasible
        slack = None
        radius = float(up((max(1.0, r) if np.isfinite(r) else 1.0) * (1.0 + EMPTY_TOL)))
        vals, mu, ok, _ = _certified_mins(Gs, A, b, radius, chains)
        if not ok:  # HiGHS contradicting itself: the bound of the zonotope (μ = 0 is valid)
            mu = np.zeros_like(mu)
            vals = dual_bounds(Gs, A, b, mu, radius)
    lo = down(c + vals[:n])
    hi = up(c - vals[n : 2 * n])
    width = np.maximum(hi - lo, 1e-12 * (1.0 + np.abs(c)))
    weight = [1.0 / width, 1.0 / width]
    if k:
        p_width = -(vals[2 * n : 2 * n + k] + vals[2 * n + k :])
        p_width = np.maximum(p_width, 1e-12 * (1.0 + np.abs(P).sum(axis=1)))
        weight += [1.0 / p_width, 1.0 / p_width]
    return lo, hi, Certificates(Gs, mu, np.concatenate(weight), radius, slack)


COMBINED_GAP = 0.05
"""A bound of ``±P`` (``extra`` of :func:`hull_certificates`) keeps the certificate combined
from the box's (:func:`_combined_mins`) when it is within this fraction of the spread of
``P ξ`` over the box's optimal points from the best of them; the others are solved for. The
bounds of ``P`` only guide the elimination: on ``cora-tank30`` 0.01 solves 44 % of them,
0.05 3 %, with widths within 1 % of solving all. Taking every combination unchecked is as
tight on random dense plants, but not where the plant turns its coordinates (two copies of
``cora-vehicle6`` side by side: 1.29x the exact hull instead of 1.0004x)."""


def _combined_mins(
    Gs: np.ndarray, A: np.ndarray, b: np.ndarray, n: int, M: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`_certified_mins` of ``Gs = [G; −G; P; −P]`` with ``P = M G + Q`` (``Q`` on
    factors in no row of ``G``), solving only the ``2 n`` programs of the box and those of
    ``±P`` whose combined certificate is not good enough.

    Any multipliers give a valid bound (W), so those of ``±P_i`` may be combined from the box's,
    ``Σ_j M_ij⁺ μ_{+j} + M_ij⁻ μ_{−j}`` for ``+P_i`` (the mirror for ``−P_i``): at least the
    bound of ``M`` times the hull. Where the plant mixes the coordinates (``cora-vehicle6``)
    that bound is far from the optimum; the box's ``2 n`` optimal points, all in the set, show
    how far (``min_l P_i ξ_l`` is at or above the optimum), and a bound whose gap exceeds
    :data:`COMBINED_GAP` of the spread of ``P_i ξ_l`` is solved for instead."""
    vals, mu, ok, xs = _certified_mins(Gs[: 2 * n], A, b, 1.0, _hull_chains(n, 0), points=True)
    if not ok:
        return vals, mu, False
    pos, neg = np.maximum(M, 0.0), np.maximum(-M, 0.0)
    plus, minus = mu[:n], mu[n:]
    mu_p = np.concatenate([pos @ plus + neg @ minus, pos @ minus + neg @ plus])
    Ps = Gs[2 * n :]
    v_p = dual_bounds(Ps, A, b, mu_p)
    seen = xs[np.isfinite(xs).all(axis=1)]
    if seen.shape[0]:
        reach = Ps @ seen.T  # (2k, points)
        inner = reach.min(axis=1)
        bad = inner - v_p > COMBINED_GAP * (reach.max(axis=1) - inner)
    else:
        bad = np.ones(Ps.shape[0], dtype=bool)
    if bad.any():  # solved on from the box's two chains (minima, then maxima)
        idx = np.flatnonzero(bad)
        half = int(np.count_nonzero(idx < Ps.shape[0] // 2))
        chains = [list(range(half)), list(range(half, idx.size))]
        v2, mu2, ok2, _ = _certified_mins(Ps[idx], A, b, 1.0, chains, warm=True)
        if not ok2:
            return np.full(Gs.shape[0], np.nan), np.zeros((Gs.shape[0], A.shape[0])), False
        better = v2 > v_p[idx]
        v_p[idx] = np.where(better, v2, v_p[idx])
        mu_p[idx] = np.where(better[:, None], mu2, mu_p[idx])
    return np.concatenate([vals, v_p]), np.concatenate([mu, mu_p]), True


RELAXATIONS = (1e-10, 1e-8)
"""Relative slacks tried in turn when HiGHS calls a set infeasible that it cannot prove empty
(:func:`hull_certificates`): each constraint ``i`` gets a slack factor of size
``tol (|b_i| + ‖A_i‖₁)``. A set pinned down by its constraints to widths near the solver's
tolerances is then feasible for it, and its hull widens by about the slack; the fallback,
widening the factors' box to the solver's smallest feasible radius, can multiply the widths
when that radius is found inaccurately on such ill-conditioned programs."""


def with_slacks(G: np.ndarray, A: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[G 0]``, ``[A diag(s)]`` on the rows with ``s > 0``: the constraints
    ``A ξ + diag(s) η = b``, ``‖η‖∞ <= 1`` (a slack factor per such row, in no generator)."""
    live = np.flatnonzero(s > 0)
    S = np.zeros((A.shape[0], live.size))
    S[live, np.arange(live.size)] = s[live]
    G = np.concatenate([G, np.zeros((G.shape[0], live.size))], axis=1)
    return G, np.concatenate([A, S], axis=1)


def soften(
    G: np.ndarray, A: np.ndarray, radius: float = 1.0, slack: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The softened set of :func:`hull_certificates` (``cert.radius``, ``cert.slack``) with the
    unit box of factors: ``{c + G ξ : ‖ξ‖∞ <= radius, A ξ + diag(slack) η = b, ‖η‖∞ <= 1}`` as
    ``G radius``, ``A radius`` plus the rounding of these products: ``e = product_error(|G'| 1,
    1)`` per row of ``G`` (the returned box, at ``|ξ| <= 1``) and a slack factor per
    constraint, which also carries ``slack`` (``[G' 0]``, ``[A' diag(s)]``)."""
    if radius != 1.0:
        G, A = G * radius, A * radius
        e = product_error(np.abs(G).sum(axis=1), 1)
        s = product_error(np.abs(A).sum(axis=1), 1)
    else:
        e, s = np.zeros(G.shape[0]), np.zeros(A.shape[0])
    if slack is not None:
        s = up(s + slack)
    return (*with_slacks(G, A, s), e)


LOSS_CANDIDATES = 12
"""Candidates whose exact elimination loss :meth:`Certificates.elimination_loss` evaluates
(those with the smallest upper bound of it). More cost ``O(K m)`` each per elimination; fewer
may miss the factor that loosens the box least."""


class Certificates:
    """Dual certificates of some linear bounds of ``<c, G, A, b>``, kept valid through reduction.

    Row ``i`` certifies ``min_ξ D_iᵀξ >= μ_iᵀb - ρ ‖D_i - Aᵀμ_i‖₁`` (``D`` (K, m): objectives in
    the factors ``ξ``, ``μ`` (K, nc): multipliers, ``ρ``: ``radius``, the factors' box the
    certificates assume, 1 unless the set was softened by :func:`hull_certificates`). Each
    reparametrisation of the set (row scaling, rescaling, elimination of a factor) maps the
    objectives and multipliers so that the certificates keep meaning the same linear functions
    of ``x``. What a reduction step does to the certified bounds is then known before it is
    taken: :meth:`elimination_loss` is the loosening, weighted by ``weight`` (K,), of every
    bound if factor ``j`` were eliminated. This is how the estimators choose what to eliminate
    (the bounds of the box they report stay as tight as possible), instead of the shape-only
    Hausdorff heuristic of [Scott2016, Section 4.2], which only breaks ties here.
    """

    __slots__ = ("_dt", "_rct", "mu", "radius", "slack", "weight")

    def __init__(
        self,
        D: np.ndarray,
        mu: np.ndarray,
        weight: np.ndarray,
        radius: float = 1.0,
        slack: np.ndarray | None = None,
    ):
        self.mu, self.weight, self.radius = mu, weight, radius
        self.slack = slack  # the rows' slack factors of a relaxed set (hull_certificates)
        # D and the reduced costs are kept by factor (m, K): an elimination removes a factor
        # and the losses gather the factors of a pivot row, both contiguous that way
        self._dt = np.ascontiguousarray(D.T)
        self._rct: np.ndarray | None = None  # (D - mu A)ᵀ, once asked for (reduced_costs)

    @property
    def D(self) -> np.ndarray:
        """The objectives ``D`` (K, m) in the current factors."""
        return self._dt.T

    @property
    def softened(self) -> bool:
        """Whether the certificates are those of a softened superset of the set asked about
        (:func:`hull_certificates`), which the caller must then keep (:func:`soften`)."""
        return self.radius != 1.0 or self.slack is not None

    def reduced_costs(self, A: np.ndarray) -> np.ndarray:
        """``D − μ A`` (K, m), kept up to date through the eliminations (each changes it by a
        rank-one term, where recomputing it costs ``K nc m``). Coefficients that the
        elimination moves to a slack as noise (below ``ZERO_TOL`` of their row) are not taken
        out of it: these reduced costs only guide the choice of factor."""
        return self._reduced_t(A).T

    def _reduced_t(self, A: np.ndarray) -> np.ndarray:
        """:meth:`reduced_costs` by factor (m, K)."""
        if self._rct is None:
            self._rct = self._dt - A.T @ self.mu.T
        return self._rct

    def keep(self, rows: np.ndarray, cols: np.ndarray) -> None:
        """Constraints ``rows`` and factors ``cols`` are kept (masks; the others were zero)."""
        if not rows.all():
            self.mu = self.mu[:, rows]
            self._rct = None
        if not cols.all():
            self._dt = self._dt[cols]
            if self._rct is not None:
                self._rct = self._rct[cols]

    def pad(self, n_cols: int) -> None:
        """``n_cols`` new factors, in no objective."""
        self._dt = np.concatenate([self._dt, np.zeros((n_cols, self._dt.shape[1]))])
        self._rct = None

    def scale_rows(self, s: np.ndarray) -> None:
        """Constraint ``r`` was divided by ``s_r`` (the reduced costs do not change)."""
        self.mu = self.mu * s

    def scale_factors(self, rad: np.ndarray) -> None:
        """Factor ``j`` was rescaled, ``ξ_j = m_j + rad_j ξ'_j`` (offsets go to constants)."""
        self._dt = self._dt * rad[:, None]
        if self._rct is not None:
            self._rct = self._rct * rad[:, None]

    def elimination_loss(
        self, A: np.ndarray, b: np.ndarray, piv: np.ndarray, cand: np.ndarray
    ) -> np.ndarray:
        """Weighted loosening of the certified bounds if factor ``j`` is eliminated with row
        ``piv[j]`` (for every ``j``; ``inf`` outside the candidates ``cand``). The multipliers
        move to ``μ + (r_j / a_pj) e_p`` so that the reduced cost ``r = D - Aᵀμ`` of ``ξ_j``,
        whose box is dropped, becomes zero.

        The exact loss costs ``O(K m)`` per candidate; it is evaluated for the
        :data:`LOSS_CANDIDATES` candidates with the smallest upper bound
        ``Σ_k w_k |t_kj| (‖A_p‖₁ + |b_p|)`` (``|r - t a| - |r| <= |t| |a|``)."""
        m = A.shape[1]
        RT = self._reduced_t(A)  # (m, K)
        apj = A[piv, np.arange(m)]
        apj = np.where(apj != 0, apj, 1.0)
        row_size = np.abs(A).sum(axis=1) + np.abs(b)
        bound = (np.abs(RT) @ self.weight) / np.abs(apj) * row_size[piv]
        idx = cand.nonzero()[0]
        if idx.size > LOSS_CANDIDATES:
            idx = idx[np.argsort(bound[idx], kind="stable")[:LOSS_CANDIDATES]]
        out = np.full(m, np.inf)
        t = RT[idx] / apj[idx, None]  # (c, K): multiplier change per candidate
        # only the factors where the pivot row is nonzero change: Σ over them of
        # |R_k - t_k a_p| - |R_k|, the candidates' supports side by side
        which, col = np.nonzero(A[piv[idx]])
        starts = np.searchsorted(which, np.arange(idx.size))
        R = RT[col]
        moved = t[which]
        moved *= A[piv[idx][which], col, None]
        np.subtract(R, moved, out=moved)
        np.abs(moved, out=moved)
        moved -= np.abs(R, out=R)
        change = np.add.reduceat(moved, starts, axis=0) - t * b[piv[idx], None]
        out[idx] = change @ self.weight
        return out

    def eliminate(self, A: np.ndarray, j: int, p: int) -> None:
        """Factor ``j`` eliminated with row ``p``; both are removed here. The objectives
        become ``D − D_j A_p / a_pj`` and the reduced costs ``r − (r_j / a_pj) A_p``; row ``p``
        is zero after the elimination, so its multiplier no longer matters."""
        rct = self._reduced_t(A)
        rows, cols = np.arange(A.shape[0]) != p, np.arange(A.shape[1]) != j
        row = A[p, cols, None] / A[p, j]
        self._dt = self._dt[cols] - row * self._dt[j]
        self._rct = rct[cols] - row * rct[j]
        self.mu = self.mu[:, rows]
