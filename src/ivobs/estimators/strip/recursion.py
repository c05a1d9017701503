"""One step of the strip method on raw arrays: joint set, strips, box, prediction, reduction.

The step is a composition of set operations, each with its proven rounding (the equations and
the proofs are in :mod:`ivobs.estimators.strip` and :mod:`ivobs.sets.strip`):

1. :func:`joint_set`: ``(x_k, d_jc) ∈ <z, H> ⊕ box(acc)`` and the box ``[lo, hi]`` of it;
2. :func:`measure`: the strips of the measured components of ``y[k]``, one after the other
   (:func:`ivobs.sets.strip.intersect_strip`);
3. :func:`state_box`: the box of ``x[k]``, the zonotope's hull intersected with ``[lo, hi]``;
4. :func:`predict`: ``x[k+1] ∈ [A E_jc] <z, H> ⊕ E_pc <c_d, R> ⊕ B u`` as a zonotope whose last
   generators box every rounding, then the order reduction (:mod:`ivobs.sets.reduction`).

:func:`step` runs the four for the common case (exactly known matrices); the estimator
composes them itself with the interval-matrix terms between them. Loops over raw arrays,
compiled by numba when it is installed (:mod:`ivobs._jit`).
"""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from ..._jit import jit, kernels_in
from ...sets.reduction import reduce_girard, reduce_parallelotope
from ...sets.rounding import ETA
from ...sets.strip import _gamma, _upper, intersect_strip

__all__ = ["GIRARD", "NONE", "PARALLELOTOPE", "joint_set", "measure", "predict", "reduce_step",
           "state_box", "step"]  # fmt: skip

PARALLELOTOPE, GIRARD, NONE = 0, 1, 2
"""The order reductions :func:`step` applies (``NONE``: the caller reduces)."""

_INF = np.inf
Arr = np.ndarray


@jit
def joint_set(
    p: np.ndarray, H: np.ndarray, e: np.ndarray, jc: np.ndarray, cd: np.ndarray,
    rd: np.ndarray, dlo: np.ndarray, dhi: np.ndarray, room: int,
) -> tuple[Arr, Arr, int, Arr, Arr, Arr, Arr]:  # fmt: skip
    """``(z, Hz, m, acc, rows, lo, hi)``: ``(x_k, d_jc) ∈ <z, Hz[:, :m]> ⊕ box(acc)`` from ``x_k
    ∈ <p, H> ⊕ box(e)`` and ``d ∈ [dlo, dhi] ⊆ <cd, diag(rd)>`` (no rounding: copies), ``Hz``
    with ``room`` free columns for the strips, ``rows = |Hz| 1``; the box ``[lo, hi]`` of the
    pair: the hull of ``x``'s set (rounded outwards) and ``d``'s bounds."""
    nx, nh, nj = p.shape[0], H.shape[1], jc.shape[0]
    nd_live = 0
    for c in range(nj):
        nd_live += rd[jc[c]] > 0.0
    nz, m = nx + nj, nh + nd_live
    z, acc, rows = np.empty(nz), np.zeros(nz), np.empty(nz)
    lo, hi = np.empty(nz), np.empty(nz)
    Hz = np.zeros((nz, m + room))
    for i in range(nx):
        total = 0.0
        for col in range(nh):
            Hz[i, col] = H[i, col]
            total += abs(H[i, col])
        z[i], acc[i], rows[i] = p[i], e[i], total
        rad = _upper(total + e[i], nh + 1)
        lo[i] = np.nextafter(p[i] - rad, -_INF)
        hi[i] = np.nextafter(p[i] + rad, _INF)
    col = nh
    for c in range(nj):
        j = jc[c]
        z[nx + c], lo[nx + c], hi[nx + c], rows[nx + c] = cd[j], dlo[j], dhi[j], rd[j]
        if rd[j] > 0.0:
            Hz[nx + c, col] = rd[j]
            col += 1
    return z, Hz, m, acc, rows, lo, hi


@jit
def measure(
    z: np.ndarray, Hz: np.ndarray, m: int, acc: np.ndarray, rows: np.ndarray, lo: np.ndarray,
    hi: np.ndarray, y: np.ndarray, u: np.ndarray, v: np.ndarray, D: np.ndarray, h: np.ndarray,
    nx: int, g_meas: float,
) -> tuple[int, bool]:  # fmt: skip
    """Intersect the joint set with the strip of every measured (not NaN) component of ``y``
    in turn, in place: ``|h_iᵀζ - t_i| <= σ_i``, ``t_i = fl(y_i - D_i u)``, ``σ_i`` the bound
    of the rounding of ``t_i`` and of a float64 evaluation of the output equation (``g_meas
    (|y_i| + |D_i||u| + |h_i|ᵀ max(|lo|, |hi|))``) plus ``v_i`` (interval matrices). Returns
    the number of generators and whether a strip certainly missed the set (that strip is not
    used)."""
    nz, nu = z.shape[0], u.shape[0]
    inconsistent = False
    for i in range(y.shape[0]):
        if not y[i] == y[i]:
            continue  # missing
        du_ = du = mag = 0.0
        for k in range(nu):
            du_ += D[i, k] * u[k]
            du += abs(D[i, k]) * abs(u[k])
        for r in range(nz):
            if h[i, r] != 0.0:
                mag += abs(h[i, r]) * max(abs(lo[r]), abs(hi[r]))
        sigma = _upper(g_meas * (abs(y[i]) + du + mag) + v[i], nz + nu + 4)
        grown = intersect_strip(h[i], y[i] - du_, sigma, z, Hz, m, acc, rows, lo, hi, nx)
        if grown < 0:
            inconsistent = True
        else:
            m = grown
    return m, inconsistent


@jit
def state_box(
    z: np.ndarray, rows: np.ndarray, acc: np.ndarray, m: int, lo: np.ndarray, hi: np.ndarray,
    nx: int,
) -> tuple[np.ndarray, np.ndarray, bool]:  # fmt: skip
    """The box of ``x[k]``: the hull ``z ± (|H| 1 + acc)`` of the zonotope (rounded outwards)
    intersected with the box of the pair; and whether the two are disjoint somewhere (both
    hold every state that explains the data: none does). Where disjoint, their hull."""
    xlo, xhi = np.empty(nx), np.empty(nx)
    crossed = False
    for i in range(nx):
        rad = _upper(rows[i] + acc[i], m + 1)
        a = max(float(np.nextafter(z[i] - rad, -_INF)), lo[i])
        b = min(float(np.nextafter(z[i] + rad, _INF)), hi[i])
        if a > b:
            crossed = True
            a, b = min(a, lo[i]), max(b, hi[i])
        xlo[i], xhi[i] = a, b
    return xlo, xhi, crossed


@jit
def predict(
    z: np.ndarray, Hz: np.ndarray, m: int, rows: np.ndarray, acc: np.ndarray, u: np.ndarray,
    cd: np.ndarray, rd: np.ndarray, w: np.ndarray, M: np.ndarray, mc: np.ndarray,
    Ep: np.ndarray, pc: np.ndarray, B: np.ndarray, n_plant: int,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``(p, H)`` of ``x[k+1]`` before the reduction: ``p = fl(M z + E_pc c_pc + B u)``, ``H =
    [fl(M Hz), E_pc diag(r_pc), diag(err)]`` (``M = [A E_jc]`` on the columns ``mc``), zero
    columns dropped. ``err`` bounds, per row, the rounding of ``p`` and of the generators
    (``γ`` of their dot products times ``|M| (|z| + |Hz| 1 + acc) + |E_pc| (|c_pc| + r_pc) +
    |B||u|``), the same for a float64 evaluation of the plant (``n_plant`` terms), the image
    ``|M| acc`` of the box aside and ``w`` (interval matrices)."""
    nx, nmc, npc, nu = M.shape[0], mc.shape[0], pc.shape[0], u.shape[0]
    p, err = np.empty(nx), np.empty(nx)
    g = 3.0 * _gamma(n_plant)  # ours and the plant's, and the evaluation of the bound
    tiny = (m + npc + 2) * (nmc + npc + nu + 2) * ETA  # underflow of the products
    for i in range(nx):
        a = mag = img = 0.0
        for k in range(nmc):
            j = mc[k]
            a += M[i, k] * z[j]
            mag += abs(M[i, k]) * (abs(z[j]) + rows[j] + acc[j])
            img += abs(M[i, k]) * acc[j]
        for k in range(npc):
            a += Ep[i, k] * cd[pc[k]]
            mag += abs(Ep[i, k]) * (abs(cd[pc[k]]) + rd[pc[k]])
        for k in range(nu):
            a += B[i, k] * u[k]
            mag += abs(B[i, k]) * abs(u[k])
        p[i] = a
        err[i] = _upper(g * mag + img + w[i], nmc + npc + nu + 3) + tiny
    n_live = n_err = 0
    for k in range(npc):
        n_live += rd[pc[k]] > 0.0
    for i in range(nx):
        n_err += err[i] > 0.0
    Hn = np.zeros((nx, m + n_live + n_err))
    for i in range(nx):
        for k in range(nmc):
            a = M[i, k]
            if a != 0.0:
                for col in range(m):
                    Hn[i, col] += a * Hz[mc[k], col]
    col = m
    for k in range(npc):
        if rd[pc[k]] > 0.0:
            for i in range(nx):
                Hn[i, col] = Ep[i, k] * rd[pc[k]]
            col += 1
    for i in range(nx):
        if err[i] > 0.0:
            Hn[i, col] = err[i]
            col += 1
    used = np.zeros(Hn.shape[1], np.bool_)
    for i in range(nx):
        for col in range(Hn.shape[1]):
            used[col] = used[col] or Hn[i, col] != 0.0
    return p, np.ascontiguousarray(Hn[:, used])


@jit
def step(
    p: np.ndarray, H: np.ndarray, e: np.ndarray, u: np.ndarray, y: np.ndarray, cd: np.ndarray,
    rd: np.ndarray, dlo: np.ndarray, dhi: np.ndarray,
    model: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                 np.ndarray, np.ndarray],
    order: int, reduction: int, g_meas: float, n_plant: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool, bool]:  # fmt: skip
    """One step for exactly known matrices: ``(p', H', e', lo, hi, inconsistent, finite)``;
    ``model = (D, h, jc, pc, mc, M, E_pc, B)``. ``finite`` False: the predicted set left the
    float range (returned unreduced, ``e' = 0``)."""
    D, h, jc, pc, mc, M, Ep, B = model
    nx, ny = p.shape[0], y.shape[0]
    z, Hz, m, acc, rows, lo, hi = joint_set(p, H, e, jc, cd, rd, dlo, dhi, ny)
    m, inconsistent = measure(z, Hz, m, acc, rows, lo, hi, y, u, np.zeros(ny), D, h, nx, g_meas)
    xlo, xhi, crossed = state_box(z, rows, acc, m, lo, hi, nx)
    pn, Hn = predict(z, Hz, m, rows, acc, u, cd, rd, np.zeros(nx), M, mc, Ep, pc, B, n_plant)
    return reduce_step(pn, Hn, xlo, xhi, inconsistent or crossed, order, reduction)


@jit
def reduce_step(
    pn: np.ndarray, Hn: np.ndarray, xlo: np.ndarray, xhi: np.ndarray, inconsistent: bool,
    order: int, reduction: int,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool, bool]:  # fmt: skip
    """The end of :func:`step`: the predicted generators reduced by ``reduction``."""
    nx = pn.shape[0]
    finite = np.isfinite(pn).all() and np.isfinite(Hn).all()
    if not finite or reduction == NONE:
        return pn, Hn, np.zeros(nx), xlo, xhi, inconsistent, finite
    if reduction == GIRARD:
        return pn, reduce_girard(Hn, order), np.zeros(nx), xlo, xhi, inconsistent, True
    Hr, rho = reduce_parallelotope(Hn, order)
    return pn, Hr, rho, xlo, xhi, inconsistent, True


def kernels() -> list[Any]:
    """The compiled kernels a step of the strip filter calls: this module's and those of
    :mod:`ivobs.sets.strip` and :mod:`ivobs.sets.reduction` (the first-use notice of
    :func:`ivobs._jit.first_use_notice`)."""
    from ...sets import reduction, strip

    return kernels_in(sys.modules[__name__], strip, reduction)
