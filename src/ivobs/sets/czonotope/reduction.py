"""Generator reduction of constrained zonotopes ([Scott2016, Section 4.3]), on raw arrays.

The lifted zonotope ``<[c; -b], [G; A]>`` is reduced, so the ``x`` part and the constraints shrink
together and the constrained zonotope it represents contains the original. Removed generators are
absorbed by a parallelotope ([Chisci1998]); what the basis misses, and the rounding of every
step, go to a box ([Higham2002, Lemma 3.1] bounds).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg

from ..rounding import ETA, UNIT_ROUNDOFF, gamma, upper
from ..zonotope import MAX_BASIS_CONDITION, reduce_girard

__all__ = ["consolidate_small", "reduce_generators"]


def consolidate_small(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray, tol_x: float, tol_c: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Replace the generators that are small in both parts (``|G_j| <= tol_x`` and
    ``|A_j| <= tol_c``: the rounding slacks and boxes of earlier steps, factors pinned down by
    rescaling) by two boxes: ``diag(Σ_j |G_j|)`` in ``x`` and ``diag(Σ_j |A_j|)`` in the
    constraints (a slack per row). The segment ``{(G_j; A_j) t}`` lies in the sum of the two,
    so the result contains the original (only correlations between rows of the replaced
    factors are lost); at most ``n + nc`` columns are left of them (the sums rounded up,
    :func:`~ivobs.sets.rounding.upper`). Dropping them instead would give a subset."""
    n, m = G.shape
    if m == 0:
        return c, G, A, b
    small = (np.abs(G) <= tol_x).all(axis=0)
    if A.shape[0]:
        small &= (np.abs(A) <= tol_c).all(axis=0)
    k = int(small.sum())
    if k <= 1:
        return c, G, A, b
    gx = upper(np.abs(G[:, small]).sum(axis=1), k)
    ga = upper(np.abs(A[:, small]).sum(axis=1), k)
    ix, ia = (gx > 0).nonzero()[0], (ga > 0).nonzero()[0]
    if ix.size + ia.size >= k:
        return c, G, A, b
    nc = A.shape[0]
    Gb = np.zeros((n, ix.size + ia.size))
    Ab = np.zeros((nc, ix.size + ia.size))
    Gb[ix, np.arange(ix.size)] = gx[ix]
    Ab[ia, ix.size + np.arange(ia.size)] = ga[ia]
    return c, np.concatenate([G[:, ~small], Gb], 1), np.concatenate([A[:, ~small], Ab], 1), b


def reduce_generators(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    max_generators: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """At most ``max_generators`` generators, by reducing the lifted zonotope
    ``<[c; -b], [G; A]>`` ([Scott2016, Section 4.3]; its ``x`` part and constraint part
    shrink together, so the constrained zonotope it represents contains the original).

    The lifted generators ``L = [G; A]`` (``N = n + nc`` rows) are first equilibrated by
    powers of two, ``D L`` (exact: only exponents change), so that the choice and the
    conditioning of the basis do not depend on the units of the states or the scaling of the
    constraint rows; the result is scaled back by ``D⁻¹``, exactly again. Then a parallelotope
    enclosure ([Chisci1998]; :func:`_absorb_in_basis`), or, when the ``N`` pivots of the QR
    with column pivoting are ill-conditioned (estimate above
    :data:`~ivobs.sets.zonotope.MAX_BASIS_CONDITION`) or do not span the lifted space,
    [Girard2005]'s box (:func:`~ivobs.sets.zonotope.reduce_girard`, as the strip method).
    An ill-conditioned basis is what lets the scale factors grow step after step without
    bound. Either way the result contains the original in exact arithmetic, whatever the
    rounding, and no box is left aside.

    At least ``N`` generators are kept, whatever ``max_generators``."""
    n, m = G.shape
    N = n + A.shape[0]
    order = max(int(max_generators), N)
    if m <= order:
        return c, G, A, b
    # the same array as the vstack when there are no constraints (the nonlinear zonotope)
    L = G if not A.shape[0] and G.flags.c_contiguous else np.vstack([G, A])
    d = _pow2_scaling(L)
    Ls = L * d[:, None] if d is not None else L
    L2 = _absorb_in_basis(Ls, order)
    if L2 is None:
        L2 = reduce_girard(Ls, order)
    if d is not None:
        back = L2 / d[:, None]
        if _exactly_scaled(back, L2):
            L2 = back
        else:  # an entry would leave the normal range: reduce the unscaled matrix instead
            L2 = _absorb_in_basis(L, order)
            L2 = reduce_girard(L, order) if L2 is None else L2
    return c, L2[:n], L2[n:], b


_TINY = float(np.finfo(float).tiny)


def _pow2_scaling(L: np.ndarray) -> np.ndarray | None:
    """Powers of two ``d`` with ``max_j |d_i L_ij|`` in ``[1, 2)`` (zero rows: 1), or ``None``
    when scaling an entry would leave the normal range (then it would not be exact)."""
    aL = np.abs(L)
    v = aL.max(axis=1)
    if not np.isfinite(v).all():  # an inf or a NaN
        return None
    e = np.where(v > 0, 1 - np.frexp(v)[1], 0)
    if (e > 1023).any():  # a subnormal row: its scale overflows
        return None
    scale = np.ldexp(1.0, e)
    # no entry can overflow (the largest lands in [1, 2)); the smallest nonzero one of each
    # row must stay normal (rounding is monotone: the smallest scaled entry is the scaled
    # smallest one) — the same test as _exactly_scaled(L * d, L), without forming L * d
    smallest = np.where(aL > 0, aL, np.inf).min(axis=1)
    return scale if bool((smallest * scale >= _TINY).all()) else None


def _exactly_scaled(S: np.ndarray, M: np.ndarray) -> bool:
    """Whether ``S`` (``M`` scaled by powers of two) was computed exactly: every entry finite
    and normal or zero where ``M`` is zero."""
    aS = np.abs(S)
    if not np.isfinite(aS.max(initial=0.0)):  # an inf or a NaN
        return False
    return bool(np.where(M != 0, aS, np.inf).min(initial=np.inf) >= _TINY)


def _absorb_in_basis(L: np.ndarray, order: int) -> np.ndarray | None:
    """``order >= N`` generators ``L'`` with ``<0, L> ⊆ <0, L'>`` in exact arithmetic, by a
    parallelotope enclosure ([Chisci1998]), or ``None`` when the basis is ill-conditioned.

    The basis ``P`` (``N`` generators) is chosen by QR with column pivoting; its condition
    estimate ``|R_11| / |R_NN|`` must be at most
    :data:`~ivobs.sets.zonotope.MAX_BASIS_CONDITION`. Each generator ``l`` to remove has
    coordinates ``α = P⁻¹ l`` and ``<0, [P, l]> ⊆ <0, P diag(1 + |α|)>``; those with the
    smallest ``‖α‖₁`` are removed: ``<0, L> ⊆ <0, [P diag(s₀), L_kept]> ⊕ box(ρ)``
    with ``s₀ >= 1 + Σ|α|`` (rounded up) and ``ρ >= Σ |l - P α|`` (evaluated, plus the bound
    ``γ_{N+2} (|l| + |P| |α|)`` of its rounding, [Higham2002, Lemma 3.1]). The box and the
    rounding of the product ``P diag(t)`` itself are then absorbed by the basis:
    with ``X ≈ P⁻¹``, ``θ >= ‖I - X P‖∞ < 1/2``, ``|P⁻¹ v| <= τ`` on ``box(ρ)``
    (:func:`_box_in_basis`) and ``μ >= u ‖|P⁻¹| |P|‖∞``, the computed
    ``P' = fl(P diag(t))`` is ``P (diag(t) + F)`` with ``|F diag(t)⁻¹| <= u |P⁻¹| |P|``,
    so ``t = z + μ / (1 - μ) ‖z‖∞``, ``z = s₀ + τ``, gives ``<0, P diag(s₀)> ⊕ box(ρ) ⊆
    <0, P'>`` (a Neumann-series bound on ``(I + F diag(t)⁻¹)⁻¹``)."""
    N, m = L.shape
    if m <= order:
        return L
    if m < N:
        return None
    R, jpvt = scipy.linalg.qr(L, mode="r", pivoting=True, check_finite=False)
    r_first, r_last = abs(float(R[0, 0])), abs(float(R[N - 1, N - 1]))
    if not r_last * MAX_BASIS_CONDITION >= r_first > 0.0:
        return None
    basis, others = jpvt[:N], jpvt[N:]
    alpha = scipy.linalg.solve_triangular(R[:N, :N], R[:N, N:], check_finite=False)
    if not np.isfinite(alpha).all():
        return None
    srt = np.abs(alpha).sum(axis=0).argsort(kind="stable")
    n_rm = m - order
    rm, kept = srt[:n_rm], others[srt[n_rm:]]
    P, a_rm, L_rm = L[:, basis], alpha[:, rm], L[:, others[rm]]
    a1 = np.abs(a_rm).sum(axis=1)
    rho = upper(
        np.abs(L_rm - P @ a_rm).sum(axis=1)
        + gamma(N + 2) * (np.abs(L_rm).sum(axis=1) + np.abs(P) @ a1),
        n_rm + 3,
    )
    absorbed = _box_in_basis(P, rho)
    if absorbed is None:
        return None
    tau, mu = absorbed
    z = upper(upper(1.0 + a1, n_rm + 1) + tau, 1)
    t = upper(z + mu / (1.0 - mu) * float(z.max()), 4)
    return np.concatenate([P * t, L[:, kept]], axis=1)


def _box_in_basis(P: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, float] | None:
    """``(τ, μ)`` with ``τ >= 0``, ``box(ρ) ⊆ <0, P diag(τ)>`` and ``μ >= u ‖|P⁻¹| |P|‖∞``
    (plus the bound of an underflow in ``P diag(t)``, ``t >= 1``) for a square invertible
    ``P``, verified in floating point, or ``None`` (``P`` too ill-conditioned to verify).

    ``v ∈ box(ρ)`` has coordinates ``P⁻¹ v``. With ``X ≈ P⁻¹`` and ``θ >= ‖I - X P‖∞`` (the
    computed residual plus the bound ``γ_{n+1} (I + |X| |P|)`` of its rounding), ``θ < 1/2``
    gives ``P⁻¹ v = X v + (I - X P) P⁻¹ v``, so
    ``|P⁻¹ v| <= |X| ρ + θ / (1 - θ) ‖|X| ρ‖∞``, and ``P⁻¹ = X + (I - X P) P⁻¹`` gives
    ``‖|P⁻¹| |P|‖∞ <= ‖|X| |P|‖∞ / (1 - θ)`` (Skeel's condition number, invariant to the scaling
    of the columns; Neumann-series bounds, as in verified linear algebra)."""
    n = P.shape[0]
    try:
        X = np.linalg.inv(P)
    except np.linalg.LinAlgError:
        return None
    if not np.isfinite(X).all():
        return None
    aX, aP = np.abs(X), np.abs(P)
    eye = np.eye(n)
    aXaP = aX @ aP
    theta = float(upper((np.abs(eye - X @ P) + gamma(n + 1) * (eye + aXaP)).sum(axis=1).max(), n))
    if not theta < 0.5:
        return None
    skeel = float(upper(aXaP.sum(axis=1).max(), 2 * n + 2))  # >= ‖|X| |P|‖∞ (exact)
    nX = float(upper(aX.sum(axis=1).max(), n))
    mu = float(upper((UNIT_ROUNDOFF * skeel + nX * n * 2.0 * ETA) / (1.0 - theta), 4))
    if not mu < 0.5:
        return None
    v = upper(aX @ rho, n)
    tau: np.ndarray = upper(v + theta / (1.0 - theta) * float(v.max()), 4)
    return tau, mu


def reduce_consolidated(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    max_generators: int,
    tols: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`consolidate_small` with tolerances relative to the set (``tols = (tx, tc)``:
    ``tx (1 + max |c|)`` for generators, ``tc max |A|`` for constraint entries), then
    :func:`reduce_generators` to at most ``max_generators``: the last stage of every prediction
    of the constrained-zonotope filters (linear and nonlinear)."""
    tol_x = tols[0] * (1.0 + float(np.abs(c).max(initial=0.0)))
    tol_c = tols[1] * float(np.abs(A).max(initial=0.0))
    c, G, A, b = consolidate_small(c, G, A, b, tol_x, tol_c)
    return reduce_generators(c, G, A, b, max_generators)
