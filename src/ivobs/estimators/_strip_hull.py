"""The two exact box enclosures of the strip method's measurement update [Alamo2005].

Both are called once per strip and per step, so they are written as a handful of fused array
operations on stacked ``(2, ·)`` arrays (lower and upper bound, or the two optimal ``μ``, in
one call each) rather than one NumPy call per bound: at the servo's size every NumPy call costs
about as much as its arithmetic. The numbers are those of the one-bound-at-a-time form, bit for
bit (the same elementwise operations in the same order; tests/test_strip_speed.py keeps that
form as its reference).

* :func:`section_hull`: the interval hull of ``(zonotope) ∩ (strip)`` per coordinate, the
  Lagrangian dual of ``max x_j`` minimised at a weighted quantile of its breakpoints.
* :func:`propagate_strip`: one pass of interval constraint propagation of the strip over a box;
  :func:`propagate_lists` the same on Python lists (the same numbers, several times faster for
  the few unknowns of a nonlinear model's joint box).
"""

from __future__ import annotations

import math
from bisect import bisect_left
from itertools import accumulate

import numpy as np

from ..linalg import gamma

__all__ = [
    "pairwise_sum",
    "propagate_hyperplane",
    "propagate_lists",
    "propagate_strip",
    "section_hull",
]

_SIGN = np.array([[1.0], [-1.0]])  # the upper bound f_j(μ) and the lower one -f_j(-μ)
_GAMMA2 = gamma(2)
_FEW = 4  # section_hull: rows finished on Python floats
# the ufuncs' reductions called directly (ndarray.sum and friends add a Python-level wrapper)
_add, _max, _min = np.add.reduce, np.maximum.reduce, np.minimum.reduce


def section_hull(
    z: np.ndarray,
    H: np.ndarray,
    s: np.ndarray,
    e: float,
    sigma: float = 0.0,
    absH: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate hull of ``{z + H ξ : ‖ξ‖∞ <= 1, |sᵀξ - e| <= σ}`` without a solver.

    By LP duality ``max_ξ H_j ξ = min_μ f_j(μ)``, ``f_j(μ) = μ e + |μ| σ + ‖H_j - μ s‖₁`` (and
    any ``μ`` gives a valid bound). ``f_j = μ e + Σ_l w_l |μ - b_l|`` is convex and piecewise
    linear, with breakpoints ``b_l = H_jl / s_l`` of weight ``w_l = |s_l|`` and ``b = 0`` of
    weight ``σ``: its slope ``e - W + 2 Σ_{b_l < μ} w_l`` (``W = Σ w_l``) crosses zero at the
    weighted quantile ``(W - e) / 2`` of the breakpoints, found by sorting them
    (``O(m log m)`` per coordinate, all coordinates at once). The lower bound is the same
    with ``e -> -e`` (same sort, same cumulative weights: both quantiles and both evaluations
    in one array operation each). ``f_j`` is evaluated at the chosen ``μ`` and increased by
    the bound ``γ_{m+4} (|z_j| + |μ| (|e| + σ + ‖s‖₁) + ‖H_j‖₁)`` of its rounding, so the
    returned bounds hold for the exact set whatever the rounding of the sort keys. ``absH``:
    ``‖H_j‖₁`` when the caller has it.
    """
    n, m = H.shape
    if absH is None:
        absH = _add(np.abs(H), axis=1)
    a_s = np.abs(s)
    smax = float(_max(a_s)) if m else 0.0
    if not smax > 0.0:
        r = absH + gamma(m + 2) * (np.abs(z) + absH)
        return z - r, z + r
    keep = a_s > 1e-14 * smax  # tiny s_l: a breakpoint far away of negligible weight
    n_keep = int(np.count_nonzero(keep))
    b = np.empty((n, n_keep + 1))
    w = np.empty(n_keep + 1)
    if n_keep == m:
        w[:-1] = a_s
        Hk, sk = H, s
    else:
        w[:-1] = a_s[keep]
        Hk, sk = H[:, keep], s[keep]
    # a breakpoint beyond the float range (|H_jl| huge against s_l): any finite μ gives a valid
    # bound (weak duality), so it is taken as 0 — only the choice of μ, never the bound,
    # changes. |b_jl| <= ‖H_j‖₁ / min w: the scan (and NumPy's error state, 3 µs) is skipped
    # when that is far from overflow
    if float(_max(absH)) < 1e300 * float(_min(w[:-1])):
        np.divide(Hk, sk, out=b[:, :-1])
    else:
        with np.errstate(over="ignore"):
            np.divide(Hk, sk, out=b[:, :-1])
        b[~np.isfinite(b)] = 0.0
    b[:, -1] = 0.0
    w[-1] = sigma
    idx = b.argsort(axis=1)
    mu = _quantiles(b, w, idx, e) if n <= _FEW else None
    if mu is None:
        cw = w[idx]
        cw.cumsum(axis=1, out=cw)
        # the quantiles (W - e)/2 (upper bound) and (W + e)/2 (lower bound), rows 0 and 1
        thr = 0.5 * (cw[:, -1] + np.array([[-e], [e]]))
        pos = (cw >= thr[:, :, None]).argmax(axis=2)
        rows = np.arange(n)
        mu = b[rows, idx[rows, pos]]
    s1 = float(_add(a_s))
    # f_j(μ) + its rounding bound for the upper bound; for the lower bound -f_j(-μ) with
    # f_j(-μ) = -μ e + |μ| σ + ‖H_j - μ s‖₁ (the same breakpoints, e -> -e)
    # in one (2, n, m) buffer, in place: at n = 60 each temporary is 0.7 MB, allocated and
    # faulted in again at every call
    tmp = np.multiply(mu[:, :, None], s)
    np.subtract(H, tmp, out=tmp)
    spread = _add(np.abs(tmp, out=tmp), axis=2)
    g = gamma(m + 4)
    if n <= _FEW:  # the same operations on floats: cheaper than NumPy calls for a few rows
        c = abs(e) + sigma + s1
        hi_, lo_ = [], []
        for zj, hj, m0, m1, f0, f1 in zip(
            z.tolist(), absH.tolist(), *mu.tolist(), *spread.tolist()
        ):
            az = abs(zj)
            hi_.append(zj + ((m0 * e + abs(m0) * sigma + f0) + g * (az + abs(m0) * c + hj)))
            lo_.append(zj - ((-m1 * e + abs(m1) * sigma + f1) + g * (az + abs(m1) * c + hj)))
        return np.array(lo_), np.array(hi_)
    am = np.abs(mu)
    err = g * (np.abs(z) + am * (abs(e) + sigma + s1) + absH)
    bounds = _SIGN * mu * e + am * sigma + spread + err
    return z - bounds[1], z + bounds[0]


def _quantiles(b: np.ndarray, w: np.ndarray, idx: np.ndarray, e: float) -> np.ndarray | None:
    """The ``μ`` of :func:`section_hull` (rows: upper, lower bound) on floats for a few rows:
    the cumulative weights summed in the same order as ``cumsum``, the first position where
    they reach the quantile found by bisection (they never decrease: ``w >= 0``); ``None``
    when a weight or ``e`` is not finite (the array form decides)."""
    wl = w.tolist()
    up, down = [], []
    for brow, irow in zip(b.tolist(), idx.tolist()):
        cw = list(accumulate([wl[i] for i in irow]))
        total = cw[-1]
        if not (total < math.inf and abs(e) < math.inf):
            return None
        k0, k1 = bisect_left(cw, 0.5 * (total - e)), bisect_left(cw, 0.5 * (total + e))
        # none reaches the quantile (rounding): argmax of all False is 0
        up.append(brow[irow[k0 if k0 < len(cw) else 0]])
        down.append(brow[irow[k1 if k1 < len(cw) else 0]])
    return np.array([up, down])


def propagate_strip(
    h: np.ndarray, t: float, box: np.ndarray, sigma: float = 0.0, nz: np.ndarray | None = None
) -> np.ndarray | None:
    """Contract the box ``box = [lo; hi]`` (shape ``(2, n)``) with the strip ``|hᵀw - t| <=
    σ`` (one pass of interval propagation: ``w_j ∈ ([t - σ, t + σ] - Σ_{l≠j} h_l [w_l]) /
    h_j``), into a new ``(2, n)`` array; ``None`` if the strip certainly misses the box. The
    interval sums are widened by the bound ``γ_{n+3} (|t| + σ + Σ_l |h_l| max(|lo_l|,
    |hi_l|))`` of their rounding, the quotients by ``γ_2`` (relative). ``nz``: the indices of
    the nonzero ``h_j`` when the caller has them."""
    # [h_l lo_l; h_l hi_l] sorted per column: rows t_lo, t_hi, the interval h_l [w_l]
    ext = np.sort(h * box, axis=0)
    s_lo, s_hi = _add(ext, axis=1).tolist()
    delta = gamma(h.size + 3) * (abs(t) + sigma + float(_add(_max(np.abs(ext), axis=0))))
    if t + sigma < s_lo - delta or t - sigma > s_hi + delta:
        return None
    if nz is None:
        nz = np.flatnonzero(h)
    # h_j w_j <= (t + σ) - (s_lo - t_lo_j) + δ (row 0), >= (t - σ) - (s_hi - t_hi_j) - δ (row 1)
    c = np.array([[t + sigma, delta], [t - sigma, -delta]])
    q = (c[:, :1] - (np.array([[s_lo], [s_hi]]) - ext[:, nz]) + c[:, 1:]) / h[nz]
    pad = _GAMMA2 * _max(np.abs(q), axis=0)
    out = box.copy()
    out[0, nz] = np.maximum(box[0, nz], _min(q, axis=0) - pad)
    out[1, nz] = np.minimum(box[1, nz], _max(q, axis=0) + pad)
    if (out[0] > out[1]).any():
        return None  # both intervals hold every (x, d) that explains the data: none does
    return out


def propagate_hyperplane(
    h: np.ndarray, t: float, lo: np.ndarray, hi: np.ndarray, sigma: float = 0.0
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`propagate_strip` on the box ``[lo, hi]`` given as two vectors (new arrays)."""
    out = propagate_strip(h, t, np.stack([lo, hi]), sigma)
    return None if out is None else (out[0], out[1])


def pairwise_sum(a: list[float]) -> float:
    """``np.add.reduce`` of a contiguous float64 vector, on a list, bit for bit: NumPy's
    pairwise summation (a plain loop below 8 terms, 8 accumulators up to 128, halves above;
    tests/test_nl_zonotope_fast.py checks it against NumPy)."""
    return _pairwise(a, 0, len(a))


def _pairwise(a: list[float], lo: int, n: int) -> float:
    if n < 8:
        res = -0.0
        for i in range(lo, lo + n):
            res += a[i]
        return res
    if n <= 128:
        r = a[lo : lo + 8]
        i = 8
        stop = n - n % 8
        while i < stop:
            base = lo + i
            r = [x + y for x, y in zip(r, a[base : base + 8])]
            i += 8
        res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        for k in range(lo + i, lo + n):
            res += a[k]
        return res
    n2 = n // 2
    n2 -= n2 % 8
    return _pairwise(a, lo, n2) + _pairwise(a, lo + n2, n - n2)


def propagate_lists(
    h: list[float], t: float, lo: list[float], hi: list[float], sigma: float = 0.0
) -> tuple[list[float], list[float]] | None:
    """:func:`propagate_strip` on the box ``[lo, hi]`` given as lists (new lists), with the
    same floating-point operations in the same order (the interval sums by
    :func:`pairwise_sum`, as NumPy sums them), so the same bounds bit for bit; ``None`` if the
    strip certainly misses the box."""
    t_lo, t_hi, mag = [], [], []
    for hj, a, b in zip(h, lo, hi):  # the interval h_j [w_j], as np.sort of (h_j lo_j, h_j hi_j)
        p, q = hj * a, hj * b
        if q < p:
            p, q = q, p
        t_lo.append(p)
        t_hi.append(q)
        mag.append(max(abs(p), abs(q)))
    s_lo, s_hi = pairwise_sum(t_lo), pairwise_sum(t_hi)
    delta = gamma(len(h) + 3) * (abs(t) + sigma + pairwise_sum(mag))
    if t + sigma < s_lo - delta or t - sigma > s_hi + delta:
        return None
    up, down = t + sigma, t - sigma
    out_lo, out_hi = list(lo), list(hi)
    for j, hj in enumerate(h):
        if hj == 0.0:
            continue
        q0 = (up - (s_lo - t_lo[j]) + delta) / hj
        q1 = (down - (s_hi - t_hi[j]) - delta) / hj
        pad = _GAMMA2 * max(abs(q0), abs(q1))
        out_lo[j] = max(lo[j], min(q0, q1) - pad)
        out_hi[j] = min(hi[j], max(q0, q1) + pad)
        if out_lo[j] > out_hi[j]:
            return None  # no (x, d) of the box explains the data
    return out_lo, out_hi
