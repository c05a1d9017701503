"""Certified bounds of ``x[k]`` from fixed multipliers of the moving-window program.

For the time-invariant model ``x[j+1] = A x[j] + B u[j] + E d[j] + e[j]``,
``y[j] = C x[j] + D u[j] + F d[j] + e'[j]`` (``d[j] ∈ [d_lo, d_hi]``; ``|e| <= τ``, ``|e'| <= τ'``
the rounding ranges of :mod:`ivobs.estimators.exact.rows`, so that a floating-point simulation
of the model is covered), any multipliers ``μ[s..k]`` of the measurement rows and any numbers
``q̂`` give, for an objective ``c`` (``±e_i``), the identity (weak duality, [Neumaier2004])

::

    c^T x[k] = Σ_j μ_j^T y_j + Σ_j v_j^T u_j + Σ_j h_j^T d_j + Σ_{j<k} q̂_{j+1}^T e_j
               - Σ_j μ_j^T e'_j + q̂_s^T x[s] + Σ_j ρ_j^T x[j]                           (D)

with the adjoint recursion, evaluated in floating point,
``q̂_k = fl(c − C^T μ_k)``, ``q̂_j = fl(A^T q̂_{j+1} − C^T μ_j)``,
``v_j = B^T q̂_{j+1} − D^T μ_j``, ``h_j = E^T q̂_{j+1} − F^T μ_j`` (no ``q̂_{k+1}`` term at
``j = k``), and ``ρ_j`` the rounding of the recursion, ``|ρ_j| <= γ_{nx+ny+2} (|A|^T |q̂_{j+1}|
+ |C|^T |μ_j| + |c|)`` ([Higham2002, §3.1]). Bounding each term over its box (``x[s]`` in the
box proven at step ``s``, ``d[j]`` in the model's box, ``|x[j]| <= w_j``) gives an upper bound of
``c^T x[k]`` for *every* ``μ``; the exact hull is reached when ``μ`` is the optimal dual of the
window program. For a fixed ``μ`` every coefficient is fixed: the bound is one dot product with
the window's data, which is what makes a cache of multipliers cheap to evaluate each step.

One multiplier's bound is a single dot product, ``ub = fl(G · z)`` rounded up once more
(:func:`row_matrix`, :func:`data_vector`), of its row ``G`` with the step's vector ``z``:

::

    z:  [ y_j, u_j (every block),  m_1, m_2, m_3, m_4,     lo_s,          hi_s,          ‖x_s‖, 1 ]
    G:  [ μ_j, v̂_j,                n_1, n_2, n_3, n_4,     min(q̂_s, 0),   max(q̂_s, 0),   2γ‖q̂_s‖_1,
          dcum_s + 2γ|dcum_s| ]

``min(q̂_s, 0)^T lo + max(q̂_s, 0)^T hi`` is the maximum of ``q̂_s^T x`` over the box of
``x[s]``; ``dcum_s`` the sum over the blocks from ``s`` of ``max_d h_j^T d`` plus the rounding
of ``h_j`` (the model's box is constant, so it is computed once per ``μ``, rounded up). The
rounding terms are bounded by the 1-norms of the coefficients times the largest magnitudes of
the data over the window (``Σ_j a_j b_j <= ‖a‖_1 max_j b_j`` for ``a, b >= 0``):

::

    n_1 = Σ|μ_j|                     m_1 = max_j (κ ‖y_j‖ + 2 max τ'_j)
    n_2 = κ Σ|v̂_j| + 2 Σ ev_j        m_2 = max_j ‖u_j‖
    n_3 = Σ|q̂_{j+1}|                 m_3 = max_j 2 max τ_j
    n_4 = Σ ‖ρ̄_j‖_1                  m_4 = max_j 2 ‖x_j‖

(``ev_j`` the rounding bound of ``v̂_j``, ``τ_j`` the range of the dynamics row ``j → j+1``,
``‖x_j‖`` that of the block's interval prediction). ``κ = 4 γ_n`` (``n`` the length of the
dot product) covers the rounding of the signed terms ``μ_j^T y_j + v̂_j^T u_j``, the ``2γ`` terms
that of the box and ``dcum`` terms, and the factors 2 the rounding of the error terms
themselves. A window that starts at position ``s > 0`` (while it fills) zeroes the data before
``s`` and uses ``q̂_s``, ``dcum_s``. A missing or dropped measurement component is replaced by
the centre of a box ``mid ± rad`` that contains it (from the interval prediction), and
``|μ|^T rad`` is added: every multiplier stays valid.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from .._uncertain import magnitude as mag
from ..exact.safe import EPS, TINY, gamma_n

__all__ = [
    "Coefficients",
    "Layout",
    "Predictor",
    "coefficients",
    "data_vector",
    "row_matrix",
    "upper_bounds",
]

_ONE = np.ones(1)


@dataclass(frozen=True)
class Layout:
    """The sizes of the window: ``N + 1`` blocks of ``width`` numbers each."""

    nx: int
    nu: int
    ny: int
    nd: int
    N: int

    @cached_property
    def width(self) -> int:
        return self.ny + self.nu

    @cached_property
    def n_main(self) -> int:
        return (self.N + 1) * self.width

    @cached_property
    def n_total(self) -> int:
        """The length of the dot product of one bound (:func:`data_vector`)."""
        return self.n_main + 4 + 2 * self.nx + 2

    @cached_property
    def kappa(self) -> float:
        """``κ = 4 γ_{n+2}``: covers the rounding of the dot product (length ``n``)."""
        return 4.0 * gamma_n(self.n_total + 2)


class Coefficients(NamedTuple):
    """The fixed coefficients of ``R`` multipliers: ``main`` (R, n_main) the signed row of (D)
    against the data ``(y_j, u_j)``, ``norms`` (R, 4) the 1-norms of its rounding terms, ``q``
    (R, N+1, nx) the coefficient of ``x`` at each window start, ``dcum`` (R, N+1) the bound of
    the ``h_j^T d_j`` terms from each start on; ``G0`` (R, n_total) the row of :func:`row_matrix`
    for a window starting at position 0 (the common case, kept)."""

    main: np.ndarray
    norms: np.ndarray
    q: np.ndarray
    dcum: np.ndarray
    G0: np.ndarray


def coefficients(
    mats: tuple[np.ndarray, ...],
    d_lo: np.ndarray,
    d_hi: np.ndarray,
    c: np.ndarray,
    mu: np.ndarray,
    lay: Layout,
) -> Coefficients:
    """The coefficients of (D) for the objectives ``c`` (R, nx) and multipliers ``mu``
    (R, N+1, ny): the adjoint recursion from the newest block back, then the terms of every
    block at once (module docstring)."""
    A, B, C, D, E, F = mats
    R, N = c.shape[0], lay.N
    g = gamma_n(lay.nx + lay.ny + lay.nu + lay.nd + 2)
    aA, aB, aC, aD, aE, aF = (np.abs(M) for M in mats)
    muC = mu @ C
    q = np.empty((R, N + 1, lay.nx))
    q[:, N] = c - muC[:, N]
    for p in range(N - 1, -1, -1):
        q[:, p] = q[:, p + 1] @ A - muC[:, p]
    qn = np.zeros_like(q)  # q̂_{j+1}; zero past the newest block
    qn[:, :-1] = q[:, 1:]
    am, aq = np.abs(mu), np.abs(qn)
    q_mag = aq @ aA + am @ aC
    q_mag[:, N] += np.abs(c)
    v = qn @ B - mu @ D
    ev = g * (aq @ aB + am @ aD)
    h = qn @ E - mu @ F
    eh = g * (aq @ aE + am @ aF)
    wd = mag(d_lo, d_hi)
    # max over the box of h^T d, its rounding, and the rounding of h itself
    dconst = np.maximum(h * d_lo, h * d_hi).sum(axis=2) + 2.0 * (g * (np.abs(h) @ wd) + eh @ wd)
    main = np.concatenate([mu, v], axis=2).reshape(R, -1)
    norms = np.stack(
        [am.sum(axis=(1, 2)), lay.kappa * np.abs(v).sum(axis=(1, 2)) + 2.0 * ev.sum(axis=(1, 2)),
         aq.sum(axis=(1, 2)), g * q_mag.sum(axis=(1, 2))], axis=1,
    ) * (1.0 + gamma_n(lay.n_main + 3))  # fmt: skip
    # sums from each position to the newest block, rounded up
    rev = np.cumsum(dconst[:, ::-1], axis=1)[:, ::-1]
    err = np.cumsum(np.abs(dconst[:, ::-1]), axis=1)[:, ::-1]
    dcum = rev + 2.0 * gamma_n(N + 3) * err + (N + 3) * TINY
    part = Coefficients(main, norms, q, dcum, np.zeros((R, 0)))
    return part._replace(G0=row_matrix(part, 0, lay))


def row_matrix(coef: Coefficients, s: int, lay: Layout) -> np.ndarray:
    """The rows ``[main, norms, min(q_s, 0), max(q_s, 0), 2 γ ‖q_s‖_1, dcum_s + 2 γ |dcum_s|]``
    (``γ`` of the length of the whole dot product) against :func:`data_vector`: the maximum of
    ``q_s^T x`` over a box is ``min(q_s, 0)^T lo + max(q_s, 0)^T hi``."""
    g = gamma_n(lay.n_total + 2)
    Q = coef.q[:, s]
    dc = coef.dcum[:, s]
    tail = np.column_stack([2.0 * g * np.abs(Q).sum(axis=1), dc + 2.0 * g * np.abs(dc)])
    return np.hstack([coef.main, coef.norms, np.minimum(Q, 0.0), np.maximum(Q, 0.0), tail])


def data_vector(
    data: np.ndarray, s: int, lo_s: np.ndarray, hi_s: np.ndarray, width: int
) -> np.ndarray:
    """``[y, u of the blocks (before s: zero), max of the rounding magnitudes from s, lo_s,
    hi_s, ‖x_s‖_∞, 1]`` (``data``: rows ``(y, u, the four magnitudes)``, ``width = ny + nu``;
    the last magnitude of row ``s`` is ``2 ‖x_s‖_∞``)."""
    flat = data[:, :width].ravel()
    if s > 0:
        flat[: s * width] = 0.0
    return np.concatenate([flat, data[s:, width:].max(axis=0), lo_s, hi_s,
                           (0.5 * data[s, width + 3], 1.0)])  # fmt: skip


def upper_bounds(coef: Coefficients, vec: np.ndarray, s: int, lay: Layout) -> np.ndarray:
    """Upper bounds of ``c_r^T x[k]`` for every multiplier ``r`` (``+inf`` where it cannot be
    evaluated) from the data vector ``vec`` of a window starting at position ``s``: one dot
    product per multiplier, rounded up (module docstring)."""
    G = coef.G0 if s == 0 else row_matrix(coef, s, lay)
    ub = np.nextafter(G @ vec + 4 * lay.n_total * TINY, np.inf)
    if not np.isfinite(ub).all():  # overflow, or inf - inf: no bound
        ub[~np.isfinite(ub)] = np.inf
    return np.asarray(ub)


class Predictor:
    """The interval prediction of ``x[k]`` from the box of ``x[k-1]`` [Efimov2013, Lemma 1]
    and the largest rounding ranges ``τ`` (dynamics) and ``τ'`` (measurement) of
    :mod:`ivobs.estimators.exact.rows`, bounded through the norms of the matrices (``‖|A| x̄‖_∞
    <= ‖A‖_∞ ‖x̄‖_∞``) and taken twice as wide, which covers their own rounding; the prediction
    is widened by ``4 γ_{n+4}`` times the magnitudes involved ([Higham2002, §3.1],
    ``n = nx + nu + nd``) besides ``τ``."""

    def __init__(self, mats: tuple[np.ndarray, ...], d_lo: np.ndarray, d_hi: np.ndarray):
        A, B, C, D, E, F = mats
        Ap, An = np.maximum(A, 0), np.minimum(A, 0)
        self.PM = np.block([[Ap, An], [An, Ap]])  # [lo; hi] -> the bounds of A x
        self.B2 = np.vstack([B, B])
        self.g = gamma_n(A.shape[0] + B.shape[1] + E.shape[1] + 4)
        wd = mag(d_lo, d_hi)
        Ep, En = np.maximum(E, 0), np.minimum(E, 0)
        self.Ed = np.concatenate([Ep @ d_lo + En @ d_hi, Ep @ d_hi + En @ d_lo])
        self.sign = np.repeat([-1.0, 1.0], A.shape[0])

        def norm(M: np.ndarray) -> float:  # ‖M‖_∞, rounded up
            return float(np.abs(M).sum(axis=1).max(initial=0.0)) * (1.0 + 4.0 * EPS * M.size)

        self.nA, self.nB, self.nC, self.nD = norm(A), norm(B), norm(C), norm(D)
        Cp, Cn = np.maximum(C, 0), np.minimum(C, 0)
        self.CM = np.block([[Cp, Cn], [Cn, Cp]])  # [lo; hi] -> the bounds of C x
        self.D2 = np.vstack([D, D])
        Fp, Fn = np.maximum(F, 0), np.minimum(F, 0)
        self.Fd = np.concatenate([Fp @ d_lo + Fn @ d_hi, Fp @ d_hi + Fn @ d_lo])
        self.Ew = float((np.abs(E) @ wd).max(initial=0.0)) * (1.0 + 4.0 * EPS * E.size)
        self.Fw = float((np.abs(F) @ wd).max(initial=0.0)) * (1.0 + 4.0 * EPS * F.size)

    def predict(
        self, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, x_mag: float, u_mag: float
    ) -> tuple[np.ndarray, np.ndarray, float]:
        """The box of ``A x + B u + E d + e`` over ``x ∈ [lo, hi]``, ``d``, ``|e| <= τ``, and
        ``max τ`` (doubled); ``x_mag``, ``u_mag``: bounds on ``‖x‖_∞`` and ``‖u‖_∞``."""
        m = self.nA * x_mag + self.nB * u_mag + self.Ew
        tau = 2.0 * self.g * m
        p = self.PM @ np.concatenate([lo, hi]) + self.B2 @ u + self.Ed
        p += (6.0 * self.g * m) * self.sign  # the rounding of the evaluation, and τ
        n = lo.size
        return p[:n], p[n:], 2.0 * tau

    def tau_y(self, x_mag: float, u_mag: float, y_mag: float) -> float:
        """``max τ'`` (doubled) of the measurement rows, from bounds on ``‖x‖_∞`` (the
        predicted box), ``‖u‖_∞`` and ``‖y‖_∞``."""
        return 4.0 * self.g * (self.nC * x_mag + self.nD * u_mag + self.Fw + y_mag)

    def y_range(
        self, p_lo: np.ndarray, p_hi: np.ndarray, u: np.ndarray, x_mag: float, u_mag: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """Centre and radius of a box that contains ``y = C x + D u + F d + e'`` for ``x`` in
        the predicted box: what replaces a missing (or dropped) measurement, so that every
        cached multiplier stays valid (``μ^T y <= μ^T mid + |μ|^T rad``)."""
        m = self.nC * x_mag + self.nD * u_mag + self.Fw
        r = self.CM @ np.concatenate([p_lo, p_hi]) + self.D2 @ u + self.Fd
        n = r.size // 2
        lo, hi = r[:n], r[n:]
        err = 6.0 * self.g * m + 4.0 * EPS * np.maximum(np.abs(lo), np.abs(hi)) + TINY
        return 0.5 * (lo + hi), 0.5 * (hi - lo) + err
