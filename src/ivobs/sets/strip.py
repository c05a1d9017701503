"""Intersection of a zonotope with a strip [Alamo2005], and the exact boxes it gives.

A measurement ``y_i = hᵀζ + (noise)`` confines ``ζ`` to the strip ``S = {ζ : |hᵀζ - t| <= σ}``.
The set of ``ζ`` is held as a zonotope with a box of rounding errors kept aside and a box,

    ζ ∈ <z, H> ⊕ box(acc),        ζ ∈ [lo, hi],

and :func:`intersect_strip` intersects both with ``S`` (the raw arrays are updated in place):

* **the box** is contracted by the strip (:func:`contract_box`, one pass of interval
  propagation) and by the exact interval hull of ``<z, H> ∩ S`` per coordinate
  (:func:`section_hull`, the Lagrangian dual of ``max ζ_j``: no solver);
* **the zonotope** becomes [Alamo2005]'s ``<z + λ e, [H - λ sᵀ, σ_z λ]>`` (below), with the
  ``λ`` of smallest Frobenius radius of its generator matrix.

**In the generators' coordinates** ``ζ = z + H ξ + a`` (``‖ξ‖∞ <= 1``, ``|a| <= acc``) the strip
reads ``|sᵀξ - e| <= σ_z`` with ``s = fl(Hᵀh)``, ``e = fl(t - hᵀz)`` and ([Higham2002, §3.1]:
``|fl(xᵀy) - xᵀy| <= γ_n |x|ᵀ|y|`` in any order of summation)

    σ_z >= σ + |h|ᵀ acc + γ_{n+1} (|t| + |h|ᵀ|z|) + γ_n |h|ᵀ |H| 1,                  (1)

which covers the rounding of ``s`` and ``e`` and the box aside. The strip certainly misses the
set (an inconsistent measurement) when ``|e| > ‖s‖₁ + σ_z``, or when the box contraction or the
section hull leaves an empty box: each of these holds every point of the set.

**Update** [Alamo2005, Property 1]: for every ``λ``, ``z + Hξ = (z + λe) + (H - λsᵀ)ξ + λ(sᵀξ -
e)`` with ``|sᵀξ - e| <= σ_z``, so ``<z, H> ∩ S ⊆ <z + λe, [H - λsᵀ, σ_z λ]>``, and ``λ* = H s /
(sᵀs + σ_z²)`` minimises the Frobenius norm of the new generator matrix. Any float ``λ`` is
exact in this identity; the rounding of ``z + λe`` and ``H - λsᵀ`` is at most ``γ_2 (|z| +
|λ||e| + |H| 1 + |λ| ‖s‖₁)`` per row, added to ``acc``.

**Rounding.** Every bound is an upper bound of the exact quantity: a nonnegative expression of
``n`` roundings per term is multiplied by ``1 + 2 γ_{n+2}`` and increased by ``(n + 2) η``
(``η``: the underflow of a product; as :func:`ivobs.sets.rounding.upper`), and a returned box end
is one directed step outwards (``nextafter``) from a value whose error is already bounded.

The functions are loops over raw arrays, compiled by numba when it is installed
(:mod:`ivobs._jit`); the same source runs interpreted without it.
"""

from __future__ import annotations

import numpy as np

from .._jit import jit
from ..linalg import gamma
from .rounding import ETA

__all__ = [
    "HEAVY",
    "contract_box",
    "intersect_strip",
    "meet_strips",
    "section_hull",
    "weighted_quantiles",
]

_gamma = jit(gamma)
_INF = np.inf


@jit
def _upper(s: float, n: int) -> float:
    """:func:`ivobs.sets.rounding.upper`: ``s (1 + 2 γ_{n+2}) + (n + 2) η``."""
    return s * (1.0 + 2.0 * _gamma(n + 2)) + (n + 2) * ETA


@jit
def _up(x: float) -> float:
    return float(np.nextafter(x, _INF))


@jit
def _down(x: float) -> float:
    return float(np.nextafter(x, -_INF))


@jit
def _dot(x: np.ndarray, y: np.ndarray, n: int) -> float:
    """``Σ_{l<n} x_l y_l`` in four partial sums (``γ_n`` holds in any order; a single chain of
    additions would wait on each one)."""
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
def _abs_sum(x: np.ndarray, n: int) -> float:
    """``Σ_{l<n} |x_l|`` in four partial sums (as :func:`_dot`)."""
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
def _spread(x: np.ndarray, mu: float, y: np.ndarray, n: int) -> float:
    """``Σ_{l<n} |x_l - μ y_l|`` in four partial sums (as :func:`_dot`)."""
    a0 = a1 = a2 = a3 = 0.0
    k = 0
    while k + 4 <= n:
        a0 += abs(x[k] - mu * y[k])
        a1 += abs(x[k + 1] - mu * y[k + 1])
        a2 += abs(x[k + 2] - mu * y[k + 2])
        a3 += abs(x[k + 3] - mu * y[k + 3])
        k += 4
    while k < n:
        a0 += abs(x[k] - mu * y[k])
        k += 1
    return (a0 + a1) + (a2 + a3)


@jit
def contract_box(h: np.ndarray, t: float, sigma: float, lo: np.ndarray, hi: np.ndarray) -> bool:
    """Contract the box ``[lo, hi]`` (in place) with the strip ``|hᵀζ - t| <= σ``: one pass of
    interval propagation, ``h_j ζ_j ∈ [t - σ, t + σ] - Σ_{l≠j} h_l [ζ_l]``. False when the strip
    certainly misses the box (``lo``, ``hi`` then partly contracted: discard them).

    The interval sums ``Σ_l h_l [ζ_l]`` and the numerators carry at most ``n + 3`` roundings of
    terms no larger than ``|t| + σ + Σ_l |h_l| max(|lo_l|, |hi_l|)``, so ``δ = 2 γ_{n+5}`` times
    that bounds their error; each numerator is then moved by ``δ`` and divided, both rounded
    outwards. A box with a non-finite end is left as it is."""
    n = h.shape[0]
    s_lo = s_hi = mag = 0.0
    for j in range(n):
        if h[j] != 0.0:
            a, b = h[j] * lo[j], h[j] * hi[j]
            if b < a:
                a, b = b, a
            s_lo += a
            s_hi += b
            mag += max(abs(a), abs(b))
    if not mag < _INF:
        return True
    delta = 2.0 * _gamma(n + 5) * (abs(t) + sigma + mag) + (n + 5) * ETA
    if _up(t + sigma) < _down(s_lo - delta) or _down(t - sigma) > _up(s_hi + delta):
        return False
    for j in range(n):
        hj = h[j]
        if hj == 0.0:
            continue
        a, b = hj * lo[j], hj * hi[j]
        if b < a:
            a, b = b, a
        top = _up(((t + sigma) - (s_lo - a)) + delta)  # >= h_j ζ_j
        bottom = _down(((t - sigma) - (s_hi - b)) - delta)  # <= h_j ζ_j
        if hj > 0.0:
            new_lo, new_hi = _down(bottom / hj), _up(top / hj)
        else:
            new_lo, new_hi = _down(top / hj), _up(bottom / hj)
        lo[j] = max(lo[j], new_lo)
        hi[j] = min(hi[j], new_hi)
        if lo[j] > hi[j]:
            return False
    return True


@jit
def _select(
    b: np.ndarray, w: np.ndarray, lo: int, hi: int, base: float, thr: float, piv: float
) -> float:
    """The least ``v`` in ``b[lo:hi]`` with ``base + Σ_{b_l <= v} w_l >= thr`` (``base``: the
    weight of ``b[:lo]``, all smaller; ``b[hi:]`` all larger), by quickselect; ``piv``, the
    value next to the range, when the range is empty (the threshold lies between it and
    its neighbour)."""
    while hi > lo:
        piv, lt, gt, w_lt, w_eq = _partition(b, w, lo, hi)
        if base + w_lt >= thr:
            hi = lt
        elif base + w_lt + w_eq >= thr:
            return float(piv)
        else:
            base += w_lt + w_eq
            lo = gt
    return float(piv)


@jit
def _partition(
    b: np.ndarray, w: np.ndarray, lo: int, hi: int
) -> tuple[float, int, int, float, float]:
    """``b[lo:hi]`` (``w`` alongside) split around the median of three ``piv``: ``[lo, lt)``
    below it, ``[lt, gt)`` equal, ``[gt, hi)`` above; ``(piv, lt, gt, w_lt, w_eq)`` with the
    weights of the first two parts."""
    a, c, d = b[lo], b[(lo + hi) // 2], b[hi - 1]
    piv = max(min(a, c), min(max(a, c), d))
    lt, i, gt = lo, lo, hi
    w_lt = w_eq = 0.0
    while i < gt:
        v = b[i]
        if v < piv:
            w_lt += w[i]
            b[i], b[lt] = b[lt], v
            w[i], w[lt] = w[lt], w[i]
            lt += 1
            i += 1
        elif v > piv:
            gt -= 1
            b[i], b[gt] = b[gt], v
            w[i], w[gt] = w[gt], w[i]
        else:
            w_eq += w[i]
            i += 1
    return piv, lt, gt, w_lt, w_eq


@jit
def weighted_quantiles(
    b: np.ndarray, w: np.ndarray, n: int, t1: float, t2: float
) -> tuple[float, float]:
    """For each threshold ``t`` the least ``v`` among ``b[:n]`` with ``Σ_{b_l <= v} w_l >= t``
    (``w >= 0``; the least value when ``t <= 0``, the largest when the weights never reach
    ``t``), by quickselect: both thresholds follow the same partitions until they part, then
    each is finished alone. ``b`` and ``w`` are permuted together in place."""
    lo, hi, base, piv = 0, n, 0.0, 0.0
    while hi > lo:
        piv, lt, gt, w_lt, w_eq = _partition(b, w, lo, hi)
        below, upto = base + w_lt, base + w_lt + w_eq
        side1 = 0 if below >= t1 else (1 if upto >= t1 else 2)
        side2 = 0 if below >= t2 else (1 if upto >= t2 else 2)
        if side1 == side2 == 0:
            hi = lt
        elif side1 == side2 == 2:
            base, lo = upto, gt
        else:  # the thresholds part here (or both hit the pivot): each finished alone
            v1 = v2 = float(piv)
            if side1 == 0:
                v1 = _select(b, w, lo, lt, base, t1, piv)
            elif side1 == 2:
                v1 = _select(b, w, gt, hi, upto, t1, piv)
            if side2 == 0:
                v2 = _select(b, w, lo, lt, base, t2, piv)
            elif side2 == 2:
                v2 = _select(b, w, gt, hi, upto, t2, piv)
            return v1, v2
    return float(piv), float(piv)


HEAVY = 16
"""Breakpoints of largest weight that :func:`section_hull` tries first."""


@jit
def _breakpoint(row: np.ndarray, s: np.ndarray, col: int) -> float:
    """``b = row[col] / s[col]`` (``col = -1``: the breakpoint 0 of weight ``σ``), 0 when it
    leaves the float range (any ``μ`` gives a valid bound)."""
    if col < 0:
        return 0.0
    v = row[col] / s[col]
    return v if abs(v) < _INF else 0.0


@jit
def _bracket(v: np.ndarray, w: np.ndarray, n: int, rest: float, t: float) -> tuple[float, float]:
    """``(v_a, v_b)`` around the weighted quantile ``t`` of all the breakpoints from ``n`` of
    them (sorted values ``v``, weights ``w``) and the weight ``rest`` of the others: with
    ``C_n`` the cumulative weight of these ``n``, ``C_n(x) <= C(x) <= C_n(x) + rest``, so the
    quantile is at least ``v_a``, the least ``v_i`` with ``C_n + rest >= t`` (``-∞`` when
    ``rest >= t``), and at most ``v_b``, the least with ``C_n >= t`` (``+∞``: none)."""
    va = -_INF if rest >= t else _INF
    vb = _INF
    c = 0.0
    for i in range(n):
        c += w[i]
        if i + 1 < n and v[i + 1] == v[i]:
            continue  # C counts every breakpoint equal to v[i]
        if va == _INF and c + rest >= t:
            va = v[i]
        if c >= t:
            vb = v[i]
            break
    return va, vb


@jit
def section_hull(
    z: np.ndarray, H: np.ndarray, m: int, n: int, s: np.ndarray, e: float, sigma: float,
    rows: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """The interval hull of ``{z + H ξ : ‖ξ‖∞ <= 1, |sᵀξ - e| <= σ}`` on its first ``n``
    coordinates (``H[:, :m]``; ``rows``: ``|H| 1``), without a solver; rounded outwards.

    By LP duality ``max H_j ξ = min_μ f_j(μ)``, ``f_j(μ) = μ e + |μ| σ + ‖H_j - μ s‖₁``, and every
    ``μ`` gives an upper bound (``H_j ξ = μ sᵀξ + (H_j - μ s)ᵀ ξ``). ``f_j = μ e + Σ_l w_l |μ -
    b_l|`` is convex piecewise linear, with breakpoints ``b_l = H_jl / s_l`` of weight ``w_l =
    |s_l|`` and ``b = 0`` of weight ``σ``: its slope ``e - W + 2 Σ_{b_l < μ} w_l`` (``W = Σ w``)
    changes sign at the weighted quantile ``(W - e) / 2`` of the breakpoints. The lower bound
    is ``-max (-H_j) ξ``: the quantile ``(W + e) / 2``, ``z_j - f_j(-μ)`` with ``f_j(-μ) = -μ e
    + |μ| σ + ‖H_j - μ s‖₁``.

    The weights are the same for every coordinate and usually concentrated, so when there
    are more than ``4 HEAVY`` breakpoints the :data:`HEAVY` heaviest bracket each quantile
    (:func:`_bracket`), often to one breakpoint; otherwise one pass gathers the breakpoints
    inside the bracket and :func:`weighted_quantiles` selects among them (among all of them
    when there are few).

    ``f_j(μ)`` evaluated in floats has at most ``m + 3`` roundings per term, of terms no larger
    than ``|μ| (|e| + σ + ‖s‖₁) + ‖H_j‖₁``: that times ``2 γ_{m+4}`` (plus underflow) is added,
    and both additions are rounded outwards. A breakpoint beyond the float range is taken as 0,
    and the ``s_l`` below ``10⁻¹⁴ max |s|`` are not breakpoints (far, of negligible weight):
    only the choice of ``μ`` changes, never the bound's validity."""
    lo, hi = np.empty(n), np.empty(n)
    smax = s1 = 0.0
    for col in range(m):
        smax = max(smax, abs(s[col]))
        s1 += abs(s[col])
    # the breakpoints' columns (-1: the breakpoint 0) and weights, heaviest first
    cols = np.empty(m + 1, np.int64)
    w = np.empty(m + 1)
    nb = 0
    for col in range(m):
        if abs(s[col]) > 1e-14 * smax:
            cols[nb], w[nb] = col, abs(s[col])
            nb += 1
    cols[nb], w[nb] = -1, sigma
    nb += 1
    heavy = nb > 4 * HEAVY  # fewer breakpoints: the selection over all of them at once
    if heavy:
        order = np.argsort(-w[:nb])
        cols, w = cols[order], w[order]
    total = 0.0
    for k in range(nb):
        total += w[k]
    t_up, t_lo = 0.5 * (total - e), 0.5 * (total + e)
    rest = total  # the weight of all but the heaviest
    if heavy:
        for k in range(HEAVY):
            rest -= w[k]
    rest = max(rest, 0.0)
    hv, hw = np.empty(HEAVY), np.empty(HEAVY)
    gb, gw = np.empty(nb), np.empty(nb)
    g, tail = 2.0 * _gamma(m + 4), abs(e) + sigma + s1
    for j in range(n):
        mu_up = mu_lo = 0.0
        if smax > 0.0:
            row = H[j]
            lo_b, hi_b, decided = -_INF, _INF, False
            if heavy:  # the heaviest breakpoints, inserted by value, bracket the quantiles
                for k in range(HEAVY):
                    v, i = _breakpoint(row, s, cols[k]), k
                    while i > 0 and hv[i - 1] > v:
                        hv[i], hw[i] = hv[i - 1], hw[i - 1]
                        i -= 1
                    hv[i], hw[i] = v, w[k]
                va_up, vb_up = _bracket(hv, hw, HEAVY, rest, t_up)
                va_lo, vb_lo = _bracket(hv, hw, HEAVY, rest, t_lo)
                decided = va_up == vb_up and va_lo == vb_lo
                mu_up, mu_lo = vb_up, vb_lo
                lo_b, hi_b = min(va_up, va_lo), max(vb_up, vb_lo)
            if not decided:  # the breakpoints inside the bracket, and the weight below it
                below, ng = 0.0, 0
                for k in range(nb):
                    v = _breakpoint(row, s, cols[k])
                    if v < lo_b:
                        below += w[k]
                    elif v <= hi_b:
                        gb[ng], gw[ng] = v, w[k]
                        ng += 1
                mu_up = mu_lo = 0.0
                if ng > 0:
                    mu_up, mu_lo = weighted_quantiles(gb, gw, ng, t_up - below, t_lo - below)
        spread_up = _spread(H[j], mu_up, s, m)
        spread_lo = spread_up if mu_lo == mu_up else _spread(H[j], mu_lo, s, m)
        f_up = spread_up + (mu_up * e + abs(mu_up) * sigma)
        f_lo = spread_lo + (-mu_lo * e + abs(mu_lo) * sigma)
        err_up = g * (abs(mu_up) * tail + rows[j]) + (m + 4) * ETA
        err_lo = g * (abs(mu_lo) * tail + rows[j]) + (m + 4) * ETA
        hi[j] = _up(z[j] + _up(f_up + err_up))
        lo[j] = _down(z[j] - _up(f_lo + err_lo))
    return lo, hi


@jit
def meet_strips(
    P: np.ndarray, nx: int, nu: int, a: float, b: float, lo: np.ndarray, hi: np.ndarray,
    u: np.ndarray, y: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """Contract each box ``[lo[k], hi[k]]`` (rows, in place) with the strips of the outputs
    ``y[k]`` whose value is not NaN, one after the other (:func:`contract_box`), in two sweeps
    (a strip of several states gains from the states the others pin). Row ``i`` of ``P = [C,
    D, f, κ]`` gives the strip ``|C_i ζ - t| <= σ`` of ``y_i = y[k, i]`` with inputs ``u[k]``
    (:mod:`ivobs.estimators.measured` has the proof)::

        t = y_i - D_i u[k] - f_i,    σ = a (|y_i| + |D_i| |u[k]|) + b |C_i| m + κ_i,

    ``m = max(|lo[k]|, |hi[k]|)``; ``σ`` is rounded up for its own evaluation (at most ``nx + nu
    + 4`` roundings on every path). A strip with a non-finite ``σ`` is skipped (a box with an
    infinite end: nothing to contract). Returns, per row, False when a strip certainly misses
    the box: that row is then left as it was. Rows with a NaN bound are skipped."""
    T, ny = y.shape
    ok = np.ones(T, dtype=np.bool_)
    t, sigma = np.empty(ny), np.empty(ny)
    box_lo, box_hi = np.empty(nx), np.empty(nx)
    for k in range(T):
        if np.isnan(lo[k, 0]) or np.isnan(hi[k, 0]):
            continue
        for i in range(ny):
            yi = y[k, i]
            t[i] = yi
            if np.isnan(yi):
                continue
            s, mag, xm = yi, abs(yi), 0.0
            for j in range(nu):
                s -= P[i, nx + j] * u[k, j]
                mag += abs(P[i, nx + j]) * abs(u[k, j])
            for j in range(nx):
                if P[i, j] != 0.0:
                    xm += abs(P[i, j]) * max(abs(lo[k, j]), abs(hi[k, j]))
            t[i] = s - P[i, nx + nu]
            sigma[i] = _upper(a * mag + b * xm + P[i, nx + nu + 1], nx + nu + 4)
        for j in range(nx):
            box_lo[j], box_hi[j] = lo[k, j], hi[k, j]
        for q in range(2 * ny):
            i = q % ny
            if np.isnan(t[i]) or not sigma[i] < _INF:
                continue
            if not contract_box(P[i, :nx], t[i], sigma[i], box_lo, box_hi):
                ok[k] = False
                break
        if ok[k]:
            for j in range(nx):
                lo[k, j], hi[k, j] = box_lo[j], box_hi[j]
    return ok


@jit
def intersect_strip(
    h: np.ndarray, t: float, sigma: float, z: np.ndarray, H: np.ndarray, m: int,
    acc: np.ndarray, rows: np.ndarray, lo: np.ndarray, hi: np.ndarray, n_hull: int,
) -> int:  # fmt: skip
    """Intersect ``ζ ∈ <z, H[:, :m]> ⊕ box(acc)``, ``ζ ∈ [lo, hi]`` with the strip ``|hᵀζ - t|
    <= σ`` (module docstring), all in place; ``rows = |H[:, :m]| 1`` on entry and on return,
    ``H`` with room for one more column. The section hull bounds the first ``n_hull``
    coordinates. Returns the new number of generators, or -1 when the strip certainly misses
    the set (nothing changed)."""
    nz = z.shape[0]
    s = np.zeros(m)
    hz = h_z = h_acc = h_rows = 0.0
    for r in range(nz):
        if h[r] != 0.0:
            hr = h[r]
            hz += hr * z[r]
            h_z += abs(hr) * abs(z[r])
            h_acc += abs(hr) * acc[r]
            h_rows += abs(hr) * rows[r]
            for col in range(m):
                s[col] += hr * H[r, col]
    e = t - hz
    # (1), its γ terms doubled for their own evaluation, and the underflow of the sums of s
    g_e, g_s = 2.0 * _gamma(nz + 1), 2.0 * _gamma(nz)
    sigma_z = (
        _upper(sigma + h_acc + g_e * (abs(t) + h_z) + g_s * h_rows, nz + 5)
        + (m + 1) * (nz + 2) * ETA
    )
    s1 = 0.0
    for col in range(m):
        s1 += abs(s[col])
    if abs(e) > _upper(s1 + sigma_z, m + 1):
        return -1  # no ‖ξ‖∞ <= 1 has |sᵀξ - e| <= σ_z
    box_lo, box_hi = lo.copy(), hi.copy()
    if not contract_box(h, t, sigma, box_lo, box_hi):
        return -1
    hull_lo, hull_hi = section_hull(z, H, m, n_hull, s, e, sigma_z, rows)
    for j in range(n_hull):
        box_lo[j] = max(box_lo[j], _down(hull_lo[j] - acc[j]))
        box_hi[j] = min(box_hi[j], _up(hull_hi[j] + acc[j]))
        if box_lo[j] > box_hi[j]:
            return -1
    lo[:] = box_lo
    hi[:] = box_hi
    den = sigma_z * sigma_z
    for col in range(m):
        den += s[col] * s[col]
    if s1 == 0.0 or not 0.0 < den < _INF:
        return m  # nothing to gain for the zonotope (or out of the float range)
    g, ae, se = 2.0 * _gamma(4), abs(e), s1 + sigma_z
    for r in range(nz):
        row = H[r]
        lam = _dot(row, s, m) / den  # λ* [Alamo2005]; any λ is exact in the docstring's identity
        if not abs(lam) < _INF:
            lam = 0.0
        al = abs(lam)
        # the rounding of z + λ e, H - λ sᵀ and σ_z λ: into the box aside
        acc[r] = _up(acc[r] + (g * (abs(z[r]) + al * ae + rows[r] + al * se) + (m + 4) * ETA))
        z[r] = z[r] + lam * e
        for col in range(m):
            row[col] = row[col] - lam * s[col]
        row[m] = sigma_z * lam
        rows[r] = _abs_sum(row, m + 1)
    return m + 1
