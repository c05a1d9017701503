"""Constraint elimination of constrained zonotopes ([Scott2016, Section 4.2]), on raw arrays.

In turn: normalise the constraints, rescale the factors ``ξ`` to their propagated bounds (an
exact reparametrisation), drop implied constraints, choose a factor and solve a constraint for
it. Each step returns a superset of the set it is given. With :class:`~.hull.Certificates` the
factor chosen is the one whose elimination loosens the certified interval hull least; without,
the one with the smallest estimate of the Hausdorff error ([Scott2016, eq. (A.8)]).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

try:  # the gufuncs behind np.linalg.qr (private to NumPy: present in 1.26 and 2.x)
    from numpy.linalg import _umath_linalg as _gufuncs
except ImportError:  # pragma: no cover - a NumPy without it: the public call
    _gufuncs = None  # type: ignore[assignment]

from ._elim_kernels import select as _kernels_for
from ._tolerances import PIVOT_TOL, ROW_TOL, ZERO_TOL
from .hull import Certificates

_max, _any, _all = np.maximum.reduce, np.logical_or.reduce, np.logical_and.reduce

__all__ = ["eliminate_constraints", "independent_constraints"]


def _drop_zero_idx(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray, own: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """Remove (numerically) trivial constraints ``0 ξ = 0`` (all coefficients below
    :data:`ROW_TOL`: dropping a constraint gives a superset) and generators that are zero in
    ``G`` and ``A`` (exactly: dropping a small one would give a subset).

    Returns ``(c, G, A, b, rows, cols, consistent)``: the masks of the kept constraints and
    generators, and False for a dropped constraint ``a ξ = b`` with ``|b| > ‖a‖₁`` (an empty
    set). ``own``: ``G`` and ``A`` are temporaries of the caller's (never a caller's
    arrays), which may be returned themselves.
    """
    # the ufuncs' reductions called directly (what ndarray.max / any / all call, without their
    # Python wrappers: a few µs a call, five calls per step on the servo)
    absA = np.abs(A)
    scale = 1.0 + (_max(absA, axis=None) if A.size else 0.0)
    rows = _any(absA > ROW_TOL * scale, axis=1)
    all_rows, consistent = bool(_all(rows)), True
    if not all_rows:
        # a dropped row a ξ = b can only hold if |b| <= ‖a‖₁ (up to rounding)
        zb, za = b[~rows], absA[~rows].sum(axis=1)
        consistent = bool((np.abs(zb) <= za + 1e-8 * (1.0 + np.abs(zb))).all())
        A = A[rows]
    b = b[rows]
    # only exactly zero generators: fixing a small nonzero ξ_j at 0 would shrink the set
    cols = _any(G != 0, axis=0) | _any(A != 0, axis=0)
    # the copies are made even when nothing is dropped: their memory layout (``G[:, cols]`` is
    # column-major) decides how BLAS rounds the products that follow; arrays already laid out
    # as these copies would be (own temporaries, in the loop of eliminate_constraints) are kept
    if own and all_rows and _all(cols) and _column_major(G) and _column_major(A):
        return c, G, A, b, rows, cols, consistent
    return c, G[:, cols], A[:, cols], b, rows, cols, consistent


def _column_major(M: np.ndarray) -> bool:
    """Whether ``M`` (2-D float64) has the strides of a fresh column-major copy of itself."""
    return M.dtype == np.float64 and M.strides == (8, 8 * M.shape[0])


def _normalise_rows_s(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scale each constraint so that its largest coefficient is 1 (same set, better
    conditioned); also returns the scales."""
    if A.shape[0] == 0:
        return A, b, np.ones(0)
    s = _max(np.abs(A), axis=1)
    if not _all(s):
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
    ``1e-10`` (relative) so that rounding never excludes a feasible ``ξ``. On large sets
    (tank30) the compiled :func:`._elim_nb.propagate` gives the same numbers, bit for bit.
    """
    fast = _kernels_for(A, b)
    if fast is not None:
        feasible, lo_k, hi_k = fast[0].propagate(A, b, sweeps, fast[1])
        return (lo_k, hi_k) if feasible else None
    m = A.shape[1]
    lo = -np.ones(m)
    hi = np.ones(m)
    absA = np.abs(A)
    nz = absA > ZERO_TOL * np.maximum(1.0, absA.max(axis=1, keepdims=True))
    safe = np.where(nz, A, 1.0)
    zero = ~nz
    any_zero = bool(zero.any())
    bc = b[:, None]
    # four scratch arrays of A's shape and layout (the layout decides the order of the row
    # sums), reused by every sweep: on tank30 (81 x 552) fresh temporaries cost more than the
    # arithmetic
    b0, b1, b2, pad = (np.empty_like(A) for _ in range(4))
    for _ in range(sweeps):
        # the same operations as before, each product once, in place
        a_lo, a_hi = np.multiply(A, lo, out=b0), np.multiply(A, hi, out=b1)
        t_lo = np.minimum(a_lo, a_hi, out=b2)
        t_hi = np.maximum(a_lo, a_hi, out=a_hi)
        rest_lo = np.subtract(t_lo.sum(axis=1, keepdims=True), t_lo, out=t_lo)
        rest_hi = np.subtract(t_hi.sum(axis=1, keepdims=True), t_hi, out=t_hi)
        q1 = np.divide(np.subtract(bc, rest_hi, out=rest_hi), safe, out=rest_hi)
        q2 = np.divide(np.subtract(bc, rest_lo, out=rest_lo), safe, out=rest_lo)
        # pad = 1e-10 (1 + |q1| + |q2|), term by term as written
        np.add(1.0, np.abs(q1, out=pad), out=pad)
        np.add(pad, np.abs(q2, out=b0), out=pad)
        np.multiply(1e-10, pad, out=pad)
        q_lo, q_hi = np.minimum(q1, q2, out=b0), np.maximum(q1, q2, out=q1)
        q_lo -= pad
        q_hi += pad
        if any_zero:  # copyto: the masked assignment without its indexing machinery
            np.copyto(q_lo, -np.inf, where=zero)
            np.copyto(q_hi, np.inf, where=zero)
        new_lo = q_lo.max(axis=0, initial=-np.inf)
        new_hi = q_hi.min(axis=0, initial=np.inf)
        lo_next = np.maximum(lo, new_lo)
        hi_next = np.minimum(hi, new_hi)
        if (lo_next > hi_next + 1e-9).any():
            return None
        hi_next = np.maximum(hi_next, lo_next)
        if (lo_next == lo).all() and (hi_next == hi).all():
            break  # a fixed point: the remaining sweeps would repeat this one exactly
        lo, hi = lo_next, hi_next
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

    ``R_j = max(0, max|ρ_j| - 1)`` with ``ρ_j = ∩_i (b_i - Σ_{l≠j} a_il [-1, 1]) / a_ij``
    (:func:`_overshoot`). Dropping ``|ξ_j| <= 1`` lets ``ξ_j`` move by about ``R_j`` along the
    constraints' null space; the error estimate is ``‖G δ_j‖₂`` for the shortest such move
    ``δ_j = R_j P e_j / P_jj`` (``P`` the projector onto the null space of ``A``), computed
    for all ``j`` from one QR factorisation of ``Aᵀ`` (:func:`_hausdorff`).
    """
    R = _overshoot(A, b)
    return R, _hausdorff(G, A, R)


def _overshoot(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``R_j`` of :func:`_elimination_scores` (``inf``: ``ξ_j`` is in no constraint); on large
    sets by the compiled :func:`._elim_nb.overshoot` (the same numbers, bit for bit)."""
    fast = _kernels_for(A, b)
    if fast is not None:
        return fast[0].overshoot(A, b, fast[1])
    absA = np.abs(A)
    tol = ZERO_TOL * max(1.0, float(absA.max()) if absA.size else 1.0)
    nz = absA > tol
    safe = np.where(nz, A, 1.0)
    spread = (absA.sum(axis=1, keepdims=True) - absA) / np.abs(safe)
    mid = b[:, None] / safe
    rho_lo = np.where(nz, mid - spread, -np.inf).max(axis=0, initial=-np.inf)
    rho_hi = np.where(nz, mid + spread, np.inf).min(axis=0, initial=np.inf)
    R: np.ndarray = np.maximum(0.0, np.maximum(-1.0 - rho_lo, rho_hi - 1.0))
    return R


def _hausdorff(G: np.ndarray, A: np.ndarray, R: np.ndarray) -> np.ndarray:
    """The Hausdorff-error estimate of :func:`_elimination_scores` from the overshoots ``R``
    (0 on the exact eliminations, ``R_j <= 1e-3``, when there are any; ``inf`` where none)."""
    cand = np.isfinite(R)
    exact = cand & (R <= 1e-3)
    if _any(exact):
        return np.where(exact, 0.0, np.inf)
    Q = _qr_q(A.T)  # orthonormal basis of the row space of A
    Pjj = 1.0 - np.einsum("ij,ij->i", Q, Q)
    GP = G - (G @ Q) @ Q.T  # G P, column j = G P e_j
    with np.errstate(divide="ignore", invalid="ignore"):
        # ‖G P e_j‖₂ by np.linalg.norm(GP, axis=0)'s own formula, without its wrapper
        move = np.sqrt(np.add.reduce(GP * GP, axis=0)) * R / Pjj
    ok = cand & (Pjj > 1e-12) & np.isfinite(move)
    out: np.ndarray = np.where(ok, move, np.inf)
    return out


def _qr_q(M: np.ndarray) -> np.ndarray:
    """``np.linalg.qr(M)[0]`` (the reduced ``Q``) by the two LAPACK gufuncs it calls, without its
    checks, type dispatch and error-state context (the same calls on the same copy: the same
    numbers; 5x cheaper on the small systems of a filter step). Failure gives NaNs, which
    :func:`_hausdorff` treats as no estimate, instead of an exception."""
    if _gufuncs is None:  # pragma: no cover - a NumPy without the private module
        return np.linalg.qr(M)[0]
    a = M.astype(float, copy=True)
    with np.errstate(all="ignore"):
        tau = _gufuncs.qr_r_raw(a, signature="d->d")
        q: np.ndarray = _gufuncs.qr_reduced(a, tau, signature="dd->d")
    return q


def _eliminate(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray, j: int, i: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Solve constraint ``i`` for ``ξ_j`` and substitute: one constraint and one generator
    fewer; the box constraint ``|ξ_j| <= 1`` is dropped, so the result contains the original
    ([Scott2016, Proposition 5, eqs. (27) and (29)])."""
    piv_row = A[i] / A[i, j]
    piv_b = b[i] / A[i, j]
    # ξ_j = piv_b - Σ_{l≠j} piv_row_l ξ_l (the products of np.outer, without its wrapper)
    c = c + G[:, j] * piv_b
    G = G - G[:, j, None] * piv_row[None, :]
    b = b - A[:, j] * piv_b
    A = A - A[:, j, None] * piv_row[None, :]
    keep_r = np.arange(A.shape[0]) != i
    keep_c = np.arange(A.shape[1]) != j
    # two masks in turn rather than np.ix_ (the same entries; the caller's _drop_zero_idx
    # copies them again, into a layout that does not depend on this one)
    return c, G[:, keep_c], A[keep_r][:, keep_c], b[keep_r]


def independent_constraints(A: np.ndarray) -> np.ndarray:
    """Mask of a maximal set of linearly independent constraints (QR with pivoting of ``Aᵀ``).

    The others are linear combinations of these: implied when the set is nonempty, so dropping
    them keeps the set (and gives a superset if rounding made them slightly inconsistent)."""
    nc = A.shape[0]
    keep = np.ones(nc, dtype=bool)
    if nc <= 1:
        return keep
    # LAPACK's QR with column pivoting directly (what scipy.linalg.qr calls, without the
    # argument checks and copies that cost more than the factorisation on small systems; a
    # blocked workspace, as SciPy's size query gives, so the same factorisation)
    R, jpvt = _dgeqp3()(np.array(A.T, dtype=float, order="F"), lwork=2 * nc + (nc + 1) * 64)[:2]
    d = np.abs(R.diagonal()[:nc])
    rank = int(np.count_nonzero(d > 1e-10 * d[0])) if d.size and d[0] > 0 else 0
    if rank < nc:
        keep[:] = False
        keep[jpvt[:rank] - 1] = True
    return keep


@cache
def _dgeqp3() -> Any:
    """SciPy's ``dgeqp3``, imported on first use (SciPy is slow to import) and kept (the import
    statement costs a sixth of a servo-sized factorisation)."""
    from scipy.linalg.lapack import dgeqp3

    return dgeqp3


def _choose_factor(
    G: np.ndarray, A: np.ndarray, b: np.ndarray, cert: Certificates | None
) -> tuple[int, int] | None:
    """The factor ``j`` to eliminate and its pivot row ``p`` (largest ``|a_pj|``).

    With certificates: the least weighted loosening of the certified bounds, ties broken by the
    Hausdorff estimate of :func:`_elimination_scores`; without: that estimate alone (or, when
    ``A`` has no null space, the overshoot ``R_j`` times ``‖G e_j‖``)."""
    m = A.shape[1]
    R = _overshoot(A, b)
    piv = np.argmax(np.abs(A), axis=0)
    cand = np.isfinite(R) & (np.abs(A[piv, np.arange(m)]) >= PIVOT_TOL)
    if not _any(cand):
        return None
    if cert is None:
        j = int(np.argmin(_shape(G, A, R, cand)))
        return j, int(piv[j])
    loss = cert.elimination_loss(A, b, piv, cand)
    best = np.minimum.reduce(loss)
    ties = loss <= best + 1e-9 * (1.0 + abs(best))
    if np.count_nonzero(ties) == 1:  # a unique least loss: the Hausdorff estimate is not needed
        j = int(ties.argmax())
        return j, int(piv[j])
    key = np.where(ties, _shape(G, A, R, cand), np.inf)
    if not _any(np.isfinite(key)):
        key = loss
    j = int(key.argmin())
    return j, int(piv[j])


def _shape(G: np.ndarray, A: np.ndarray, R: np.ndarray, cand: np.ndarray) -> np.ndarray:
    """The shape key of :func:`_choose_factor` on the candidates (``inf`` elsewhere): the
    Hausdorff estimate, or where it is nowhere finite the overshoot times ``‖G e_j‖``."""
    err = _hausdorff(G, A, R)
    shape = np.where(cand & np.isfinite(err), err, np.inf)
    if not _any(np.isfinite(shape)):
        with np.errstate(invalid="ignore"):  # R = inf on the non-candidates
            shape = np.where(cand, R * np.linalg.norm(G, axis=0), np.inf)
    return shape


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
        c, G, A, b, rows, cols, ok = _drop_zero_idx(c, G, A, b, own=True)
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
        if not _all(rows):  # implied constraints: dropping them keeps the set
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
        c, G, A, b, rows, cols, ok = _drop_zero_idx(c, G, A, b, own=True)
        if not ok:
            return None
        if cert is not None:
            cert.keep(rows, cols)
    return c, G, A, b
