"""Validated matrix exponentials: enclosures ``E ± R`` (elementwise) of ``e^{M}``, ``e^{A t}``
and of the integrals ``∫_0^t e^{A s} ds B``, in midpoint-radius interval matrix arithmetic with
the proven error model of :mod:`ivobs.sets.rounding`.

**Interval matrices.** A pair ``(M, R)`` of float matrices, ``R >= 0``, stands for every real
matrix ``X`` with ``|X − M| <= R`` elementwise. The product of two of them
(:func:`interval_product`) contains every product ``X Y``:
``|X Y − fl(M N)| <= |fl(M N) − M N| + |M| R_N + R_M (|N| + R_N)``, the first term bounded by
:func:`~ivobs.sets.rounding.product_error` ([Higham2002, Lemma 3.1]), the others evaluated in
floats and rounded up (:func:`~ivobs.sets.rounding.upper`).

**The exponential** (:func:`expm`): scaling and squaring with a Taylor remainder
([Higham2008, §10.3]) in interval arithmetic ([Moore2009]). With ``ν >= ‖|M| + R‖∞`` and
``s`` such that ``ν / 2^s <= θ``, every ``X`` of the scaled interval matrix ``(M, R) / 2^s``
(exact: a power of two) satisfies

    e^X = Σ_{j<=K} X^j / j! + Ρ_K,    ‖Ρ_K‖∞ <= (ν/2^s)^{K+1} / (K+1)! · 1 / (1 − (ν/2^s)/(K+2))

(the tail of the series, bounded by a geometric one), and each entry of ``Ρ_K`` is at most its
∞-norm. The polynomial is evaluated by Horner's rule in interval arithmetic (so it contains the
polynomial of every ``X`` of the interval), the remainder added to the radius, and the result
squared ``s`` times in interval arithmetic: ``e^X = (e^{X/2^s})^{2^s}``. Every step contains
the exact result, so the returned ``E ± R`` contains ``e^X`` for every ``X`` in ``(M, R)``.

**Integrals** (:func:`expm_integral`): by Van Loan's block exponential ([VanLoan1978])

    exp([[A, B], [0, 0]] t) = [[e^{A t}, ∫_0^t e^{A s} ds B], [0, I]],

the blocks of one validated exponential. ``t`` may be an interval ``(t_lo, t_hi)``: the
enclosures then hold for every ``t`` in it (a sampling period known to within rounding).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import IvobsError
from .rounding import ETA, UNIT_ROUNDOFF, product_error, up, upper

__all__ = ["IntervalMatrix", "expm", "expm_integral", "interval_product", "scaled"]

IntervalMatrix = tuple[np.ndarray, np.ndarray]
"""``(M, R)``: the real matrices ``X`` with ``|X − M| <= R`` elementwise."""

THETA = 1.0
"""Norm of the scaled matrix whose exponential is summed as a Taylor series."""
TAIL = 2.0**-60
"""Largest Taylor remainder accepted (relative to ``‖e^X‖ >= e^{-θ}``): well below rounding."""


def interval_product(
    A: np.ndarray, RA: np.ndarray | None, B: np.ndarray, RB: np.ndarray | None
) -> IntervalMatrix:
    """``(C, R)`` containing every ``X Y`` with ``|X − A| <= RA``, ``|Y − B| <= RB`` (a radius
    None is zero): ``C = fl(A B)``, ``R >= |fl(A B) − A B| + |A| RB + RA (|B| + RB)``."""
    n = A.shape[-1]
    C = A @ B
    absA, absB = np.abs(A), np.abs(B)
    R = product_error(absA @ absB, n)
    s = None
    if RB is not None:
        s = absA @ RB
    if RA is not None:
        t = RA @ (absB if RB is None else up(absB + RB))
        s = t if s is None else s + t
    if s is not None:  # at most 2 n + 2 roundings on every path of s
        R = up(R + upper(s, 2 * n + 2))
    return C, R


def scaled(A: Any, t: Any) -> IntervalMatrix:
    """``(M, R)`` containing ``A τ`` for every ``τ`` in ``t`` (a float, or a pair ``(t_lo,
    t_hi)``): ``M = fl(A t_c)``, ``R >= |A| t_r + |fl(A t_c) − A t_c|``."""
    A = np.asarray(A, dtype=float)
    lo, hi = (float(t), float(t)) if np.ndim(t) == 0 else (float(t[0]), float(t[1]))
    if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
        raise IvobsError(f"t: expected a finite time or interval of times, got {t!r}")
    c = 0.5 * lo + 0.5 * hi
    r = float(up(max(hi - c, c - lo)))  # [lo, hi] ⊆ [c − r, c + r]
    M = A * c
    R = upper(np.abs(A) * r, 1) + product_error(np.abs(M), 1)
    return M, R


def expm(M: Any, R: Any = None) -> IntervalMatrix:
    """An enclosure ``(E, R_E)`` of ``e^X`` for every ``X`` with ``|X − M| <= R`` (module
    docstring): ``|e^X − E| <= R_E`` elementwise. ``R`` None: the float matrix ``M`` itself.
    For ``e^{A t}`` pass ``*scaled(A, t)``."""
    M = np.asarray(M, dtype=float)
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise IvobsError(f"M: expected a square matrix, got shape {M.shape}")
    R = np.zeros_like(M) if R is None else np.asarray(R, dtype=float)
    n = M.shape[0]
    if n == 0:
        return M.copy(), R.copy()
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(R))):
        raise IvobsError("M: expected finite entries (and radii)")
    nu = float(upper(np.max(np.sum(np.abs(M) + R, axis=1)), n + 1))  # >= ‖X‖∞ over (M, R)
    s = 0 if nu <= THETA else math.ceil(math.log2(nu / THETA))
    if s > 1000:
        raise IvobsError(f"M: norm {nu:.3g} too large for an enclosure of its exponential")
    # scaling by 2^-s is exact (up to underflow: ETA added to the radius)
    f = 2.0**-s
    Ms, Rs = M * f, R * f + (ETA if s else 0.0)
    nus = float(up(nu * f))
    # Taylor degree K: remainder bound below TAIL
    K, term = 0, 1.0
    while True:
        K += 1
        term = term * nus / K
        tail = term * nus / (K + 1) / (1.0 - nus / (K + 2))
        if tail <= TAIL or K >= 30:
            break
    rem = float(up(tail * (1.0 + 8 * UNIT_ROUNDOFF)))
    eye = np.eye(n)
    # Horner: P = I + X (I + X/2 (I + ... (I + X/K)))
    P, RP = eye.copy(), np.zeros((n, n))
    for j in range(K, 0, -1):
        Q, RQ = interval_product(Ms, Rs, P, RP)
        Q = Q / j  # one rounding
        RQ = up(RQ / j) + product_error(np.abs(Q), 1)
        P = Q + eye
        RP = up(RQ + product_error(np.abs(P), 1))
    RP = up(RP + rem)
    for _ in range(s):
        P, RP = interval_product(P, RP, P, RP)
    return P, RP


def expm_integral(A: Any, B: Any, t: Any = 1.0) -> tuple[IntervalMatrix, IntervalMatrix]:
    """Enclosures of ``e^{A t}`` and of ``∫_0^t e^{A s} ds B`` (Van Loan's block exponential,
    module docstring) for every ``t`` in ``t`` (a float or a pair ``(t_lo, t_hi)``): the
    zero-order-hold discretisation ``(A_d, B_d)`` of ``x' = A x + B u``."""
    A = np.asarray(A, dtype=float)
    B = np.asarray(B, dtype=float)
    n = A.shape[0]
    if A.ndim != 2 or A.shape != (n, n) or B.ndim != 2 or B.shape[0] != n:
        raise IvobsError(f"A, B: expected (n, n) and (n, m) matrices, got {A.shape}, {B.shape}")
    m = B.shape[1]
    top = np.zeros((n + m, n + m))
    top[:n, :n], top[:n, n:] = A, B
    E, R = expm(*scaled(top, t))
    return (E[:n, :n], R[:n, :n]), (E[:n, n:], R[:n, n:])
