"""Order reduction of a zonotope's generator matrix, compiled by numba when it is installed.

Both keep at most ``order`` generators (``order >= n``) and enclose the exact zonotope,
rounding included:

* :func:`reduce_girard` ([Girard2005], CORA's default): the generators cheapest to box
  (smallest ``‖g‖₁ - ‖g‖∞``) are enclosed in the box of their absolute row sums.
* :func:`reduce_parallelotope` ([Chisci1998]'s parallelotope rule): the generators to remove
  are absorbed into a basis of ``n`` large, independent ones, when that basis is well
  conditioned (else Girard's box).

Loops over raw arrays (:mod:`ivobs._jit`): the same source runs interpreted without numba.
"""

from __future__ import annotations

import math

import numpy as np

from .._jit import jit
from .rounding import ETA
from .strip import _gamma, _upper
from .zonotope import MAX_BASIS_CONDITION

__all__ = ["MAX_BASIS_CONDITION", "reduce_girard", "reduce_parallelotope"]


@jit
def reduce_girard(G: np.ndarray, order: int) -> np.ndarray:
    """At most ``order`` generators by [Girard2005]'s rule: the ``m - order + n`` generators
    with the smallest ``‖g‖₁ - ‖g‖∞`` (what boxing ``g`` costs: nothing for a generator along
    an axis) are enclosed in the box ``diag(Σ |g|)``, its sums rounded up, so ``<0, G> ⊆ <0,
    G'>`` exactly."""
    n, m = G.shape
    if m <= order:
        return G
    n_rm = m - order + n
    key = np.empty(m)
    for col in range(m):
        total = big = 0.0
        for r in range(n):
            total += abs(G[r, col])
            big = max(big, abs(G[r, col]))
        key[col] = total - big
    idx = np.argsort(key, kind="mergesort")
    kept = np.sort(idx[n_rm:])
    out = np.zeros((n, kept.shape[0] + n))
    for r in range(n):
        for k in range(kept.shape[0]):
            out[r, k] = G[r, kept[k]]
        box = 0.0
        for k in range(n_rm):
            box += abs(G[r, idx[k]])
        out[r, kept.shape[0] + r] = _upper(box, n_rm)
    return out


@jit
def _greedy_basis(G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gram-Schmidt with column pivoting on the generators (the columns of ``G``, ``n <= m``):
    at each step the generator of largest norm orthogonal to those chosen. Returns ``(piv,
    R)``: the permutation (basis first) and ``R`` (``n x m``) with ``G[:, piv] = Q R``, ``Q``
    orthonormal, ``R[:, :n]`` upper triangular; a zero diagonal when the generators do not
    span the space. The loops run along the rows of ``G`` (contiguous, vectorised)."""
    n, m = G.shape
    A = G.copy()
    piv = np.arange(m)
    R = np.zeros((n, m))
    q = np.empty(n)
    rc = np.empty(m)
    norm2 = np.zeros(m)  # squared norms of the parts orthogonal to the basis (downdated)
    for r in range(n):
        for c in range(m):
            norm2[c] += A[r, c] * A[r, c]
    fresh = norm2.copy()  # each norm when last computed afresh
    for i in range(n):
        at = i
        for c in range(i + 1, m):
            if norm2[c] > norm2[at]:
                at = c
        if at != i:
            for r in range(n):
                A[r, i], A[r, at] = A[r, at], A[r, i]
            for k in range(i):
                R[k, i], R[k, at] = R[k, at], R[k, i]
            piv[i], piv[at] = piv[at], piv[i]
            norm2[i], norm2[at] = norm2[at], norm2[i]
            fresh[i], fresh[at] = fresh[at], fresh[i]
        d = 0.0
        for r in range(n):  # the chosen norm afresh (the others are downdated)
            d += A[r, i] * A[r, i]
        d = math.sqrt(d)
        R[i, i] = d
        if d == 0.0:
            return piv, R
        for r in range(n):
            q[r] = A[r, i] / d
        rc[i + 1 :] = 0.0
        for r in range(n):
            qr, Ar = q[r], A[r]
            for c in range(i + 1, m):
                rc[c] += qr * Ar[c]
        for r in range(n):
            qr, Ar = q[r], A[r]
            for c in range(i + 1, m):
                Ar[c] -= rc[c] * qr
        for c in range(i + 1, m):  # only the pivots' choice depends on them
            norm2[c] -= rc[c] * rc[c]
            if norm2[c] <= 1e-6 * fresh[c]:  # cancelled: computed afresh
                norm2[c] = 0.0
                for r in range(n):
                    norm2[c] += A[r, c] * A[r, c]
                fresh[c] = norm2[c]
        R[i, i + 1 :] = rc[i + 1 :]
    return piv, R


@jit
def reduce_parallelotope(G: np.ndarray, order: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ``order`` generators, absorbed into a basis of ``n`` generators
    ([Chisci1998]); returns ``(G', ρ)`` with ``<0, G> ⊆ <0, G'> ⊕ box(ρ)`` exactly.

    The basis ``P`` is chosen greedily (:func:`_greedy_basis`). Each generator ``l`` has
    coordinates ``α = P⁻¹ l`` in it, and ``P ξ_P + Σ_k l_k ξ_k = P (ξ_P + Σ_k α_k ξ_k) + Σ_k (l_k -
    P α_k) ξ_k``, so the removed ones (smallest ``‖α‖₁``) rescale the basis, ``P diag(1 +
    Σ_k |α_k|)``, and leave the box ``ρ >= Σ_k |l_k - P α_k|``: exact for whatever ``α`` the
    floats give, so soundness does not rest on the basis' accuracy. ``ρ`` adds the rounding of
    ``l - P α`` (``γ_{n+1} (|l| + |P| |α|)``) and of the scaled basis (``u |P| scale``), the
    scale factors are rounded up. The basis is picked among the generators, and the strip
    updates and the prediction can make it nearly dependent: the factors ``|α|`` then grow
    step after step (CORA's tank30 at ``order = 2 nx`` reached boxes of 10⁷), so a basis whose
    ``|R_11| / |R_nn|`` exceeds :data:`MAX_BASIS_CONDITION` is not used: Girard's box instead."""
    n, m = G.shape
    if m <= order:
        return G, np.zeros(n)
    piv, R = _greedy_basis(G)
    if not R[n - 1, n - 1] * MAX_BASIS_CONDITION >= R[0, 0] > 0.0:
        return reduce_girard(G, order), np.zeros(n)
    n_oth = m - n
    alpha = R[:, n:].copy()  # R_11⁻¹ R_12 by back substitution
    for q in range(n - 1, -1, -1):
        for k in range(n_oth):
            alpha[q, k] /= R[q, q]
        for r in range(q):
            f = R[r, q]
            for k in range(n_oth):
                alpha[r, k] -= f * alpha[q, k]
    norms = np.zeros(n_oth)
    for q in range(n):
        for k in range(n_oth):
            norms[k] += abs(alpha[q, k])
    srt = np.argsort(norms, kind="mergesort")
    n_rm = m - order
    a1 = np.zeros(n)  # Σ_k |α_k| over the removed
    for q in range(n):
        for k in range(n_rm):
            a1[q] += abs(alpha[q, srt[k]])
    scale = np.empty(n)
    for q in range(n):
        scale[q] = _upper(1.0 + a1[q], n_rm + 1)
    rm = srt[:n_rm]
    P = np.empty((n, n))  # the basis, the removed generators and their coordinates, gathered
    L = np.empty((n, n_rm))
    a_rm = np.empty((n, n_rm))
    for r in range(n):
        for q in range(n):
            P[r, q] = G[r, piv[q]]
        for k in range(n_rm):
            L[r, k] = G[r, piv[n + rm[k]]]
    for q in range(n):
        for k in range(n_rm):
            a_rm[q, k] = alpha[q, rm[k]]
    g = _gamma(n + 1)
    rho = np.empty(n)
    out = np.empty((n, m - n_rm))
    pa, pa_abs = np.empty(n_rm), np.empty(n_rm)
    for r in range(n):
        pa[:] = 0.0
        pa_abs[:] = 0.0
        for q in range(n):  # (P α)_r and (|P| |α|)_r for every removed generator
            prq = P[r, q]
            for k in range(n_rm):
                pa[k] += prq * a_rm[q, k]
                pa_abs[k] += abs(prq) * abs(a_rm[q, k])
        res = mag = 0.0
        for k in range(n_rm):
            res += abs(L[r, k] - pa[k])
            mag += abs(L[r, k]) + pa_abs[k]
        p_scale = 0.0
        for q in range(n):
            out[r, q] = P[r, q] * scale[q]
            p_scale += abs(P[r, q]) * scale[q]
        rho[r] = _upper(res + 2.0 * g * mag + 2.0 * _gamma(1) * p_scale, n_rm + n + 3) + (
            n_rm * (n + 1) * ETA  # the underflow of the products P α
        )
        for k in range(n_rm, n_oth):
            out[r, n + k - n_rm] = G[r, piv[n + srt[k]]]
    return out, rho
