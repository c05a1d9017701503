"""Proven bounds on floating-point error: what a set operation adds so that its result contains
the exact one, at every magnitude.

**Model** ([Higham2002, §2.2, Lemma 3.1, §3.1]). In IEEE double precision with rounding to
nearest, ``fl(a op b) = (a op b)(1 + δ)``, ``|δ| <= u = 2⁻⁵³``, when the result is in the
normal range; a product that underflows is off by at most ``η = 2⁻¹⁰⁷⁵`` in absolute value (a
sum or difference is exact when its result is subnormal). Hence a dot product of ``n`` terms,
evaluated in any order (BLAS blocking, FMA and pairwise sums included), satisfies

    |fl(xᵀy) − xᵀy| <= γ_n |x|ᵀ|y| + n η,        γ_n = n u / (1 − n u),

and a sum of ``n`` nonnegative terms computed in floating point is within a factor
``(1 ± γ_{n-1})`` of the exact sum. Every bound below is itself evaluated in floating point, so
each carries a factor 2 on ``γ`` (and a few ``η``) that absorbs the rounding of its own
evaluation: the returned numbers are upper bounds of the exact quantities, never estimates.

A bound after one rounded operation is made safe with one step of directed rounding,
``np.nextafter`` (:func:`up`, :func:`down`): the exact result of one operation lies within half
an ulp of the rounded one.

Nothing here needs the processor's rounding mode, so NumPy and BLAS run as they are.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DesignError
from ..linalg import UNIT_ROUNDOFF, gamma

__all__ = [
    "ETA",
    "UNIT_ROUNDOFF",
    "DecayBound",
    "certified_norms",
    "decay_of",
    "down",
    "enclose",
    "exactly_scaled",
    "gamma",
    "mid_rad",
    "overflowed",
    "product_error",
    "up",
    "upper",
]

ETA = 2.0**-1074
"""The smallest positive subnormal double (``2η``): a product's underflow error is below it."""

_INF = np.inf


NORMAL = 2.0**-1021
"""A nonzero product of a float by a power of two that is at least this in magnitude was exact
(had its exact value been below the smallest normal ``2^-1022``, the rounded one would be at
most ``2^-1022``)."""


def exactly_scaled(X: np.ndarray, f: np.ndarray) -> np.ndarray | None:
    """``X f`` (``f`` powers of two, broadcast), or None when a product may have been rounded
    (below :data:`NORMAL` or not finite where ``f != 1``)."""
    out: np.ndarray = X * f
    inexact = (f != 1.0) & (X != 0.0) & ~(np.abs(out) >= NORMAL)
    return None if inexact.any() or not np.isfinite(out).all() else out


def up(x: Any) -> Any:
    """The next double above ``x`` (elementwise): an upper bound of the exact result of the one
    rounded operation that gave ``x``."""
    return np.nextafter(x, _INF)


def down(x: Any) -> Any:
    """The next double below ``x`` (elementwise): a lower bound of the exact result of the one
    rounded operation that gave ``x``."""
    return np.nextafter(x, -_INF)


def upper(s: Any, n: int) -> Any:
    """An upper bound of the exact value of a nonnegative expression ``s`` computed in floating
    point from nonnegative numbers by at most ``n`` roundings on every path (a sum of ``n``
    products, a row sum of ``n`` entries): ``s (1 + 2 γ_{n+2}) + (n + 2) ETA``."""
    return s * (1.0 + 2.0 * gamma(n + 2)) + (n + 2) * ETA


def product_error(s: Any, n: int) -> Any:
    """An upper bound of ``|fl(A B) − A B|`` (elementwise) from ``s = fl(|A| |B|)`` and the inner
    dimension ``n``: ``γ_n`` times the exact ``|A| |B|``, plus underflow; also for the
    matrix-vector and vector forms. ``2 γ_{n+2} s + (n + 2) ETA``."""
    return (2.0 * gamma(n + 2)) * s + (n + 2) * ETA


def mid_rad(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(c, r)`` with ``[lo, hi] ⊆ [c − r, c + r]`` exactly: ``c = fl((lo + hi) / 2)`` and
    ``r = fl((hi − lo) / 2)`` enlarged by ``γ_3 (|c| + r)`` and by the underflow of the halving
    ([Higham2002, Lemma 3.1]); ``r = 0``, ``c = lo`` where ``lo = hi``."""
    c = 0.5 * lo + 0.5 * hi  # (no overflow of lo + hi near the end of the float range)
    r = 0.5 * hi - 0.5 * lo
    r = np.where(hi > lo, up(r + 2.0 * gamma(4) * (np.abs(c) + r) + 4 * ETA), 0.0)
    c = np.where(hi > lo, c, lo)
    return c, r


def enclose(c: Any, r: Any) -> tuple[Any, Any]:
    """The box ``[c − r, c + r]`` with its two bounds rounded outward (one operation each)."""
    return down(c - r), up(c + r)


@dataclass(frozen=True)
class DecayBound:
    """Proven constants of the decay of a Schur matrix's powers: ``‖Mⁱ‖∞ <= c λⁱ`` for every
    ``i >= 0``, for the *exact* powers of the float matrix ``M``.

    Errors that a recursion ``x+ = M x + ...`` makes at every step (its rounding ``r_j``) add
    up to ``Σ_j M^{k-1-j} r_j``, whose ∞-norm is at most ``q_k`` with ``q_{j+1} = λ q_j + c ‖r_j‖∞``
    (:meth:`next`): a scalar that stays bounded, also when ``|M|`` is not Schur.

    Built by :meth:`of`: proven ``‖Mⁱ‖∞ <= N_i`` until ``N_K <= θ < 1``
    (:func:`certified_norms`); then for ``i = q K + j``, ``‖Mⁱ‖ <= θ^q N_j``, so ``λ = θ^{1/K}``
    (rounded up) and ``c = max_j N_j / λ^j`` (:func:`decay_of`).
    """

    c: float
    lam: float

    @classmethod
    def of(cls, M: np.ndarray, *, theta: float = 0.5, max_power: int = 100_000) -> DecayBound:
        """The constants for ``M`` (:class:`~ivobs.DesignError` when its powers do not certify
        a decay below ``θ`` within ``max_power`` steps: ``M`` not Schur, or too close to it)."""
        M = np.asarray(M, dtype=float)
        if M.shape[0] == 0:
            return cls(1.0, 0.0)
        decay = decay_of(certified_norms(M, theta, max_power), theta)
        if decay is None:
            raise DesignError(
                "the rounding of the recursion cannot be bounded: the decay rate of its matrix "
                f"is too close to 1 (θ = {theta} not reached soon enough)"
            )
        return decay

    @property
    def gain(self) -> float:
        """``c / (1 − λ)``: the bound of ``q_k`` per unit of ``sup_j ‖r_j‖∞``."""
        return float(up(self.c / (1.0 - self.lam) * (1.0 + 8.0 * UNIT_ROUNDOFF)))

    def next(self, q: float, r: float) -> float:
        """``q_{k+1} >= λ q_k + c r_k`` (exactly; the two products and the sum rounded up)."""
        return (self.lam * q + self.c * r) * (1.0 + 4.0 * UNIT_ROUNDOFF) + ETA

    def accumulate(self, r: np.ndarray, q0: float = 0.0) -> np.ndarray:
        """``q_1, ..., q_T`` of :meth:`next` over a record of step errors ``r`` (``(T,)``),
        as one linear filter (constants enlarged so that its rounding is covered: each output
        is within ``(1 ± 3u)`` of ``λ' q + c' r``, and ``(1 − 3u)(1 + 8u) >= 1``)."""
        from scipy.signal import lfilter

        lam = self.lam * (1.0 + 8.0 * UNIT_ROUNDOFF)
        c = self.c * (1.0 + 8.0 * UNIT_ROUNDOFF)
        r = np.asarray(r, dtype=float) + ETA
        out: np.ndarray = lfilter([c], [1.0, -lam], r, zi=[lam * q0 * (1.0 + 8.0 * UNIT_ROUNDOFF)])[
            0
        ]
        return out


def certified_norms(M: np.ndarray, theta: float, max_power: int = 100_000) -> np.ndarray:
    """``N_0, ..., N_K``: proven ``‖Mⁱ‖∞ <= N_i`` for the exact powers of the float matrix
    ``M``, up to the first ``N_K <= θ``.

    ``P_{i+1} = fl(M P_i)`` differs from ``M^{i+1}`` by ``Σ_{j<=i} M^{i-j} E_j``, ``E_j =
    M P_j - fl(M P_j)``, ``‖E_j‖∞ <= e_j = ‖product_error(|M| |P_j|)‖∞``; so, from the bounds
    already proven for the lower powers, ``‖M^i‖∞ <= N_i = ‖P_i‖∞ + Σ_{j<i} N_{i-1-j} e_j``
    (rounded up). Unlike enclosures propagated by ``|M|``, this grows only with the true
    powers, also when ``|M|`` is far from Schur (large gains). Raises
    :class:`~ivobs.DesignError` when ``N_i`` does not reach ``θ`` within ``max_power``
    powers."""
    n = M.shape[0]
    absM = np.abs(M)
    P = np.eye(n)
    norms, errs = np.empty(max_power + 1), np.empty(max_power)
    norms[0] = 1.0
    for i in range(1, max_power + 1):
        errs[i - 1] = float(product_error(absM @ np.abs(P).sum(axis=1), n).max())
        P = M @ P
        drift = float(np.dot(norms[i - 1 :: -1] if i > 1 else norms[:1], errs[:i]))
        N = float(upper(float(upper(np.abs(P).sum(axis=1).max(), n)) + drift, i + 2))
        norms[i] = N
        if not N < 1e150:
            break
        if N <= theta:
            return norms[: i + 1].copy()
    raise DesignError(
        "the rounding of the recursion cannot be bounded: the powers of its matrix do not "
        f"certifiably decay (‖M^i‖∞ after {i} powers: {norms[i]:.3g}); the matrix is not Schur "
        "stable or too close to the unit circle"
    )


def decay_of(norms: np.ndarray, theta: float) -> DecayBound | None:
    """``‖Mⁱ‖∞ <= c λⁱ`` for every ``i`` from :func:`certified_norms`: the first ``K`` with
    ``N_K <= θ`` gives ``λ = θ^{1/K}`` and ``c = max_{j<K} N_j / λ^j`` (``i = q K + j``:
    ``‖M^i‖ <= θ^q N_j``); None when no ``N_K <= θ``."""
    reached = np.flatnonzero(norms <= theta)
    if not reached.size or norms.shape[0] == 1:
        return DecayBound(1.0, 0.0) if norms.shape[0] == 1 else None
    K = int(max(reached[0], 1))
    lam = float(up(theta ** (1.0 / K) * (1.0 + 1e-12)))
    if not lam < 1.0:
        return None
    c = float(up(float(np.max(norms[:K] / lam ** np.arange(K))) * (1.0 + 1e-12)))
    return DecayBound(max(c, 1.0), lam)


_HUGE = 1e300
"""A bound this large is one step of growth away from the end of the float range."""


def overflowed(*arrays: np.ndarray) -> bool:
    """Whether any array holds an infinity or a finite value beyond ``1e300`` (the bounds ran
    out of the float range; NaN then comes from ``inf - inf``)."""
    with np.errstate(invalid="ignore"):
        return any(bool(np.any(np.abs(a) > _HUGE)) for a in arrays if a.dtype.kind == "f")
