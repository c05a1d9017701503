"""Constrained zonotopes (Scott, Raimondo, Marseglia & Braatz 2016, Automatica 69).

A constrained zonotope is

    Z = <c, G, A, b> = {c + G ξ : ‖ξ‖∞ <= 1, A ξ = b}          (Scott et al. 2016, Definition 3)

with center ``c`` (n,), generators ``G`` (n, m), constraints ``A`` (nc, m), ``b`` (nc,). Every
convex polytope is one (Theorem 1), and unlike zonotopes they are closed under intersection, so a
set-membership filter that works with them is exact: the linear map, the Minkowski sum and the
(generalised) intersection are all exact and cheap (Proposition 1 of the paper):

* ``M Z = <M c, M G, A, b>``
* ``Z ⊕ W = <c_z + c_w, [G_z G_w], blkdiag(A_z, A_w), [b_z; b_w]>``
* ``Z ∩_R Y = <c_z, [G_z 0], [[A_z, 0], [0, A_y], [R G_z, -G_y]], [b_z; b_y; c_y - R c_z]>``

What is not cheap is asking a question of the set: its interval hull, emptiness and membership
are linear programs (solved here with HiGHS, ``scipy.optimize.linprog``). Each bound is certified
by LP duality: for any multiplier ``μ``, ``min {gᵀξ : Aξ = b, |ξ| <= 1} >= μᵀb - ‖g - Aᵀμ‖₁``; the
returned bound is this expression at HiGHS' multipliers, so it is a valid bound whatever the
solver's tolerances (it equals the optimum when ``μ`` is optimal).

The complexity (``m`` generators, ``nc`` constraints) grows with every Minkowski sum and
intersection; :meth:`ConstrainedZonotope.reduce` bounds it (Section 4 of the paper): constraint
elimination after rescaling (4.2), then generator reduction of the lifted zonotope (4.3). Both
return a superset. The array-level functions (:func:`eliminate_constraints`,
:func:`reduce_generators`, :func:`hull_certificates`) are what the ``constrained-zonotope``
estimator uses; :class:`Certificates` lets the elimination keep the LP bounds the estimator
reports as tight as possible (see its docstring).

Rounding. Constraints are normalised (largest coefficient 1); constraints made of rounding noise
(all coefficients below :data:`_ROW_TOL` after cancellation or rescaling) and linearly dependent
constraints are dropped (a superset); propagated factor bounds are widened by ``1e-10``
(relative); a set counts as empty only beyond :data:`EMPTY_TOL`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import qr
from scipy.optimize import linprog
from scipy.sparse import block_diag, csr_matrix

from ._validate import as_float_array, as_matrix, as_vector, check_finite
from .errors import InconsistentDataError, IvobsError
from .linalg import UNIT_ROUNDOFF, gamma
from .sets import Box, Zonotope

__all__ = [
    "UNIT_ROUNDOFF",
    "Certificates",
    "ConstrainedZonotope",
    "box_generators",
    "certified_empty",
    "consolidate_small",
    "eliminate_constraints",
    "gamma",
    "hull_bounds",
    "hull_certificates",
    "independent_constraints",
    "radius_certificate",
    "reduce_generators",
    "safe_radius",
]

def safe_radius(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(c, r)`` with ``[lo, hi] ⊆ [c - r, c + r]`` in exact arithmetic: ``c = (lo + hi)/2``
    and ``r = (hi - lo)/2`` are rounded, so ``r`` is enlarged by ``γ_3 (|c| + r)``; ``r = 0``
    (and ``c = lo`` exactly) where ``lo = hi``."""
    c = 0.5 * (lo + hi)
    r = 0.5 * (hi - lo)
    return c, np.where(hi > lo, r + gamma(3) * (np.abs(c) + r), 0.0)


def box_generators(r: np.ndarray) -> np.ndarray:
    """The box ``[-r, r]`` as generator columns ``diag(r)``, only the nonzero ones (a box of
    rounding errors appended to a zonotope's generators)."""
    nz = np.flatnonzero(r > 0)
    out = np.zeros((r.shape[0], nz.size))
    out[nz, np.arange(nz.size)] = r[nz]
    return out


EMPTY_TOL = 1e-7
"""A constrained zonotope counts as empty when its constraints need ``‖ξ‖∞ > 1 + EMPTY_TOL``."""

_ZERO = 1e-13  # relative size below which a generator or constraint entry counts as zero
_ROW_TOL = 1e-9
"""A constraint whose coefficients are all below this (relative) is dropped (a superset): after
cancellation or rescaling it carries rounding noise, which row normalisation would amplify."""
_PIVOT_TOL = 1e-6  # smallest pivot (constraints normalised to a largest coefficient of 1)


# --------------------------------------------------------------------------------------------
# Linear programs (HiGHS), certified by duality
# --------------------------------------------------------------------------------------------
def _certified_min(
    g: np.ndarray, A: np.ndarray, b: np.ndarray, radius: float = 1.0
) -> tuple[float, np.ndarray, bool]:
    """A lower bound of ``min {gᵀξ : A ξ = b, ‖ξ‖∞ <= radius}``, its multipliers ``μ`` and
    whether the set is nonempty.

    The bound is the Lagrangian dual ``μᵀb - radius ‖g - Aᵀμ‖₁`` at HiGHS' equality multipliers
    ``μ`` (any ``μ`` gives a valid bound; the optimal one gives the optimum). When HiGHS reports
    infeasibility, ``(nan, 0, False)``; on any other solver failure ``μ = 0`` (the bound of the
    zonotope without constraints), never an unsound number.
    """
    nc = A.shape[0]
    mu = np.zeros(nc)
    if nc == 0:
        return -radius * float(np.abs(g).sum()), mu, True
    infeasible = 0
    for method, options in _LP_ATTEMPTS:
        res = linprog(
            g, A_eq=A, b_eq=b, bounds=(-radius, radius), method=method, options=options
        )
        if res.status == 0 and getattr(res, "eqlin", None) is not None:
            marg = np.asarray(res.eqlin.marginals, dtype=float)
            if marg.shape == mu.shape and np.all(np.isfinite(marg)):
                mu = marg
                break
        infeasible += res.status == 2
    else:
        if infeasible == len(_LP_ATTEMPTS):
            return float("nan"), mu, False
    return float(_dual_bounds(g[None, :], A, b, mu[None, :], radius)[0]), mu, True


_LP_ATTEMPTS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("highs", {}),
    ("highs", {"presolve": False}),
    ("highs-ipm", {}),
)
"""HiGHS configurations tried in turn for one bound: on the ill-conditioned programs of a set
pinned down by its constraints, HiGHS' presolve sometimes fails (status 4) or calls a feasible
program infeasible; without presolve, or with the interior point method, it usually succeeds.
Any multiplier gives a valid bound, so a failure only loosens that bound."""


def _dual_bounds(
    Gs: np.ndarray, A: np.ndarray, b: np.ndarray, mu: np.ndarray, radius: float
) -> np.ndarray:
    """``μ_iᵀb - radius ‖g_i - Aᵀμ_i‖₁`` for every row, lowered by the bound
    ``γ_{nc+m+3} (|μ_i|ᵀ|b| + radius (‖g_i‖₁ + |μ_i|ᵀ|A| 1))`` of its rounding: a lower bound of
    ``min {g_iᵀξ : A ξ = b, ‖ξ‖∞ <= radius}`` in exact arithmetic, whatever ``μ``."""
    nc, m = A.shape
    am = np.abs(mu)
    err = gamma(nc + m + 3) * (
        am @ np.abs(b) + radius * (np.abs(Gs).sum(axis=1) + am @ np.abs(A).sum(axis=1))
    )
    return mu @ b - radius * np.abs(Gs - mu @ A).sum(axis=1) - err * (1.0 + gamma(4))


def radius_certificate(A: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """``(r, r_low)``: HiGHS' value of ``r* = min {‖ξ‖∞ : A ξ = b}`` (``inf`` when it finds no
    solution, ``0`` on solver trouble) and a lower bound of ``r*`` certified in floating point.

    The set ``<c, G, A, b>`` is empty exactly when ``r* > 1``. By duality, every ``μ`` gives
    ``r* >= μᵀb / ‖Aᵀμ‖₁`` (``μᵀb = μᵀA ξ <= ‖Aᵀμ‖₁ ‖ξ‖∞``); ``r_low`` is this ratio at the
    LP's equality multipliers (or, when ``A ξ = b`` has no solution at all, at the
    least-squares residual ``μ = b - A ξ_ls``, for which ``Aᵀμ ≈ 0``), with the numerator
    lowered and the denominator raised by the ``γ_n`` bounds of their rounding. ``0`` when no
    certificate is found: emptiness is then never claimed.
    """
    nc, m = A.shape
    if nc == 0:
        return 0.0, 0.0
    if m == 0:
        ok = bool(np.all(b == 0))
        return (0.0, 0.0) if ok else (float("inf"), float("inf"))
    # variables (ξ, s): min s  s.t.  A ξ = b,  ξ - s <= 0,  -ξ - s <= 0
    eye = np.eye(m)
    ones = np.ones((m, 1))
    A_ub = np.vstack([np.hstack([eye, -ones]), np.hstack([-eye, -ones])])
    cost = np.zeros(m + 1)
    cost[-1] = 1.0
    res = linprog(
        cost,
        A_ub=A_ub,
        b_ub=np.zeros(2 * m),
        A_eq=np.hstack([A, np.zeros((nc, 1))]),
        b_eq=b,
        bounds=[(None, None)] * m + [(0, None)],
        method="highs",
    )
    if res.status == 2:
        r = float("inf")
        mu = b - A @ np.linalg.lstsq(A, b, rcond=None)[0]
    elif res.status == 0:
        r = float(res.x[-1])
        mu = np.asarray(getattr(res.eqlin, "marginals", np.zeros(nc)), dtype=float)
        if mu.shape != (nc,) or not np.all(np.isfinite(mu)):
            return r, 0.0
    else:  # numerical trouble: do not claim emptiness
        return 0.0, 0.0
    am = np.abs(mu)
    num = float(mu @ b) - gamma(nc + 1) * float(am @ np.abs(b))
    den = float(np.abs(A.T @ mu).sum()) + gamma(nc + m + 1) * float(am @ np.abs(A).sum(axis=1))
    den *= 1.0 + gamma(2)
    if not num > 0.0:
        return r, 0.0
    if den == 0.0:
        return r, float("inf")
    return r, num / den * (1.0 - gamma(2))


def certified_empty(A: np.ndarray, b: np.ndarray) -> bool:
    """Whether ``<c, G, A, b>`` is certainly empty, with a margin: even the set with the larger
    box ``‖ξ‖∞ <= 1 + EMPTY_TOL`` is empty (:func:`radius_certificate`)."""
    return radius_certificate(A, b)[1] > 1.0 + EMPTY_TOL


def _feasibility_radius(A: np.ndarray, b: np.ndarray) -> float:
    """``min {‖ξ‖∞ : A ξ = b}`` (``inf`` when ``A ξ = b`` has no solution): one LP.

    The set ``<c, G, A, b>`` is empty exactly when this exceeds 1.
    """
    nc, m = A.shape
    if m == 0 and nc:
        return 0.0 if np.all(np.abs(b) <= _ZERO * (1.0 + np.abs(b))) else float("inf")
    return radius_certificate(A, b)[0]


def _certified_mins(
    Gs: np.ndarray, A: np.ndarray, b: np.ndarray, radius: float = 1.0
) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`_certified_min` for every row ``g_i`` of ``Gs``: ``(bounds, μ (K, nc), feasible)``.

    The independent programs are solved as one block-diagonal LP (one HiGHS call: the per-call
    overhead dominates programs this small); should HiGHS fail on the big program (or call it
    infeasible), they are solved one by one (degenerate, over-determined or ill-conditioned
    constraints can fool it; see :data:`_LP_ATTEMPTS`).
    """
    K, nc = Gs.shape[0], A.shape[0]
    if nc == 0 or K == 0:
        return -radius * np.abs(Gs).sum(axis=1), np.zeros((K, nc)), True
    A_blk = block_diag([csr_matrix(A)] * K, format="csr")
    res = linprog(
        Gs.ravel(), A_eq=A_blk, b_eq=np.tile(b, K), bounds=(-radius, radius), method="highs"
    )
    mu = np.zeros((K, nc))
    if res.status == 0 and getattr(res, "eqlin", None) is not None:
        marg = np.asarray(res.eqlin.marginals, dtype=float)
        if marg.size == K * nc and np.all(np.isfinite(marg)):
            mu = marg.reshape(K, nc)
            return _dual_bounds(Gs, A, b, mu, radius), mu, True
    vals = np.empty(K)
    for i in range(K):
        vals[i], mu[i], ok = _certified_min(Gs[i], A, b, radius)
        if not ok:
            return np.full(K, np.nan), np.zeros((K, nc)), False
    return vals, mu, True


def hull_bounds(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Certified interval hull of ``<c, G, A, b>`` (two LPs per coordinate, one HiGHS call), or
    ``None`` when the set is empty. See :func:`hull_certificates`."""
    out = hull_certificates(c, G, A, b)
    return None if out is None else (out[0], out[1])


# --------------------------------------------------------------------------------------------
# Reduction helpers (Scott et al. 2016, Section 4), on raw arrays
# --------------------------------------------------------------------------------------------
def _drop_zero_idx(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Remove (numerically) trivial constraints ``0 ξ = 0`` (all coefficients below
    :data:`_ROW_TOL`: dropping a constraint gives a superset) and generators that are zero in
    ``G`` and ``A`` (exactly: dropping a small one would give a subset).

    Returns ``(c, G, A, b, rows, cols, consistent)``: the masks of the kept constraints and
    generators, and False for a dropped constraint ``a ξ = b`` with ``|b| > ‖a‖₁`` (an empty
    set).
    """
    scale = 1.0 + (np.abs(A).max() if A.size else 0.0)
    rows = np.any(np.abs(A) > _ROW_TOL * scale, axis=1)
    # a dropped row a ξ = b can only hold if |b| <= ‖a‖₁ (up to rounding)
    zb, za = b[~rows], np.abs(A[~rows]).sum(axis=1)
    consistent = bool(np.all(np.abs(zb) <= za + 1e-8 * (1.0 + np.abs(zb))))
    A, b = A[rows], b[rows]
    # only exactly zero generators: fixing a small nonzero ξ_j at 0 would shrink the set
    cols = np.any(G != 0, axis=0) | np.any(A != 0, axis=0)
    return c, G[:, cols], A[:, cols], b, rows, cols, consistent


def _normalise_rows_s(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scale each constraint so that its largest coefficient is 1 (same set, better
    conditioned); also returns the scales."""
    if A.shape[0] == 0:
        return A, b, np.ones(0)
    s = np.abs(A).max(axis=1)
    s[s == 0] = 1.0
    return A / s[:, None], b / s, s


def _propagate(
    A: np.ndarray, b: np.ndarray, sweeps: int = 3
) -> tuple[np.ndarray, np.ndarray] | None:
    """Interval bounds ``[ξL, ξU] ⊆ [-1, 1]^m`` on every ``ξ`` with ``A ξ = b`` (constraint
    propagation, Algorithm 1 of Scott et al. 2016, Section 4.2), or ``None`` when a
    constraint cannot be met (the set is empty).

    Each row ``a ξ = b`` gives ``ξ_j ∈ (b - Σ_{l≠j} a_l [ξ_l]) / a_j``; all rows are applied at
    once and the results intersected (``sweeps`` times). The computed intervals are widened by
    ``1e-10`` (relative) so that rounding never excludes a feasible ``ξ``.
    """
    m = A.shape[1]
    lo = -np.ones(m)
    hi = np.ones(m)
    absA = np.abs(A)
    nz = absA > _ZERO * np.maximum(1.0, absA.max(axis=1, keepdims=True))
    safe = np.where(nz, A, 1.0)
    for _ in range(sweeps):
        t_lo = np.minimum(A * lo, A * hi)
        t_hi = np.maximum(A * lo, A * hi)
        rest_lo = t_lo.sum(axis=1, keepdims=True) - t_lo
        rest_hi = t_hi.sum(axis=1, keepdims=True) - t_hi
        q1 = (b[:, None] - rest_hi) / safe
        q2 = (b[:, None] - rest_lo) / safe
        pad = 1e-10 * (1.0 + np.abs(q1) + np.abs(q2))
        new_lo = np.where(nz, np.minimum(q1, q2) - pad, -np.inf).max(axis=0, initial=-np.inf)
        new_hi = np.where(nz, np.maximum(q1, q2) + pad, np.inf).min(axis=0, initial=np.inf)
        lo = np.maximum(lo, new_lo)
        hi = np.minimum(hi, new_hi)
        if np.any(lo > hi + 1e-9):
            return None
        hi = np.maximum(hi, lo)
    return lo, hi


def _rescale(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The same set with ``ξ = m + diag(r) ξ'``, ``[m - r, m + r]`` the propagated bounds of ξ
    (Scott et al. 2016, Section 4.2): an exact reparametrisation after which more box
    constraints are redundant. Returns ``(c, G, A, b, r)``, or ``None`` when propagation
    proves the set empty."""
    bounds = _propagate(A, b)
    if bounds is None:
        return None
    lo, hi = bounds
    mid = 0.5 * (lo + hi)
    rad = 0.5 * (hi - lo)
    return c + G @ mid, G * rad, A * rad, b - A @ mid, rad


def _elimination_scores(
    G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """For each ``ξ_j``: how far the constraints alone let it leave ``[-1, 1]`` (``R_j``; 0 means
    its box constraint is redundant and eliminating ``ξ_j`` is exact), and an estimate of the
    Hausdorff error of eliminating it (Scott et al. 2016, Section 4.2 and eq. (A.8)).

    ``R_j = max(0, max|ρ_j| - 1)`` with ``ρ_j = ∩_i (b_i - Σ_{l≠j} a_il [-1, 1]) / a_ij``.
    Dropping ``|ξ_j| <= 1`` lets ``ξ_j`` move by about ``R_j`` along the constraints' null
    space; the error estimate is ``‖G δ_j‖₂`` for the shortest such move
    ``δ_j = R_j P e_j / P_jj`` (``P`` the projector onto the null space of ``A``), computed
    for all ``j`` from one QR factorisation of ``Aᵀ``.
    """
    m = A.shape[1]
    absA = np.abs(A)
    tol = _ZERO * max(1.0, float(absA.max()) if absA.size else 1.0)
    nz = absA > tol
    safe = np.where(nz, A, 1.0)
    spread = (absA.sum(axis=1, keepdims=True) - absA) / np.abs(safe)
    mid = b[:, None] / safe
    rho_lo = np.where(nz, mid - spread, -np.inf).max(axis=0, initial=-np.inf)
    rho_hi = np.where(nz, mid + spread, np.inf).min(axis=0, initial=np.inf)
    R = np.maximum(0.0, np.maximum(-1.0 - rho_lo, rho_hi - 1.0))  # inf: ξ_j is unconstrained
    err = np.full(m, np.inf)
    cand = np.isfinite(R)
    exact = cand & (R <= 1e-3)
    if np.any(exact):
        err[exact] = 0.0
        return R, err
    Q = np.linalg.qr(A.T)[0]  # orthonormal basis of the row space of A
    Pjj = 1.0 - np.einsum("ij,ij->i", Q, Q)
    GP = G - (G @ Q) @ Q.T  # G P, column j = G P e_j
    with np.errstate(divide="ignore", invalid="ignore"):
        move = np.linalg.norm(GP, axis=0) * R / Pjj
    ok = cand & (Pjj > 1e-12) & np.isfinite(move)
    err[ok] = move[ok]
    return R, err


def _eliminate(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray, j: int, i: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Solve constraint ``i`` for ``ξ_j`` and substitute: one constraint and one generator
    fewer; the box constraint ``|ξ_j| <= 1`` is dropped, so the result contains the original
    (Scott et al. 2016, Proposition 5, eqs. (27) and (29))."""
    piv_row = A[i] / A[i, j]
    piv_b = b[i] / A[i, j]
    # ξ_j = piv_b - Σ_{l≠j} piv_row_l ξ_l
    c = c + G[:, j] * piv_b
    G = G - np.outer(G[:, j], piv_row)
    b = b - A[:, j] * piv_b
    A = A - np.outer(A[:, j], piv_row)
    keep_r = np.arange(A.shape[0]) != i
    keep_c = np.arange(A.shape[1]) != j
    return c, G[:, keep_c], A[np.ix_(keep_r, keep_c)], b[keep_r]


class Certificates:
    """Dual certificates of some linear bounds of ``<c, G, A, b>``, kept valid through reduction.

    Row ``i`` certifies ``min_ξ D_iᵀξ >= μ_iᵀb - ‖D_i - Aᵀμ_i‖₁`` (``D`` (K, m): objectives in
    the factors ``ξ``, ``μ`` (K, nc): multipliers, e.g. those of :func:`hull_certificates`).
    Each reparametrisation of the set (row scaling, rescaling, elimination of a factor) maps the
    objectives and multipliers so that the certificates keep meaning the same linear functions
    of ``x``. What a reduction step does to the certified bounds is then known before it is
    taken: :meth:`elimination_loss` is the loosening, weighted by ``weight`` (K,), of every
    bound if factor ``j`` were eliminated. This is how the estimator chooses what to eliminate
    (the bounds of the box it reports stay as tight as possible), instead of the shape-only
    Hausdorff heuristic of Scott et al. 2016, Section 4.2, which only breaks ties here.
    """

    __slots__ = ("D", "mu", "radius", "weight")

    def __init__(self, D: np.ndarray, mu: np.ndarray, weight: np.ndarray):
        self.D, self.mu, self.weight = D, mu, weight
        self.radius = 1.0  # see hull_certificates: the factors' box the certificates assume

    def keep(self, rows: np.ndarray, cols: np.ndarray) -> None:
        """Constraints ``rows`` and factors ``cols`` are kept (the others were zero)."""
        self.mu = self.mu[:, rows]
        self.D = self.D[:, cols]

    def scale_rows(self, s: np.ndarray) -> None:
        """Constraint ``r`` was divided by ``s_r``."""
        self.mu = self.mu * s

    def scale_factors(self, rad: np.ndarray) -> None:
        """Factor ``j`` was rescaled, ``ξ_j = m_j + rad_j ξ'_j`` (offsets go to constants)."""
        self.D = self.D * rad

    def elimination_loss(self, A: np.ndarray, b: np.ndarray, piv: np.ndarray) -> np.ndarray:
        """Weighted loosening of the certified bounds if factor ``j`` is eliminated with row
        ``piv[j]`` (for every ``j``). The multipliers move to ``μ + (r_j / a_pj) e_p`` so that
        the reduced cost ``r = D - Aᵀμ`` of ``ξ_j``, whose box is dropped, becomes zero."""
        m = A.shape[1]
        Rc = self.D - self.mu @ A  # (K, m)
        apj = A[piv, np.arange(m)]
        t = Rc / np.where(apj != 0, apj, 1.0)  # (K, m): multiplier change per candidate
        new = np.abs(Rc[:, None, :] - t[:, :, None] * A[piv][None, :, :]).sum(axis=2)
        loss = new - t * b[piv][None, :] - np.abs(Rc).sum(axis=1, keepdims=True)
        return self.weight @ loss

    def eliminate(self, A: np.ndarray, j: int, p: int) -> None:
        """Factor ``j`` eliminated with row ``p`` (before the row and column are removed)."""
        Rc = self.D[:, j] - self.mu @ A[:, j]
        self.mu = self.mu.copy()
        self.mu[:, p] += Rc / A[p, j]
        self.D = self.D - np.outer(self.D[:, j] / A[p, j], A[p])


def hull_certificates(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, Certificates] | None:
    """Certified interval hull of ``<c, G, A, b>`` and the certificates of its ``2 n`` bounds
    (weighted by the inverse width of each coordinate, so that losses are relative), or
    ``None`` when the set is certainly empty (:func:`certified_empty`: a dual certificate,
    checked in floating point, that even the box ``‖ξ‖∞ <= 1 + EMPTY_TOL`` misses the
    constraints).

    When HiGHS calls the set infeasible without such a certificate (a set that is thin, or
    empty only by rounding), the bounds are those of the *softened* set with the box
    ``‖ξ‖∞ <= ρ``, ``ρ = max(1, r*) (1 + EMPTY_TOL)`` (``r*`` the smallest feasible radius
    found): a superset, so still sound. ``cert.radius`` is then ``ρ``: the certificates are
    those of ``<c, ρ G, ρ A, b>`` (the same set, with the factors rescaled to the unit box),
    which the caller should keep instead of the original.
    """
    n = G.shape[0]
    Gs = np.vstack([G, -G])
    vals, mu, ok = _certified_mins(Gs, A, b)
    radius = 1.0
    if not ok:
        r, r_low = radius_certificate(A, b)
        if r_low > 1.0 + EMPTY_TOL:
            return None
        radius = (max(1.0, r) if np.isfinite(r) else 1.0) * (1.0 + EMPTY_TOL)
        vals, mu, ok = _certified_mins(Gs, A, b, radius)
        if not ok:  # HiGHS contradicting itself: the bound of the zonotope (any μ is valid)
            mu = np.zeros_like(mu)
            vals = _dual_bounds(Gs, A, b, mu, radius)
    lo = c + vals[:n]
    hi = c - vals[n:]
    width = np.maximum(hi - lo, 1e-12 * (1.0 + np.abs(c)))
    cert = Certificates(Gs * radius, mu, np.concatenate([1.0 / width, 1.0 / width]))
    cert.radius = radius
    return lo, hi, cert


def independent_constraints(A: np.ndarray) -> np.ndarray:
    """Mask of a maximal set of linearly independent constraints (QR with pivoting of ``Aᵀ``).

    The others are linear combinations of these: implied when the set is nonempty, so dropping
    them keeps the set (and gives a superset if rounding made them slightly inconsistent)."""
    nc = A.shape[0]
    keep = np.ones(nc, dtype=bool)
    if nc <= 1:
        return keep
    R, piv = qr(A.T, mode="r", pivoting=True)
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > 1e-10 * d[0])) if d.size and d[0] > 0 else 0
    if rank < nc:
        keep[:] = False
        keep[piv[:rank]] = True
    return keep


def _choose_factor(
    G: np.ndarray, A: np.ndarray, b: np.ndarray, cert: Certificates | None
) -> tuple[int, int] | None:
    """The factor ``j`` to eliminate and its pivot row ``p`` (largest ``|a_pj|``).

    With certificates: the least weighted loosening of the certified bounds, ties broken by the
    Hausdorff estimate of :func:`_elimination_scores`; without: that estimate alone (or, when
    ``A`` has no null space, the overshoot ``R_j`` times ``‖G e_j‖``)."""
    m = A.shape[1]
    R, err = _elimination_scores(G, A, b)
    piv = np.argmax(np.abs(A), axis=0)
    cand = np.isfinite(R) & (np.abs(A[piv, np.arange(m)]) >= _PIVOT_TOL)
    if not np.any(cand):
        return None
    shape = np.where(cand & np.isfinite(err), err, np.inf)
    if not np.any(np.isfinite(shape)):
        with np.errstate(invalid="ignore"):  # R = inf on the non-candidates
            shape = np.where(cand, R * np.linalg.norm(G, axis=0), np.inf)
    if cert is not None:
        loss = np.where(cand, cert.elimination_loss(A, b, piv), np.inf)
        best = loss.min()
        ties = loss <= best + 1e-9 * (1.0 + abs(best))
        key = np.where(ties, shape, np.inf)
        if not np.any(np.isfinite(key)):
            key = loss
    else:
        key = shape
    j = int(np.argmin(key))
    return j, int(piv[j])


def eliminate_constraints(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    max_constraints: int,
    cert: Certificates | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Reduce to at most ``max_constraints`` constraints (Scott et al. 2016, Section 4.2): in
    turn, rescale the factors to their propagated bounds, choose a factor, eliminate it with
    the constraint where it has the largest coefficient. The factor is the one with the least
    loss of the certified bounds ``cert`` (:class:`Certificates`, updated in place), or without
    certificates the one with the smallest Hausdorff-error estimate. ``None`` when the set is
    found empty on the way."""
    c, G, A, b, rows, cols, ok = _drop_zero_idx(c, G, A, b)
    if not ok:
        return None
    if cert is not None:
        cert.keep(rows, cols)
    while A.shape[0] > max_constraints:
        A, b, s = _normalise_rows_s(A, b)
        if cert is not None:
            cert.scale_rows(s)
        out = _rescale(c, G, A, b)
        if out is None:
            return None
        c, G, A, b, rad = out
        if cert is not None:
            cert.scale_factors(rad)
        c, G, A, b, rows, cols, ok = _drop_zero_idx(c, G, A, b)
        if not ok:
            return None
        if cert is not None:
            cert.keep(rows, cols)
        if A.shape[0] <= max_constraints:
            break
        A, b, s = _normalise_rows_s(A, b)
        if cert is not None:
            cert.scale_rows(s)
        rows = independent_constraints(A)
        if not np.all(rows):  # implied constraints: dropping them keeps the set
            A, b = A[rows], b[rows]
            if cert is not None:
                cert.keep(rows, np.ones(A.shape[1], dtype=bool))
            continue
        choice = _choose_factor(G, A, b, cert)
        if choice is None:  # pragma: no cover - no usable pivot: drop the oldest constraint
            rows = np.arange(A.shape[0]) != 0
            A, b = A[rows], b[rows]
            if cert is not None:
                cert.keep(rows, np.ones(A.shape[1], dtype=bool))
            continue
        j, p = choice
        if cert is not None:
            cert.eliminate(A, j, p)
        c, G, A, b = _eliminate(c, G, A, b, j, p)
        if cert is not None:
            cert.keep(np.arange(A.shape[0] + 1) != p, np.arange(G.shape[1] + 1) != j)
        c, G, A, b, rows, cols, ok = _drop_zero_idx(c, G, A, b)
        if not ok:
            return None
        if cert is not None:
            cert.keep(rows, cols)
    return c, G, A, b


def consolidate_small(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray, tol_x: float, tol_c: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Replace the generators that are small in both parts (``|G_j| <= tol_x`` and
    ``|A_j| <= tol_c``: the rounding slacks and boxes of earlier steps, factors pinned down by
    rescaling) by two boxes: ``diag(Σ_j |G_j|)`` in ``x`` and ``diag(Σ_j |A_j|)`` in the
    constraints (a slack per row). The segment ``{(G_j; A_j) t}`` lies in the sum of the two,
    so the result contains the original (only correlations between rows of the replaced
    factors are lost); at most ``n + nc`` columns are left of them (the sums rounded up by
    ``γ_{k+1}``). Dropping them instead would give a subset."""
    n, m = G.shape
    if m == 0:
        return c, G, A, b
    small = np.all(np.abs(G) <= tol_x, axis=0)
    if A.shape[0]:
        small &= np.all(np.abs(A) <= tol_c, axis=0)
    k = int(small.sum())
    if k <= 1:
        return c, G, A, b
    up = 1.0 + gamma(k + 1)
    gx = np.abs(G[:, small]).sum(axis=1) * up
    ga = np.abs(A[:, small]).sum(axis=1) * up
    ix, ia = np.flatnonzero(gx > 0), np.flatnonzero(ga > 0)
    if ix.size + ia.size >= k:
        return c, G, A, b
    nc = A.shape[0]
    Gb = np.zeros((n, ix.size + ia.size))
    Ab = np.zeros((nc, ix.size + ia.size))
    Gb[ix, np.arange(ix.size)] = gx[ix]
    Ab[ia, ix.size + np.arange(ia.size)] = ga[ia]
    return c, np.hstack([G[:, ~small], Gb]), np.hstack([A[:, ~small], Ab]), b


def reduce_generators(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    max_generators: int,
    residual: bool = False,
) -> Any:
    """At most ``max_generators`` generators, by reducing the lifted zonotope
    ``<[c; -b], [G; A]>`` (Scott et al. 2016, Section 4.3; its ``x`` part and constraint part
    shrink together, so the constrained zonotope it represents contains the original).

    The lifted zonotope is reduced with a parallelotope enclosure (Chisci, Garulli & Zappa
    1996, as in the ZETA toolbox): a basis ``P`` of ``r = rank [G; A]`` large, independent
    generators is chosen (QR with column pivoting); each generator ``l`` to remove has
    coordinates ``α = P⁺ l`` and ``<0, [P, l]> ⊆ <0, P diag(1 + |α|)>``, so the removed
    generators are absorbed by rescaling the basis, ``P diag(1 + Σ|α|)``. Those with the
    smallest ``‖α‖₁`` are removed. No generator is added, the directions of the kept ones are
    unchanged (coordinates are invariant to the scaling of the constraint rows). What the
    basis misses of the removed generators, ``Σ |l - P α|`` (the part outside the basis' span
    when the lifted generators do not span the lifted space, and the error of the computed
    ``α``), is enclosed in a box, enlarged by the bound ``γ_{r+2} (|l| + |P| |α|)`` of its
    rounding; the scale factors are rounded up. The result contains the original in exact
    arithmetic, whatever the rounding.

    At least the ``r <= n + nc`` basis generators are kept, whatever ``max_generators``.

    With ``residual=True`` the box is not added: ``(c, G, A, b, box)`` is returned, ``box``
    ``(n + nc,)`` the radii of the box the caller must add (Minkowski) to the result."""
    n, m = G.shape
    if m <= max_generators:
        return (c, G, A, b, np.zeros(n + A.shape[0])) if residual else (c, G, A, b)
    L = np.vstack([G, A])
    R, piv = qr(L, mode="r", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > 1e-10 * diag[0])) if diag.size and diag[0] > 0 else 0
    max_generators = max(max_generators, rank)  # the basis is always kept
    basis, others = piv[:rank], piv[rank:]
    # L[:, piv] = Q R: the others have coordinates α = R11⁻¹ R12 in the basis L[:, basis]
    alpha = np.linalg.solve(R[:rank, :rank], R[:rank, rank:])  # (scipy trsm is slow here)
    order = np.argsort(np.abs(alpha).sum(axis=0), kind="stable")
    n_rm = m - max_generators
    rm, kept = order[:n_rm], others[order[n_rm:]]
    # rounding: the computed α are not the exact coordinates, so what the basis misses of each
    # removed generator l is the residual l - P α, evaluated directly (in exact arithmetic the
    # Q2 R22 part) plus the bound γ_{r+2} (|l| + |P| |α|) of its rounding; the scale factors
    # are rounded up (γ_{k+3}) so that the scaled basis is never smaller than the exact one
    Lb, a_rm = L[:, basis], alpha[:, rm]
    L_rm = L[:, others[rm]]
    resid = np.abs(L_rm - Lb @ a_rm).sum(axis=1) + gamma(rank + 2) * (
        np.abs(L_rm).sum(axis=1) + np.abs(Lb) @ np.abs(a_rm).sum(axis=1)
    )
    scale = 1.0 + np.abs(a_rm).sum(axis=1)
    if residual:
        L2 = np.hstack([Lb * (scale * (1.0 + gamma(n_rm + 3))), L[:, kept]])
        return c, L2[:n], L2[n:], b, resid
    tau = _box_in_basis(Lb, resid) if rank == L.shape[0] else None
    if tau is not None:  # the basis spans the space: absorb the box too
        scale, resid = scale + tau, np.zeros_like(resid)
    P = Lb * (scale * (1.0 + gamma(n_rm + 3)))
    big = resid > 0
    box = np.zeros((L.shape[0], int(big.sum())))
    box[np.flatnonzero(big), np.arange(box.shape[1])] = resid[big]
    L2 = np.hstack([P, L[:, kept], box])
    return c, L2[:n], L2[n:], b


def _box_in_basis(P: np.ndarray, rho: np.ndarray) -> np.ndarray | None:
    """``τ >= 0`` with ``box(ρ) ⊆ <0, P diag(τ)>`` for a square invertible ``P``, verified in
    floating point, or ``None`` (``P`` too ill-conditioned to verify).

    ``v ∈ box(ρ)`` has coordinates ``P⁻¹ v``. With ``X ≈ P⁻¹`` and ``θ >= ‖I - X P‖∞`` (the
    computed residual plus the bound ``γ_{n+1} (I + |X| |P|)`` of its rounding), ``θ < 1``
    gives ``P⁻¹ v = X v + (I - X P) P⁻¹ v``, so
    ``|P⁻¹ v| <= |X| ρ + θ / (1 - θ) ‖|X| ρ‖∞`` (a Neumann-series bound, as in verified
    linear algebra)."""
    if not np.any(rho):
        return np.zeros_like(rho)
    n = P.shape[0]
    try:
        X = np.linalg.inv(P)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(X)):
        return None
    aX = np.abs(X)
    Rm = np.eye(n) - X @ P
    theta = float(
        (np.abs(Rm) + gamma(n + 1) * (np.eye(n) + aX @ np.abs(P))).sum(axis=1).max()
    ) * (1.0 + gamma(n + 2))
    if not theta < 0.5:
        return None
    v = (aX @ rho) * (1.0 + gamma(n + 1))
    return (v + theta / (1.0 - theta) * float(v.max())) * (1.0 + gamma(4))


# --------------------------------------------------------------------------------------------
# The set
# --------------------------------------------------------------------------------------------
class ConstrainedZonotope:
    """``<c, G, A, b> = {c + G ξ : ‖ξ‖∞ <= 1, A ξ = b}`` (Scott et al. 2016, Definition 3).

    Parameters
    ----------
    center : (n,)
    generators : (n, m), optional (``m = 0`` when omitted)
    A : (nc, m), optional (no constraint: a zonotope)
    b : (nc,), required with ``A``

    Answers the verbs of :class:`~ivobs.Box` and :class:`~ivobs.Zonotope` (``M @ Z``, ``Z + W``,
    ``interval_hull()``, ``reduce()``, ``contains()``) plus ``intersect``, ``intersect_strip``,
    ``intersect_hyperplane`` and ``is_empty``.
    """

    __slots__ = ("A", "G", "b", "c")
    __array_priority__ = 100

    def __init__(self, center: Any, generators: Any = None, A: Any = None, b: Any = None):
        c = as_vector("ConstrainedZonotope center", center)
        n = c.shape[0]
        if generators is None:
            G = np.zeros((n, 0))
        else:
            G = as_float_array("ConstrainedZonotope generators", generators)
            if G.ndim == 1 and n == 1:
                G = G.reshape(1, -1)
            if G.ndim != 2 or G.shape[0] != n:
                raise IvobsError(
                    f"ConstrainedZonotope generators: expected shape ({n}, m), got {G.shape}"
                )
            check_finite("ConstrainedZonotope generators", G)
        m = G.shape[1]
        if (A is None) != (b is None):
            raise IvobsError("ConstrainedZonotope: give both A and b (A ξ = b), or neither")
        if A is None:
            A_ = np.zeros((0, m))
            b_ = np.zeros(0)
        else:
            A_ = as_float_array("ConstrainedZonotope A", A)
            if A_.ndim == 1:
                A_ = A_.reshape(1, -1)
            if A_.ndim != 2 or A_.shape[1] != m:
                raise IvobsError(
                    f"ConstrainedZonotope A: expected shape (nc, {m}) (one column per "
                    f"generator), got {A_.shape}"
                )
            check_finite("ConstrainedZonotope A", A_)
            b_ = as_vector("ConstrainedZonotope b", b, A_.shape[0]) if A_.shape[0] else np.zeros(0)
        self.c, self.G, self.A, self.b = c, G, A_, b_

    @classmethod
    def _trusted(
        cls, c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
    ) -> ConstrainedZonotope:
        z = object.__new__(cls)
        z.c, z.G, z.A, z.b = c, G, A, b
        return z

    @classmethod
    def from_box(cls, box: Box) -> ConstrainedZonotope:
        """``<center, diag(radius)>`` with no constraint (constant bounded boxes)."""
        z = box.to_zonotope()
        keep = np.any(z.G != 0, axis=0)
        return cls._trusted(z.c, z.G[:, keep], np.zeros((0, int(keep.sum()))), np.zeros(0))

    @classmethod
    def from_zonotope(cls, z: Zonotope) -> ConstrainedZonotope:
        """The zonotope ``<c, G>`` (no constraint)."""
        return cls._trusted(z.c.copy(), z.G.copy(), np.zeros((0, z.G.shape[1])), np.zeros(0))

    # -- properties ---------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return int(self.c.shape[0])

    @property
    def num_generators(self) -> int:
        return int(self.G.shape[1])

    @property
    def num_constraints(self) -> int:
        return int(self.A.shape[0])

    # -- exact operations (Scott et al. 2016, Proposition 1) ----------------------------------
    def linear_map(self, M: Any) -> ConstrainedZonotope:
        """``M Z = <M c, M G, A, b>`` (Proposition 1)."""
        M = as_matrix("M", M, cols=self.dim, vector="row")
        return ConstrainedZonotope._trusted(M @ self.c, M @ self.G, self.A, self.b)

    def __rmatmul__(self, M: Any) -> ConstrainedZonotope:
        return self.linear_map(M)

    def __add__(self, other: Any) -> ConstrainedZonotope:
        """Minkowski sum (Proposition 1) with a constrained zonotope, zonotope or box; a vector
        translates."""
        if isinstance(other, Box):
            other = ConstrainedZonotope.from_box(other)
        elif isinstance(other, Zonotope):
            other = ConstrainedZonotope.from_zonotope(other)
        if isinstance(other, ConstrainedZonotope):
            if other.dim != self.dim:
                raise IvobsError(f"Minkowski sum: dimensions differ ({self.dim}, {other.dim})")
            A = np.block(
                [
                    [self.A, np.zeros((self.num_constraints, other.num_generators))],
                    [np.zeros((other.num_constraints, self.num_generators)), other.A],
                ]
            )
            return ConstrainedZonotope._trusted(
                self.c + other.c,
                np.hstack([self.G, other.G]),
                A,
                np.concatenate([self.b, other.b]),
            )
        v = as_vector("translation", other, self.dim)
        return ConstrainedZonotope._trusted(self.c + v, self.G, self.A, self.b)

    __radd__ = __add__

    def intersect(self, other: Any, R: Any = None) -> ConstrainedZonotope:
        """Generalised intersection ``Z ∩_R Y = {z ∈ Z : R z ∈ Y}`` (Proposition 1); ``R = I``
        (plain intersection) by default. ``Y`` may be a constrained zonotope, zonotope or box."""
        if isinstance(other, Box):
            other = ConstrainedZonotope.from_box(other)
        elif isinstance(other, Zonotope):
            other = ConstrainedZonotope.from_zonotope(other)
        if not isinstance(other, ConstrainedZonotope):
            raise IvobsError(
                f"intersect: expected a ConstrainedZonotope, Zonotope or Box, "
                f"got {type(other).__name__}"
            )
        R_ = np.eye(self.dim) if R is None else as_matrix("R", R, other.dim, self.dim)
        if R is None and other.dim != self.dim:
            raise IvobsError(f"intersect: dimensions differ ({self.dim}, {other.dim})")
        m1, m2 = self.num_generators, other.num_generators
        A = np.block(
            [
                [self.A, np.zeros((self.num_constraints, m2))],
                [np.zeros((other.num_constraints, m1)), other.A],
                [R_ @ self.G, -other.G],
            ]
        )
        b = np.concatenate([self.b, other.b, other.c - R_ @ self.c])
        G = np.hstack([self.G, np.zeros((self.dim, m2))])
        return ConstrainedZonotope._trusted(self.c, G, A, b)

    def intersect_hyperplane(self, h: Any, y: float) -> ConstrainedZonotope:
        """``{x ∈ Z : hᵀx = y}``: one constraint ``hᵀG ξ = y - hᵀc`` (``Y`` a point)."""
        h = as_vector("h", h, self.dim)
        A = np.vstack([self.A, (h @ self.G)[None, :]])
        b = np.append(self.b, float(y) - h @ self.c)
        return ConstrainedZonotope._trusted(self.c, self.G, A, b)

    def intersect_strip(self, h: Any, y: float, sigma: float) -> ConstrainedZonotope:
        """``{x ∈ Z : |hᵀx - y| <= σ}`` (``Z ∩_R Y`` with ``Y = <y, σ>``, ``R = hᵀ``): one
        constraint and one generator more."""
        if not np.isfinite(sigma) or sigma < 0:
            raise IvobsError(f"sigma: expected a half-width >= 0, got {sigma}")
        return self.intersect(ConstrainedZonotope([float(y)], [[float(sigma)]]), R=np.atleast_2d(h))

    # -- questions (linear programs) ----------------------------------------------------------
    def is_empty(self) -> bool:
        """Whether no ``ξ`` in the unit box meets ``A ξ = b``, certainly: one LP, whose dual
        certificate is checked in floating point with the margin :data:`EMPTY_TOL`
        (:func:`certified_empty`)."""
        return certified_empty(self.A, self.b)

    def interval_hull(self) -> Box:
        """The smallest box containing the set: ``2 n`` LPs with HiGHS, each bound certified by
        duality (see the module docstring). Raises :class:`~ivobs.InconsistentDataError` for an
        empty set."""
        out = hull_bounds(self.c, self.G, self.A, self.b)
        if out is None:
            raise InconsistentDataError("interval_hull: the constrained zonotope is empty")
        return Box._trusted(*out)

    def contains(self, x: Any, tol: float = 1e-9) -> bool:
        """Whether ``x`` is in the set (one LP: ``min ‖ξ‖∞`` with ``G ξ = x - c``, ``A ξ = b``)."""
        x = as_vector("x", x, self.dim)
        Aeq = np.vstack([self.G, self.A])
        beq = np.concatenate([x - self.c, self.b])
        if self.num_generators == 0:
            return bool(np.all(np.abs(beq) <= tol))
        return _feasibility_radius(Aeq, beq) <= 1.0 + tol

    # -- reduction (Scott et al. 2016, Section 4) ---------------------------------------------
    def rescale(self) -> ConstrainedZonotope:
        """The same set with its factors rescaled to their propagated bounds (Section 4.2).
        Raises :class:`~ivobs.InconsistentDataError` when propagation proves it empty."""
        A, b, _ = _normalise_rows_s(self.A, self.b)
        out = _rescale(self.c, self.G, A, b)
        if out is None:
            raise InconsistentDataError("rescale: the constrained zonotope is empty")
        return ConstrainedZonotope._trusted(*_drop_zero_idx(*out[:4])[:4])

    def reduce(
        self, max_generators: int | None = None, max_constraints: int | None = None
    ) -> ConstrainedZonotope:
        """A constrained zonotope containing this one with at most ``max_constraints``
        constraints (eliminated first, Section 4.2) and ``max_generators`` generators (lifted
        zonotope reduction, Section 4.3). ``None`` leaves that count alone."""
        c, G, A, b = self.c, self.G, self.A, self.b
        if max_constraints is not None:
            if max_constraints < 0:
                raise IvobsError(f"max_constraints: expected >= 0, got {max_constraints}")
            out = eliminate_constraints(c, G, A, b, int(max_constraints))
            if out is None:
                raise InconsistentDataError("reduce: the constrained zonotope is empty")
            c, G, A, b = out
        if max_generators is not None:
            c, G, A, b = reduce_generators(c, G, A, b, int(max_generators))
        return ConstrainedZonotope._trusted(c, G, A, b)

    def to_zonotope(self) -> Zonotope:
        """A zonotope containing the set (every constraint eliminated)."""
        z = self.reduce(max_constraints=0)
        return Zonotope._trusted(z.c, z.G)

    def sample(self, size: int, rng: Any = None) -> np.ndarray:
        """Vertices of the set that maximise random linear objectives (one LP each; for tests
        and plots)."""
        rng = np.random.default_rng(rng)
        pts = []
        m = self.num_generators
        for _ in range(size):
            w = rng.normal(size=self.dim)
            res = linprog(
                -(w @ self.G),
                A_eq=self.A if self.num_constraints else None,
                b_eq=self.b if self.num_constraints else None,
                bounds=(-1, 1),
                method="highs",
            )
            if res.status != 0:
                raise InconsistentDataError("sample: the constrained zonotope is empty")
            pts.append(self.c + self.G @ res.x if m else self.c)
        return np.array(pts)

    def __repr__(self) -> str:
        return (
            f"ConstrainedZonotope(n={self.dim}, generators={self.num_generators}, "
            f"constraints={self.num_constraints})"
        )
