"""Constraint elimination of constrained zonotopes ([Scott2016, Section 4.2]), on raw arrays.

In turn: normalise the constraints, rescale the factors ``ξ`` to their propagated bounds (an
exact reparametrisation), drop implied constraints, choose a factor and solve a constraint for
it. Each step returns a superset of the set it is given. With :class:`~.hull.Certificates` the
factor chosen is the one whose elimination loosens the certified interval hull least; without,
the one with the smallest estimate of the Hausdorff error ([Scott2016, eq. (A.8)]).
"""

from __future__ import annotations

import numpy as np

from ._tolerances import PIVOT_TOL, ROW_TOL, ZERO_TOL
from .hull import Certificates

__all__ = ["eliminate_constraints", "independent_constraints"]


def _drop_zero_idx(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Remove (numerically) trivial constraints ``0 ξ = 0`` (all coefficients below
    :data:`ROW_TOL`: dropping a constraint gives a superset) and generators that are zero in
    ``G`` and ``A`` (exactly: dropping a small one would give a subset).

    Returns ``(c, G, A, b, rows, cols, consistent)``: the masks of the kept constraints and
    generators, and False for a dropped constraint ``a ξ = b`` with ``|b| > ‖a‖₁`` (an empty
    set).
    """
    scale = 1.0 + (np.abs(A).max() if A.size else 0.0)
    rows = np.any(np.abs(A) > ROW_TOL * scale, axis=1)
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
    propagation, [Scott2016, Section 4.2, Algorithm 1]), or ``None`` when a
    constraint cannot be met (the set is empty).

    Each row ``a ξ = b`` gives ``ξ_j ∈ (b - Σ_{l≠j} a_l [ξ_l]) / a_j``; all rows are applied at
    once and the results intersected (``sweeps`` times). The computed intervals are widened by
    ``1e-10`` (relative) so that rounding never excludes a feasible ``ξ``.
    """
    m = A.shape[1]
    lo = -np.ones(m)
    hi = np.ones(m)
    absA = np.abs(A)
    nz = absA > ZERO_TOL * np.maximum(1.0, absA.max(axis=1, keepdims=True))
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
    ([Scott2016, Section 4.2]): an exact reparametrisation after which more box
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
    Hausdorff error of eliminating it ([Scott2016, Section 4.2 and eq. (A.8)]).

    ``R_j = max(0, max|ρ_j| - 1)`` with ``ρ_j = ∩_i (b_i - Σ_{l≠j} a_il [-1, 1]) / a_ij``.
    Dropping ``|ξ_j| <= 1`` lets ``ξ_j`` move by about ``R_j`` along the constraints' null
    space; the error estimate is ``‖G δ_j‖₂`` for the shortest such move
    ``δ_j = R_j P e_j / P_jj`` (``P`` the projector onto the null space of ``A``), computed
    for all ``j`` from one QR factorisation of ``Aᵀ``.
    """
    m = A.shape[1]
    absA = np.abs(A)
    tol = ZERO_TOL * max(1.0, float(absA.max()) if absA.size else 1.0)
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
    ([Scott2016, Proposition 5, eqs. (27) and (29)])."""
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


def independent_constraints(A: np.ndarray) -> np.ndarray:
    """Mask of a maximal set of linearly independent constraints (QR with pivoting of ``Aᵀ``).

    The others are linear combinations of these: implied when the set is nonempty, so dropping
    them keeps the set (and gives a superset if rounding made them slightly inconsistent)."""
    nc = A.shape[0]
    keep = np.ones(nc, dtype=bool)
    if nc <= 1:
        return keep
    from scipy.linalg import qr  # imported here: SciPy is slow to import

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
    cand = np.isfinite(R) & (np.abs(A[piv, np.arange(m)]) >= PIVOT_TOL)
    if not np.any(cand):
        return None
    shape = np.where(cand & np.isfinite(err), err, np.inf)
    if not np.any(np.isfinite(shape)):
        with np.errstate(invalid="ignore"):  # R = inf on the non-candidates
            shape = np.where(cand, R * np.linalg.norm(G, axis=0), np.inf)
    if cert is not None:
        loss = cert.elimination_loss(A, b, piv, cand)
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
    """Reduce to at most ``max_constraints`` constraints ([Scott2016, Section 4.2]): in
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
