"""Ellipsoidal set-membership filter: the prediction of [Liu2016] and the strip update of
[Schweppe1968] with trace-minimising parameters (CORA's ESO family, [Althoff2021]).

The set of ``x[k]`` is an ellipsoid ``E(c, Q) = {x : (x - c)ᵀ Q⁻¹ (x - c) <= 1}`` (``Q``
positive semidefinite; ``E(c, Q) = c + Q^{1/2} B``, so singular ``Q`` is allowed).

**Bounds as ellipsoids.** A box ``c + diag(r) b``, ``|b| <= 1``, mapped by ``G`` lies in
``E(G c, G diag(q) Gᵀ)`` for ``q_i = r_i Σ_j r_j ‖G_j‖ / ‖G_i‖`` (the box's vertices satisfy
``Σ r_i² / q_i = 1``; this ``q`` minimises the trace): used for ``x0`` (``G = I``) and the
process disturbance ``E d``.

**Prediction** [Liu2016]: ``A E(c, Q) + B u ⊕ E(E c_d, Q_w) ⊆ E(A c + B u + E c_d,
(1 + 1/p) A Q Aᵀ + (1 + p) Q_w)`` for every ``p > 0`` (the Minkowski sum of two ellipsoids);
``p = sqrt(tr(A Q Aᵀ) / tr(Q_w))`` minimises the trace.

**Update** with one measured output ``|h x - t| <= σ`` (``h = C_i``, ``t = y_i - D_i u - F_i
c_d``, ``σ = Σ_j |F_ij| r_j``: the measurement noise of that row; rows are used one after the
other): for every ``λ ∈ [0, 1)`` the intersection lies in ``{(1-λ)(x-c)ᵀQ⁻¹(x-c) + λ (h x -
t)² / σ² <= 1}`` [Schweppe1968], which is the ellipsoid ``E(c + (λ/s) Q h e, (1 - δ)/(1 - λ)
(Q - (λ/s) Q h hᵀ Q))`` with ``e = t - h c``, ``g = hᵀ Q h``, ``s = (1 - λ) σ² + λ g``, ``δ =
λ (1 - λ) e² / s``. ``λ`` minimises the trace (a scalar function: a grid, then golden
section). Any ``λ`` is sound; so is skipping a row (when the strip already contains the
ellipsoid's range in that direction).

**Floating point.** Beyond the outward rounding of every box (:mod:`ivobs.estimators.rounding`),
the recursion keeps its ellipsoid sound itself: each strip is widened by a bound on the
rounding of ``t`` and ``h c``; a computed shape matrix ``Q̃`` (entrywise error at most
``γ M``, ``M`` the magnitudes of its operands, ``γ = 2 (n + 4) u / (1 - 2 (n + 4) u)``) gets
``γ ‖M‖_F I`` added (then ``Q̃ + γ ‖M‖_F I ⪰ Q``), and the rounding ``ε_c`` of the centre is
covered by the Minkowski sum with the ball of radius ``‖ε_c‖``, ``Q <- (1 + τ) Q + (1 + 1/τ)
‖ε_c‖² I`` (``τ`` minimising the trace).

**Inconsistent data**: a strip that misses the ellipsoid is reported and ``y[k]`` not used.
**Missing samples**: NaN rows are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..model import LinearSystem
from ..sets import Box
from . import register
from .base import Design, Estimator, check_size
from .state import OnlineState, Step

__all__ = ["EllipsoidDesign", "EllipsoidEstimator", "EllipsoidState", "box_ellipsoid"]

_U = np.finfo(float).eps / 2.0
GRID = np.linspace(0.0, 1.0, 66)[1:-1] ** 0.5
"""Values of ``λ`` tried before the golden-section refinement (denser towards 1)."""


def _gamma(n: int) -> float:
    m = 2 * (n + 4) * _U
    return m / (1.0 - m)


def box_ellipsoid(G: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``Q`` of the trace-minimal ellipsoid ``E(0, G diag(q) Gᵀ)`` containing ``G diag(r) B``
    (module docstring)."""
    norms = np.sqrt((G * G).sum(axis=0))
    keep = (r > 0) & (norms > 0)
    if not keep.any():
        return np.zeros((G.shape[0], G.shape[0]))
    rk, nk = r[keep], norms[keep]
    q = rk * float(np.sum(rk * nk)) / nk
    Gk = G[:, keep]
    Q = (Gk * q) @ Gk.T
    # the sum's rounding: Q + γ ‖|G| q |G|ᵀ‖_F I contains the exact one
    M = (np.abs(Gk) * q) @ np.abs(Gk).T
    out: np.ndarray = 0.5 * (Q + Q.T) + _gamma(len(q)) * float(np.linalg.norm(M)) * np.eye(
        G.shape[0]
    )
    return out


@dataclass(frozen=True)
class EllipsoidDesign(Design):
    """``Q_w``: the ellipsoid of the process disturbance ``E d`` (constant bounds; ``None``
    when the bounds vary with ``k``)."""

    Q_w: np.ndarray | None


@dataclass(frozen=True)
class EllipsoidState(OnlineState):
    """``x[k] ∈ E(c, Q)`` before ``y[k]`` is used (the predicted ellipsoid)."""

    c: np.ndarray
    Q: np.ndarray


def _cover_centre(Q: np.ndarray, eps_c: np.ndarray) -> np.ndarray:
    """``E(c, Q) ⊕ ball(‖eps_c‖) ⊆ E(c, (1 + τ) Q + (1 + 1/τ) ‖eps_c‖² I)``, trace-minimal τ."""
    e2 = float(eps_c @ eps_c)
    if e2 == 0.0:
        return Q
    n = Q.shape[0]
    tr = max(float(np.trace(Q)), e2)
    tau = float(np.sqrt(n * e2 / tr))
    out: np.ndarray = (1.0 + tau) * Q + ((1.0 + 1.0 / tau) * e2 * (1.0 + 4 * _U)) * np.eye(n)
    return out


def _trace_after(lam: Any, trQ: float, qh2: float, g: float, e2: float, s2: float) -> Any:
    s = (1.0 - lam) * s2 + lam * g
    delta = lam * (1.0 - lam) * e2 / s
    return (1.0 - delta) / (1.0 - lam) * (trQ - lam * qh2 / s)


def _best_lambda(trQ: float, qh2: float, g: float, e2: float, s2: float) -> float:
    """The ``λ ∈ (0, 1)`` minimising the trace of the updated ellipsoid (a grid, then golden
    section on the bracket of the best grid point, in floats)."""
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
    """

    name = "ellipsoid"
    order = 85
    summary = "ellipsoidal set-membership filter, trace-minimal prediction and strip updates"
    reference = "[Liu2016]; [Schweppe1968]"
    data_used = "filter"
    design: EllipsoidDesign

    def __init__(self, sys: LinearSystem, x0: Box | None = None, **options: Any) -> None:
        super().__init__(sys, x0, **options)
        check_size(self.name, sys.nx, "multiplies dense nx x nx matrices (O(nx^3) work)")
        self._mats = sys.matrices_at(0)
        E = self._mats[4]
        Q_w = None
        if sys.has_constant_bounds and sys.nd:
            dbox = sys.d_at(0)
            Q_w = box_ellipsoid(E, dbox.radius)
        self.design = EllipsoidDesign(Q_w=Q_w)
        self._absA = np.abs(self._mats[0])

    # -- online ----------------------------------------------------------------------------
    def _initial_state(self) -> EllipsoidState:
        assert self.x0 is not None
        nx = self.sys.nx
        Q = box_ellipsoid(np.eye(nx), self.x0.radius)
        eps_c = _gamma(1) * np.abs(self.x0.center)  # the centre's rounding
        return EllipsoidState(c=self.x0.center.copy(), Q=_cover_centre(Q, eps_c))

    def _disturbance(self, k: int, y_k: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centre and radius of ``d[k]`` and ``Q_w`` of ``E d[k]``."""
        if not self.sys.nd:
            z = np.zeros(0)
            return z, z, np.zeros((self.sys.nx, self.sys.nx))
        box = self.sys.d_at(k, y_k)
        cd, rd = box.center, box.radius
        Q_w = self.design.Q_w if self.design.Q_w is not None else box_ellipsoid(self._mats[4], rd)
        return cd, rd, Q_w

    def _step(
        self, state: EllipsoidState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[EllipsoidState]:
        cd, rd, Q_w = self._disturbance(state.k, y_k)
        c, Q, inconsistent = self._update(state.c, state.Q, u_k, y_k, cd, rd)
        rad = np.sqrt(np.maximum(np.diag(Q), 0.0))
        lo, hi = c - rad, c + rad
        c_next, Q_next = self._predict(c, Q, u_k, cd, Q_w)
        return Step(replace(state, c=c_next, Q=Q_next), lo, hi, inconsistent)

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
        prior ``(c, Q)`` and ``True`` when a strip misses the ellipsoid (inconsistent)."""
        _, _, C, D, _, F = self._mats
        c0, Q0 = c, Q
        nx = c.shape[0]
        gam = _gamma(nx + u_k.shape[0] + cd.shape[0])
        for i in np.flatnonzero(~np.isnan(y_k)):
            h = C[i]
            t = float(y_k[i] - D[i] @ u_k - F[i] @ cd)
            sigma = float(np.abs(F[i]) @ rd)
            # the rounding of t and of h c (an outer strip: sound whatever the error)
            sigma += gam * float(
                abs(y_k[i]) + np.abs(D[i]) @ np.abs(u_k) + np.abs(F[i]) @ np.abs(cd)
            )
            sigma += gam * float(np.abs(h) @ np.abs(c)) + 1e-300
            Qh = Q @ h
            g = float(h @ Qh)
            e = t - float(h @ c)
            root = np.sqrt(max(g, 0.0)) * (1.0 + gam)
            if abs(e) > root + sigma:  # the strip misses the ellipsoid: inconsistent
                return c0, Q0, True
            if g <= 0.0 or abs(e) + root <= sigma:
                continue  # the strip contains the ellipsoid's range along h: nothing to gain
            s2 = sigma * sigma
            lam = _best_lambda(float(np.trace(Q)), float(Qh @ Qh), g, e * e, s2)
            s = (1.0 - lam) * s2 + lam * g
            delta = lam * (1.0 - lam) * e * e / s
            scale = (1.0 - delta) / (1.0 - lam)
            if not scale > 0.0:
                continue
            k_gain = (lam / s) * Qh
            c_new = c + k_gain * e
            Q_new = scale * (Q - np.outer(k_gain, Qh))
            # rounding: entrywise error <= γ scale (|Q| + |k| |Qh|ᵀ); the centre's <= γ |k e|
            M = scale * (np.abs(Q) + np.outer(np.abs(k_gain), np.abs(Qh)))
            Q_new = 0.5 * (Q_new + Q_new.T) + gam * float(np.linalg.norm(M)) * np.eye(nx)
            Q = _cover_centre(Q_new, gam * (np.abs(c) + np.abs(k_gain * e)))
            c = c_new
        return c, Q, False

    def _predict(
        self, c: np.ndarray, Q: np.ndarray, u_k: np.ndarray, cd: np.ndarray, Q_w: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``E(A c + B u + E c_d, (1 + 1/p) A Q Aᵀ + (1 + p) Q_w)``, trace-minimal ``p``."""
        A, B, _, _, E, _ = self._mats
        nx = c.shape[0]
        c_next = A @ c + B @ u_k + E @ cd
        AQA = A @ Q @ A.T
        a, w = float(np.trace(AQA)), float(np.trace(Q_w))
        absA = self._absA
        if w > 0.0 and a > 0.0:
            p = np.sqrt(a / w)
            Q_next = (1.0 + 1.0 / p) * AQA + (1.0 + p) * Q_w
            M = (1.0 + 1.0 / p) * (absA @ np.abs(Q) @ absA.T) + (1.0 + p) * np.abs(Q_w)
        else:
            Q_next = AQA + Q_w
            M = absA @ np.abs(Q) @ absA.T + np.abs(Q_w)
        gam = _gamma(2 * nx + 2)
        Q_next = 0.5 * (Q_next + Q_next.T) + gam * float(np.linalg.norm(M)) * np.eye(nx)
        eps_c = _gamma(nx + u_k.shape[0] + cd.shape[0]) * (
            absA @ np.abs(c) + np.abs(B) @ np.abs(u_k) + np.abs(E) @ np.abs(cd)
        )
        return c_next, _cover_centre(Q_next, eps_c)
