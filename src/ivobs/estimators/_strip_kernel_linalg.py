"""Linear algebra of the strip method's compiled step (numba, issue 17): the order reductions
of ``sets/zonotope.py`` as loops, with a Householder QR with column pivoting after LAPACK's
``dlaqp2`` (the parallelotope rule's basis [Chisci1998]; Girard's box [Girard2005]), and the
``γ_n`` bound ([Higham2002, Lemma 3.1]) and the partial-sum helpers. Rounding: see
:mod:`._strip_kernel_nb` (the same margins, valid for any order of the sums)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
from numba import njit

Arr = Any  # a NumPy array inside numba
F = TypeVar("F", bound=Callable[..., Any])

U = 2.0**-53  # UNIT_ROUNDOFF
TOL3Z = float(np.sqrt(U))  # LAPACK dlaqp2's sqrt(dlamch('Epsilon'))
SAFMIN = 2.2250738585072014e-308 / U  # dlarfg's dlamch('S') / dlamch('E')
MAX_COND = 1e3  # sets.zonotope.MAX_BASIS_CONDITION (tests/test_strip_kernel.py checks it)


def jit(f: F) -> F:
    """``numba.njit(cache=True)``: compiled once and cached on disk; no ``fastmath`` (IEEE
    semantics: no reassociation, no contraction into FMA)."""
    return cast(F, njit(cache=True)(f))


@jit
def _g(n: int) -> float:  # ivobs.linalg.gamma
    nu = n * U
    if not nu < 0.5:
        return np.inf
    return nu / (1.0 - nu)


@jit
def _asum(x: Arr, n: int) -> float:
    """``Σ_{l<n} |x_l|`` with four partial sums (γ_n holds in any order; no fastmath, so the
    compiler does not reorder a single chain and would leave it latency-bound)."""
    a0 = a1 = a2 = a3 = 0.0
    k = 0
    while k + 4 <= n:
        a0 += abs(x[k])
        a1 += abs(x[k + 1])
        a2 += abs(x[k + 2])
        a3 += abs(x[k + 3])
        k += 4
    while k < n:
        a0 += abs(x[k])
        k += 1
    return (a0 + a1) + (a2 + a3)


@jit
def _dot(x: Arr, y: Arr, n: int) -> float:
    """``Σ_{l<n} x_l y_l`` with four partial sums (as :func:`_asum`)."""
    a0 = a1 = a2 = a3 = 0.0
    k = 0
    while k + 4 <= n:
        a0 += x[k] * y[k]
        a1 += x[k + 1] * y[k + 1]
        a2 += x[k + 2] * y[k + 2]
        a3 += x[k + 3] * y[k + 3]
        k += 4
    while k < n:
        a0 += x[k] * y[k]
        k += 1
    return (a0 + a1) + (a2 + a3)


@jit
def _reduce_girard(G: Arr, order: int) -> Arr:
    """sets.zonotope.reduce_girard."""
    n, m = G.shape
    if m <= order:
        return G
    n_rm = m - order + n
    key = np.empty(m)
    for c in range(m):
        sm = mx = 0.0
        for r in range(n):
            sm += abs(G[r, c])
            mx = max(mx, abs(G[r, c]))
        key[c] = sm - mx
    idx = np.argsort(key, kind="mergesort")
    kept = np.sort(idx[n_rm:])
    out = np.zeros((n, kept.shape[0] + n))
    g = 1.0 + _g(n_rm + 1)
    for r in range(n):
        for k in range(kept.shape[0]):
            out[r, k] = G[r, kept[k]]
        bx = 0.0
        for k in range(n_rm):
            bx += abs(G[r, idx[k]])
        out[r, kept.shape[0] + r] = bx * g
    return out


@jit
def _nrm2(x: Arr) -> float:
    """‖x‖₂, scaled when the squares could overflow or underflow."""
    amax = 0.0
    for v in x:
        amax = max(amax, abs(v))
    if amax == 0.0 or not amax < np.inf:
        return amax
    s = 0.0
    if 1e-150 < amax < 1e150:
        for v in x:
            s += v * v
        return math.sqrt(s)
    for v in x:
        t = v / amax
        s += t * t
    return amax * math.sqrt(s)


@jit
def _lapy2(x: float, y: float) -> float:  # LAPACK dlapy2
    w, v = max(abs(x), abs(y)), min(abs(x), abs(y))
    if v == 0.0 or w > 1.7976931348623157e308:
        return w
    q = v / w
    return w * math.sqrt(1.0 + q * q)


@jit
def _larfg(A: Arr, i: int) -> float:
    """LAPACK dlarfg on ``alpha = A[i, i]``, ``x = A[i+1:, i]`` in place; returns ``tau``."""
    n = A.shape[0]
    xnorm = _nrm2(A[i + 1 :, i])
    if xnorm == 0.0:
        return 0.0
    alpha = A[i, i]
    beta = -np.copysign(_lapy2(alpha, xnorm), alpha)
    knt = 0
    if abs(beta) < SAFMIN:
        while True:
            knt += 1
            for r in range(i + 1, n):
                A[r, i] /= SAFMIN
            beta /= SAFMIN
            alpha /= SAFMIN
            if not (abs(beta) < SAFMIN and knt < 20):
                break
        beta = -np.copysign(_lapy2(alpha, _nrm2(A[i + 1 :, i])), alpha)
    tau = (beta - alpha) / beta
    f = 1.0 / (alpha - beta)
    for r in range(i + 1, n):
        A[r, i] *= f
    for _ in range(knt):
        beta *= SAFMIN
    A[i, i] = beta
    return float(tau)


@jit
def _pivoted_qr(A: Arr) -> Arr:
    """Householder QR with column pivoting of ``A`` (n x m, n <= m) in place, as LAPACK's
    ``dlaqp2`` (``dgeqp3`` below its block size): the column of largest remaining norm first,
    norms downdated and recomputed where cancellation spoils them. Returns the permutation;
    ``R`` is the upper triangle of ``A``. The reflections are applied row by row (``w = vᵀ C``
    accumulated over the rows, vectorised over the columns)."""
    n, m = A.shape
    jpvt = np.arange(m)
    vn1 = np.empty(m)
    for c in range(m):
        vn1[c] = _nrm2(A[:, c])
    vn2 = vn1.copy()
    w = np.empty(m)
    for i in range(n):
        pvt = i
        for c in range(i + 1, m):
            if vn1[c] > vn1[pvt]:
                pvt = c
        if pvt != i:
            for r in range(n):
                A[r, i], A[r, pvt] = A[r, pvt], A[r, i]
            jpvt[i], jpvt[pvt] = jpvt[pvt], jpvt[i]
            vn1[pvt], vn2[pvt] = vn1[i], vn2[i]
        tau = _larfg(A, i) if i < n - 1 else 0.0
        if tau != 0.0:  # dlarf: C -= tau v (vᵀ C) on the remaining columns, v = (1, A[i+1:, i])
            w[i + 1 :] = A[i, i + 1 :]
            for r in range(i + 1, n):
                vr = A[r, i]
                for c in range(i + 1, m):
                    w[c] += vr * A[r, c]
            for c in range(i + 1, m):
                w[c] *= -tau
            for c in range(i + 1, m):
                A[i, c] += w[c]
            for r in range(i + 1, n):
                vr = A[r, i]
                for c in range(i + 1, m):
                    A[r, c] += vr * w[c]
        for c in range(i + 1, m):
            if vn1[c] != 0.0:
                q = abs(A[i, c]) / vn1[c]
                temp = max(1.0 - q * q, 0.0)
                q = vn1[c] / vn2[c]
                if temp * q * q <= TOL3Z:
                    vn1[c] = _nrm2(A[i + 1 :, c]) if i < n - 1 else 0.0
                    vn2[c] = vn1[c]
                else:
                    vn1[c] = vn1[c] * math.sqrt(temp)
    return jpvt


@jit
def _reduce_parallelotope(G: Arr, order: int) -> tuple[Arr, Arr]:
    """sets.zonotope.reduce_parallelotope: ``(G', ρ)`` with ``<0, G> ⊆ <0, G'> ⊕ box(ρ)``."""
    n, m = G.shape
    if m <= order:
        return G, np.zeros(n)
    A = G.copy()
    piv = _pivoted_qr(A)
    d0, dn = abs(A[0, 0]), abs(A[n - 1, n - 1])
    ok = dn * MAX_COND >= d0 > 0.0
    for r in range(n):
        ok = ok and A[r, r] != 0.0  # dtrtrs' singularity check
    if not ok:
        return _reduce_girard(G, order), np.zeros(n)
    k_oth = m - n
    alpha = np.ascontiguousarray(A[:, n:])
    for kk in range(n - 1, -1, -1):  # R11⁻¹ R12 by back substitution, all columns at once
        d = A[kk, kk]
        for k in range(k_oth):
            alpha[kk, k] /= d
        for r in range(kk):
            f = A[r, kk]
            for k in range(k_oth):
                alpha[r, k] -= f * alpha[kk, k]
    norms = np.zeros(k_oth)
    for r in range(n):
        for k in range(k_oth):
            norms[k] += abs(alpha[r, k])
    srt = np.argsort(norms, kind="mergesort")
    n_rm = m - order
    basis = piv[:n]
    a1 = np.zeros(n)
    for r in range(n):
        for k in range(n_rm):
            a1[r] += abs(alpha[r, srt[k]])
    g = _g(n + 2)
    rho = np.empty(n)
    a_rm = np.empty((n, n_rm))
    for q in range(n):
        for k in range(n_rm):
            a_rm[q, k] = alpha[q, srt[k]]
    pa = np.empty(n_rm)
    for r in range(n):
        pa[:] = 0.0
        for q in range(n):  # (P α)_r, accumulated over q (vectorised over the columns)
            prq = G[r, basis[q]]
            for k in range(n_rm):
                pa[k] += prq * a_rm[q, k]
        res = lab = 0.0
        for k in range(n_rm):
            j = piv[n + srt[k]]
            res += abs(G[r, j] - pa[k])
            lab += abs(G[r, j])
        pa1 = 0.0
        for q in range(n):
            pa1 += abs(G[r, basis[q]]) * a1[q]
        rho[r] = res + g * (lab + pa1)
    scale = np.empty(n)
    gs = 1.0 + _g(n_rm + 3)
    for q in range(n):
        scale[q] = (1.0 + a1[q]) * gs
    out = np.empty((n, n + k_oth - n_rm))
    g1, gr = _g(1), 1.0 + _g(n_rm + n + 3)
    for r in range(n):
        ps = 0.0
        for q in range(n):
            ps += abs(G[r, basis[q]]) * scale[q]
            out[r, q] = G[r, basis[q]] * scale[q]
        rho[r] = (rho[r] + g1 * ps) * gr
        for k in range(n_rm, k_oth):
            out[r, n + k - n_rm] = G[r, piv[n + srt[k]]]
    return out, rho
