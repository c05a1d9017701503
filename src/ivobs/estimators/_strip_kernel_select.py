"""The weighted quantiles of the strip method's section hull, compiled (numba, issue 17).

The section hull of ``<z, H> ∩ {|sᵀξ - e| <= σ}`` (:func:`._strip_hull.section_hull`) bounds
coordinate ``j`` by ``f_j(μ) = μ e + |μ| σ + Σ_l w_l |μ - b_l|`` at the weighted quantile
``μ`` of the breakpoints ``b_l = H_jl / s_l`` (weights ``w_l = |s_l|``, and ``b = 0`` of
weight ``σ``): the least ``v`` with ``C(v) = Σ_{b_l <= v} w_l >= t`` for the thresholds
``t = (W ∓ e) / 2`` [Alamo2005]. Any ``μ`` gives a valid bound (weak duality), so how it is
found is a matter of speed and of tightness only, never of soundness.

Three ways, each tried when the one before cannot decide:

* :func:`heavy_quantiles`, from the heaviest breakpoints alone. The weights ``|s_l|`` of a
  strip, the same for every coordinate ``j``, are concentrated (tank30: of ~330, the ~10
  largest hold all but 1 % of the total, the ~30 largest all but 1e-4). With ``C_q`` the
  cumulative weight of the ``q`` heaviest breakpoints and ``R_q`` the weight of all the
  others, ``C_q(v) <= C(v) <= C_q(v) + R_q``, so the quantile lies between ``v_a`` (the least
  of those ``q`` breakpoints with ``C_q(v) + R_q >= t``) and ``v_b`` (the least with ``C_q(v)
  >= t``): when ``v_a = v_b`` it *is* that breakpoint, whatever the other ones are, and they
  are neither divided nor visited. The breakpoints are inserted in decreasing weight into a
  sorted list, the bracket tested at ``q = 2, 4, 8, …, MAX_HEAVY`` (tank30: three quarters
  of the coordinates decided by ``q = 16``).
* :func:`bracketed_quantiles`: else the quantiles are in ``[v_a, v_b]``; one pass over all
  the breakpoints sums the weight below ``v_a`` and sorts the few inside (tank30: most of
  the rest).
* :func:`quantiles`, the exact selection over every breakpoint (tank30: about 4 % of the
  coordinates): a sample of 17 brackets the thresholds, one three-way partition, then
  quickselect (median of three) in the part that holds each threshold.

The first two test their cumulative weights with the slack ``δ`` (a bound of the rounding of
every such sum, :func:`quantile_slack`) and give up inside it, so the breakpoint they take is
the one the exact selection takes, bit for bit (tests/test_strip_select.py). The kernel tries
them on strips of at least :data:`FEW` breakpoints whose weights are not :data:`FLAT`, and
stops for the rest of a strip when they fail on most of its coordinates.
"""

from __future__ import annotations

import numpy as np

from ._strip_kernel_linalg import Arr, _g, jit

MAX_HEAVY = 16
"""The heaviest breakpoints :func:`heavy_quantiles` takes at most."""
MAX_BRACKET = 64
"""The breakpoints :func:`bracketed_quantiles` sorts at most."""
FEW = 128
"""Fewer breakpoints: the exact selection at once. Below this the quickselect costs about as
much as the two stages before it (measured: random systems of 5 to 10 states, ~50 to ~120
breakpoints, ran 2-8 % slower with the stages from 48 on; tank30's strips have ~50-160)."""
FLAT = 0.3
"""Weights are flat when all but the :data:`MAX_HEAVY` heaviest hold this share of the
total: the exact selection at once (random 20-state systems: the heaviest never decide)."""


@jit
def heavy_set(w: Arr, n: int, hk: Arr, hw: Arr, rest: Arr) -> int:
    """The ``K <= MAX_HEAVY`` heaviest of the weights ``w[:n]`` in decreasing order: their
    positions into ``hk``, their values into ``hw``; ``rest[q]`` the weight of all but the
    ``q`` heaviest (``q <= K``). Returns ``K``. The same for every coordinate of a strip."""
    k = 0
    for i in range(n):  # insertion into the list of the heaviest so far
        wi = w[i]
        if k == MAX_HEAVY and not wi > hw[k - 1]:
            continue
        q = min(k, MAX_HEAVY - 1)
        while q > 0 and hw[q - 1] < wi:
            hk[q], hw[q] = hk[q - 1], hw[q - 1]
            q -= 1
        hk[q], hw[q] = i, wi
        k = min(k + 1, MAX_HEAVY)
    tot = 0.0
    for i in range(n):
        tot += w[i]
    for q in range(k + 1):  # the total less the q heaviest (rounding: within δ)
        rest[q] = max(tot, 0.0)
        if q < k:
            tot -= hw[q]
    return k


@jit
def quantile_slack(n: int, tot: float) -> float:
    """``δ = 8 γ_{n+3} W``: bounds the rounding of a cumulative weight (a sum of at most ``n``
    nonnegative terms of total ``W``, [Higham2002, Lemma 3.1]) in the exact selection and of
    ``C_q``, ``R_q`` in :func:`heavy_quantiles` (``R_q``: the total less ``q`` weights)
    together, with room for the rounding of ``t ± δ``."""
    return 8.0 * _g(n + 3) * tot


@jit
def heavy_quantiles(
    row: Arr, s: Arr, kidx: Arr, scan: bool, hk: Arr, hw: Arr, rest: Arr, k: int, t1: float,
    t2: float, delta: float, sb: Arr, sw: Arr,
) -> tuple[bool, float, float, float, float]:  # fmt: skip
    """Both quantiles of the coordinate ``row`` from its heaviest breakpoints (module
    docstring; ``hk``, ``hw``, ``rest``, ``k`` of :func:`heavy_set`; ``kidx``: the columns of
    the breakpoints, -1 for ``b = 0``; ``scan``: a non-finite ``b`` is taken as 0):
    ``(found, μ_1, μ_2, lo, hi)``; when not ``found`` (the ``k`` heaviest do not decide), both
    quantiles are in ``[lo, hi]`` (for :func:`bracketed_quantiles`). ``sb``, ``sw``: scratch
    of ``k``, the sorted list."""
    check, lo, hi = 2, -np.inf, np.inf  # the bracket only narrows with q: q = 1 is skipped
    for q in range(k):
        v = _breakpoint(row, s, kidx[hk[q]], scan)
        i = q
        while i > 0 and sb[i - 1] > v:  # after the equal ones
            sb[i], sw[i] = sb[i - 1], sw[i - 1]
            i -= 1
        sb[i], sw[i] = v, hw[q]
        if q + 1 == check or q + 1 == k:
            check *= 2
            va1, vb1 = _bracket(sb, sw, q + 1, rest[q + 1], t1, delta)
            va2, vb2 = _bracket(sb, sw, q + 1, rest[q + 1], t2, delta)
            if va1 == vb1 and va2 == vb2:
                return True, vb1, vb2, vb1, vb2
            lo, hi = min(va1, va2), max(vb1, vb2)
    return False, 0.0, 0.0, lo, hi


@jit
def _breakpoint(row: Arr, s: Arr, c: int, scan: bool) -> float:
    """``b = row[c] / s[c]`` (0 for ``c = -1``, and when ``scan`` for a non-finite one)."""
    v = row[c] / s[c] if c >= 0 else 0.0
    return v if not scan or np.isfinite(v) else 0.0


@jit
def _bracket(sb: Arr, sw: Arr, n: int, light: float, t: float, delta: float) -> tuple[float, float]:
    """``(v_a, v_b)`` for the threshold ``t`` widened by ``δ`` on both sides, on the sorted
    breakpoints ``sb[:n]`` (weights ``sw``) and the weight ``light`` of the others: ``v_b``
    the least with ``C_q >= t + δ`` (``+∞``: none), ``v_a`` the least with ``C_q + R_q >= t -
    δ`` (``-∞`` when ``R_q`` alone may reach it). The quantile is in ``[v_a, v_b]``, and is
    ``v_b`` when they are equal, also for the exact selection's rounded sums."""
    va, vb = -np.inf, np.inf
    seek = light < t - delta  # else the others alone may reach t (or t <= 0)
    c = 0.0
    for i in range(n):
        c += sw[i]
        if i + 1 < n and sb[i + 1] == sb[i]:
            continue  # C counts every breakpoint equal to v
        if seek and c + light >= t - delta:
            va, seek = sb[i], False
        if c >= t + delta:
            vb = sb[i]
            break
    return va, vb


@jit
def bracketed_quantiles(
    row: Arr, s: Arr, kidx: Arr, scan: bool, w: Arr, n: int, lo: float, hi: float,
    t1: float, t2: float, delta: float, bv: Arr, bw: Arr,
) -> tuple[bool, float, float]:  # fmt: skip
    """Both quantiles when they are known to be in ``[lo, hi]`` (:func:`heavy_quantiles`):
    one pass over the ``n`` breakpoints sums the weight below ``lo`` (without branches: half
    of them are) and gathers those in ``[lo, hi]``, which are sorted (insertion) and scanned
    with the threshold ``t`` widened by ``δ`` as in :func:`_bracket`. ``(found, μ_1, μ_2)``,
    ``found`` False when more than :data:`MAX_BRACKET` are in the bracket, a breakpoint is
    NaN or the rounding of the sums could matter (then :func:`quantiles`). ``bv``, ``bw``:
    scratch of :data:`MAX_BRACKET`."""
    b0 = b1 = 0.0
    nb = 0
    for k in range(n):
        v = _breakpoint(row, s, kidx[k], scan)
        if k % 2 == 0:  # two partial sums: half the latency (γ holds in any order)
            b0 += w[k] if v < lo else 0.0
        else:
            b1 += w[k] if v < lo else 0.0
        if lo <= v <= hi:
            if nb == MAX_BRACKET:
                return False, 0.0, 0.0
            i = nb
            while i > 0 and bv[i - 1] > v:
                bv[i], bw[i] = bv[i - 1], bw[i - 1]
                i -= 1
            bv[i], bw[i] = v, w[k]
            nb += 1
        elif not (v < lo or v > hi):
            return False, 0.0, 0.0  # NaN
    ok1, m1 = _scan(bv, bw, nb, b0 + b1, t1, delta)
    ok2, m2 = _scan(bv, bw, nb, b0 + b1, t2, delta)
    return ok1 and ok2, m1, m2


@jit
def _scan(bv: Arr, bw: Arr, n: int, below: float, t: float, delta: float) -> tuple[bool, float]:
    """The least of the sorted ``bv[:n]`` whose cumulative weight (from ``below``) reaches
    ``t``: ``(found, v)``, ``found`` when it is ``>= t + δ`` there and ``< t - δ`` before."""
    c, i = below, 0
    while i < n:
        prev = c
        c += bw[i]
        while i + 1 < n and bv[i + 1] == bv[i]:  # the whole group of equal breakpoints
            i += 1
            c += bw[i]
        if c >= t - delta:
            return c >= t + delta and prev < t - delta, bv[i]
        i += 1
    return False, 0.0


@jit
def quantiles(
    vb: Arr, vw: Arr, n: int, t1: float, t2: float, tot: float, smp: Arr
) -> tuple[float, float]:
    """The two weighted quantiles of the section hull: for each threshold ``t`` the least
    breakpoint ``v`` with ``Σ_{b_l <= v} w_l >= t`` (NumPy's first sorted breakpoint whose
    cumulative weight reaches ``t``; the least one when none does), by selection on
    the values ``vb`` and weights ``vw`` (permuted in place) instead of a sort. A sample of 17
    values brackets both thresholds (``tot``: the total weight), one pass splits the values
    into below, between and above the bracket, and :func:`_select` finishes in the part
    that holds each threshold (usually the small middle one)."""
    vb, vw = vb[:n], vw[:n]
    if n < 64:
        return _select(vb, vw, 0, n, 0.0, t1), _select(vb, vw, 0, n, 0.0, t2)
    k = 17
    sv, sw = smp[0], smp[1]
    for i in range(k):  # evenly spaced sample, insertion-sorted
        v, w = vb[(2 * i + 1) * n // (2 * k)], vw[(2 * i + 1) * n // (2 * k)]
        j = i
        while j > 0 and sv[j - 1] > v:
            sv[j], sw[j] = sv[j - 1], sw[j - 1]
            j -= 1
        sv[j], sw[j] = v, w
    ws = 0.0
    for i in range(k):
        ws += sw[i]
    f = tot / ws if ws > 0.0 else 1.0
    ia, ib, cum = k, k, 0.0
    for i in range(k):  # first sample reaching each threshold (scaled to the total)
        cum += sw[i] * f
        if ia == k and cum >= min(t1, t2):
            ia = i
        if ib == k and cum >= max(t1, t2):
            ib = i
    p_lo = sv[ia - 1] if 0 < ia <= k else -np.inf
    p_hi = sv[ib + 1] if ib + 1 < k else np.inf
    lt, gt, wl, wm = _partition(vb, vw, 0, n, p_lo, p_hi)
    return _part(vb, vw, n, lt, gt, wl, wm, t1), _part(vb, vw, n, lt, gt, wl, wm, t2)


@jit
def _partition(
    vb: Arr, vw: Arr, lo: int, hi: int, p_lo: float, p_hi: float
) -> tuple[int, int, float, float]:
    """Three-way partition of ``vb[lo:hi]`` (``vw`` moved alongside): ``[lo, lt)`` below
    ``p_lo``, ``[lt, gt)`` in ``[p_lo, p_hi]``, ``[gt, hi)`` above ``p_hi``; returns ``lt``,
    ``gt`` and the weights ``wl`` below and ``wm`` between."""
    lt, i, gt = lo, lo, hi
    wl = wm = 0.0
    while i < gt:
        v = vb[i]
        if v < p_lo:
            wl += vw[i]
            vb[i], vb[lt] = vb[lt], v
            vw[i], vw[lt] = vw[lt], vw[i]
            lt += 1
            i += 1
        elif v > p_hi:
            gt -= 1
            vb[i], vb[gt] = vb[gt], v
            vw[i], vw[gt] = vw[gt], vw[i]
        else:
            wm += vw[i]
            i += 1
    return lt, gt, wl, wm


@jit
def _part(vb: Arr, vw: Arr, n: int, lt: int, gt: int, wl: float, wm: float, t: float) -> float:
    """:func:`_select` in the part of ``vb`` split at ``lt``, ``gt`` (weights ``wl`` below,
    ``wm`` between) that holds the threshold ``t``."""
    if wl >= t:
        return _select(vb, vw, 0, lt, 0.0, t)
    if wl + wm >= t:
        return _select(vb, vw, lt, gt, wl, t)
    return _select(vb, vw, gt, n, wl + wm, t)


@jit
def _least(vb: Arr) -> float:
    """The least breakpoint (``vb`` holds them all, in any order; the last one is 0)."""
    out = 0.0
    for v in vb:
        out = min(out, v)
    return out


@jit
def _select(vb: Arr, vw: Arr, lo: int, hi: int, base: float, thr: float) -> float:
    """Quickselect of the least ``v`` in ``vb[lo:hi]`` with ``base + Σ_{vb_l <= v} vw_l >=
    thr`` (``base``: the weight of ``vb[:lo]``, all smaller; ``vb[hi:]`` all larger); the least
    breakpoint when the weight never reaches ``thr`` or ``thr <= 0`` (NumPy's ``argmax`` of an
    all-False row, or the first breakpoint reaching it)."""
    if not thr > 0.0:
        return _least(vb)
    while hi > lo:
        a, c, d = vb[lo], vb[(lo + hi) // 2], vb[hi - 1]
        piv = max(min(a, c), min(max(a, c), d))  # median of three
        lt, gt, wl, we = _partition(vb, vw, lo, hi, piv, piv)  # < piv, == piv, > piv
        if base + wl >= thr:
            hi = lt
        elif base + wl + we >= thr:
            return float(piv)
        else:
            base += wl + we
            lo = gt
    return _least(vb)
