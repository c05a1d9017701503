"""The flow of ``x' = A(t) x + B(t) u + E(t) d`` over one interval between samples, enclosed: the
transition matrix and the integrals the continuous-time observer needs, each as an interval
matrix ``(mid, rad)`` that contains the exact one (:mod:`ivobs.sets.expm` for the arithmetic).

With ``h = t1 − t0`` and ``σ = t1 − s`` the time back from the end of the interval, the
exact state at ``t1`` is

    x(t1) = Φ(t1, t0) x(t0) + ∫_0^h Φ(t1, t1 − σ) (B u + E d)(t1 − σ) dσ

for every measurable ``d(s)`` within its bounds. :class:`Passage` holds, for one interval,
enclosures of ``Φ(t1, t0)``, of ``e^{A_z h}``, of ``G0 = ∫ Φ B``, ``G1 = ∫ Φ B (s − t0)/h`` and
``GE = ∫ Φ E``, and the *kernels* ``σ ↦ Φ(t1, t1 − σ) E(t1 − σ)`` (and ``B``):
:class:`Kernel`, which gives for any float matrix ``M`` an upper bound of
``∫_0^h |M Φ(t1, t1 − σ) E(t1 − σ)| dσ`` (the radius the disturbance adds, [Dinh2024, Lemma 1]
under the integral) and the integrals over sub-intervals (a callable input).

**Kernels.** ``[0, h]`` is cut into ``P`` pieces of length ``ℓ`` (``P ℓ = h``); on piece ``p``,
``σ = p ℓ + τ``, the kernel is a Taylor model in ``τ ∈ [0, ℓ]``:

    f(p ℓ + τ) ∈ Σ_{j<=K} D_pj τ^j + τ^{K+1} D_p,K+1

(``D_pj`` interval matrices; the last one bounds the remainder for every ``τ``). Integrals and
ranges over any ``[a, b] ⊆ [0, ℓ]`` follow with interval weights (``(b^{j+1} − a^{j+1})/(j+1)``
and ``[a^j, b^j]``, ``τ >= 0``). For ``∫ |M f|`` each piece is cut into :data:`SUBPIECES`: on a
sub-piece where an entry's range excludes 0, ``∫ |f| = |∫ f|`` (tight); elsewhere the length
times the largest ``|f|`` of the range.

Time-invariant (:func:`lti_kernel`): ``f(p ℓ + τ) = e^{A p ℓ} e^{A τ} X`` with the powers of a
validated ``e^{A ℓ}`` and ``e^{A τ} X = Σ_{j<=K} A^j X τ^j / j! + τ^{K+1} ρ``, ``|ρ| <=
‖A‖^{K+1}/(K+1)! / (1 − ‖A‖ ℓ/(K+2)) max_i |X_ik|`` (∞-norms; the tail of the series).
Time-varying (:func:`ltv_passage`): the interval Taylor method for the linear equation
([Nedialkov1999], [Moore2009]) on each piece (from ``t1`` backwards): ``Ψ(τ) = Φ(r, r − τ)``
(``r`` the right end of the piece) solves ``dΨ/dτ = Ψ(τ) a(τ)``, ``a(τ) = A(r − τ)``, so with
the Taylor coefficients ``a_i`` of ``a`` at ``τ = 0`` (:mod:`.traced`)

    Ψ_0 = I,   Ψ_{j+1} = (1 / (j + 1)) Σ_{i<=j} Ψ_{j−i} a_i,

and the remainder ``τ^{K+1} Ψ̃_{K+1}`` from the same recurrence on the coefficients of ``a``
over the piece, started from an a priori enclosure ``Ψ(τ) ∈ I ± (e^{αℓ} − 1)`` (Grönwall,
``α >= ‖A(t)‖∞`` on the piece; ``e^y − 1 <= y / (1 − y/2)``): the Taylor coefficient of order
``K+1`` at any ``τ`` of the piece lies in it (Lagrange's form of the remainder, entrywise).
Pieces are chosen with ``α ℓ <= θ`` (:data:`THETA`), and chained: ``Φ(t1, t1 − p ℓ)`` is the
product of the pieces' ``Ψ(ℓ)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

import numpy as np

from ...sets.expm import IntervalMatrix, expm, interval_product, scaled
from ...sets.rounding import ETA, down, product_error, up, upper

__all__ = ["K", "Kernel", "Passage", "lti_kernel", "pieces_for"]

K = 6
"""Taylor order of the kernels."""
THETA = 0.25
"""Largest ``α ℓ`` of a piece (``α >= ‖A‖∞``): the remainder is below ``θ^{K+1}/(K+1)! ≈ 1e-8``
relative (time-varying) and the series of the time-invariant kernel converges fast."""
SUBPIECES = 8
"""Sub-pieces of each piece over which the sign of ``|M f|`` is tested."""

Scalar = tuple[float, float]


def _enclose(q: Fraction) -> Scalar:
    f = float(q)
    return float(down(f)), float(up(f))


def _times(a: Scalar, b: Scalar) -> Scalar:
    """``[a] [b]`` for nonnegative intervals, rounded outward."""
    return float(down(a[0] * b[0])), float(up(a[1] * b[1]))


def pieces_for(alpha: float, h: float) -> int:
    """The number of pieces of an interval of length ``h`` for ``‖A‖∞ <= alpha``."""
    return max(1, math.ceil(alpha * h / THETA)) if math.isfinite(alpha * h) else 1 << 20


@dataclass(frozen=True)
class Weights:
    """Interval weights (``(mid, rad)``, for ``j = 0..K+1``) of a piece of length ``ℓ ∈
    [ell]``: ``end`` (``ℓ^j``), ``full`` (``∫_0^ℓ τ^j``), and per sub-piece ``s``: ``sub``
    (``∫`` over it), ``rng`` (``[a^j, b^j]``); ``moment[p]``: ``∫_0^ℓ (p ℓ + τ) τ^j dτ``."""

    end: tuple[np.ndarray, np.ndarray]
    full: tuple[np.ndarray, np.ndarray]
    sub: tuple[np.ndarray, np.ndarray]
    rng: tuple[np.ndarray, np.ndarray]
    moment: tuple[np.ndarray, np.ndarray]
    seg: float
    ell: Scalar

    @classmethod
    def of(cls, ell: Scalar, P: int, q: int = SUBPIECES) -> Weights:
        J = K + 2
        pw = [(1.0, 1.0)]  # [ℓ_lo^k, ℓ_hi^k], k = 0 .. K + 3
        for _ in range(K + 3):
            pw.append(_times(pw[-1], ell))

        def w(const: Fraction, k: int) -> Scalar:  # const ℓ^k
            return _times(_enclose(const), pw[k]) if const >= 0 else (0.0, 0.0)

        end = [w(Fraction(1), j) for j in range(J)]
        full = [w(Fraction(1, j + 1), j + 1) for j in range(J)]
        sub = [[w(Fraction((s + 1) ** (j + 1) - s ** (j + 1), (j + 1) * q ** (j + 1)), j + 1)
                for j in range(J)] for s in range(q)]  # fmt: skip
        rng = [[(w(Fraction(s**j, q**j), j)[0], w(Fraction((s + 1) ** j, q**j), j)[1])
                for j in range(J)] for s in range(q)]  # fmt: skip
        mom = [[_sum(w(Fraction(p, j + 1), j + 2), w(Fraction(1, j + 2), j + 2))
                for j in range(J)] for p in range(P)]  # fmt: skip
        seg = float(up(ell[1] / q))
        return cls(_mr(end), _mr(full), _mr(sub), _mr(rng), _mr(mom), seg, ell)


def _sum(a: Scalar, b: Scalar) -> Scalar:
    return float(down(a[0] + b[0])), float(up(a[1] + b[1]))


def _mr(pairs: Any) -> tuple[np.ndarray, np.ndarray]:
    """Intervals ``[lo, hi]`` as ``(mid, rad)`` arrays with ``[lo, hi] ⊆ [mid ± rad]``."""
    a = np.asarray(pairs, dtype=float)
    lo, hi = a[..., 0], a[..., 1]
    c = 0.5 * lo + 0.5 * hi
    r = up(np.maximum(hi - c, c - lo))
    return c, r


def weighted(C: IntervalMatrix, W: tuple[np.ndarray, np.ndarray], spec: str) -> IntervalMatrix:
    """``Σ_j C_j w_j`` in interval arithmetic (``np.einsum`` subscripts ``spec``, summing over
    ``j``): the centre, and the radius ``|C| w_r + C_r (|w_c| + w_r)`` plus the rounding of the
    centre (``J`` terms in any order, [Higham2002, Lemma 3.1])."""
    (Cc, Cr), (wc, wr) = C, W
    J = wc.shape[-1]
    mid = np.einsum(spec, Cc, wc)
    aC = np.abs(Cc)
    rad = np.einsum(spec, aC, wr) + np.einsum(spec, Cr, up(np.abs(wc) + wr))
    rad = upper(rad, 2 * J + 1) + product_error(np.einsum(spec, aC, np.abs(wc)), J)
    return mid, up(rad)


@dataclass(frozen=True)
class Kernel:
    """``σ ↦ f(σ)`` on ``[0, h]``, ``P`` pieces of length ``ℓ``: ``D = (mid, rad)`` of shape
    ``(P, K+2, rows, cols)`` (module docstring), with the :class:`Weights` of ``ℓ``."""

    D: IntervalMatrix
    w: Weights

    @property
    def P(self) -> int:
        return int(self.D[0].shape[0])

    def times(self, M: np.ndarray | None) -> Kernel:
        """The kernel ``M f`` (``M`` a float matrix; None: ``f``)."""
        if M is None:
            return self
        return Kernel(interval_product(M, None, *self.D), self.w)

    def integral(self) -> IntervalMatrix:
        """``∫_0^h f``."""
        c, r = weighted(self.D, self.w.full, "pjab,j->pab")
        return _total(c, r)

    def moment(self) -> IntervalMatrix:
        """``∫_0^h σ f(σ) dσ``."""
        c, r = weighted(self.D, self.w.moment, "pjab,pj->pab")
        return _total(c, r)

    def subintegrals(self) -> IntervalMatrix:
        """``∫ f`` over each sub-piece: shape ``(P, q, rows, cols)``."""
        return weighted(self.D, self.w.sub, "pjab,sj->psab")

    def abs_integral(self) -> np.ndarray:
        """An upper bound of ``∫_0^h |f(σ)| dσ`` (elementwise; module docstring)."""
        if self.D[0].size == 0:
            return np.zeros(self.D[0].shape[2:])
        ic, ir = self.subintegrals()
        rc, rr = weighted(self.D, self.w.rng, "pjab,sj->psab")
        lo, hi = down(rc - rr), up(rc + rr)
        one_sign = (lo > 0.0) | (hi < 0.0)
        big = up(self.w.seg * up(np.maximum(np.abs(lo), np.abs(hi))))
        part = np.where(one_sign, up(np.abs(ic) + ir), big)
        n = part.shape[0] * part.shape[1]
        out: np.ndarray = upper(part.sum(axis=(0, 1)), n)
        return out


def _total(c: np.ndarray, r: np.ndarray) -> IntervalMatrix:
    """The sum over pieces (axis 0) of interval matrices."""
    P = c.shape[0]
    s = c.sum(axis=0)
    return s, up(upper(r.sum(axis=0), P) + product_error(np.abs(c).sum(axis=0), P))


def _tail(alpha: float, ell: float, X: np.ndarray) -> np.ndarray:
    """``|e^{Aτ} X − Σ_{j<=K} (Aτ)^j X / j!| <= τ^{K+1} ρ`` for ``τ <= ℓ``, ``‖A‖∞ <= α``:
    ``ρ = α^{K+1}/(K+1)! / (1 − α ℓ/(K+2)) max_i |X_ik|`` (rows alike)."""
    y = float(up(alpha * ell))
    if not y < K + 2:
        return np.full(X.shape, np.inf)
    f = float(up(alpha ** (K + 1) / math.factorial(K + 1) * (1 + 1e-12) / (1.0 - y / (K + 2))))
    col = np.max(np.abs(X), axis=0) if X.shape[0] else np.zeros(X.shape[1])
    return np.broadcast_to(up(f * col * (1 + 1e-15)) + ETA, X.shape).copy()


def lti_kernel(A: np.ndarray, X: np.ndarray, ell: Scalar, P: int, eA: IntervalMatrix) -> Kernel:
    """The kernel ``σ ↦ e^{A σ} X`` on ``P`` pieces of length ``ℓ ∈ [ell]`` (module
    docstring); ``eA`` encloses ``e^{A ℓ}``."""
    n, c = X.shape
    alpha = float(upper(np.max(np.abs(A).sum(axis=1)), n + 1)) if n else 0.0
    Cc, Cr = np.empty((K + 2, n, c)), np.zeros((K + 2, n, c))
    Cc[0] = X
    for j in range(K):
        m, r = interval_product(A, None, Cc[j], Cr[j])
        Cc[j + 1] = m / (j + 1)
        Cr[j + 1] = up(up(r / (j + 1)) + product_error(np.abs(Cc[j + 1]), 1))
    Cc[K + 1], Cr[K + 1] = 0.0, _tail(alpha, ell[1], X)
    Dc, Dr = np.empty((P, K + 2, n, c)), np.empty((P, K + 2, n, c))
    pre: IntervalMatrix = (np.eye(n), np.zeros((n, n)))
    for p in range(P):  # D_p = e^{A p ℓ} C
        Dc[p], Dr[p] = interval_product(pre[0], pre[1], Cc, Cr)
        if p + 1 < P:
            pre = interval_product(pre[0], pre[1], *eA)
    return Kernel((Dc, Dr), Weights.of(ell, P))


@dataclass
class Passage:
    """One interval between samples (module docstring): ``h`` (an interval containing the exact
    length), enclosures of ``Φ(t1, t0)`` (``Phi``), ``e^{A_z h}`` (``Phiz``), ``G0``, ``G1``,
    ``GE``, and the kernels of ``E`` and (callable input) ``B``. ``kept``: what is computed
    once per sampling period (time-invariant: the forcings of the matrices used every
    interval, the anchor of :mod:`.sampled`)."""

    h: Scalar
    Phi: IntervalMatrix
    Phiz: IntervalMatrix
    G0: IntervalMatrix
    G1: IntervalMatrix
    GE: IntervalMatrix
    kE: Kernel
    kB: Kernel | None
    kept: dict[str, Any] = field(default_factory=dict)


def target_exponential(A_z: np.ndarray, h: Scalar) -> IntervalMatrix:
    """``e^{A_z τ}`` for ``τ ∈ [h]`` (``A_z`` Metzler: the exact one is nonnegative)."""
    return expm(*scaled(A_z, h))


def scale_by(M: IntervalMatrix, s: Scalar) -> IntervalMatrix:
    """``M [s]`` for an interval matrix and a nonnegative scalar interval."""
    c, r = M
    sc = 0.5 * s[0] + 0.5 * s[1]
    sr = float(up(max(s[1] - sc, sc - s[0])))
    out = c * sc
    rad = upper(np.abs(c) * sr + r * float(up(abs(sc) + sr)), 2) + product_error(np.abs(out), 1)
    return out, up(rad)


def minus(A: IntervalMatrix, B: IntervalMatrix) -> IntervalMatrix:
    """``A − B`` for interval matrices."""
    d = A[0] - B[0]
    return d, up(upper(A[1] + B[1], 1) + product_error(np.abs(d), 1))


def _signs(c: np.ndarray) -> np.ndarray:
    """The coefficients of ``f(r − τ)`` in ``τ`` from those of ``f(t)`` at ``r``: ``(−1)^i``."""
    out = c.copy()
    out[1::2] *= -1.0
    return out


def _taylor_recurrence(
    first: IntervalMatrix, a: IntervalMatrix, order: int
) -> list[IntervalMatrix]:
    """``Ψ_0 = first``, ``Ψ_{j+1} = (1/(j+1)) Σ_{i<=j} Ψ_{j−i} a_i`` for ``j < order``
    (interval arithmetic; ``a`` stacked ``(>= order, n, n)``)."""
    n = first[0].shape[0]
    out = [first]
    ac, ar = a
    for j in range(order):
        Pc = np.stack([out[j - i][0] for i in range(j + 1)])
        Pr = np.stack([out[j - i][1] for i in range(j + 1)])
        m, r = interval_product(Pc, Pr, ac[: j + 1], ar[: j + 1])
        s = m.sum(axis=0)
        rs = up(upper(r.sum(axis=0), j + 1) + product_error(np.abs(m).sum(axis=0), j + 1))
        c = s / (j + 1)
        out.append((c, up(up(rs / (j + 1)) + product_error(np.abs(c), 1))))
    assert all(o[0].shape == (n, n) for o in out)
    return out


def _product_model(
    psi: list[IntervalMatrix], x_thin: IntervalMatrix, x_wide: IntervalMatrix, ell: Scalar,
    psi_range: IntervalMatrix,
) -> IntervalMatrix:  # fmt: skip
    """The Taylor model ``(K+2, n, c)`` of ``Ψ(τ) x(τ)`` from those of ``Ψ`` (``psi``:
    ``Ψ_0..Ψ_K`` and the remainder) and of ``x`` (thin coefficients ``x_0..x_K``, wide
    ``x̃_0..x̃_{K+1}``): ``c_j = Σ_{i<=j} Ψ_i x_{j−i}`` for ``j <= K``; the remainder
    ``Σ_{j>K} c_j τ^{j−K−1} + ρ_Ψ x(τ) + Ψ_poly(τ) ρ_x`` bounded over ``τ ∈ [0, ℓ]`` with
    ``x(τ) ∈ x̃_0`` and ``Ψ_poly(τ) ∈ psi_range``."""
    xc, xr = x_thin
    coefs = []
    for j in range(2 * K + 1):
        lo, hi = max(0, j - K), min(j, K)
        Pc = np.stack([psi[i][0] for i in range(lo, hi + 1)])
        Pr = np.stack([psi[i][1] for i in range(lo, hi + 1)])
        m, r = interval_product(
            Pc, Pr, xc[j - hi : j - lo + 1][::-1], xr[j - hi : j - lo + 1][::-1]
        )
        cnt = hi - lo + 1
        coefs.append(
            (
                m.sum(axis=0),
                up(upper(r.sum(axis=0), cnt) + product_error(np.abs(m).sum(axis=0), cnt)),
            )
        )
    shape = coefs[0][0].shape
    Rc, Rr = np.zeros(shape), np.zeros(shape)
    lp = [(1.0, 1.0)]
    for _ in range(K):
        lp.append(_times(lp[-1], ell))
    for j in range(K + 1, 2 * K + 1):  # c_j τ^(j-K-1), τ^(j-K-1) ∈ [0, ℓ^(j-K-1)]
        c, r = scale_by(coefs[j], (0.0, lp[j - K - 1][1]))
        Rc, Rr = Rc + c, up(Rr + r + product_error(np.abs(Rc + c), 1))
    t1c, t1r = interval_product(psi[K + 1][0], psi[K + 1][1], x_wide[0][0], x_wide[1][0])
    t2c, t2r = interval_product(psi_range[0], psi_range[1], x_wide[0][K + 1], x_wide[1][K + 1])
    Rc2 = Rc + t1c + t2c
    Rr = up(upper(Rr + t1r + t2r, 3) + product_error(np.abs(Rc) + np.abs(t1c) + np.abs(t2c), 3))
    out_c = np.stack([c for c, _ in coefs[: K + 1]] + [Rc2])
    out_r = np.stack([r for _, r in coefs[: K + 1]] + [Rr])
    return out_c, out_r


def ltv_passage(
    A: Any, B: Any, E: Any, t0: float, t1: float, Phiz: IntervalMatrix, callable_input: bool
) -> Passage:
    """:class:`Passage` of a time-varying system over ``[t0, t1]`` (module docstring). ``A``,
    ``B``, ``E``: a :class:`~.traced.TimeFunction` (Taylor coefficients to order ``K`` for
    ``A``, ``K + 1`` for ``B`` and ``E``) or a constant float matrix."""
    hf = t1 - t0
    H = (float(down(hf)), float(up(hf)))
    n = A.shape[0]
    wide0 = A.coefficients(t0, t1)
    alpha = float(upper(np.max((np.abs(wide0[0][0]) + wide0[1][0]).sum(axis=1)), n + 1))
    P = pieces_for(alpha, H[1])
    ends = np.linspace(t1, t0, P + 1)
    ends[0], ends[-1] = t1, t0
    if np.any(np.diff(ends) >= 0):
        ends, P = np.array([t1, t0]), 1  # lengths below resolution: one piece
    lens = -np.diff(ends)
    ell = (float(down(lens.min())), float(up(lens.max())))
    w = Weights.of(ell, P)
    eye = (np.eye(n), np.zeros((n, n)))
    pre = eye
    DE: list[IntervalMatrix] = []
    DB: list[IntervalMatrix] = []
    for p in range(P):
        r, left = float(ends[p]), float(ends[p + 1])
        wide = wide0 if P == 1 else A.coefficients(left, r)
        thin = A.coefficients(r, r)
        a_thin = (_signs(thin[0]), thin[1])
        a_wide = (_signs(wide[0]), wide[1])
        # a priori enclosure of Ψ on the piece (Grönwall): I ± (e^y − 1), e^y − 1 <= y/(1 − y/2)
        al = float(upper(np.max((np.abs(a_wide[0][0]) + a_wide[1][0]).sum(axis=1)), n + 1))
        y = float(up(al * ell[1]))
        if not y < 1.0:  # pieces_for keeps y <= θ on the whole interval's bound
            y = min(y, 1.0 - 1e-3)
        eb = float(up(up(y) / float(down(1.0 - up(y / 2.0)))))
        apriori = (np.eye(n), np.full((n, n), eb))
        psi = _taylor_recurrence(eye, a_thin, K)
        rem = _taylor_recurrence(apriori, a_wide, K + 1)[K + 1]
        psi.append(rem)
        Pc, Pr = np.stack([c for c, _ in psi]), np.stack([r for _, r in psi])
        rw = _mr(
            [[(1.0, 1.0)] + [(0.0, float(up(w.end[0][j] + w.end[1][j]))) for j in range(1, K + 1)]]
        )
        psr = weighted((Pc[None, : K + 1], Pr[None, : K + 1]), rw, "pjab,sj->psab")
        psi_range = (psr[0][0, 0], psr[1][0, 0])  # Σ_{j<=K} Ψ_j τ^j over τ ∈ [0, ℓ]
        for X, out in ((E, DE), (B, DB)):
            if X is None:
                continue
            if isinstance(X, np.ndarray):
                m = interval_product(Pc, Pr, X, None)
            else:
                xt = X.coefficients(r, r)
                xw = X.coefficients(left, r)
                m = _product_model(
                    psi, (_signs(xt[0]), xt[1]), (_signs(xw[0]), xw[1]), ell, psi_range
                )
            out.append(interval_product(pre[0], pre[1], *m))
        end = weighted((Pc[None], Pr[None]), (w.end[0][None], w.end[1][None]), "pjab,sj->psab")
        pre = interval_product(pre[0], pre[1], end[0][0, 0], end[1][0, 0])
    kE = Kernel((np.stack([c for c, _ in DE]), np.stack([r for _, r in DE])), w)
    kB = Kernel((np.stack([c for c, _ in DB]), np.stack([r for _, r in DB])), w)
    G0 = kB.integral()
    inv = (float(down(1.0 / H[1])), float(up(1.0 / H[0])))
    G1 = minus(G0, scale_by(kB.moment(), inv))  # ∫ Φ B (s − t0)/h, (s − t0)/h = 1 − σ/h
    return Passage(
        h=H, Phi=pre, Phiz=Phiz, G0=G0, G1=G1, GE=kE.integral(), kE=kE,
        kB=kB if callable_input else None,
    )  # fmt: skip
