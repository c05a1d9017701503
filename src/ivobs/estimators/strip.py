"""Zonotopic set-membership filter with strip intersection (Alamo, Bravo & Camacho 2005).

T. Alamo, J. M. Bravo, E. F. Camacho, *Guaranteed state estimation by zonotopes*, Automatica 41
(2005) 1035-1043; J. M. Bravo, T. Alamo, E. F. Camacho, *Bounded error identification of
systems with time-varying parameters*, IEEE TAC 51 (2006) (the same intersection).

**Intersection with a strip (Alamo et al. 2005).** For a zonotope ``<p, H>`` and a
strip ``S = {x : |hᵀx - t| <= σ}``, every ``λ`` gives a zonotope containing ``<p, H> ∩ S``::

    X(λ) = <p + λ (t - hᵀp), [(I - λ hᵀ) H, σ λ]>

and the one with the smallest Frobenius radius ``‖·‖_F`` of its generator matrix has the closed
form ``λ* = H Hᵀ h / (hᵀ H Hᵀ h + σ²)``.

**Correlated disturbance.** ``d`` enters both ``x+ = A x + B u + E d`` and
``y = C x + D u + F d``, so the filter works on the pair ``(x_k, d_k)``: the joint zonotope
``<(p, c_d), blkdiag(H, R)>`` (``d = c_d + R δ``), each measured component ``i`` is the
hyperplane ``C_i x + F_i d = y_i - D_i u`` in the joint space (a strip with ``σ = 0``: the
measurement noise is the ``F d`` part of the joint set), and the prediction maps the
intersected joint set with ``[A E]``. This is exact for the correlation, and reduces to the
classical strip ``σ_i = Σ_j |F_ij| r_j`` when the noise components enter one output and not the
state. The components of ``y_k`` are intersected one after the other.

**Boxes.** The box of ``x[k]`` is the interval hull of the filtered zonotope, intersected with
two cheap exact enclosures computed at each strip before the zonotope update: the interval hull
of ``(current zonotope) ∩ (hyperplane)`` per coordinate (the Lagrangian dual of the LP
``max x_j``, a one-dimensional convex piecewise-linear function minimised at its breakpoints: no
solver), and constraint propagation of the hyperplane over the box of ``(x, d)``. When every
state is measured the box is therefore the measurement box whenever the prediction is wider.

**Order reduction.** After the prediction the zonotope keeps at most ``order`` generators.
The default (``reduction="parallelotope"``) absorbs the generators to remove into a basis of
``nx`` large, independent ones (Chisci's parallelotope rule; see
:func:`ivobs.czonotope.reduce_generators`): at the same order it is markedly tighter than
Combastel's box reduction (``reduction="box"``, :meth:`ivobs.Zonotope.reduce`, paper 002,
Remark 2, which encloses the smallest generators in a box).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_int, as_matrix
from ..czonotope import reduce_generators
from ..errors import IvobsError
from ..model import LinearSystem
from ..sets import Box, Zonotope
from . import register
from .base import Design, Estimator

__all__ = ["StripDesign", "StripEstimator"]


@dataclass(frozen=True)
class StripDesign(Design):
    """``order``: generators kept by the reduction (the zonotope *order* of papers 001/002);
    ``reduction``: ``"parallelotope"`` or ``"box"``; ``weight``: the weight ``W`` of the box
    reduction (identity when None)."""

    order: int
    reduction: str
    weight: np.ndarray | None


@register
class StripEstimator(Estimator):
    """Zonotopic filter with strip intersection and F-radius gain (Alamo et al. 2005).

    Uses ``u[0..k]`` and ``y[0..k]``: the box at step ``k`` is the filtered set, after the
    intersection with the strips of ``y[k]``. Needs the prior box ``x0``. Per step: ``ny``
    closed-form intersections and one order reduction, no optimisation; the cost is bounded by
    ``order``.

    Parameters
    ----------
    sys : LinearSystem (discrete time; matrices and bounds may vary with ``k``)
    x0 : Box, the prior box on ``x[0]``
    order : int, optional
        Generators kept between steps (default ``10 nx``; at least ``nx``). More generators
        give tighter boxes at a cost per step growing with ``order`` (``O(ny nx order²)``).
    reduction : ``"parallelotope"`` (default) or ``"box"``
        Order reduction: Chisci's parallelotope absorption, or Combastel's box.
    weight : (nx, nx) array, optional
        Positive definite weight of the box reduction (which generators are kept).
    """

    name = "strip"
    summary = "zonotopic set-membership filter, strip intersection (Alamo et al. 2005)"
    reference = (
        "T. Alamo, J. M. Bravo, E. F. Camacho, Guaranteed state estimation by zonotopes, "
        "Automatica 41 (2005) 1035-1043"
    )
    supports_time_varying = True
    needs_x0 = True

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        order: int | None = None,
        reduction: str = "parallelotope",
        weight: Any = None,
        **base: Any,
    ):
        super().__init__(sys, x0, **base)
        if reduction not in ("parallelotope", "box"):
            raise IvobsError(f"reduction: expected 'parallelotope' or 'box', got {reduction!r}")
        q = 10 * sys.nx if order is None else as_int("order", order, 1)
        if q < sys.nx:
            raise IvobsError(
                f"order: the reduction keeps at least nx = {sys.nx} generators, got {q}"
            )
        W = None
        if weight is not None:
            W = as_matrix("weight", weight, sys.nx, sys.nx)
            if not np.allclose(W, W.T) or np.min(np.linalg.eigvalsh(0.5 * (W + W.T))) <= 0:
                raise IvobsError("weight: expected a symmetric positive definite matrix")
        if W is not None and reduction != "box":
            raise IvobsError("weight: only the 'box' reduction takes a weight")
        self.design = StripDesign(order=q, reduction=reduction, weight=W)
        self.valid_from = 0

    def _initial_state(self) -> dict[str, Any]:
        assert self.x0 is not None
        r = self.x0.radius
        return {"p": self.x0.center.copy(), "H": np.diag(r)[:, r > 0]}

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        A, B, C, D, E, F = self.sys.matrices_at(k)
        dbox = self.sys.d_at(k, y_k)
        nx = self.sys.nx
        p, H = state["p"], state["H"]
        cd, rd = dbox.center, dbox.radius
        cols = np.flatnonzero((rd > 0) & (np.any(E != 0, axis=0) | np.any(F != 0, axis=0)))
        nd = cd.shape[0]
        # joint zonotope of (x_k, d_k)
        z = np.concatenate([p, cd])
        Hz = np.zeros((nx + nd, H.shape[1] + cols.size))
        Hz[:nx, : H.shape[1]] = H
        Hz[nx + cols, H.shape[1] + np.arange(cols.size)] = rd[cols]
        r0 = np.abs(H).sum(axis=1)
        box_lo = np.concatenate([p - r0, dbox.lo])
        box_hi = np.concatenate([p + r0, dbox.hi])
        for i in np.flatnonzero(~np.isnan(y_k)):
            h = np.concatenate([C[i], F[i]])
            t = float(y_k[i] - D[i] @ u_k)
            s = Hz.T @ h
            e = t - h @ z
            if abs(e) > np.abs(s).sum() * (1 + 1e-9) + 1e-12 * (1.0 + abs(t)):
                state["_inconsistent"] = True  # the hyperplane misses the zonotope
                continue
            contracted = _propagate_hyperplane(h, t, box_lo, box_hi)
            if contracted is None:
                state["_inconsistent"] = True
                continue
            box_lo, box_hi = contracted
            lo_j, hi_j = _section_hull(z[:nx], Hz[:nx], s, e)
            box_lo[:nx] = np.maximum(box_lo[:nx], lo_j)
            box_hi[:nx] = np.minimum(box_hi[:nx], hi_j)
            ss = s @ s
            if ss <= 1e-300:
                continue
            lam = Hz @ s / ss  # the F-radius optimal λ* with σ = 0 (joint space)
            z = z + lam * e
            Hz = Hz - np.outer(lam, s)
        r = np.abs(Hz[:nx]).sum(axis=1)
        lo = np.maximum(z[:nx] - r, box_lo[:nx])
        hi = np.minimum(z[:nx] + r, box_hi[:nx])
        hi = np.maximum(hi, lo)  # equal up to rounding when a state is pinned down exactly
        # prediction with [A E] on the joint set, then order reduction
        M = np.hstack([A, E])
        p_next, H_next = M @ z + B @ u_k, M @ Hz
        if self.design.reduction == "box":
            zp = Zonotope._trusted(p_next, H_next).reduce(self.design.order, self.design.weight)
            p_next, H_next = zp.c, zp.G
        else:
            H_next = H_next[:, np.any(H_next != 0, axis=0)]
            none = np.zeros((0, H_next.shape[1]))
            H_next = reduce_generators(p_next, H_next, none, np.zeros(0), self.design.order)[1]
        state["p"], state["H"] = p_next, H_next
        return lo, hi


def _section_hull(
    z: np.ndarray, H: np.ndarray, s: np.ndarray, e: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate hull of ``{z + H ξ : ‖ξ‖∞ <= 1, sᵀξ = e}`` without a solver.

    By LP duality ``max_ξ H_j ξ = min_μ (μ e + ‖H_j - μ s‖₁)`` (and any ``μ`` gives a valid
    bound); the right-hand side is convex and piecewise linear in ``μ``, so its minimum is at a
    breakpoint ``μ = H_jl / s_l``: evaluate them all (``O(n m²)``).
    """
    nz = np.abs(s) > 1e-14 * np.abs(s).max() if s.size and np.any(s) else np.zeros(s.shape, bool)
    if not np.any(nz):
        r = np.abs(H).sum(axis=1)
        return z - r, z + r
    mu = np.concatenate([H[:, nz] / s[nz], np.zeros((H.shape[0], 1))], axis=1)  # (n, K)
    spread = np.abs(H[:, None, :] - mu[:, :, None] * s[None, None, :]).sum(axis=2)  # (n, K)
    hi = z + np.min(mu * e + spread, axis=1)
    lo = z + np.max(mu * e - spread, axis=1)
    return lo, hi


def _propagate_hyperplane(
    h: np.ndarray, t: float, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Contract the box ``[lo, hi]`` with ``hᵀw = t`` (one pass of interval propagation:
    ``w_j ∈ (t - Σ_{l≠j} h_l [w_l]) / h_j``); ``None`` if the hyperplane misses the box."""
    t_lo = np.minimum(h * lo, h * hi)
    t_hi = np.maximum(h * lo, h * hi)
    s_lo, s_hi = t_lo.sum(), t_hi.sum()
    slack = 1e-9 * (1.0 + abs(t) + np.abs(t_lo).sum() + np.abs(t_hi).sum())
    if t < s_lo - slack or t > s_hi + slack:
        return None
    nz = h != 0
    q1 = (t - (s_hi - t_hi[nz])) / h[nz]
    q2 = (t - (s_lo - t_lo[nz])) / h[nz]
    pad = 1e-12 * (1.0 + np.abs(q1) + np.abs(q2))
    lo, hi = lo.copy(), hi.copy()
    lo[nz] = np.maximum(lo[nz], np.minimum(q1, q2) - pad)
    hi[nz] = np.minimum(hi[nz], np.maximum(q1, q2) + pad)
    return lo, np.maximum(hi, lo)
