"""Constraint elimination of constrained zonotopes ([Scott2016, Section 4.2]), on raw arrays,
every rounding bounded.

Once: normalise the constraints, rescale the factors ``ξ`` to their propagated bounds, drop
implied constraints; then, in turn, choose a factor and solve a constraint for it. Each step
returns a superset of the set it is given. With :class:`~.hull.Certificates` the factor chosen
is the one whose elimination loosens the certified interval hull least; without, the one with
the smallest estimate of the Hausdorff error ([Scott2016, eq. (A.8)]).

**Rounding.** While eliminating, the set is kept as

    {c + G ξ + ε : ‖ξ‖∞ <= 1, |A ξ − b| <= s, |ε| <= e}                                  (R)

where ``s`` (per constraint) and ``e`` (per coordinate) collect the proven bounds of every
rounding so far ([Higham2002, Lemma 3.1]; :mod:`ivobs.sets.rounding`): each computed quantity
differs from the exact one by at most ``γ_k`` times the same expression on absolute values, and
the factors are in the unit box, so the error of ``G ξ`` (``A ξ``) for the true ``ξ`` is at most
the error bound of the coefficients times ``|ξ| <= 1``. At the end the slacks become factors,
``A ξ + diag(s) τ = b`` (``|τ| <= 1``), so the result is an ordinary constrained zonotope
``⊕ box(e)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg

from ..rounding import ETA, UNIT_ROUNDOFF, down, mid_rad, product_error, up, upper
from .hull import Certificates, with_slacks
from .tolerances import PIVOT_TOL, ROW_TOL, ZERO_TOL

__all__ = ["Reduced", "eliminate_constraints", "independent_constraints", "rescale_factors"]


class Reduced(NamedTuple):
    """``<c, G, A, b> ⊕ box(e)``: a constrained zonotope and the box of its rounding."""

    c: np.ndarray
    G: np.ndarray
    A: np.ndarray
    b: np.ndarray
    e: np.ndarray


class _Set:
    """The set (R) during an elimination (module docstring), changed in place."""

    def __init__(self, c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray) -> None:
        self.c, self.G, self.A, self.b = c, G, A, b
        self.s = np.zeros(A.shape[0])
        self.e = np.zeros(c.shape[0])

    def finish(self, cert: Certificates | None) -> Reduced:
        """The slacks as factors: ``[G 0], [A diag(s)]`` (rows with ``s > 0`` only)."""
        G, A = with_slacks(self.G, self.A, self.s)
        if cert is not None:
            cert.pad(G.shape[1] - self.G.shape[1])
        return Reduced(self.c, G, A, self.b, self.e)


def _drop_zero(z: _Set, cert: Certificates | None) -> bool:
    """Drop what is negligible, keeping a superset:

    * coefficients of a constraint below :data:`ZERO_TOL` times its largest go to its slack
      (``|a_ij ξ_j| <= |a_ij|``), entries of ``G`` below ``ZERO_TOL`` times the largest of
      their row to ``e``: cancellation leaves such noise, down to subnormal numbers, which
      would fill the sparse constraints and slow every later operation;
    * constraints whose coefficients are all below :data:`ROW_TOL` (relative; after
      cancellation or rescaling they carry rounding, which normalising would amplify);
    * factors that are zero in ``G`` and ``A``.

    False when a dropped constraint cannot hold, ``|b_i| > ‖a_i‖₁ + s_i`` (rounded so that this
    is certain): the set is empty."""
    m = z.A.shape[1]
    absA = np.abs(z.A)
    noise = (absA <= ZERO_TOL * absA.max(axis=1, initial=0.0)[:, None]) & (absA > 0)
    if noise.any():
        z.s = up(z.s + upper(np.where(noise, absA, 0.0).sum(axis=1), m))
        z.A = np.where(noise, 0.0, z.A)
        absA = np.abs(z.A)
    absG = np.abs(z.G)
    noise = (absG <= ZERO_TOL * absG.max(axis=1, initial=0.0)[:, None]) & (absG > 0)
    if noise.any():
        z.e = up(z.e + upper(np.where(noise, absG, 0.0).sum(axis=1), m))
        z.G = np.where(noise, 0.0, z.G)
    scale = 1.0 + (absA.max() if absA.size else 0.0)
    rows = (absA > ROW_TOL * scale).any(axis=1)
    if not rows.all():
        reach = upper(absA[~rows].sum(axis=1) + z.s[~rows], m + 1)
        if (np.abs(z.b[~rows]) > reach).any():
            return False
        z.A, z.b, z.s = z.A[rows], z.b[rows], z.s[rows]
    cols = (z.G != 0).any(axis=0) | (z.A != 0).any(axis=0)
    if not cols.all():
        z.G, z.A = z.G[:, cols], z.A[:, cols]
    if cert is not None:
        cert.keep(rows, cols)
    return True


def _normalise_rows(z: _Set, cert: Certificates | None) -> None:
    """Scale each constraint by a power of two so that its largest coefficient is in
    ``[1, 2)`` (the same set, better conditioned; exact but for underflow, whose error, at most
    ``ETA`` per entry, goes to the slack)."""
    if z.A.shape[0] == 0:
        return
    top = np.abs(z.A).max(axis=1)
    d = np.ldexp(1.0, 1 - np.frexp(np.where(top > 0, top, 1.0))[1])
    z.A, z.b, z.s = z.A * d[:, None], z.b * d, up(z.s * d + (z.A.shape[1] + 1) * ETA)
    if cert is not None:
        cert.scale_rows(1.0 / d)


class _Entries(NamedTuple):
    """The nonzero entries of a constraint matrix ``A`` (a few percent of it once the
    constraints of many steps are in it), sorted by column: rows ``r``, columns ``c``, values
    ``a``; ``cols`` the columns that have entries and ``starts`` where each begins."""

    r: np.ndarray
    c: np.ndarray
    a: np.ndarray
    cols: np.ndarray
    starts: np.ndarray

    @classmethod
    def of(cls, A: np.ndarray) -> _Entries:
        c, r = np.nonzero(A.T)  # by column, then row
        starts = np.flatnonzero(np.diff(c, prepend=-1))
        return cls(r, c, A[r, c], c[starts], starts)

    def col_max(self, v: np.ndarray, m: int) -> np.ndarray:
        """``max`` of the entry values ``v`` over each column (``-inf`` where none)."""
        out = np.full(m, -np.inf)
        if v.size:
            out[self.cols] = np.maximum.reduceat(v, self.starts)
        return out

    def row_sum(self, v: np.ndarray, nc: int) -> np.ndarray:
        """``Σ`` of the entry values ``v`` over each row."""
        return np.bincount(self.r, weights=v, minlength=nc)


def _propagate(z: _Set, sweeps: int = 3) -> tuple[np.ndarray, np.ndarray] | None:
    """Bounds ``[lo, hi] ⊆ [-1, 1]^m`` on every ``ξ`` of (R) (constraint propagation,
    [Scott2016, Section 4.2, Algorithm 1]), or ``None`` when they prove the set empty.

    Row ``i`` gives ``a_ij ξ_j ∈ b_i ± s_i − Σ_{l≠j} a_il [ξ_l]`` for every ``j`` with ``a_ij``
    above :data:`ZERO_TOL` (the rows are normalised); all rows at once (on the nonzero entries
    of ``A``), the results intersected, ``sweeps`` times. Proof of the rounding: each end
    ``n_ij`` of that interval is a sum of at most ``m + 3`` rounded terms bounded by
    ``M_i = |b_i| + s_i + |A_i| w`` (``w = max(|lo|, |hi|)``), so it is within ``γ_{m+3} M_i``
    of its exact value, and ``|n_ij| <= M_i``; dividing by ``a_ij`` adds at most
    ``u |n_ij| / |a_ij|``. So each computed quotient is within ``(E_i + 4 u M_i) / |a_ij|`` of
    the exact one (``E_i``: :func:`product_error`, whose factor 2 absorbs the rounding of this
    pad), and the bounds are rounded outward once after the max / min over the rows."""
    A, b, s = z.A, z.b, z.s
    nc, m = A.shape
    ent = _Entries.of(A)
    r, c, a = ent.r, ent.c, ent.a
    pos, absa = a > 0, np.abs(a)
    far = np.where(absa > ZERO_TOL, 0.0, np.inf)  # a negligible coefficient: no bound
    lo, hi = -np.ones(m), np.ones(m)
    for _ in range(sweeps):
        a_lo, a_hi = a * lo[c], a * hi[c]
        t_lo, t_hi = np.where(pos, a_lo, a_hi), np.where(pos, a_hi, a_lo)  # a_ij [ξ_j]
        M = np.abs(b) + s + ent.row_sum(absa * np.maximum(np.abs(lo), np.abs(hi))[c], nc)
        pad = (product_error(M, m + 3) + (4.0 * UNIT_ROUNDOFF) * M)[r] / absa + far
        q1 = ((b - s - ent.row_sum(t_hi, nc))[r] + t_hi) / a
        q2 = ((b + s - ent.row_sum(t_lo, nc))[r] + t_lo) / a
        new_lo = down(ent.col_max(np.minimum(q1, q2) - pad, m))
        new_hi = up(-ent.col_max(-(np.maximum(q1, q2) + pad), m))
        lo_next, hi_next = np.maximum(lo, new_lo), np.minimum(hi, new_hi)
        if (lo_next > hi_next).any():
            return None
        if (lo_next == lo).all() and (hi_next == hi).all():
            break
        lo, hi = lo_next, hi_next
    return lo, hi


def _rescale(z: _Set, cert: Certificates | None) -> bool:
    """The factors rescaled to their propagated bounds, ``ξ = μ + diag(r) ξ'`` with
    ``[lo, hi] ⊆ [μ − r, μ + r]`` ([Scott2016, Section 4.2]; :func:`mid_rad`): after it more
    box constraints are redundant. ``c + G μ``, ``G diag(r)``, ``A diag(r)``, ``b − A μ`` are
    dot products of at most ``m + 1`` terms: ``e`` and ``s`` grow by their
    :func:`product_error` at ``|ξ'| <= 1``. False when propagation proves the set empty."""
    bounds = _propagate(z)
    if bounds is None:
        return False
    mu, r = mid_rad(*bounds)
    m = z.A.shape[1]
    w = np.abs(mu) + r
    z.e = up(z.e + product_error(np.abs(z.c) + np.abs(z.G) @ w, m + 1))
    z.s = up(z.s + product_error(np.abs(z.b) + np.abs(z.A) @ w, m + 1))
    z.c, z.G, z.A, z.b = z.c + z.G @ mu, z.G * r, z.A * r, z.b - z.A @ mu
    if cert is not None:
        cert.scale_factors(r)
    return True


def _eliminate(z: _Set, j: int, p: int, cert: Certificates | None) -> None:
    """Solve constraint ``p`` for ``ξ_j`` and substitute: one constraint and one factor fewer;
    the box ``|ξ_j| <= 1`` is dropped, so the result contains the original ([Scott2016,
    Proposition 5, eqs. (27) and (29)]).

    With ``a_p ξ = b_p + t`` (``|t| <= s_p``), ``ξ_j = (b_p + t − Σ_{l≠j} a_pl ξ_l) / a_pj``.
    The terms in ``t`` are bounded over ``|t| <= s_p``: ``|G_j| s_p / |a_pj|`` joins ``e``,
    ``|A_ij| s_p / |a_pj|`` joins ``s_i``. Each computed coefficient (``c + G_j (b_p / a_pj)``,
    ``G_l − G_j (a_pl / a_pj)``, likewise for ``b`` and ``A``) passes through 3 roundings: their
    :func:`product_error` at ``|ξ| <= 1`` joins ``e`` and ``s``."""
    if cert is not None:
        cert.eliminate(z.A, j, p)
    A, G, b, s = z.A, z.G, z.b, z.s
    apj = A[p, j]
    piv_row, piv_b, piv_s = A[p] / apj, b[p] / apj, up(s[p] / abs(apj))
    w = abs(piv_b) + np.abs(piv_row).sum()
    aG, aA = np.abs(G), np.abs(A)
    z.e = up(
        z.e + upper(aG[:, j] * piv_s, 1) + product_error(np.abs(z.c) + aG.sum(1) + aG[:, j] * w, 3)
    )
    s = up(s + upper(aA[:, j] * piv_s, 1) + product_error(np.abs(b) + aA.sum(1) + aA[:, j] * w, 3))
    c = z.c + G[:, j] * piv_b
    G = G - np.outer(G[:, j], piv_row)
    b = b - A[:, j] * piv_b
    A = A - np.outer(A[:, j], piv_row)
    rows, cols = np.arange(A.shape[0]) != p, np.arange(A.shape[1]) != j
    z.c, z.G, z.A, z.b, z.s = c, G[:, cols], A[np.ix_(rows, cols)], b[rows], s[rows]


def rescale_factors(c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray) -> Reduced | None:
    """``<c, G, A, b>`` with its constraints normalised and its factors rescaled to their
    propagated bounds ([Scott2016, Section 4.2]): a superset, its rounding included (the form of
    :func:`eliminate_constraints`' result), or ``None`` when propagation proves it empty."""
    z = _Set(c, G, A, b)
    _normalise_rows(z, None)
    return z.finish(None) if _rescale(z, None) else None


def independent_constraints(A: np.ndarray) -> np.ndarray:
    """Mask of a maximal set of linearly independent constraints (QR with pivoting of ``Aᵀ``).

    The others are linear combinations of these: implied when the set is nonempty, so dropping
    them keeps the set (and gives a superset if rounding made them slightly inconsistent)."""
    nc = A.shape[0]
    keep = np.ones(nc, dtype=bool)
    if nc <= 1:
        return keep
    R, piv = scipy.linalg.qr(A.T, mode="r", pivoting=True, check_finite=False)
    d = np.abs(np.diagonal(R)[:nc])
    rank = int(np.count_nonzero(d > 1e-10 * d[0])) if d.size and d[0] > 0 else 0
    if rank < nc:
        keep[:] = False
        keep[piv[:rank]] = True
    return keep


def _overshoot(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """For each ``ξ_j``, how far the constraints alone let it leave ``[-1, 1]``:
    ``R_j = max(0, max|ρ_j| - 1)`` with ``ρ_j = ∩_i (b_i - Σ_{l≠j} a_il [-1, 1]) / a_ij``
    (``inf``: ``ξ_j`` is in no constraint; 0: its box is redundant and eliminating it is
    exact). A score, not a bound: no rounding to bound."""
    m = A.shape[1]
    absA = np.abs(A)
    ent = _Entries.of(np.where(absA > ZERO_TOL, A, 0.0))
    absa = np.abs(ent.a)
    row_l1 = absA.sum(axis=1)
    spread = (row_l1[ent.r] - absa) / absa
    mid = b[ent.r] / ent.a
    rho_lo = ent.col_max(mid - spread, m)
    rho_hi = -ent.col_max(-(mid + spread), m)
    R: np.ndarray = np.maximum(0.0, np.maximum(-1.0 - rho_lo, rho_hi - 1.0))
    return R


def _hausdorff(G: np.ndarray, A: np.ndarray, R: np.ndarray) -> np.ndarray:
    """An estimate of the Hausdorff error of eliminating each ``ξ_j`` ([Scott2016, Section 4.2
    and eq. (A.8)]): dropping ``|ξ_j| <= 1`` lets ``ξ_j`` move by about ``R_j`` along the
    constraints' null space, so ``‖G δ_j‖₂`` for the shortest such move ``δ_j = R_j P e_j /
    P_jj`` (``P`` the projector onto the null space of ``A``, from one QR factorisation of
    ``Aᵀ``). 0 on the exact eliminations (``R_j <= 1e-3``) when there are any; ``inf`` where
    there is no estimate."""
    cand = np.isfinite(R)
    exact = cand & (R <= 1e-3)
    if exact.any():
        return np.where(exact, 0.0, np.inf)
    with np.errstate(all="ignore"):
        Q = np.linalg.qr(A.T)[0]  # orthonormal basis of the row space of A
        Pjj = 1.0 - np.einsum("ij,ij->i", Q, Q)
        GP = G - (G @ Q) @ Q.T  # G P, column j = G P e_j
        move = np.linalg.norm(GP, axis=0) * R / Pjj
    ok = cand & (Pjj > 1e-12) & np.isfinite(move)
    out: np.ndarray = np.where(ok, move, np.inf)
    return out


def _choose_factor(
    G: np.ndarray, A: np.ndarray, b: np.ndarray, cert: Certificates | None
) -> tuple[int, int] | None:
    """The factor ``j`` to eliminate and its pivot row ``p``.

    With certificates: the least weighted loosening of the certified bounds, ties broken by the
    Hausdorff estimate; without: that estimate alone (or, when ``A`` has no null space, the
    overshoot ``R_j`` times ``‖G e_j‖``).

    The pivot row of ``ξ_j`` is the one with the largest ``|a_pj|``; without certificates,
    relative to the row's largest coefficient, ``|a_pj| / max_l |a_pl|`` (the rows are scaled
    by powers of two, their largest coefficient anywhere in ``[1, 2)``, so the absolute
    ``|a_pj|`` would prefer a row for its scale, not for ``ξ_j``'s weight in it: on
    ``cora-pedestrian4`` that choice alone widens the ``nl-constrained-zonotope`` boxes by
    about 2 %). With certificates the loss of each pair ``(j, p)`` is measured and the
    absolute rule is kept. Only the choice changes: every pivot gives a superset."""
    m = A.shape[1]
    R = _overshoot(A, b)
    absA = np.abs(A)
    if cert is None:  # the rows are normalised: none is zero
        absA = absA / absA.max(axis=1)[:, None]
    piv = np.argmax(absA, axis=0)
    cand = np.isfinite(R) & (absA[piv, np.arange(m)] >= PIVOT_TOL)
    if not cand.any():
        return None
    if cert is not None:
        loss = cert.elimination_loss(A, b, piv, cand)
        best = loss.min()
        ties = loss <= best + 1e-9 * (1.0 + abs(best))
        if np.count_nonzero(ties) == 1:
            j = int(ties.argmax())
            return j, int(piv[j])
        cand = cand & ties
    # an exact elimination anywhere (R_j <= 1e-3, not only among the candidates) makes the
    # overshoot times the generator's norm decide (below): over the tied candidates alone,
    # the Hausdorff estimate lets CORA's pedestrian drift to twice the exact hull at 6 nx
    # constraints and 8 nx generators
    shape = np.where(cand, _hausdorff(G, A, R), np.inf)
    if not np.isfinite(shape).any():
        with np.errstate(invalid="ignore"):  # R = inf on the non-candidates
            shape = np.where(cand, R * np.linalg.norm(G, axis=0), np.inf)
    j = int(shape.argmin())
    return j, int(piv[j])


def eliminate_constraints(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    max_constraints: int,
    cert: Certificates | None = None,
) -> Reduced | None:
    """At most ``max_constraints`` constraints ([Scott2016, Section 4.2]): rescale the factors
    to their propagated bounds and drop implied constraints, then, in turn, choose a factor and
    eliminate it with the constraint where it has the largest coefficient (propagating again
    between eliminations bounds the factors no better on the benchmarks, and an elimination
    keeps the other constraints independent). The factor is the one with the least loss of
    the certified bounds ``cert`` (:class:`Certificates`, updated in place), or without
    certificates the one with the smallest Hausdorff-error estimate.

    Returns ``<c', G', A', b'> ⊕ box(e)`` containing ``<c, G, A, b>`` in exact arithmetic (the
    slacks of the module docstring as last factors), or ``None`` when the set is found empty on
    the way."""
    z = _Set(c, G, A, b)
    if not _drop_zero(z, cert):
        return None
    if z.A.shape[0] <= max_constraints:
        return z.finish(cert)
    # once: the propagated bounds and the implied constraints (an elimination keeps the other
    # rows independent: it is a row operation followed by the removal of the pivot row)
    _normalise_rows(z, cert)
    if not _rescale(z, cert) or not _drop_zero(z, cert):
        return None
    _normalise_rows(z, cert)
    rows = independent_constraints(z.A)
    if not rows.all():  # implied constraints: dropping them keeps the set
        z.A, z.b, z.s = z.A[rows], z.b[rows], z.s[rows]
        if cert is not None:
            cert.keep(rows, np.ones(z.A.shape[1], dtype=bool))
    while z.A.shape[0] > max_constraints:
        _normalise_rows(z, cert)
        choice = _choose_factor(z.G, z.A, z.b, cert)
        if choice is None:  # no usable pivot: drop the oldest constraint (a superset)
            rows = np.arange(z.A.shape[0]) != 0
            z.A, z.b, z.s = z.A[rows], z.b[rows], z.s[rows]
            if cert is not None:
                cert.keep(rows, np.ones(z.A.shape[1], dtype=bool))
            continue
        _eliminate(z, *choice, cert)
        if not _drop_zero(z, cert):
            return None
    return z.finish(cert)
