"""Conservative linearisation of a nonlinear map over a box: the mean-value form.

For a map ``g(ζ)`` of the joint vector ``ζ = (x, w)`` (state, then the per-step unknowns ``w``
of a :class:`~ivobs.NonlinearSystem`), a box ``B = [lo, hi]`` that certainly holds ``ζ`` and an
expansion point ``c ∈ B``, the mean-value theorem applied to each component gives, for every
``ζ ∈ B``, a point ``ξ_i`` of the segment ``[c, ζ] ⊆ B`` with
``g_i(ζ) = g_i(c) + ∇g_i(ξ_i) (ζ - c)``. With ``[J]`` an interval enclosure of the Jacobian over
``B`` and any real matrix ``J̃``::

    g(ζ) ∈ g(c) + J̃ (ζ - c) + ([J] - J̃)(B - c)                                      (MV)

[Rego2020] (their mean-value extension; the first-order Taylor form with the Lagrange
remainder of [Althoff2008] is the same statement with ``J̃ = J(c)``). ``J̃ = mid [J]`` makes
``[J] - J̃`` symmetric, ``|[J] - J̃| <= rad [J]``, the smallest remainder
``|([J] - J̃)(B - c)| <= rad[J] |B - c|`` of all choices (``J(c)`` is not centred in ``[J]``).

:func:`linearise` returns ``(g0, J̃, ρ)`` with, in exact arithmetic and for every ``ζ ∈ B``,
``|g(ζ) - g0 - J̃ (ζ - c)| <= ρ`` componentwise. **Rounding**: ``g(c)`` is enclosed by the
model's point evaluation ``[gl, gh]`` (outward rounded); ``g0 = fl((gl + gh) / 2)`` and its
distance to any point of ``[gl, gh]`` is at most ``r = (gh - gl)/2`` rounded up by
``γ_3 (|g0| + r)`` (:func:`~ivobs.sets.rounding.mid_rad`). ``J̃`` is any float matrix (it
need not be the exact midpoint). ``D = max(Jh - J̃, J̃ - Jl)`` and ``Δ = max(hi - c, c - lo)``
are single rounded subtractions, so ``(1 + 2u) D`` and ``(1 + 2u) Δ`` bound the exact ones; the
product ``D Δ`` (non-negative terms, ``n`` of them) is rounded up by ``(1 + γ_{n+1})`` and the
final sum ``r + D Δ`` by ``(1 + γ_2)`` ([Higham2002, Lemma 3.1 and Section 3.1]). Where the
Jacobian enclosure is not finite (a domain edge) the row falls back to the natural inclusion
``g(B) ⊆ [nl, nh]``: ``J̃_i = 0``, ``g0_i`` and ``ρ_i`` its centre and radius.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from functools import cache
from typing import Any, NamedTuple

import numpy as np

from ..linalg import UNIT_ROUNDOFF, gamma

__all__ = [
    "Linearisation",
    "LinearisationLists",
    "TermwiseMargin",
    "contract_back",
    "contract_back_lists",
    "linearise",
    "linearise_lists",
]

_UP = 1.0 + 2.0 * UNIT_ROUNDOFF
_gamma = cache(gamma)  # the few sizes of one model, looked up at every call

Evals = tuple[Callable[..., Any], Callable[..., Any]]
"""``(natural, natjac)`` of the model's ``f`` or ``h`` on lists
(:meth:`~ivobs.NonlinearSystem.evaluators`)."""


class Linearisation(NamedTuple):
    """``g(ζ) ∈ g0 + J (ζ - c) ± rho`` for every ``ζ`` of the box (exact arithmetic), and the
    natural inclusion ``[nat_lo, nat_hi]`` of ``g`` over the box."""

    g0: np.ndarray
    J: np.ndarray
    rho: np.ndarray
    c: np.ndarray
    nat_lo: np.ndarray
    nat_hi: np.ndarray


class LinearisationLists(NamedTuple):
    """:class:`Linearisation` with its vectors as lists (the callers work on them one float
    at a time); ``J`` and ``c`` stay arrays (they enter matrix products)."""

    g0: list[float]
    J: np.ndarray
    rho: list[float]
    c: np.ndarray
    nat_lo: list[float]
    nat_hi: list[float]


def linearise_lists(
    evals: Evals,
    lo: np.ndarray | list[float],
    hi: np.ndarray | list[float],
    c: np.ndarray,
    u: np.ndarray,
    nx: int,
    natural: bool = True,
) -> LinearisationLists:
    """The mean-value form (MV) of the module docstring of ``g`` (``evals``: the model's
    :meth:`~ivobs.NonlinearSystem.evaluators` of ``f`` or ``h``) over the joint box
    ``[lo, hi]`` (``x`` then ``w``; ``nx`` states; arrays or lists) at ``c`` (clipped into
    the box). ``natural=False``: the natural inclusion is not tightened by the centred form
    and monotonicity (the caller does not use it). Scalar Python arithmetic on lists: for the
    small vectors of one step it is several times faster than NumPy calls, and each operation
    is the same IEEE double operation as the error analysis above assumes."""
    value, natjac = evals
    bl = lo.tolist() if isinstance(lo, np.ndarray) else lo
    bh = hi.tolist() if isinstance(hi, np.ndarray) else hi
    cl = [min(max(a, p), q) for a, p, q in zip(c.tolist(), bl, bh)]
    ul = u.tolist()
    gl, gh = value(cl[:nx], cl[:nx], ul, cl[nx:], cl[nx:])
    nl, nh, jl, jh = natjac(bl[:nx], bh[:nx], ul, bl[nx:], bh[nx:])
    n, m = len(cl), len(gl)
    delta = [max(q - a, a - p) * _UP for a, p, q in zip(cl, bl, bh)]
    up_rem, up_sum, g3 = 1.0 + _gamma(n + 1), 1.0 + _gamma(2), _gamma(3)
    g0s, rhos = [0.0] * m, [0.0] * m
    mids = [0.5 * p + 0.5 * q for p, q in zip(jl, jh)]  # J̃ = mid [J], halves first: no overflow
    rows = [mids[i * n : i * n + n] for i in range(m)]
    D = [max(q - t, t - p) * _UP for p, q, t in zip(jl, jh, mids)]
    # D Δ: one product, as BLAS sums it; NumPy's error state (3 µs) only where the terms could
    # overflow or be NaN (ΣD Σ Δ bounds the nonnegative sums; a NaN fails the test)
    if sum(D) * sum(delta) < 1e300:
        rems = ((np.array(D).reshape(m, n) @ np.array(delta)) * up_rem).tolist()
    else:
        with np.errstate(invalid="ignore", over="ignore"):
            rems = ((np.array(D).reshape(m, n) @ np.array(delta)) * up_rem).tolist()
    curved: dict[tuple[bool, ...], list[int]] = {}  # rows to tighten, by sign pattern
    for i in range(m):
        Jl, Jh, Jt = jl[i * n : i * n + n], jh[i * n : i * n + n], rows[i]
        g0, r = _safe_radius(gl[i], gh[i], g3)
        rho = (r + rems[i]) * up_sum
        if not math.isfinite(rho + g0 + sum(Jt)):  # a domain edge: the natural inclusion
            rows[i] = [0.0] * n
            g0, rho = _safe_radius(nl[i], nh[i], g3)
        elif natural:
            nl[i], nh[i] = _centred(g0, Jt, rho, bl, bh, cl, nl[i], nh[i])
            # a row whose Jacobian is a point up to the enclosure of its constants is affine
            # on the box: the centred form is already its range, monotonicity adds nothing
            if any(q - p > 1e-12 * max(-p, q, p, -q) for p, q in zip(Jl, Jh)):
                up = [p >= 0.0 for p in Jl]
                key = tuple(up + [q <= 0.0 and not s for q, s in zip(Jh, up)])
                curved.setdefault(key, []).append(i)
        g0s[i], rhos[i] = g0, rho
    for key, members in curved.items():
        _monotone(value, key, bl, bh, ul, nx, members, nl, nh)
    return LinearisationLists(g0s, np.array(rows).reshape(m, n), rhos, np.array(cl), nl, nh)


def linearise(
    evals: Evals,
    lo: np.ndarray | list[float],
    hi: np.ndarray | list[float],
    c: np.ndarray,
    u: np.ndarray,
    nx: int,
    natural: bool = True,
) -> Linearisation:
    """:func:`linearise_lists` with every vector as an array."""
    out = linearise_lists(evals, lo, hi, c, u, nx, natural)
    a = np.array
    return Linearisation(a(out.g0), out.J, a(out.rho), out.c, a(out.nat_lo), a(out.nat_hi))


def _safe_radius(lo: float, hi: float, g3: float) -> tuple[float, float]:
    """:func:`~ivobs.sets.rounding.mid_rad` of one interval (``g3 = γ_3``)."""
    c = 0.5 * (lo + hi)
    r = 0.5 * (hi - lo)
    return c, (r + g3 * (abs(c) + r) if hi > lo else 0.0)


def _monotone(
    value: Callable[..., Any],
    key: tuple[bool, ...],
    lo: list[float],
    hi: list[float],
    u: list[float],
    nx: int,
    rows: list[int],
    nl: list[float],
    nh: list[float],
) -> None:
    """The natural inclusion ``[nl, nh]`` of ``rows`` tightened in place by monotonicity: where
    the Jacobian enclosure of a row over the box has a sign (``key``: ``Jl_j >= 0`` for each
    ``j``, then ``Jh_j <= 0``), ``g_i`` is monotone in ``ζ_j`` over the whole box, so its
    minimum (maximum) over the box is reached with ``ζ_j`` at the lower or upper end; the
    natural inclusion over the box with those coordinates fixed is still an enclosure of that
    minimum (maximum) [Jaulin2001, Chapter 2]. Rows with the same sign pattern share one pair of
    evaluations."""
    n = len(lo)
    up, down = key[:n], key[n:]
    if not any(key):
        return
    a_lo = [q if d else p for p, q, d in zip(lo, hi, down)]  # where g_i is smallest
    a_hi = [p if s else q for p, q, s in zip(lo, hi, up)]
    b_lo = [q if s else p for p, q, s in zip(lo, hi, up)]  # where g_i is largest
    b_hi = [p if d else q for p, q, d in zip(lo, hi, down)]
    low = value(a_lo[:nx], a_hi[:nx], u, a_lo[nx:], a_hi[nx:])[0]
    high = value(b_lo[:nx], b_hi[:nx], u, b_lo[nx:], b_hi[nx:])[1]
    for i in rows:
        nl[i], nh[i] = max(nl[i], low[i]), min(nh[i], high[i])


def _centred(
    g0: float,
    J: list[float],
    rho: float,
    lo: list[float],
    hi: list[float],
    c: list[float],
    nl: float,
    nh: float,
) -> tuple[float, float]:
    """``[nl, nh]`` intersected with the centred form ``g0 + J (B - c) ± ρ`` of one row (MV
    over the box; exact for a row where ``g`` is affine). Each interval sum is widened by
    ``γ_{n+2}`` times the sum of the magnitudes of its terms (its rounding)."""
    s_lo = s_hi = s_abs = 0.0
    for j, p, q, m in zip(J, lo, hi, c):
        a, b = j * (p - m), j * (q - m)
        if a > b:
            a, b = b, a
        s_lo += a
        s_hi += b
        s_abs += max(-a, b)
    err = _gamma(len(c) + 3) * (abs(g0) + rho + s_abs)
    low, high = g0 + s_lo - rho - err, g0 + s_hi + rho + err
    return max(nl, low), min(nh, high)  # a NaN bound (never here: finite rows) is ignored


def contract_back(
    sys: Any,
    lo: np.ndarray,
    hi: np.ndarray,
    u_prev: np.ndarray,
    u: np.ndarray,
    wlo: np.ndarray,
    whi: np.ndarray,
    y: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """One step back through the model: the box ``[lo, hi]`` of ``ζ_{k-1} = (x_{k-1},
    w_{k-1})`` and the box ``[wlo, whi]`` of ``w_k`` contracted with
    ``h(f(x_{k-1}, u_{k-1}, w_{k-1}), u_k, w_k) = y_k`` (the model's forward-backward
    contractors of ``h ∘ f``, two sweeps; NaN components skipped). ``None`` when no point of
    the boxes explains ``y_k`` (an inconsistent measurement). When ``y_k`` does not pin down
    the states of step ``k`` but does those of step ``k - 1`` (Hénon with ``y = x2 = 0.3
    x1[k-1]``), this bounds the box over which ``f`` is then linearised."""
    out = contract_back_lists(
        sys, lo.tolist(), hi.tolist(), u_prev, u, wlo.tolist(), whi.tolist(), y
    )
    if out is None:
        return None
    a = np.array
    return a(out[0]), a(out[1]), a(out[2], dtype=float), a(out[3], dtype=float)


def contract_back_lists(
    sys: Any,
    lo: list[float],
    hi: list[float],
    u_prev: np.ndarray,
    u: np.ndarray,
    wlo: list[float],
    whi: list[float],
    y: np.ndarray,
) -> tuple[list[float], list[float], list[float], list[float]] | None:
    """:func:`contract_back` on the boxes given as lists (new lists returned)."""
    bl = lo + wlo
    bh = hi + whi
    uu = u_prev.tolist() + u.tolist()
    pairs = [(c, float(v)) for c, v in zip(sys.hf_contractors(), y, strict=True) if v == v]
    for _ in range(2):
        for (fn, sites), yi in pairs:
            if not sys._call(fn, sites, bl, bh, uu, yi):
                return None
    n = len(lo)
    return bl[:n], bh[:n], bl[n:], bh[n:]


class TermwiseMargin:
    """Mixin of the set-based nonlinear estimators: no data scale ``s_k`` in the returned
    bounds' margin (:mod:`ivobs.estimators.rounding`), which stays ``ROUNDING (1 + |bound|)``.

    For a nonlinear model the data scale takes the largest bound of the unknowns ``w`` as the
    magnitude of the data terms; a parameter such as an Arrhenius constant ``k0 ~ 7e10``, which
    only enters as ``k0 exp(-E/T) ~ 0.04``, would widen every bound by ``ROUNDING k0 ~ 7``.
    These methods put the data margin in the recursion instead, relative to the terms it
    combines: the prediction's box of generators holds ``ROUNDING (1 + |f0| + |J| (|z - c| +
    |G_z| 1))`` (the magnitudes of the linearised terms of ``f`` over the set) and each measured
    output's strip ``ROUNDING (1 + |y_i|)``, so a float64 simulation's rounding of each step is
    covered where it occurs; the returned bounds are widened by ``ROUNDING (1 + |bound|)``, as
    ``nl-interval`` does (it has no data scale either)."""

    def _step_scale(self, k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> float:
        return 0.0

    def _data_scale(self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> np.ndarray:
        return np.zeros(y.shape[:-1])
