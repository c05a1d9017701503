"""The terms an interval matrix adds to a recursion, bounded soundly in floating point.

A system with interval matrices (:mod:`ivobs.model.uncertain`) is its nominal system plus

    w = ΔA x + ΔB u   in the state equation,    v = ΔC x + ΔD u   in the output equation,

with ``|ΔM| <= R_M`` entrywise. For ``x`` in the box ``[x̲, x̄]`` (an enclosure of ``x[k]``
the method already has) the interval product of ``[-R_M, R_M]`` with the box is exactly
``[-R_M m, R_M m]``, ``m = max(|x̲|, |x̄|)`` (the exact hull: never wider than the interval-matrix
bound of [Efimov2012, Lemma 1]), so

    |w| <= R_A m + R_B |u|,        |v| <= R_C m + R_D |u|.

Each method adds them where its model has a bounded input: the interval observers and the
Luenberger observers of ``reachability``/``zonotope`` through their output injection
(``w − L v``, error dynamics of the nominal ``A − LC``), the filters ``strip`` and
``constrained-zonotope`` as a box of generators in the prediction (``w``) and a wider strip /
slack per measured row (``v``).

**Rounding.** Every bound here is an upper bound of the exact real value: ``m = max(|x̲|, |x̄|)`` is
exact, a sum of ``n`` nonnegative products computed in floating point is
at most ``γ_n`` below its exact value ([Higham2002, Chapter 3]), hence multiplied by
``1 + 2 γ_{n+1}``, plus ``n`` half-subnormals for underflow, then one step up (``nextafter``);
adding a term to a bound steps the result one float outwards (the sum is rounded to nearest).
"""

from __future__ import annotations

import numpy as np

from ..linalg import gamma
from ..model.uncertain import MatrixUncertainty

__all__ = ["growth_radius", "magnitude", "observer_term", "terms", "up", "widen"]

_TINY = 5e-324
"""The smallest subnormal: twice the largest absolute error of one underflowing product."""


def up(s: np.ndarray, n: int) -> np.ndarray:
    """An upper bound of the exact value of ``s``, a sum of ``n`` nonnegative products computed
    in floating point (module docstring); NaN (``0 · inf``) becomes ``inf``."""
    with np.errstate(invalid="ignore", over="ignore"):
        out = s * (1.0 + 2.0 * gamma(n + 1)) + (n + 1) * _TINY
    out = np.where(np.isnan(out), np.inf, out)
    return np.nextafter(out, np.inf)


def magnitude(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``m >= |x|`` entrywise for every ``x`` of ``[lo, hi]`` (exact: no arithmetic)."""
    out: np.ndarray = np.maximum(np.abs(lo), np.abs(hi))
    return out


def terms(
    unc: MatrixUncertainty, lo: np.ndarray, hi: np.ndarray, u: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``(w̄, v̄)``: ``|ΔA x + ΔB u| <= w̄`` and ``|ΔC x + ΔD u| <= v̄`` for every ``x`` in
    ``[lo, hi]`` and every matrix in the interval matrices (module docstring)."""
    m = magnitude(lo, hi)
    au = np.abs(u)
    n = m.shape[0] + au.shape[0]
    with np.errstate(invalid="ignore", over="ignore"):
        w = unc.RA @ m + unc.RB @ au
        v = unc.RC @ m + unc.RD @ au
    return up(w, n), up(v, n)


def observer_term(
    w: np.ndarray, v: np.ndarray, L: np.ndarray, S: np.ndarray | None = None
) -> np.ndarray:
    """``t >= |S (w' − L v')|`` for every ``|w'| <= w̄``, ``|v'| <= v̄``: ``|S| w̄ + |S L| v̄``
    (``L`` here the product ``S L`` when ``S`` is given; ``S = I`` when None)."""
    aL = np.abs(L)
    with np.errstate(invalid="ignore", over="ignore"):
        if S is None:
            t = w + aL @ v
            n = 1 + v.shape[0]
        else:
            t = np.abs(S) @ w + aL @ v
            n = w.shape[0] + v.shape[0]
    return up(t, n)


def widen(lo: np.ndarray, hi: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``[lo − t, hi + t]``, each end one float outwards (its sum is rounded to nearest)."""
    return np.nextafter(lo - t, -np.inf), np.nextafter(hi + t, np.inf)


def growth_radius(
    unc: MatrixUncertainty, R: np.ndarray, L: np.ndarray, S: np.ndarray | None = None
) -> float:
    """``ρ(G)``, ``G = |R| + (|S| R_A + |S L| R_C) |S⁻¹|`` (``S = I`` when None), for an interval
    observer whose bounds of ``z = S x`` evolve with ``R = S (A0 − L C0) S⁻¹``.

    With every measurement present, the radius ``r`` of those bounds obeys ``r+ >= G r``
    entrywise: ``|R| r`` from the nominal part, and the term ``|S| w̄ + |S L| v̄`` with
    ``w̄ = R_A m``, ``v̄ = R_C m`` and ``m >= |S⁻¹| r`` (the magnitude of the box of ``x`` is at
    least its radius). ``G >= 0``, so from a prior box of positive radius ``ρ(G) > 1`` makes the
    bounds diverge whatever the data, and ``ρ(G) < 1`` keeps them bounded."""
    if S is None:
        H = unc.RA + np.abs(L) @ unc.RC
        G = np.abs(R) + H
    else:
        Si = np.abs(np.linalg.inv(S))
        G = np.abs(R) + (np.abs(S) @ unc.RA + np.abs(S @ L) @ unc.RC) @ Si
    return float(np.max(np.abs(np.linalg.eigvals(G)))) if G.size else 0.0
