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
``γ_3 (|g0| + r)`` (:func:`~ivobs.sets.zonotope.safe_radius`). ``J̃`` is any float matrix (it
need not be the exact midpoint). ``D = max(Jh - J̃, J̃ - Jl)`` and ``Δ = max(hi - c, c - lo)``
are single rounded subtractions, so ``(1 + 2u) D`` and ``(1 + 2u) Δ`` bound the exact ones; the
product ``D Δ`` (non-negative terms, ``n`` of them) is rounded up by ``(1 + γ_{n+1})`` and the
final sum ``r + D Δ`` by ``(1 + γ_2)`` ([Higham2002, Lemma 3.1 and Section 3.1]). Where the
Jacobian enclosure is not finite (a domain edge) the row falls back to the natural inclusion
``g(B) ⊆ [nl, nh]``: ``J̃_i = 0``, ``g0_i`` and ``ρ_i`` its centre and radius.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

from ..linalg import UNIT_ROUNDOFF, gamma
from ..sets.zonotope import safe_radius

__all__ = ["Linearisation", "contract_back", "linearise"]

_UP = 1.0 + 2.0 * UNIT_ROUNDOFF

BoxFn = Callable[..., tuple[np.ndarray, ...]]
JacFn = Callable[..., tuple[np.ndarray, ...]]


class Linearisation(NamedTuple):
    """``g(ζ) ∈ g0 + J (ζ - c) ± rho`` for every ``ζ`` of the box (exact arithmetic), and the
    natural inclusion ``[nat_lo, nat_hi]`` of ``g`` over the box."""

    g0: np.ndarray
    J: np.ndarray
    rho: np.ndarray
    c: np.ndarray
    nat_lo: np.ndarray
    nat_hi: np.ndarray


def linearise(
    value: BoxFn,
    jac: JacFn,
    lo: np.ndarray,
    hi: np.ndarray,
    c: np.ndarray,
    u: np.ndarray,
    nx: int,
    natural: bool = True,
) -> Linearisation:
    """The mean-value form (MV) of the module docstring of ``g`` (``value``: the model's
    ``f_box`` or ``h_box``; ``jac``: ``f_jac_box`` or ``h_jac_box``) over the joint box
    ``[lo, hi]`` (``x`` then ``w``; ``nx`` states) at ``c`` (clipped into the box).
    ``natural=False``: the caller does not need the natural inclusion (it is then only
    computed for the rows that fall back to it, and NaN elsewhere)."""
    c = np.minimum(np.maximum(c, lo), hi)
    xl, xh, wl, wh = lo[:nx], hi[:nx], lo[nx:], hi[nx:]
    gl, gh = value(c[:nx], c[:nx], u, c[nx:], c[nx:])
    jxl, jxh, jwl, jwh = jac(xl, xh, u, wl, wh)
    Jl, Jh = np.hstack([jxl, jwl]), np.hstack([jxh, jwh])
    g0, r = safe_radius(gl, gh)
    with np.errstate(invalid="ignore", over="ignore"):
        Jt = 0.5 * Jl + 0.5 * Jh  # halves first: no overflow for huge entries
        D = np.maximum(Jh - Jt, Jt - Jl) * _UP
        delta = np.maximum(hi - c, c - lo) * _UP
        rem = (D @ delta) * (1.0 + gamma(c.shape[0] + 1))
        rho = (r + rem) * (1.0 + gamma(2))
    with np.errstate(invalid="ignore", over="ignore"):
        finite = bool(np.isfinite(rho.sum() + g0.sum() + Jt.sum()))  # one test, usually true
    bad = (
        np.zeros(g0.shape, bool)
        if finite
        else ~(np.isfinite(rho) & np.isfinite(g0) & np.all(np.isfinite(Jt), axis=1))
    )
    if natural or not finite:
        nl, nh = value(xl, xh, u, wl, wh)
        if natural:
            nl, nh = _centred(g0, Jt, rho, lo, hi, c, nl, nh)
            # rows whose Jacobian is a point up to the enclosure of their constants are affine
            # on the box: the centred form is already their range, monotonicity adds nothing
            thin = (Jh - Jl) <= 1e-12 * np.maximum(np.abs(Jl), np.abs(Jh))
            curved = np.flatnonzero(~np.all(thin, axis=1))
            nl, nh = _monotone(value, Jl[curved], Jh[curved], lo, hi, u, nx, nl, nh, curved)
    else:
        nl = nh = np.full(g0.shape, np.nan)
    if not finite and np.any(bad):
        Jt[bad] = 0.0
        g0_n, r_n = safe_radius(nl[bad], nh[bad])
        g0, rho = g0.copy(), rho.copy()
        g0[bad], rho[bad] = g0_n, r_n
    return Linearisation(g0=g0, J=Jt, rho=rho, c=c, nat_lo=nl, nat_hi=nh)


def _monotone(
    value: BoxFn,
    Jl: np.ndarray,
    Jh: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    u: np.ndarray,
    nx: int,
    nl: np.ndarray,
    nh: np.ndarray,
    rows: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """The natural inclusion ``[nl, nh]`` tightened by monotonicity: where the Jacobian
    enclosure over the box has a sign (``Jl_ij >= 0`` or ``Jh_ij <= 0``), ``g_i`` is monotone in
    ``ζ_j`` over the whole box, so its minimum (maximum) over the box is reached with ``ζ_j`` at
    the lower or upper end; the natural inclusion over the box with those coordinates fixed is
    still an enclosure of that minimum (maximum) [Jaulin2001, Chapter 2].
    Only ``rows`` are tightened (``Jl``, ``Jh``: their Jacobian rows); rows with the same sign
    pattern share one pair of evaluations."""
    up = Jl >= 0
    down = (Jh <= 0) & ~up
    sel = np.flatnonzero((up | down).any(axis=1))
    if sel.size == 0:
        return nl, nh
    nl, nh = nl.copy(), nh.copy()
    groups: dict[bytes, list[int]] = {}
    for r in sel.tolist():
        groups.setdefault(up[r].tobytes() + down[r].tobytes(), []).append(r)
    for local in groups.values():
        i, members = local[0], rows[local]
        ui, di = up[i], down[i]
        a_lo, a_hi = np.where(di, hi, lo), np.where(ui, lo, hi)  # where g_i is smallest
        b_lo, b_hi = np.where(ui, hi, lo), np.where(di, lo, hi)  # where g_i is largest
        low = value(a_lo[:nx], a_hi[:nx], u, a_lo[nx:], a_hi[nx:])[0]
        high = value(b_lo[:nx], b_hi[:nx], u, b_lo[nx:], b_hi[nx:])[1]
        nl[members] = np.maximum(nl[members], low[members])
        nh[members] = np.minimum(nh[members], high[members])
    return nl, nh


def _centred(
    g0: np.ndarray,
    J: np.ndarray,
    rho: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    c: np.ndarray,
    nl: np.ndarray,
    nh: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``[nl, nh]`` intersected with the centred form ``g0 + J (B - c) ± ρ`` (MV over the
    box; exact for the rows where ``g`` is affine). Each interval sum is widened by
    ``γ_{n+2}`` times the sum of the magnitudes of its terms (its rounding)."""
    a, b = J * (lo - c), J * (hi - c)
    t_lo, t_hi = np.minimum(a, b), np.maximum(a, b)
    err = gamma(c.shape[0] + 3) * (np.abs(g0) + rho + np.maximum(-t_lo, t_hi).sum(axis=1))
    with np.errstate(invalid="ignore"):
        low = g0 + t_lo.sum(axis=1) - rho - err
        high = g0 + t_hi.sum(axis=1) + rho + err
    return np.maximum(nl, low), np.minimum(nh, high)


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
    bl = lo.tolist() + wlo.tolist()
    bh = hi.tolist() + whi.tolist()
    uu = u_prev.tolist() + u.tolist()
    pairs = [(c, float(v)) for c, v in zip(sys.hf_contractors(), y, strict=True) if v == v]
    for _ in range(2):
        for (fn, sites), yi in pairs:
            if not sys._call(fn, sites, bl, bh, uu, yi):
                return None
    n = lo.shape[0]
    a = np.array
    return a(bl[:n]), a(bh[:n]), a(bl[n:], dtype=float), a(bh[n:], dtype=float)
