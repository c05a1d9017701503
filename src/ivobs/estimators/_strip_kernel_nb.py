"""The strip method's whole step compiled with numba (issue 17); see :mod:`._strip_kernel`.

The same recursion as :meth:`StripEstimator._step` with the NumPy helpers
(``_strip_hull.section_hull``, ``_strip_hull.propagate_strip``,
``sets.zonotope.reduce_parallelotope`` / ``reduce_girard``), written as loops: the joint set,
the strips [Alamo2005] (eq. (8) half-widths, the propagation, the per-coordinate section hull,
its weighted quantile from the heaviest breakpoints or by quickselect instead of a sort
(:mod:`._strip_kernel_select`: the same breakpoint; any ``μ`` gives a valid bound, the
choice only its tightness); the F-radius update) and the
prediction here; the parallelotope reduction [Chisci1998] (its pivoted QR after LAPACK's
``dlaqp2``) and Girard's [Girard2005] in :mod:`._strip_kernel_linalg`.

**Rounding.** Every margin is the NumPy path's, with the same term counts: ``γ_n``
([Higham2002, Lemma 3.1]) bounds the rounding of a sum or dot product of ``n`` terms in *any*
order, so the loops' left-to-right sums (instead of NumPy's pairwise sums and BLAS kernels)
are covered by the same ``γ``. Terms that are exactly zero are skipped (fewer roundings). The
functions are compiled with ``@njit(cache=True)`` and *no* ``fastmath``: IEEE semantics, no
reassociation, and LLVM does not contract ``a * b + c`` into an FMA without the ``contract``
flag (tests/test_strip_kernel.py checks the machine code). The parallelotope reduction's
``ρ`` bounds ``|l - P α|`` computed from whatever ``α`` the QR gave, so its soundness does not
depend on the QR's accuracy (only the choice between it and Girard's box does).
"""

from __future__ import annotations

import numpy as np

from ._strip_kernel_linalg import (
    MAX_COND,
    Arr,
    U,
    _asum,
    _dot,
    _g,
    _reduce_girard,
    _reduce_parallelotope,
    jit,
)
from ._strip_kernel_select import (
    FEW,
    FLAT,
    MAX_BRACKET,
    MAX_HEAVY,
    bracketed_quantiles,
    heavy_quantiles,
    heavy_set,
    quantile_slack,
    quantiles,
)

__all__ = ["MAX_COND", "strip_step"]


# -- the measurement update --------------------------------------------------------------------


@jit
def _joint(
    p: Arr, H: Arr, e: Arr, jc: Arr, cd: Arr, rd: Arr, dlo: Arr, dhi: Arr, room: int
) -> tuple[Arr, Arr, int, Arr, Arr]:
    """StripEstimator._joint: ``(z, Hz, m, box, acc)`` of ``(x_k, d_jc)``."""
    nx, nh, nj = p.shape[0], H.shape[1], jc.shape[0]
    ncol = 0
    for c in range(nj):
        if rd[jc[c]] > 0:
            ncol += 1
    nz, m = nx + nj, nh + ncol
    z = np.empty(nz)
    Hz = np.zeros((nz, m + room))
    box = np.empty((2, nz))
    acc = np.zeros(nz)
    g, g2 = _g(nh + 2), 1.0 + _g(2)
    for i in range(nx):
        r0 = 0.0
        for j in range(nh):
            Hz[i, j] = H[i, j]
            r0 += abs(H[i, j])
        pad = g * (abs(p[i]) + r0) + e[i] * g2
        z[i] = p[i]
        box[0, i] = p[i] - r0 - pad
        box[1, i] = p[i] + r0 + pad
        acc[i] = e[i]
    k = nh
    for c in range(nj):
        z[nx + c] = cd[jc[c]]
        box[0, nx + c] = dlo[jc[c]]
        box[1, nx + c] = dhi[jc[c]]
        if rd[jc[c]] > 0:
            Hz[nx + c, k] = rd[jc[c]]
            k += 1
    return z, Hz, m, box, acc


@jit
def _propagate(h: Arr, t: float, box: Arr, sigma: float, ext: Arr, out: Arr) -> bool:
    """_strip_hull.propagate_strip, into ``box`` in place; False (box untouched) when the
    strip certainly misses it. ``ext``, ``out``: (2, n) scratch."""
    n = h.shape[0]
    s_lo = s_hi = amax = 0.0
    for j in range(n):
        a, b = h[j] * box[0, j], h[j] * box[1, j]
        if b < a:
            a, b = b, a
        ext[0, j], ext[1, j] = a, b
        s_lo += a
        s_hi += b
        amax += max(abs(a), abs(b))
    delta = _g(n + 3) * (abs(t) + sigma + amax)
    if t + sigma < s_lo - delta or t - sigma > s_hi + delta:
        return False
    g2 = _g(2)
    for j in range(n):
        out[0, j], out[1, j] = box[0, j], box[1, j]
        if h[j] != 0.0:
            q0 = ((t + sigma) - (s_lo - ext[0, j]) + delta) / h[j]
            q1 = ((t - sigma) - (s_hi - ext[1, j]) - delta) / h[j]
            pad = g2 * max(abs(q0), abs(q1))
            out[0, j] = max(box[0, j], min(q0, q1) - pad)
            out[1, j] = min(box[1, j], max(q0, q1) + pad)
    for j in range(n):
        if out[0, j] > out[1, j]:
            return False  # no (x, d) explains the data
    box[:, :] = out
    return True


@jit
def _section_hull(
    z: Arr, Hz: Arr, n: int, m: int, s: Arr, e: float, sigma: float, absH: Arr, lo: Arr,
    hi: Arr, sel: tuple[Arr, ...],
) -> None:  # fmt: skip
    """_strip_hull.section_hull for ``<z[:n], Hz[:n, :m]>``, into ``lo``, ``hi``; ``sel``:
    the scratch of :func:`_selection_scratch`. Each ``μ`` from the heaviest breakpoints or
    their bracket when they decide it, else by the exact selection
    (:mod:`._strip_kernel_select`: the same ``μ``, bit for bit); ``μ_u = μ_l``: one sum."""
    kidx, b, w, cw, sp, smp, hk, hb, hw, cum, rest, bv, bw = sel
    smax = 0.0
    for c in range(m):
        smax = max(smax, abs(s[c]))
    if not smax > 0.0:
        g = _g(m + 2)
        for j in range(n):
            r = absH[j] + g * (abs(z[j]) + absH[j])
            lo[j], hi[j] = z[j] - r, z[j] + r
        return
    nk, wmin, s1 = 0, np.inf, 0.0
    for c in range(m):
        a = abs(s[c])
        s1 += a
        if a > 1e-14 * smax:  # tiny s_l: a far breakpoint of negligible weight
            kidx[nk], w[nk] = c, a
            wmin = min(wmin, a)
            nk += 1
    w[nk] = sigma
    kidx[nk] = -1  # the breakpoint b = 0 of weight σ is the last one
    hmax = 0.0
    for j in range(n):
        hmax = max(hmax, absH[j])
    scan = not hmax < 1e300 * wmin  # a breakpoint may overflow: taken as 0 (any μ is valid)
    g, ae = _g(m + 4), abs(e)
    tot = 0.0  # the total weight, the same for every coordinate
    for k in range(nk + 1):
        tot += w[k]
    t1, t2 = 0.5 * (tot - e), 0.5 * (tot + e)
    # few breakpoints: quickselect at once; flat weights: the heaviest rarely decide (and
    # they are given up when they fail on most coordinates)
    fails, flat, nh, delta = 0, nk + 1 < FEW, 0, 0.0
    if not flat:
        nh = heavy_set(w, nk + 1, hk, hw, rest)  # the same for every coordinate
        delta = quantile_slack(nk + 1, tot)
        flat = not rest[nh] < FLAT * tot
    for j in range(n):
        row = Hz[j]
        found, mu_u, mu_l = False, 0.0, 0.0
        if not flat:
            found, mu_u, mu_l, va, vb = heavy_quantiles(
                row, s, kidx, scan, hk, hw, rest, nh, t1, t2, delta, hb, cum
            )
            if not found:
                found, mu_u, mu_l = bracketed_quantiles(
                    row, s, kidx, scan, w, nk + 1, va, vb, t1, t2, delta, bv, bw
                )
            fails += not found
            flat = fails > 4 and 2 * fails > j + 1
        if not found:
            _breakpoints(row, s, m, nk, kidx, scan, b)
            for k in range(nk + 1):  # a loop: cw and w share a buffer, a slice copy would
                cw[k] = w[k]  # test the overlap and copy through a new array
            mu_u, mu_l = quantiles(b, cw, nk + 1, t1, t2, tot, smp)
        for c in range(m):  # elementwise (vectorised), then summed with partial sums
            sp[c] = abs(row[c] - mu_u * s[c])
        sp_u = sp_l = _asum(sp, m)
        if mu_l != mu_u:
            for c in range(m):
                sp[c] = abs(row[c] - mu_l * s[c])
            sp_l = _asum(sp, m)
        au, al = abs(mu_u), abs(mu_l)
        err_u = g * (abs(z[j]) + au * (ae + sigma + s1) + absH[j])
        err_l = g * (abs(z[j]) + al * (ae + sigma + s1) + absH[j])
        hi[j] = z[j] + (mu_u * e + au * sigma + sp_u + err_u)
        lo[j] = z[j] - (-mu_l * e + al * sigma + sp_l + err_l)


@jit
def _breakpoints(row: Arr, s: Arr, m: int, nk: int, kidx: Arr, scan: bool, b: Arr) -> None:
    """``b[:nk] = row / s`` at the kept positions ``kidx`` (non-finite ones as 0 when
    ``scan``), ``b[nk] = 0``."""
    if nk == m:  # every s_l kept: a contiguous (vectorised) division
        for k in range(m):
            b[k] = row[k] / s[k]
    else:
        for k in range(nk):
            b[k] = row[kidx[k]] / s[kidx[k]]
    if scan:
        for k in range(nk):
            b[k] = b[k] if np.isfinite(b[k]) else 0.0
    b[nk] = 0.0


@jit
def _selection_scratch(cap: int) -> tuple[Arr, ...]:
    """The scratch of :func:`_section_hull` for up to ``cap`` generators, as views of two
    arrays (each allocation costs as much as a small strip's selection): ``kidx``, ``b``,
    ``w``, ``cw``, ``sp`` (``cap + 1``), the sample (2, 17), the heaviest ``hk``, ``hb``,
    ``hw``, ``cum`` (:data:`MAX_HEAVY`), ``rest`` (one more), the bracket ``bv``, ``bw``
    (:data:`MAX_BRACKET`)."""
    n, nh, nb = cap + 1, MAX_HEAVY, MAX_BRACKET
    ints, f = np.empty(n + nh, np.int64), np.empty(4 * n + 34 + 4 * nh + 1 + 2 * nb)
    a, c = 4 * n + 34, 4 * n + 34 + 4 * nh + 1  # where the heaviest's, the bracket's start
    return (
        ints[:n], f[:n], f[n : 2 * n], f[2 * n : 3 * n], f[3 * n : 4 * n],
        f[4 * n : a].reshape((2, 17)), ints[n:], f[a : a + nh], f[a + nh : a + 2 * nh],
        f[a + 2 * nh : a + 3 * nh], f[a + 3 * nh : c], f[c : c + nb], f[c + nb : c + 2 * nb],
    )  # fmt: skip


@jit
def _rows_s(Hz: Arr, m: int, h: Arr, rows: Arr, s: Arr) -> None:
    """``rows = |Hz[:, :m]| 1`` and ``s = hᵀ Hz[:, :m]`` in one pass over ``Hz`` (only
    ``rows`` when ``h`` is empty)."""
    s[:m] = 0.0
    with_s = h.shape[0] > 0
    for r in range(Hz.shape[0]):
        rows[r] = _asum(Hz[r], m)
        if with_s and h[r] != 0.0:
            hr = h[r]
            for c in range(m):
                s[c] += hr * Hz[r, c]


@jit
def _intersect(
    h: Arr, ah: Arr, hn: Arr, t: float, y_i: float, du: float, g_meas: float, nx: int, z: Arr,
    Hz: Arr, m: int, box: Arr, acc: Arr, s: Arr, sn: Arr, sc: tuple[Arr, ...],
) -> tuple[int, bool]:  # fmt: skip
    """strip._Joint.intersect with ``v_i = 0``, given ``rows = |Hz| 1`` and ``s = hᵀ Hz``
    (:func:`_rows_s`): ``(m', ready)``, ``m'`` the new generator count or -1 when the strip
    certainly misses the set (left as it was). On return ``rows`` is that of the new ``Hz``;
    when the set was updated and ``hn`` (the next strip's ``h``) is not empty, ``sn = hnᵀ Hz``
    too, computed in the update's pass (``ready``). ``sc``: the scratch arrays."""
    rows, lo_j, hi_j, ext, out, sel = sc
    nz = z.shape[0]
    hz = haz = hw = hrows = hacc = 0.0
    for r in range(nz):
        if h[r] != 0.0:
            hz += h[r] * z[r]
            hw += ah[r] * max(abs(box[0, r]), abs(box[1, r]))
            haz += ah[r] * abs(z[r])
            hrows += ah[r] * rows[r]
            hacc += ah[r] * acc[r]
    e = t - hz
    # eq. (8) of strip.py's docstring: the strip that certainly holds (x_k, d_k)
    sigma = (g_meas * (abs(y_i) + du + hw) + _g(nz + 1) * (abs(t) + haz) + _g(nz) * hrows) * (
        1.0 + 4.0 * U
    )
    sigma_z = (sigma + hacc) * (1.0 + _g(nz + 2))
    s1 = 0.0
    for c in range(m):
        s1 += abs(s[c])
    if abs(e) > (s1 + sigma_z) * (1.0 + _g(m + 2)):
        return -1, False
    if not _propagate(h, t, box, sigma, ext, out):
        return -1, False
    _section_hull(z, Hz, nx, m, s, e, sigma_z, rows, lo_j, hi_j, sel)
    for r in range(nx):
        pad = acc[r] * (1.0 + 2.0 * U)
        box[0, r] = max(box[0, r], lo_j[r] - pad)
        box[1, r] = min(box[1, r], hi_j[r] + pad)
    den = 0.0
    for c in range(m):
        den += s[c] * s[c]
    den = den + sigma_z * sigma_z
    if s1 == 0.0 or not den > 0.0:
        return m, False
    g3, ae, se = _g(3), abs(e), s1 + sigma_z
    nxt = hn.shape[0] > 0
    if nxt:
        sn[: m + 1] = 0.0
    for r in range(nz):
        row = Hz[r]
        lam = _dot(row, s, m) / den  # the F-radius optimal λ* of [Alamo2005]
        al = abs(lam)
        acc[r] = acc[r] + g3 * (abs(z[r]) + al * ae + rows[r] + al * se)
        z[r] = z[r] + lam * e
        for c in range(m):
            row[c] -= lam * s[c]
        row[m] = sigma_z * lam
        rows[r] = _asum(row, m + 1)  # for the next strip, while the row is in cache
        if nxt and hn[r] != 0.0:
            hr = hn[r]
            for c in range(m + 1):
                sn[c] += hr * row[c]
    return m + 1, nxt


# -- prediction --------------------------------------------------------------------------------


@jit
def _predict(
    z: Arr, Hz: Arr, m: int, rows: Arr, acc: Arr, u: Arr, cd: Arr, rd: Arr, st: tuple[Arr, ...]
) -> tuple[Arr, Arr]:
    """StripEstimator._predict without ``w̄``: ``(p, H)`` before the reduction."""
    _, _, _, _, _, pc, mc, M, aM, Ep, aEp, B, aB = st
    nx, nmc, npc, nu = M.shape[0], mc.shape[0], pc.shape[0], u.shape[0]
    p = np.empty(nx)
    err = np.empty(nx)
    g, ga = 2.0 * _g(nmc + npc + nu + 1), 1.0 + _g(nmc + 1)
    for i in range(nx):
        a = t1 = t4 = 0.0
        for k in range(nmc):
            j = mc[k]
            a += M[i, k] * z[j]
            t1 += aM[i, k] * (abs(z[j]) + rows[j] + acc[j])
            t4 += aM[i, k] * acc[j]
        b = t2 = 0.0
        for k in range(npc):
            b += Ep[i, k] * cd[pc[k]]
            t2 += aEp[i, k] * (abs(cd[pc[k]]) + rd[pc[k]])
        c = t3 = 0.0
        for k in range(nu):
            c += B[i, k] * u[k]
            t3 += aB[i, k] * abs(u[k])
        p[i] = a + b + c
        err[i] = g * (t1 + t2 + t3) + t4 * ga
    nlive = nerr = 0
    for k in range(npc):
        nlive += rd[pc[k]] > 0
    for i in range(nx):
        nerr += err[i] > 0
    Hn = np.zeros((nx, m + nlive + nerr))
    for i in range(nx):
        for k in range(nmc):
            a = M[i, k]
            if a != 0.0:
                for c in range(m):
                    Hn[i, c] += a * Hz[mc[k], c]
    col = m
    for k in range(npc):
        if rd[pc[k]] > 0:
            for i in range(nx):
                Hn[i, col] = Ep[i, k] * rd[pc[k]]
            col += 1
    for i in range(nx):
        if err[i] > 0:
            Hn[i, col] = err[i]
            col += 1
    used = np.zeros(Hn.shape[1], np.bool_)
    for i in range(nx):
        for c in range(Hn.shape[1]):
            used[c] = used[c] or Hn[i, c] != 0.0
    return p, np.ascontiguousarray(Hn[:, used])


# -- the step ----------------------------------------------------------------------------------


@jit
def strip_step(
    p: Arr, H: Arr, e: Arr, u: Arr, y: Arr, cd: Arr, rd: Arr, dlo: Arr, dhi: Arr,
    st: tuple[Arr, ...], order: int, girard: bool,
) -> tuple[Arr, Arr, Arr, Arr, Arr, bool, bool]:  # fmt: skip
    """One step of the strip method: ``(p', H', e', lo, hi, inconsistent, finite)``; ``st``
    the tuple of ``_strip_kernel.kernel_structure``; ``girard``: Girard's reduction instead of
    the parallelotope. ``finite`` False: the predicted set overflowed (not reduced)."""
    D, aD, h, ah, jc = st[0], st[1], st[2], st[3], st[4]
    nx, ny, nu = p.shape[0], y.shape[0], u.shape[0]
    meas = np.flatnonzero(y == y)  # NaN: a missing component
    z, Hz, m, box, acc = _joint(p, H, e, jc, cd, rd, dlo, dhi, meas.shape[0])
    nz, cap = z.shape[0], Hz.shape[1]
    sc = (
        np.empty(nz), np.empty(nx), np.empty(nx), np.empty((2, nz)), np.empty((2, nz)),
        _selection_scratch(cap),
    )  # fmt: skip
    rows, s, sn = sc[0], np.empty(cap), np.empty(cap)
    g_meas = 2.0 * _g(nx + cd.shape[0] + nu + 2)
    inconsistent, ready = False, False
    none = h[:0, 0]  # no next strip
    for q in range(meas.shape[0]):
        i = meas[q]
        if not ready:
            _rows_s(Hz, m, h[i], rows, s)
        du_ = du = 0.0
        for k in range(nu):
            du_ += D[i, k] * u[k]
            du += aD[i, k] * abs(u[k])
        hn = h[meas[q + 1]] if q + 1 < meas.shape[0] else none
        args = (y[i] - du_, y[i], du, g_meas, nx, z, Hz, m, box, acc, s, sn, sc)
        mi, ready = _intersect(h[i], ah[i], hn, *args)
        if mi < 0:
            inconsistent = True
        else:
            m = mi
        if ready:
            s, sn = sn, s
    if meas.shape[0] == 0:
        _rows_s(Hz, m, none, rows, s)
    ga = 1.0 + _g(ny + 1)  # the rounding of acc's sums
    lo, hi = np.empty(nx), np.empty(nx)
    for r in range(nz):
        acc[r] = acc[r] * ga
        if r < nx:
            rr = rows[r] + acc[r]
            lo[r] = max(z[r] - rr, box[0, r])
            hi[r] = max(min(z[r] + rr, box[1, r]), lo[r])
    pn, Hn = _predict(z, Hz, m, rows, acc, u, cd, rd, st)
    if not (np.isfinite(pn).all() and np.isfinite(Hn).all()):
        return pn, Hn, np.zeros(nx), lo, hi, inconsistent, False
    if girard:
        return pn, _reduce_girard(Hn, order), np.zeros(nx), lo, hi, inconsistent, True
    Hr, rho = _reduce_parallelotope(Hn, order)
    return pn, Hr, rho, lo, hi, inconsistent, True
