"""A finite-memory bound of the state from ``N`` consecutive complete measurements (design).

For a time-invariant model ``x+ = A x + B u + E d``, ``y = C x + D_u u + F d`` and a window of
``N`` steps starting at ``x_s`` (the observability matrix and block-Toeplitz maps)::

    Y = O x_s + T_u U + T_d D,      x[s+N] = A^N x_s + P_u U + P_d D

with ``O = [C; CA; …; CA^(N−1)]``. Any ``M`` with ``M O = A^N`` gives

    x[s+N] = M Y + K_u U + K_d D + R x_s,    K_u = P_u − M T_u,  K_d = P_d − M T_d,
                                             R = A^N − M O  (round-off sized)

so Lemma 1 of [Efimov2013] on the ``d`` box bounds ``x[s+N]`` from the window's data alone:
whatever happened before the window (a gap of any length) no longer counts. ``N`` is the
observability index of ``(A, C)`` (the smallest with ``rank O = n``); each row of ``M`` is the
one of least width ``|K_d| Δ`` (a linear program, HiGHS; least squares above
:data:`MAX_LP_STATES` states), corrected by least squares so that ``R`` is at round-off level.
The round-off sized ``R x_s`` needs a bound of ``‖x_s‖∞``, also from the window: with
``P = O⁺`` and ``P O = I − Θ`` (``‖Θ‖∞ < 1/2``, else no bound is designed),
``x_s = P (Y − T_u U − T_d D) + Θ x_s`` gives
``‖x_s‖∞ <= ‖P (Y − T_u U − T_d D)‖∞ / (1 − ‖Θ‖∞)``. ``R x_s`` and the floating-point error
of every matrix here and of the evaluation are bounded (``γ_n`` of [Higham2002, Lemma 3.1] on
the same expressions in absolute values, doubled) and added to the radius (:meth:`WindowBound.box`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from ..linalg import UNIT_ROUNDOFF, gamma, observability_index
from ..sets.rounding import ETA, down, up, upper

__all__ = ["MAX_LP_STATES", "MAX_WINDOW_STATES", "WindowBound", "window_bound"]

MAX_WINDOW_STATES = 50
"""Above this many states no window bound is designed (the design's dense algebra grows as
``n⁴``)."""

MAX_LP_STATES = 10
"""Above this many states ``M`` is the least-squares one (no linear programs: the design stays
fast for every estimator built)."""


@dataclass(frozen=True)
class WindowBound:
    """The finite-memory bound of ``x[s+N]`` (module docstring): ``N`` steps; ``Mw``: ``M`` and
    ``K_u`` together, acting on the window as recorded, ``w = [y_s, u_s, …, y_{s+N−1},
    u_{s+N−1}]``; ``kc = fl(K_d d_c)`` (``d_c``, ``d_r``: centre and radius of the disturbance
    bounds); the radius of the bound is ``r0 + ‖w‖∞ rw`` (:meth:`box`)."""

    N: int
    Mw: np.ndarray
    kc: np.ndarray
    r0: np.ndarray
    rw: np.ndarray

    def box(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``x[s+N]`` from one window ``w`` (``(N (ny + nu),)``)."""
        return self.bounds(self.Mw @ w, max(map(abs, w.tolist())))  # (complete data: finite)

    def boxes(self, y: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``x[k]`` for ``k = N, …, T − 1`` from every window of a record ``y``
        ``(..., T, ny)``, ``u`` ``(T, nu)`` or ``(..., T, nu)`` (``T > N``): :meth:`box` of each,
        the window's sum taken as ``N`` products over the shifted record (another order of the
        same sum: the same bound)."""
        T, ny = y.shape[-2], y.shape[-1]
        n, m = self.Mw.shape[0], T - self.N
        Mj = self.Mw.reshape(n, self.N, -1)
        c = y[..., :m, :] @ Mj[:, 0, :ny].T
        for j in range(self.N):
            if j:
                c += y[..., j : m + j, :] @ Mj[:, j, :ny].T
            if u.shape[-1]:
                c += u[..., j : m + j, :] @ Mj[:, j, ny:].T
        row = _rowmax(y)  # the largest |y_i|, |u_i| of each step, then of each window
        if u.shape[-1]:
            row = np.maximum(row, _rowmax(u))
        mag = row[..., :m].copy()
        for j in range(1, self.N):
            np.maximum(mag, row[..., j : m + j], out=mag)
        return self.bounds(c, mag)

    def bounds(self, c: np.ndarray, mag: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """``fl(c + kc) ∓ fl(r0 + ‖w‖∞ rw)`` from ``c = fl(Mw w)`` and ``mag = ‖w‖∞`` (one
        window or a stack of them): enclosures of ``x[s+N]`` with every rounding, that of the
        last subtraction and addition included, in ``r0``, ``rw`` (:func:`_radius`)."""
        c += self.kc
        r = self.rw * mag if isinstance(mag, float) else np.multiply.outer(mag, self.rw)
        r += self.r0
        return c - r, c + r


def _rowmax(a: np.ndarray) -> np.ndarray:
    """``max_i |a_i|`` over the last axis, column by column (NumPy's reduction along a short
    axis is slow)."""
    out = np.zeros(a.shape[:-1])
    for i in range(a.shape[-1]):
        np.maximum(out, np.abs(a[..., i]), out=out)
    return out


def window_bound(
    A: np.ndarray,
    B: np.ndarray,
    C: np.ndarray,
    Du: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    d_lo: np.ndarray,
    d_hi: np.ndarray,
) -> WindowBound | None:
    """The :class:`WindowBound` of the model (module docstring); None when ``(A, C)`` is not
    observable (no window determines the state), a matrix is not finite, or above
    :data:`MAX_WINDOW_STATES` states."""
    ny, n = C.shape
    nu, nd = B.shape[1], E.shape[1]
    if n > MAX_WINDOW_STATES:
        return None
    if not all(np.all(np.isfinite(m)) for m in (A, B, C, Du, E, F, d_lo, d_hi)):
        return None
    N = observability_index(A, C)
    if N > n:
        return None
    powers = [np.eye(n)]
    for _ in range(N):
        powers.append(powers[-1] @ A)
    absA = np.abs(A)
    apow = [np.eye(n)]
    for _ in range(N):
        apow.append(apow[-1] @ absA)
    O = np.vstack([C @ powers[j] for j in range(N)])
    aO = np.vstack([np.abs(C) @ apow[j] for j in range(N)])
    Tu, aTu = _toeplitz(powers, apow, C, B, Du, N)
    Td, aTd = _toeplitz(powers, apow, C, E, F, N)
    Pu = np.hstack([powers[N - 1 - i] @ B for i in range(N)])
    aPu = np.hstack([apow[N - 1 - i] @ np.abs(B) for i in range(N)])
    Pd = np.hstack([powers[N - 1 - i] @ E for i in range(N)])
    aPd = np.hstack([apow[N - 1 - i] @ np.abs(E) for i in range(N)])
    AN = powers[N]
    dc = 0.5 * (d_lo + d_hi)
    dr = np.nextafter(np.maximum(d_hi - dc, dc - d_lo), np.inf)  # [dc ± dr] ⊇ [d_lo, d_hi]
    M = _least_width(O, AN, Pd, Td, np.tile(dr, N))
    M = M + (AN - M @ O) @ np.linalg.pinv(O)
    R = AN - M @ O
    Ku = Pu - M @ Tu
    Kd = Pd - M @ Td
    absM = np.abs(M)
    # every matrix above is a product C A^j X (j <= N − 1, X = B, E or I), possibly times M
    # (or P), then one difference: its inner dimensions add up to at most N n (the powers,
    # computed one factor at a time, and C, X) plus N ny (M, P), so each entry passed through at
    # most K roundings ([Higham2002, Lemma 3.7]): γ_K on the absolute-value expressions, doubled
    # (those are computed in floats too)
    K = N * (n + ny + nu + nd) + n + 4
    gK = 2.0 * gamma(K)
    ex = np.abs(R).sum(axis=1) + gK * (apow[N] + absM @ aO).sum(axis=1)
    eu = gK * (aPu + absM @ aTu).sum(axis=1)
    ed_mat = gK * (aPd + absM @ aTd)
    kc = Kd @ np.tile(dc, N)
    # (+ the rounding of the product kc)
    kr = np.abs(Kd) @ np.tile(dr, N) + 2.0 * gamma(N * nd + 2) * (
        np.abs(Kd) @ np.tile(np.abs(dc), N)
    )
    ed = ed_mat.sum(axis=1)
    # γ of the evaluation of kr, ex, eu, ed above (row sums of n products of inner dimension at
    # most N (ny + nu + nd)), doubled: _radius enlarges them by 1 + g
    g = 2.0 * gamma(N * (ny + nu + nd) + 2 * n + 4)
    # ‖x_s‖∞ from the window itself (module docstring), P = O⁺ (any matrix would do)
    P = np.linalg.pinv(O)
    absP = np.abs(P)
    delta = float(np.max(np.abs(np.eye(n) - P @ O).sum(axis=1) + gK * (absP @ aO).sum(axis=1)))
    if not delta < 0.5:
        return None
    p_y = float(np.max(absP.sum(axis=1))) * (1.0 + gK)
    p_u = float(np.max((absP @ aTu).sum(axis=1), initial=0.0)) * (1.0 + gK)
    p_d = float(np.max((absP @ aTd).sum(axis=1), initial=0.0)) * (1.0 + gK)
    d_mag = float(max(np.max(np.abs(d_lo), initial=0.0), np.max(np.abs(d_hi), initial=0.0)))
    # the window as recorded: rows [y_j, u_j], step-major
    Mw = np.concatenate((M.reshape(n, N, ny), Ku.reshape(n, N, nu)), axis=2).reshape(n, -1)
    r0, rw = _radius(np.abs(Mw), kc, kr, ex, eu, ed, g, p_y + p_u, p_d, delta, d_mag)
    return WindowBound(N, Mw, kc, r0, rw)


def _radius(
    absMw: np.ndarray,
    kc: np.ndarray,
    kr: np.ndarray,
    ex: np.ndarray,
    eu: np.ndarray,
    ed: np.ndarray,
    g: float,
    p_w: float,
    p_d: float,
    delta: float,
    d_mag: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``(r0, rw)`` of :class:`WindowBound`: with ``m = ‖w‖∞`` (which bounds ``‖Y‖∞`` and
    ``‖U‖∞``), the radius

        ρ = kr + ex ‖x_s‖ + eu m + ed ‖d‖,      ‖x_s‖ <= (p_w m + p_d ‖d‖) / (1 − δ)

    (``|K_d| d_r``, then ``R x_s`` and the round-off of ``R``, ``K_u``, ``K_d``; module
    docstring; ``g`` covers the rounding of ``kr``, ``ex``, ``eu``, ``ed`` as computed), plus
    the rounding of ``c = fl(Mw w + kc)``, a sum of ``L + 1`` terms (``L = N (ny + nu)``) in any
    order: ``γ_{L+1} (|Mw| |w| + |kc|)`` and underflow ([Higham2002, Lemma 3.1]), and the
    recorded outputs' ``2u |Mw| |w|`` (``Y`` is the float nearest to the true outputs,
    ``|Y_true − Y| <= 2u |Y|``). The last subtraction ``fl(c − r)`` is at most
    ``c − r + u (|c| + r)`` (exact when subnormal), so it stays below ``c − ρ`` when
    ``r >= (ρ + u |c|) / (1 − u)`` (and likewise above). With ``|Mw| |w| <= s m`` (``s``: row
    sums of ``|Mw|``) and ``|fl(c)| <= (1 + g_c) (s m + |kc|)`` all of it is at most
    ``(r0 + m rw) (1 + 2u)``::

        r0 = (1 + g) (kr + ed ‖d‖ + ex p_d ‖d‖ / (1 − δ)) + h |kc| + (L + 2) η
        rw = (1 + g) (eu + ex p_w / (1 − δ)) + h s,      h = g_c + u (1 + g_c) + 2u

    with ``g_c = 2γ_{L+2}`` (doubled, as :func:`~ivobs.sets.rounding.product_error`), each
    evaluated from nonnegative numbers and rounded up (:func:`upper`), then once more by
    ``upper(·, 3)``, which pays for the factor ``1 + 2u >= 1 / (1 − u)`` and the two roundings
    of ``r0 + m rw`` in :meth:`WindowBound.bounds` (``(1 + 2γ₅)(1 − u)² >= 1 + 2u``)."""
    L = absMw.shape[1]
    s = upper(absMw.sum(axis=1), L)
    inv = float(up(1.0 / down(1.0 - delta)))  # >= 1 / (1 − δ): each rounding bracketed
    gc = 2.0 * gamma(L + 2)
    h = float(upper(gc + UNIT_ROUNDOFF * (1.0 + gc) + 2.0 * UNIT_ROUNDOFF, 4))
    k = float(up(1.0 + g))
    r0 = k * (kr + ed * d_mag + ex * (p_d * d_mag * inv)) + h * np.abs(kc)
    r0 = upper(r0 + (L + 2) * ETA, 9)
    rw = upper(k * (eu + ex * (p_w * inv)) + h * s, 6)
    return upper(r0, 3), upper(rw, 3)


def _toeplitz(
    powers: list[np.ndarray],
    apow: list[np.ndarray],
    C: np.ndarray,
    X: np.ndarray,
    X0: np.ndarray,
    N: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``[C A^(j−1−i) X]`` below the diagonal and ``X0`` on it (and the same in absolute
    values): how the window's inputs enter its outputs."""
    ny, m = X0.shape
    T = np.zeros((N * ny, N * m))
    aT = np.zeros_like(T)
    for j in range(N):
        T[j * ny : (j + 1) * ny, j * m : (j + 1) * m] = X0
        aT[j * ny : (j + 1) * ny, j * m : (j + 1) * m] = np.abs(X0)
        for i in range(j):
            T[j * ny : (j + 1) * ny, i * m : (i + 1) * m] = C @ powers[j - 1 - i] @ X
            aT[j * ny : (j + 1) * ny, i * m : (i + 1) * m] = np.abs(C) @ apow[j - 1 - i] @ np.abs(X)
    return T, aT


def _least_width(
    O: np.ndarray, AN: np.ndarray, Pd: np.ndarray, Td: np.ndarray, dr: np.ndarray
) -> np.ndarray:
    """Per row ``a`` of ``A^N``: ``m`` with ``m O = a`` minimising ``|p − m T_d| d_r`` (a linear
    program in ``(m, t)``, ``−t <= p − m T_d <= t``); the least-squares ``A^N O⁺`` for a row
    whose program HiGHS does not solve, and for every row above :data:`MAX_LP_STATES`
    states."""
    n = AN.shape[0]
    p, q = O.shape[0], Td.shape[1]
    M = AN @ np.linalg.pinv(O)
    if q == 0 or not np.any(dr > 0) or n > MAX_LP_STATES:
        return M
    c = np.concatenate([np.zeros(p), dr])
    # p − m T_d <= t  <=>  −T_dᵀ m − t <= −p ;  −(p − m T_d) <= t  <=>  T_dᵀ m − t <= p
    A_ub = np.block([[-Td.T, -np.eye(q)], [Td.T, -np.eye(q)]])
    A_eq = np.hstack([O.T, np.zeros((n, q))])
    bounds = [(None, None)] * p + [(0, None)] * q
    for i in range(n):
        res = linprog(
            c,
            A_ub=A_ub,
            b_ub=np.concatenate([-Pd[i], Pd[i]]),
            A_eq=A_eq,
            b_eq=AN[i],
            bounds=bounds,
            method="highs",
        )
        if res.status == 0 and res.x is not None:
            M[i] = res.x[:p]
    return M
