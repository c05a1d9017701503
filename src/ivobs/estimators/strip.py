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
hyperplane ``C_i x + F_i d = y_i - D_i u`` in the joint space (the measurement noise is the
``F d`` part of the joint set; its half-width is only the rounding level, see below), and the
prediction maps the
intersected joint set with ``[A E]``. This is exact for the correlation, and reduces to the
classical strip ``σ_i = Σ_j |F_ij| r_j`` when the noise components enter one output and not the
state. The components of ``y_k`` are intersected one after the other.

**Rounding (audit A11).** ``y`` is a float64 record (possibly a float64 simulation of the
model) and every update is rounded, so component ``i`` is intersected as the strip of half-width
(``h = (C_i, F_i)``, ``t = y_i - D_i u``, ``w̄`` a bound on ``|(x, d)|`` from the joint box,
``γ_n = n u / (1 - n u)``, Higham 2002 §3.1)::

    σ_i = 2 γ_{nz+nu+2} (|y_i| + |D_i| |u| + |h|ᵀ w̄) + γ_{nz+1} (|t| + |h|ᵀ |z|)
          + γ_{nz} |h|ᵀ |H_z| 1                                                        (8)

which certainly holds ``(x_k, d_k)``, not as the hyperplane ``σ = 0``: with ``σ = 0`` the gain
``λ* = H s / sᵀs`` grows like ``1 / ‖s‖`` once the set is thin along ``h`` and ``eps |y|`` moved
the set off the state (a miss of 0.22 at ``|x| ~ 3e4``); (8) bounds it. The rounding of the
updates (``z + λ e``, ``H - λ sᵀ``) is accumulated in a box kept aside,
``(x_k, d_k) ∈ <z, H_z> ⊕ box(acc)``, which the prediction appends as generators together with
the rounding of ``M z + B u`` and ``M H``. A measurement is reported inconsistent only when the
strip certainly misses the zonotope: ``|t - hᵀz| > (‖s‖₁ + σ_z) (1 + γ)`` (``σ_z``: (8) widened
by the box aside).

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
from ..sets.czonotope import (
    UNIT_ROUNDOFF,
    box_generators,
    gamma,
    reduce_generators,
    safe_radius,
)
from ..errors import IvobsError
from ..model import LinearSystem
from ..sets import Box, Zonotope
from . import register
from .base import Design, Estimator, check_size

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
    order = 80
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
        check_size(
            self.name,
            sys.nx,
            "multiplies and reduces a dense nx x q generator matrix "
            "(q = 10 nx by default, O(nx^3) work)",
        )
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
        p, r = safe_radius(self.x0.lo, self.x0.hi)
        # e: a box kept aside (rounding of the last reduction), x[k] ∈ <p, H> ⊕ box(e)
        return {"p": p, "H": np.diag(r)[:, r > 0], "e": np.zeros(self.sys.nx)}

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        A, B, C, D, E, F = self.sys.matrices_at(k)
        dbox = self.sys.d_at(k, y_k)
        nx = self.sys.nx
        p, H = state["p"], state["H"]
        cd, rd = safe_radius(dbox.lo, dbox.hi)
        cols = np.flatnonzero((rd > 0) & (np.any(E != 0, axis=0) | np.any(F != 0, axis=0)))
        nd = cd.shape[0]
        nz = nx + nd
        # joint zonotope of (x_k, d_k)
        z = np.concatenate([p, cd])
        Hz = np.zeros((nz, H.shape[1] + cols.size))
        Hz[:nx, : H.shape[1]] = H
        Hz[nx + cols, H.shape[1] + np.arange(cols.size)] = rd[cols]
        r0 = np.abs(H).sum(axis=1)
        pad = gamma(H.shape[1] + 2) * (np.abs(p) + r0) + state["e"] * (1.0 + gamma(2))
        box_lo = np.concatenate([p - r0 - pad, dbox.lo])
        box_hi = np.concatenate([p + r0 + pad, dbox.hi])
        au = np.abs(u_k)
        g_meas = 2.0 * gamma(nz + u_k.shape[0] + 2)
        # the rounding of the updates, kept aside: (x_k, d_k) ∈ <z, Hz> ⊕ box(acc)
        acc = np.zeros(nz)
        acc[:nx] = state["e"]
        for i in np.flatnonzero(~np.isnan(y_k)):
            h = np.concatenate([C[i], F[i]])
            ah = np.abs(h)
            t = float(y_k[i] - D[i] @ u_k)
            s = Hz.T @ h
            e = float(t - h @ z)
            # the half-width of the strip that certainly holds (x_k, d_k): eq. (8) of the module
            # docstring with the rounding of y, of t, of e and of s (Higham's γ_n bounds)
            wmax = np.maximum(np.abs(box_lo), np.abs(box_hi))
            sigma = (
                g_meas * (abs(float(y_k[i])) + np.abs(D[i]) @ au + ah @ wmax)
                + gamma(nz + 1) * (abs(t) + ah @ np.abs(z))
                + gamma(nz) * float((ah @ np.abs(Hz)).sum())
            ) * (1.0 + 4.0 * UNIT_ROUNDOFF)
            # the point of <z, Hz> that is (x_k, d_k) minus the rounding: in a wider strip
            sigma_z = (sigma + ah @ acc) * (1.0 + gamma(nz + 2))
            s1 = float(np.abs(s).sum())
            if abs(e) > (s1 + sigma_z) * (1.0 + gamma(s.size + 2)):
                state["_inconsistent"] = True  # the strip misses the zonotope: certain
                continue
            contracted = _propagate_hyperplane(h, t, box_lo, box_hi, sigma)
            if contracted is None:
                state["_inconsistent"] = True
                continue
            box_lo, box_hi = contracted
            lo_j, hi_j = _section_hull(z[:nx], Hz[:nx], s, e, sigma_z)
            box_lo[:nx] = np.maximum(box_lo[:nx], lo_j - acc[:nx] * (1.0 + 2.0 * UNIT_ROUNDOFF))
            box_hi[:nx] = np.minimum(box_hi[:nx], hi_j + acc[:nx] * (1.0 + 2.0 * UNIT_ROUNDOFF))
            den = float(s @ s) + sigma_z * sigma_z
            if s1 == 0.0 or not den > 0.0:
                continue
            lam = Hz @ s / den  # the F-radius optimal λ* of Alamo et al. (joint space)
            al = np.abs(lam)
            # rounding of z + λ e and of H - λ sᵀ, σ λ: added to the box aside
            acc = acc + gamma(3) * (
                np.abs(z) + al * abs(e) + np.abs(Hz).sum(axis=1) + al * (s1 + sigma_z)
            )
            z = z + lam * e
            Hz = np.hstack([Hz - np.outer(lam, s), (sigma_z * lam)[:, None]])
        acc *= 1.0 + gamma(y_k.shape[0] + 1)  # the rounding of the sums of acc itself
        r = np.abs(Hz[:nx]).sum(axis=1) + acc[:nx]
        lo = np.maximum(z[:nx] - r, box_lo[:nx])
        hi = np.minimum(z[:nx] + r, box_hi[:nx])
        hi = np.maximum(hi, lo)  # equal up to rounding when a state is pinned down exactly
        # prediction with [A E] on the joint set, then order reduction; the box covers the
        # rounding of M z + B u, of M H and of the plant's own float64 arithmetic, and the
        # image of the box aside
        M = np.hstack([A, E])
        aM = np.abs(M)
        p_next, H_next = M @ z + B @ u_k, M @ Hz
        err = 2.0 * gamma(nz + u_k.shape[0] + 1) * (
            aM @ (np.abs(z) + np.abs(Hz).sum(axis=1) + acc) + np.abs(B) @ au
        ) + (aM @ acc) * (1.0 + gamma(nz + 1))
        H_next = np.hstack([H_next, box_generators(err)])
        H_next = H_next[:, np.any(H_next != 0, axis=0)]
        self._check_overflow(k + 1, p_next, H_next)
        e_next = np.zeros(nx)
        if self.design.reduction == "box":
            m = H_next.shape[1]
            zp = Zonotope._trusted(p_next, H_next).reduce(self.design.order, self.design.weight)
            p_next, H_next = zp.c, zp.G
            if m > self.design.order:  # the box of the removed generators: a rounded sum
                H_next[:, -nx:] *= 1.0 + gamma(m + 1)
        else:  # the box of what the basis misses is kept aside until the next prediction
            none = np.zeros((0, H_next.shape[1]))
            out = reduce_generators(p_next, H_next, none, np.zeros(0), self.design.order, True)
            H_next, e_next = out[1], out[4]
        # C order, as after a state() / restore() round trip (BLAS results depend on layout)
        state["p"], state["H"], state["e"] = p_next, np.ascontiguousarray(H_next), e_next
        return lo, hi


def _section_hull(
    z: np.ndarray, H: np.ndarray, s: np.ndarray, e: float, sigma: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Per-coordinate hull of ``{z + H ξ : ‖ξ‖∞ <= 1, |sᵀξ - e| <= σ}`` without a solver.

    By LP duality ``max_ξ H_j ξ = min_μ (μ e + |μ| σ + ‖H_j - μ s‖₁)`` (and any ``μ`` gives a
    valid bound); the right-hand side is convex and piecewise linear in ``μ``, so its minimum
    is at a breakpoint ``μ = H_jl / s_l`` or ``μ = 0``: evaluate them all (``O(n m²)``). Each
    value is increased by the bound ``γ_{m+4} (|z_j| + |μ| (|e| + σ + ‖s‖₁) + ‖H_j‖₁)`` of its
    rounding, so the returned bounds hold for the exact set.
    """
    absH = np.abs(H).sum(axis=1)
    nz = np.abs(s) > 1e-14 * np.abs(s).max() if s.size and np.any(s) else np.zeros(s.shape, bool)
    if not np.any(nz):
        r = absH + gamma(H.shape[1] + 2) * (np.abs(z) + absH)
        return z - r, z + r
    mu = np.concatenate([H[:, nz] / s[nz], np.zeros((H.shape[0], 1))], axis=1)  # (n, K)
    spread = np.abs(H[:, None, :] - mu[:, :, None] * s[None, None, :]).sum(axis=2)  # (n, K)
    am = np.abs(mu)
    err = gamma(H.shape[1] + 4) * (
        np.abs(z)[:, None] + am * (abs(e) + sigma + float(np.abs(s).sum())) + absH[:, None]
    )
    hi = z + np.min(mu * e + am * sigma + spread + err, axis=1)
    lo = z + np.max(mu * e - am * sigma - spread - err, axis=1)
    return lo, hi


def _propagate_hyperplane(
    h: np.ndarray, t: float, lo: np.ndarray, hi: np.ndarray, sigma: float = 0.0
) -> tuple[np.ndarray, np.ndarray] | None:
    """Contract the box ``[lo, hi]`` with the strip ``|hᵀw - t| <= σ`` (one pass of interval
    propagation: ``w_j ∈ ([t - σ, t + σ] - Σ_{l≠j} h_l [w_l]) / h_j``); ``None`` if the strip
    certainly misses the box. The interval sums are widened by the bound
    ``γ_{n+3} (|t| + σ + Σ_l |h_l| max(|lo_l|, |hi_l|))`` of their rounding, the quotients by
    ``γ_2`` (relative)."""
    t_lo = np.minimum(h * lo, h * hi)
    t_hi = np.maximum(h * lo, h * hi)
    s_lo, s_hi = t_lo.sum(), t_hi.sum()
    delta = gamma(h.size + 3) * (abs(t) + sigma + np.maximum(np.abs(t_lo), np.abs(t_hi)).sum())
    if t + sigma < s_lo - delta or t - sigma > s_hi + delta:
        return None
    nz = h != 0
    a = (t - sigma) - (s_hi - t_hi[nz]) - delta  # h_j w_j >= a
    b = (t + sigma) - (s_lo - t_lo[nz]) + delta  # h_j w_j <= b
    q1, q2 = a / h[nz], b / h[nz]
    pad = gamma(2) * np.maximum(np.abs(q1), np.abs(q2))
    lo, hi = lo.copy(), hi.copy()
    lo[nz] = np.maximum(lo[nz], np.minimum(q1, q2) - pad)
    hi[nz] = np.minimum(hi[nz], np.maximum(q1, q2) + pad)
    if np.any(lo > hi):
        return None  # both intervals hold every (x, d) that explains the data: none does
    return lo, hi
