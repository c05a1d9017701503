"""What the nonlinear methods share: the measurement as the interval of reals it stands for,
the conservative linearisation of a map over a box (the mean-value form), and one step back
through the model.

**Measurements** (:func:`measurement`). A sample is a real number rounded to a double (by the
sensor's converter, a logger, or the last operation of a simulator), so its exact value lies
within one unit in the last place of the double ``y``: in ``[down(y), up(y)]``, the two
neighbouring doubles. Every consistency test of the family uses that interval: a sample
that lies within rounding of its bound (``y = -0.1 + -0.005`` is ``-0.10500000000000001`` in
doubles, ``4e-18`` beyond the exact ``-0.105``) is never a fault.

**Mean-value form** (:func:`linearise`). For a map ``g(ζ)`` of the joint vector ``ζ = (x, w)``
(state, then the per-step unknowns ``w`` of a :class:`~ivobs.NonlinearSystem`), a box
``B = [lo, hi]`` that certainly holds ``ζ`` and an expansion point ``c ∈ B``, the mean-value
theorem applied to each component gives, for every ``ζ ∈ B``, a point ``ξ_i`` of the segment
``[c, ζ] ⊆ B`` with ``g_i(ζ) = g_i(c) + ∇g_i(ξ_i) (ζ - c)``. With ``[J]`` an interval enclosure
of the Jacobian over ``B`` and any real matrix ``J̃``::

    g(ζ) ∈ g(c) + J̃ (ζ - c) + ([J] - J̃)(B - c)                                      (MV)

[Rego2020] (their mean-value extension; the first-order Taylor form with the Lagrange
remainder of [Althoff2008] is the same statement with ``J̃ = J(c)``). ``J̃ = mid [J]`` makes
``[J] - J̃`` symmetric, ``|[J] - J̃| <= rad [J]``: the smallest remainder of all choices.

:func:`linearise` returns ``(g0, J̃, ρ)`` with ``|g(ζ) - g0 - J̃ (ζ - c)| <= ρ`` componentwise
for every ``ζ ∈ B``, in exact arithmetic on the returned doubles. **Proof of the rounding**
(the model of :mod:`ivobs.sets.rounding`, [Higham2002, Lemma 3.1 and Section 3.1]):
``g(c) ∈ [gl, gh]`` (the model's outward-rounded point evaluation), so ``g0 = gl`` is within
``r = up(gh - gl)`` of ``g(c)``; ``J̃`` is any double matrix; ``D = up(max(Jh - J̃, J̃ - Jl))``
and ``Δ = up(max(hi - c, c - lo))`` are one rounded subtraction each, rounded up, so they bound
``|[J] - J̃|`` and ``|ζ - c|`` over ``B``; then ``|g(ζ) - g0 - J̃(ζ - c)| <= r + D Δ``, and
``ρ = upper(r + D Δ, n + 1)`` bounds that sum of nonnegative terms (``n`` products, their sum
and one addition: at most ``n + 1`` roundings on every path). Where the Jacobian enclosure is
not finite (a domain edge) the row falls back to the natural inclusion ``g(B) ⊆ [nl, nh]``:
``J̃_i = 0``, ``g0_i ± ρ_i ⊇ [nl_i, nh_i]`` (:func:`~ivobs.sets.rounding.mid_rad`).

The natural inclusion returned beside it is tightened by the centred form (MV over the box,
its sums' rounding bounded by ``2 γ_{n+4}`` of their magnitudes) and by monotonicity.

**Spread** (a set-valued map). A sampled plant whose disturbances vary between samples maps a
state to a set: ``g(ζ) ⊆ g_c(ζ) ± s(B)`` for every ``ζ ∈ B``, with ``g_c`` a single-valued map
(the flow with the signals held at their centre) and ``s(B) >= 0``
(:class:`~ivobs.model.nonlinear.flow.FlowSystem`). The evaluators then have a third member
returning ``s(B)``; (MV) applies to ``g_c``, and ``ρ`` and the natural inclusion are widened by
``s(B)`` (rounded up): every point of every ``g(ζ)`` stays within ``g0 + J̃ (ζ - c) ± ρ``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np

from ...linalg import gamma
from ...model.nonlinear._runtime import dn as _down
from ...model.nonlinear._runtime import up as _up
from ...sets.rounding import ETA, down, mid_rad, up, upper

__all__ = [
    "Linearisation",
    "contract_back",
    "contract_centred",
    "joint_box",
    "linearise",
    "measurement",
]

Evals = tuple[Callable[..., Any], ...]
"""``(natural, natjac)`` of the model's ``f`` or ``h`` on lists, and for a set-valued ``f``
its spread (:meth:`~ivobs.NonlinearSystem.evaluators`, module docstring)."""

Vector = np.ndarray | Sequence[float]


def measurement(y: np.ndarray) -> tuple[list[float], list[float]]:
    """``(ylo, yhi)``: the reals each double ``y_i`` stands for, ``[down(y_i), up(y_i)]``
    (module docstring); NaN (a missing component) stays NaN."""
    values = y.tolist()
    return [_down(v) for v in values], [_up(v) for v in values]


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
    evals: Evals,
    lo: Vector,
    hi: Vector,
    c: np.ndarray,
    u: np.ndarray,
    nx: int,
    natural: bool = True,
) -> Linearisation:
    """The mean-value form (MV) of ``g`` (``evals``: the model's
    :meth:`~ivobs.NonlinearSystem.evaluators` of ``f`` or ``h``) over the joint box
    ``[lo, hi]`` (``x`` then ``w``; ``nx`` states) at ``c`` clipped into the box.
    ``natural=False``: the natural inclusion is returned as the model gives it (the caller does
    not use it), not tightened by the centred form and monotonicity.

    Written on Python floats, one row at a time: the vectors of one step are a handful of
    numbers, for which scalar arithmetic costs a fraction of NumPy's per-call overhead."""
    value, natjac = evals[0], evals[1]
    bl, bh = _floats(lo), _floats(hi)
    cl = [min(max(a, p), q) for a, p, q in zip(c.tolist(), bl, bh)]
    ul = u.tolist()
    gl, gh = value(cl[:nx], cl[:nx], ul, cl[nx:], cl[nx:])  # g(c), outward rounded
    nl, nh, jl, jh = natjac(bl[:nx], bh[:nx], ul, bl[nx:], bh[nx:])  # g(B) and [J] over B
    m, n = len(gl), len(cl)
    delta = [_up(max(q - a, a - p)) for a, p, q in zip(cl, bl, bh)]  # >= |ζ - c| over B
    g0s, rhos, rows, edges = list(gl), [0.0] * m, [], []
    groups: dict[tuple[bool, ...], list[int]] = {}  # rows to tighten by monotonicity
    for i in range(m):
        Jl, Jh = jl[i * n : i * n + n], jh[i * n : i * n + n]
        J = [0.5 * p + 0.5 * q for p, q in zip(Jl, Jh)]  # J̃ = mid [J] (halves: no overflow)
        # g(c) ∈ [gl, gh]: within up(gh - gl) of g0 = gl; |[J] - J̃| <= D = up(max(...))
        terms = [_up(max(q - t, t - p)) * d for p, q, t, d in zip(Jl, Jh, J, delta)]
        rho = upper(_up(gh[i] - gl[i]) + sum(terms), n + 1)
        if not math.isfinite(rho + gl[i] + sum(J)):  # a domain edge: the natural inclusion
            edges.append(i)
            J = [0.0] * n
        elif natural:
            nl[i], nh[i] = _centred(gl[i], J, rho, bl, bh, cl, nl[i], nh[i])
            if any(q - p > 1e-12 * max(-p, q, p, -q) for p, q in zip(Jl, Jh)):
                rising = [p >= 0.0 for p in Jl]
                key = tuple(rising + [q <= 0.0 and not r for q, r in zip(Jh, rising)])
                if any(key):
                    groups.setdefault(key, []).append(i)
        rows.append(J)
        rhos[i] = rho
    for key, members in groups.items():
        _monotone(value, key, bl, bh, ul, nx, members, nl, nh)
    nat_lo, nat_hi = np.array(nl, dtype=float), np.array(nh, dtype=float)
    g0, rho_arr = np.array(g0s, dtype=float), np.array(rhos)
    if len(evals) > 2:  # a set-valued map: g(ζ) ⊆ g_c(ζ) ± spread over the box (Spread)
        spread = np.array(evals[2](bl[:nx], bh[:nx], ul, bl[nx:], bh[nx:]), dtype=float)
        if spread.size:
            nat_lo, nat_hi = down(nat_lo - spread), up(nat_hi + spread)
            rho_arr = up(rho_arr + spread)
    if edges:
        g0[edges], rho_arr[edges] = mid_rad(nat_lo[edges], nat_hi[edges])
    J_arr = np.array(rows, dtype=float).reshape(m, n)
    return Linearisation(g0, J_arr, rho_arr, np.array(cl), nat_lo, nat_hi)


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
    over the box; the range itself where ``g`` is affine). The computed sum of ``n`` rounded
    products of rounded differences, and ``g0 + s ∓ ρ``, are within ``γ_{n+3}`` of the
    magnitude ``|g0| + ρ + Σ_j max|J_j (B_j - c_j)|`` (plus ``n`` underflows); ``2 γ_{n+4}``
    of it, and one outward rounding, cover that and the rounding of the bound itself. A bound
    that comes out NaN (an infinite box edge times a zero entry) is ignored."""
    n = len(c)
    s_lo = s_hi = s_abs = 0.0
    for j, p, q, m in zip(J, lo, hi, c):
        a, b = j * (p - m), j * (q - m)
        if a > b:
            a, b = b, a
        s_lo += a
        s_hi += b
        s_abs += max(-a, b)
    err = 2.0 * gamma(n + 4) * (abs(g0) + rho + s_abs) + (n + 4) * ETA
    low, high = _down(g0 + s_lo - rho - err), _up(g0 + s_hi + rho + err)
    return max(nl, low), min(nh, high)  # max(nl, nan) is nl


def contract_centred(
    lin: Linearisation,
    lo: list[float],
    hi: list[float],
    tl: Sequence[float],
    th: Sequence[float],
    rows: Sequence[int],
) -> bool:
    """Contract the box ``[lo, hi]`` of ``ζ`` (in place) with ``g_i(ζ) ∈ [tl_i, th_i]`` for the
    ``rows`` ``i``, ``g`` given by
    its mean-value form ``lin`` over a box that holds ``[lo, hi]`` (the centred-form
    contractor [Jaulin2001, Ch. 4]; codac's ``CtcInverse`` with its centred form). For each row
    ``i`` and each ``ζ_j`` with ``J̃_ij ≠ 0``, every ``ζ`` of the box with ``g_i(ζ) ∈ [tl_i,
    th_i]`` has, by (MV),

        J̃_ij (ζ_j - c_j) ∈ [tl_i - g0_i - ρ_i - S_i^+ + b_j, th_i - g0_i + ρ_i - S_i^- + a_j]

    with ``[a_l, b_l]`` the range of ``J̃_il (ζ_l - c_l)`` over the box and ``S_i^∓`` their sums:
    divided by ``J̃_ij``, a new interval for ``ζ_j``. Where ``ζ_j`` enters ``g_i`` more than once
    (``x - c √x``, the tanks' levels) this is much tighter than the forward-backward
    contractor, which treats each occurrence as a variable of its own. Rows are taken in turn,
    each from the box the rows before it left. A NaN target (a missing sample) skips its row.

    **Rounding.** The differences ``ζ_l - c_l``, the products, the sums and the subtractions of
    one bound are at most ``n + 5`` roundings on every path, so each computed bound is within
    ``γ_{n+5}`` of the magnitude ``|tl_i| + |th_i| + |g0_i| + ρ_i + Σ_l max(|a_l|, |b_l|)``,
    plus ``n + 5`` underflows [Higham2002, Lemma 3.1]; twice ``γ_{n+6}`` of it is subtracted
    (added) and rounded outward, the quotient and the sum with ``c_j`` rounded outward by one
    ulp each. The box only loses points that cannot meet the target. False when it becomes
    empty (no point of the box meets the target)."""
    n = len(lo)
    c = lin.c.tolist()
    J = lin.J.tolist()
    for i in rows:
        row, t0, t1 = J[i], tl[i], th[i]
        if not (t0 == t0 and t1 == t1) or not any(row):
            continue
        g0, rho = float(lin.g0[i]), float(lin.rho[i])
        ranges = []
        s_lo = s_hi = s_abs = 0.0
        for j, p, q, m in zip(row, lo, hi, c):
            a, b = j * (p - m), j * (q - m)
            if a > b:
                a, b = b, a
            ranges.append((a, b))
            s_lo += a
            s_hi += b
            s_abs += max(-a, b)
        err = 2.0 * gamma(n + 6) * (abs(t0) + abs(t1) + abs(g0) + rho + s_abs) + (n + 6) * ETA
        if not math.isfinite(err):
            continue
        for j, (Jij, (a, b)) in enumerate(zip(row, ranges)):
            if Jij == 0.0:
                continue
            low = _down(t0 - g0 - rho - s_hi + b - err)  # bounds of J̃_ij (ζ_j - c_j)
            high = _up(t1 - g0 + rho - s_lo + a + err)
            q0, q1 = low / Jij, high / Jij
            if q0 > q1:
                q0, q1 = q1, q0
            new_lo, new_hi = _down(c[j] + _down(q0)), _up(c[j] + _up(q1))
            if new_lo > lo[j]:  # (False for NaN)
                lo[j] = new_lo
            if new_hi < hi[j]:
                hi[j] = new_hi
            if lo[j] > hi[j]:
                return False
    return True


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
    natural inclusion over the box with those coordinates fixed still encloses that minimum
    (maximum) [Jaulin2001, Chapter 2]. Rows with the same sign pattern share one pair of
    evaluations. (A row whose Jacobian is a point up to the enclosure of its constants is
    affine on the box: the centred form is already its range, and it is not passed here.)"""
    n = len(lo)
    rising, falling = key[:n], key[n:]
    a_lo = [q if f else p for p, q, f in zip(lo, hi, falling)]  # where g_i is smallest
    a_hi = [p if r else q for p, q, r in zip(lo, hi, rising)]
    b_lo = [q if r else p for p, q, r in zip(lo, hi, rising)]  # where g_i is largest
    b_hi = [p if f else q for p, q, f in zip(lo, hi, falling)]
    low = value(a_lo[:nx], a_hi[:nx], u, a_lo[nx:], a_hi[nx:])[0]
    high = value(b_lo[:nx], b_hi[:nx], u, b_lo[nx:], b_hi[nx:])[1]
    for i in rows:
        nl[i], nh[i] = max(nl[i], low[i]), min(nh[i], high[i])


def joint_box(
    c: np.ndarray, G: np.ndarray, e: np.ndarray, xlo: np.ndarray, xhi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The box of ``x_k`` for a joint set: the bounds ``c ± (|G| 1 + e)`` of ``<c, G> ⊕ box(e)``,
    rounded outward, intersected with ``[xlo, xhi]`` (both hold the state; if they part, only
    by rounding, the zonotope's bounds are kept)."""
    rad = upper(np.abs(G).sum(axis=1) + e, G.shape[1] + 1)
    lo_z, hi_z = down(c - rad), up(c + rad)
    lo, hi = np.fmax(xlo, lo_z), np.fmin(xhi, hi_z)
    if (lo > hi).any():
        return lo_z, hi_z
    return lo, hi


def contract_back(
    sys: Any,
    lo: Vector,
    hi: Vector,
    u_prev: np.ndarray,
    u: np.ndarray,
    wlo: Vector,
    whi: Vector,
    y: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """One step back through the model: the box ``[lo, hi]`` of ``ζ_{k-1} = (x_{k-1},
    w_{k-1})`` and the box ``[wlo, whi]`` of ``w_k`` contracted with
    ``h(f(x_{k-1}, u_{k-1}, w_{k-1}), u_k, w_k) ∈ [y_k]`` (the measurement interval, the
    model's forward-backward contractors of ``h ∘ f``, two sweeps; NaN components skipped):
    ``(lo, hi, wlo, whi)``, or ``None`` when no point of the boxes explains ``y_k`` (an
    inconsistent measurement). When ``y_k`` does not pin down the states of step ``k`` but does
    those of step ``k - 1`` (Hénon with ``y = x2 = 0.3 x1[k-1]``), this bounds the box over
    which ``f`` is then linearised."""
    n = len(lo)
    bl = _floats(lo) + _floats(wlo)
    bh = _floats(hi) + _floats(whi)
    uu = u_prev.tolist() + u.tolist()
    ylo, yhi = measurement(y)
    pairs = [(c, a, b) for c, a, b in zip(sys.hf_contractors(), ylo, yhi, strict=True) if a == a]
    for _ in range(2):
        for (fn, sites), a, b in pairs:
            if not sys._call(fn, sites, bl, bh, uu, a, b):
                return None
    arr = np.array
    return arr(bl[:n]), arr(bh[:n]), arr(bl[n:], dtype=float), arr(bh[n:], dtype=float)


def _floats(v: Vector) -> list[float]:
    return v.tolist() if isinstance(v, np.ndarray) else list(v)
