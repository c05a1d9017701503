"""Ellipsoidal set-membership filter: the prediction of [Liu2016] and the strip update of
[Schweppe1968] with trace-minimising parameters (CORA's ESO family, [Althoff2021]).

The set of ``x[k]`` is an ellipsoid ``E(c, Q) = {x : (x - c)ᵀ Q⁻¹ (x - c) <= 1}`` (``Q``
positive definite), equivalently ``{x : (vᵀ(x - c))² <= vᵀ Q v for every v}``; so ``Q' ⪰ Q``
gives ``E(c, Q) ⊆ E(c, Q')``.

**Bounds as ellipsoids.** A box ``c + diag(r) b``, ``|b| <= 1``, mapped by ``G`` lies in
``E(G c, G diag(q) Gᵀ)`` whenever ``Σ_i r_i² / q_i <= 1`` (Cauchy-Schwarz: ``(vᵀ G diag(r) b)²
<= Σ_i (vᵀG_i)² q_i · Σ_i r_i² / q_i``); ``q_i = r_i Σ_j r_j n_j / n_i`` (``n_i = ‖G_i‖``)
minimises the trace. Used for ``x0`` (``G = I``) and the disturbance ``E d``.

**Prediction** [Liu2016]: ``A E(c, Q) + B u ⊕ E(E c_d, Q_w) ⊆ E(A c + B u + E c_d,
(1 + 1/p) A Q Aᵀ + (1 + p) Q_w)`` for every ``p > 0`` (the Minkowski sum of two ellipsoids);
``p = sqrt(tr(A Q Aᵀ) / tr(Q_w))`` minimises the trace.

**Update** with one measured output ``|h x - t| <= σ`` (``h = C_i``, ``t = y_i - D_i u - F_i
c_d``, ``σ = Σ_j |F_ij| r_j``: the measurement noise of that row; rows are used one after the
other): for every ``λ ∈ [0, 1)`` the intersection lies in ``{(1-λ)(x-c)ᵀQ⁻¹(x-c) + λ (h x -
t)² / σ² <= 1}`` [Schweppe1968], the ellipsoid ``E(c + α Q h e, ς (Q - α Q h hᵀ Q))`` with
``e = t - h c``, ``g = hᵀ Q h``, ``s = (1 - λ) σ² + λ g``, ``α = λ / s``, ``δ = λ (1 - λ) e² /
s``, ``ς = (1 - δ) / (1 - λ)``. ``λ`` minimises the trace (a scalar function: a grid, then
golden section). Any ``λ`` is sound; so is skipping a row (when the strip already contains the
ellipsoid's range in that direction), and so is a larger ``ς`` or a smaller ``α`` in the shape
(``Q - α Q h hᵀ Q`` only grows as ``α`` decreases, and stays positive semidefinite for ``α g
<= 1``).

**Rounding, proven** (no margin is added, ``proven_rounding``). Every quantity the formulas use
is either a float used as it is (``λ``, ``p``, ``τ``: any value is sound) or bounded in the safe
direction: ``σ`` covers the rounding of ``t`` and of ``e`` (so the float ``e`` is exact for the
strip actually used) and of a float64 evaluation of the output equation; ``s`` and ``g`` are
rounded up, ``α`` down and ``ς`` up. A shape matrix ``Q̃`` evaluated in floats within ``M``
entrywise of the exact ``Q`` (``M``: ``γ_n`` of [Higham2002, §3.1] times the magnitudes of its
operands) is replaced by ``sym(Q̃) + ρ I``, ``ρ >= ‖M‖_F + u ‖Q̃‖_F >= ‖sym(Q̃) - Q‖₂``, so that
``vᵀ(sym(Q̃) + ρ I) v >= vᵀ Q v``: it contains the exact ellipsoid (:func:`_cover`); the diagonal
additions are rounded up. A centre ``c̃`` within ``ε`` of the exact one is covered by the
Minkowski sum with the ball of radius ``‖ε‖``, ``E(c, Q) ⊕ B(‖ε‖) ⊆ E(c, (1 + τ) Q + (1 +
1/τ) ‖ε‖² I)`` (:func:`_cover_centre`); ``ε`` also covers a float64 evaluation of the state
equation (a record from a float64 simulation).

**Inconsistent data**: a strip that certainly misses the ellipsoid (``|e| > sqrt(g) + σ`` with
``g`` rounded up) is reported and ``y[k]`` not used. **Missing samples**: NaN rows are skipped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..linalg import UNIT_ROUNDOFF, gamma
from ..model import LinearSystem
from ..model.nonlinear._runtime import dn as _down
from ..model.nonlinear._runtime import up as _up
from ..sets import Box
from ..sets.rounding import down, mid_rad, up, upper
from . import register
from ._balanced import balanced, unbalanced
from .base import Design, Estimator, check_size
from .state import OnlineState, Step, evolve

__all__ = ["EllipsoidDesign", "EllipsoidEstimator", "EllipsoidState", "box_ellipsoid"]

GRID = np.linspace(0.0, 1.0, 66)[1:-1] ** 0.5
"""Values of ``λ`` tried before the golden-section refinement (denser towards 1)."""


def _frobenius(M: np.ndarray) -> float:
    """An upper bound of ``‖M‖_F`` (its sum of squares rounded up, the root one step up)."""
    return _up(math.sqrt(upper(float(np.vdot(M, M)), M.size + 1)))


def _add_diagonal(S: np.ndarray, rho: float | np.ndarray) -> np.ndarray:
    """``S + diag(ρ)`` in place (``ρ`` a number or a vector), each diagonal entry rounded up."""
    diag = S.reshape(-1)[:: S.shape[0] + 1]  # a view: S is C-contiguous
    diag[:] = up(diag + rho)
    return S


def _cover(Q: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``sym(Q) + ρ D² ⪰`` every symmetric matrix within ``M`` (entrywise) of ``Q`` (module
    docstring), with the rounding of the symmetrisation (``2u |S|``) added to ``M``. For any
    positive diagonal ``D``, a symmetric ``E`` with ``|E| <= M`` satisfies ``E = D (D⁻¹ E D⁻¹) D
    ⪯ ‖D⁻¹ M D⁻¹‖_F D²``; ``D² = diag(M)`` keeps each coordinate's cover at the scale of its
    own error (one isotropic ball would add the largest coordinate's error to the smallest)."""
    S: np.ndarray = 0.5 * (Q + Q.T)
    Mp = up(M + 2.0 * UNIT_ROUNDOFF * np.abs(S))
    d = np.sqrt(np.diagonal(Mp))
    top = float(d.max()) if d.size else 0.0
    if not top > 0.0:
        if not np.any(Mp):
            return S  # no error to cover
        d = np.ones_like(d)
    else:
        d = np.maximum(d, top * 2.0**-26)  # positive: a zero diagonal would scale by infinity
    Ms = up(up(Mp / d[:, None]) / d[None, :])  # >= D⁻¹ M D⁻¹ entrywise
    return _add_diagonal(S, up(_frobenius(Ms) * up(d * d)))


_TAU_MIN = 2.0**-40
"""Smallest factor ``τ`` (and ``1/p``) of the ellipsoids' Minkowski-sum covers."""


def _cover_centre(Q: np.ndarray, eps: np.ndarray) -> np.ndarray:
    """``E(c, Q) ⊕ B(‖ε‖) ⊆ E(c, (1 + τ) Q + (1 + 1/τ) ‖ε‖² I)``, ``τ`` near trace-minimal:
    ``1 + τ`` is the float ``a`` (``τ = a - 1`` exactly, ``1/τ`` rounded up), and the rounding of
    ``a Q`` (``u a |Q|``) goes into the diagonal term."""
    e2 = upper(float(eps @ eps), eps.shape[0] + 1)
    if e2 == 0.0:
        return Q
    n = Q.shape[0]
    tr = max(float(np.trace(Q)), e2)
    # τ >= 2⁻⁴⁰ so that a - 1 is exact and positive (ε far below Q: then (1 + 1/τ) ‖ε‖² is
    # still far below Q, while τ = 1 would double Q)
    a = 1.0 + max(math.sqrt(n * e2 / tr), _TAU_MIN)
    tau = _down(a - 1.0)
    aQ = a * Q
    ball = _up(_up(1.0 + _up(1.0 / tau)) * e2)
    return _add_diagonal(aQ, _up(ball + _up(2.0 * UNIT_ROUNDOFF * _frobenius(aQ))))


def box_ellipsoid(G: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``Q`` of an ellipsoid ``E(0, Q)`` containing ``G diag(r) B`` (the unit box ``B``), of
    near-minimal trace (module docstring): ``q_i`` rounded up so that ``Σ r_i² / q_i <= 1``
    exactly, ``G diag(q) Gᵀ`` covered by :func:`_cover`."""
    n = G.shape[0]
    norms = np.sqrt((G * G).sum(axis=0))
    keep = (r > 0) & (norms > 0)
    if not keep.any():
        return np.zeros((n, n))
    rk, nk, Gk = r[keep], norms[keep], G[:, keep]
    total = upper(float(rk @ nk), rk.shape[0])
    q = up(rk * up(total / nk))
    Q = (Gk * q) @ Gk.T
    aG = np.abs(Gk)
    return _cover(Q, 2.0 * gamma(rk.shape[0] + 3) * ((aG * q) @ aG.T))


@dataclass(frozen=True)
class EllipsoidDesign(Design):
    """``Q_w``: the ellipsoid of the process disturbance ``E d`` (constant bounds; ``None``
    when the bounds vary with ``k``); ``x_scale``: the balanced coordinates ``x = diag(x_scale)
    x̃`` the filter works in (None: ``x`` itself)."""

    Q_w: np.ndarray | None
    x_scale: np.ndarray | None = None


@dataclass(frozen=True)
class EllipsoidState(OnlineState):
    """``x[k] ∈ E(c, Q)`` before ``y[k]`` is used (the predicted ellipsoid)."""

    c: np.ndarray
    Q: np.ndarray


def _trace_after(lam: Any, trQ: float, qh2: float, g: float, e2: float, s2: float) -> Any:
    s = (1.0 - lam) * s2 + lam * g
    delta = lam * (1.0 - lam) * e2 / s
    return (1.0 - delta) / (1.0 - lam) * (trQ - lam * qh2 / s)


def _best_lambda(trQ: float, qh2: float, g: float, e2: float, s2: float) -> float:
    """The ``λ ∈ (0, 1)`` minimising the trace of the updated ellipsoid (a grid, then golden
    section on the bracket of the best grid point, in floats: any ``λ`` is sound)."""
    vals = _trace_after(GRID, trQ, qh2, g, e2, s2)
    i = int(np.argmin(vals))
    a = float(GRID[i - 1]) if i > 0 else 0.0
    b = float(GRID[i + 1]) if i + 1 < GRID.size else 1.0 - 1e-12
    ratio = 0.6180339887498949
    m1, m2 = b - ratio * (b - a), a + ratio * (b - a)
    f1, f2 = _trace_after(m1, trQ, qh2, g, e2, s2), _trace_after(m2, trQ, qh2, g, e2, s2)
    for _ in range(30):
        if f1 <= f2:
            b, m2, f2 = m2, m1, f1
            m1 = b - ratio * (b - a)
            f1 = _trace_after(m1, trQ, qh2, g, e2, s2)
        else:
            a, m1, f1 = m1, m2, f2
            m2 = a + ratio * (b - a)
            f2 = _trace_after(m2, trQ, qh2, g, e2, s2)
    lam, f = (m1, f1) if f1 <= f2 else (m2, f2)
    return lam if f <= vals[i] else float(GRID[i])


@register
class EllipsoidEstimator(Estimator):
    """Ellipsoidal set-membership filter [Liu2016], [Schweppe1968] (module docstring).

    Uses ``u[0..k]`` and ``y[0..k]`` (filter form): the box of ``x[k]`` is the interval hull
    ``c ± sqrt(diag Q)`` of the ellipsoid after the strips of ``y[k]``. Per step ``O(ny nx²)``
    for the updates and ``O(nx³)`` for the prediction, no optimisation. The process and
    measurement disturbances are bounded separately (``E d`` and ``F d`` as if independent):
    sound, and looser than the zonotope methods when ``d`` enters both. Ellipsoids cannot
    follow a box closely in high dimension (the trace-minimal ellipsoid around a box of ``n``
    equal sides has ``sqrt(n)`` times its radius): on CORA's 30-tank system CORA's ellipsoidal
    observers are 20-50 times the exact hull ([Althoff2021]); use it when an ellipsoid is what
    you need.

    Parameters
    ----------
    sys : LinearSystem (discrete time, time-invariant matrices; bounds may vary with ``k``)
    x0 : Box, the prior box on ``x[0]``

    Notes
    -----
    The filter works in the model's balanced coordinates (:mod:`ivobs.estimators._balanced`):
    the trace it minimises is not invariant under a change of units, and on states near
    ``1e6`` and ``1e-3`` it would weigh the large one alone (the ellipsoid then grew until it
    overflowed).
    """

    name = "ellipsoid"
    order = 85
    summary = "ellipsoidal set-membership filter, trace-minimal prediction and strip updates"
    reference = "[Liu2016]; [Schweppe1968]"
    data_used = "filter"
    proven_rounding = True  # module docstring, "Rounding, proven"
    design: EllipsoidDesign

    def __init__(self, sys: LinearSystem, x0: Box | None = None, **options: Any) -> None:
        super().__init__(sys, x0, **options)
        check_size(self.name, sys.nx, "multiplies dense nx x nx matrices (O(nx^3) work)")
        assert self.x0 is not None
        self._mats, self._x0s, scale = balanced(sys.matrices_at(0), self.x0)
        self._abs = tuple(np.abs(M) for M in self._mats)
        Q_w, self._d = None, None
        if sys.has_constant_bounds and sys.nd:
            self._d = mid_rad(sys.d_at(0).lo, sys.d_at(0).hi)
            Q_w = box_ellipsoid(self._mats[4], self._d[1])
        self.design = EllipsoidDesign(Q_w=Q_w, x_scale=scale)
        # a float64 evaluation of either equation: dot products of nx + nu + nd terms
        self._g_plant = gamma(sys.nx + sys.nu + sys.nd + 1)

    # -- online ----------------------------------------------------------------------------
    def _initial_state(self) -> EllipsoidState:
        c, r = mid_rad(self._x0s.lo, self._x0s.hi)  # the box is inside c ± r: c is exact
        return EllipsoidState(c=c, Q=box_ellipsoid(np.eye(self.sys.nx), r))

    def _disturbance(
        self, k: int, y_k: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
        """``d[k] ∈ c_d ± r_d`` (exactly) and ``Q_w`` of ``E (d[k] - c_d)``."""
        if not self.sys.nd:
            z = np.zeros(0)
            return z, z, np.zeros((self.sys.nx, self.sys.nx))
        if self._d is not None and self.design.Q_w is not None:
            return self._d[0], self._d[1], self.design.Q_w
        box = self.sys.d_at(k, y_k)
        cd, rd = mid_rad(box.lo, box.hi)
        return cd, rd, box_ellipsoid(self._mats[4], rd)

    def _step(
        self, state: EllipsoidState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[EllipsoidState]:
        cd, rd, Q_w = self._disturbance(state.k, y_k)
        c, Q, inconsistent = self._update(state.c, state.Q, u_k, y_k, cd, rd)
        rad = up(np.sqrt(np.maximum(np.diag(Q), 0.0)))
        lo, hi = unbalanced(down(c - rad), up(c + rad), self.design.x_scale)
        c_next, Q_next = self._predict(c, Q, rad, u_k, cd, rd, Q_w)
        return Step(evolve(state, c=c_next, Q=Q_next), lo, hi, inconsistent)

    def _strip(
        self, i: int, c: np.ndarray, mag: np.ndarray, u_k: np.ndarray, y_k: np.ndarray,
        cd: np.ndarray, rd: np.ndarray,
    ) -> tuple[float, float]:  # fmt: skip
        """``(e, σ)`` of output ``i``: the true state satisfies ``|C_i (x - c) - e| <= σ``
        with the float ``e`` (``σ`` holds the noise ``Σ_j |F_ij| r_j``, the rounding of ``t``
        and of ``e``, and a float64 evaluation of the output equation; ``mag >= |x|``)."""
        _, _, C, D, _, F = self._mats
        _, _, aC, aD, _, aF = self._abs
        h, nx, nu, nd = C[i], c.shape[0], u_k.shape[0], cd.shape[0]
        t = float(y_k[i] - D[i] @ u_k - F[i] @ cd)
        e = t - float(h @ c)
        ay, du, fc = abs(float(y_k[i])), float(aD[i] @ np.abs(u_k)), float(aF[i] @ np.abs(cd))
        noise = float(aF[i] @ rd)
        sigma = (
            noise
            + 2.0 * gamma(nu + nd + 1) * (ay + du + fc)  # t
            + 2.0 * gamma(nx + 1) * (abs(t) + float(aC[i] @ np.abs(c)))  # e
            + 2.0 * self._g_plant * (ay + du + fc + noise + float(aC[i] @ mag))  # a float64 plant
        )
        return e, float(upper(sigma, nx + nu + nd + 6))

    def _update(
        self,
        c: np.ndarray,
        Q: np.ndarray,
        u_k: np.ndarray,
        y_k: np.ndarray,
        cd: np.ndarray,
        rd: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """The strips of the observed outputs, one after the other (module docstring); the
        prior ``(c, Q)`` and ``True`` when a strip certainly misses the ellipsoid.

        The scalars are bounded by directed rounding, one ``nextafter`` per operation: ``g``,
        ``s`` in ``[lo, hi]``, ``α_lo <= λ / s <= α_hi``, ``δ_lo <= δ``, ``ς_up >= ς``. The
        shape ``ς_up (Q - α_lo (Q h)(Q h)ᵀ) ⪰ ς (Q - α Q h hᵀ Q)`` is evaluated with ``fl(Q h)``
        (``|fl(Q h) - Q h| <= γ_n |Q||h|``) and covered (:func:`_cover`); the centre ``c +
        α_lo fl(Q h) e`` is within ``ε`` of ``c + α Q h e`` (:func:`_cover_centre`)."""
        C = self._mats[2]
        c0, Q0 = c, Q
        nx = c.shape[0]
        g_n = 2.0 * gamma(nx + 4)
        mag = np.abs(c) + up(np.sqrt(np.maximum(np.diag(Q), 0.0)))  # >= |x| for x in E(c, Q)
        for i in np.flatnonzero(~np.isnan(y_k)):
            h = C[i]
            e, sigma = self._strip(int(i), c, mag, u_k, y_k, cd, rd)
            Qh = Q @ h
            aQh = np.abs(Q) @ np.abs(h)
            g_c = float(h @ Qh)
            err = upper(2.0 * gamma(2 * nx) * float(np.abs(h) @ aQh), nx + 2)
            g_hi, g_lo = _up(g_c + err), max(_down(g_c - err), 0.0)
            root = _up(math.sqrt(g_hi))
            if abs(e) > _up(root + sigma):  # the strip misses the ellipsoid: inconsistent
                return c0, Q0, True
            if not g_hi > 0.0 or abs(e) + root <= sigma:
                continue  # the strip contains the ellipsoid's range along h: nothing to gain
            lam = _best_lambda(float(np.trace(Q)), float(Qh @ Qh), g_c, e * e, sigma * sigma)
            om = _down(1.0 - lam)  # <= 1 - λ
            s_hi = _up(_up(_up(1.0 - lam) * _up(sigma * sigma)) + _up(lam * g_hi))
            s_lo = _down(_down(om * _down(sigma * sigma)) + _down(lam * g_lo))
            if not s_lo > 0.0:
                continue
            a_lo, a_hi = _down(lam / s_hi), _up(lam / s_lo)
            delta = _down(_down(_down(lam * om) * _down(e * e)) / s_hi)
            scale = _up(_up(1.0 - delta) / om)
            # the shape (module docstring): within M of scale (Q - α_lo (Q h)(Q h)ᵀ)
            a_v = np.abs(Qh)
            d_v = g_n * aQh  # >= |fl(Q h) - Q h|
            v = a_v + d_v
            M = scale * (g_n * (np.abs(Q) + a_lo * np.outer(a_v, a_v))
                         + a_lo * (np.outer(d_v, v) + np.outer(a_v, d_v)))  # fmt: skip
            k_gain = a_lo * Qh
            Q = _cover(scale * (Q - np.outer(k_gain, Qh)), M)
            # the centre: within ε of c + α Q h e
            c_new = c + k_gain * e
            ae = abs(e)
            eps = (_up(a_hi - a_lo) * v + a_lo * d_v) * ae + g_n * (np.abs(c) + a_lo * a_v * ae)
            Q = _cover_centre(Q, eps * (1.0 + g_n))
            c = c_new
        return c, Q, False

    def _predict(
        self, c: np.ndarray, Q: np.ndarray, rad: np.ndarray, u_k: np.ndarray, cd: np.ndarray,
        rd: np.ndarray, Q_w: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
        """``E(A c + B u + E c_d, (1 + 1/p) A Q Aᵀ + (1 + p) Q_w)``, trace-minimal ``p``, each
        rounding covered (module docstring)."""
        A, B, _, _, E, _ = self._mats
        aA, aB, _, _, aE, _ = self._abs
        nx = c.shape[0]
        c_next = A @ c + B @ u_k + E @ cd
        AQA = A @ Q @ A.T
        aAQA = aA @ np.abs(Q) @ aA.T
        a, w = float(np.trace(AQA)), float(np.trace(Q_w))
        if w > 0.0:
            # any p > 0: c1 = 1 + 1/p is the float, 1 + p rounded up from p = 1 / (c1 - 1)
            # (1/p >= 2⁻⁴⁰: c1 - 1 exact and positive when A Q Aᵀ dwarfs Q_w)
            c1 = 1.0 + max(1.0 / (math.sqrt(a / w) if a > 0.0 else 1.0), _TAU_MIN)
            c2 = _up(1.0 + _up(1.0 / _down(c1 - 1.0)))
            Q_next, M = c1 * AQA + c2 * Q_w, c1 * aAQA + c2 * np.abs(Q_w)
        else:  # E d is a point (Q_w = 0)
            Q_next, M = AQA, aAQA
        Q_next = _cover(Q_next, 2.0 * gamma(2 * nx + 4) * M)
        # the centre's rounding and a float64 evaluation of the state equation
        mag = aA @ (np.abs(c) + rad) + aB @ np.abs(u_k) + aE @ (np.abs(cd) + rd)
        eps = 3.0 * gamma(nx + u_k.shape[0] + cd.shape[0] + 1) * mag
        return c_next, _cover_centre(Q_next, eps)
