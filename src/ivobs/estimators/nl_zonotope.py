"""Zonotopic filter for nonlinear systems by conservative linearisation, with strips.

For ``x[k+1] = f(x, u, w)``, ``y[k] = h(x, u, w)`` (a :class:`~ivobs.NonlinearSystem`; ``w``:
the uncertain parameters and bounded signals of the step, ``w ∈ W``), the filter works, like
the linear ``strip`` method, on the joint vector ``ζ = (x_k, w_k)`` (the same ``w_k`` enters
``h`` and ``f``): ``ζ ∈ Z = <z, H_z> ⊕ box(acc)`` and ``ζ ∈ B``, a box. Between steps it keeps
the joint set of the last step *after* its measurement update; the prediction is done at the
start of the next step, once that step's measurement is known.

0. **One step back.** ``y_k = h(f(x_{k-1}, u_{k-1}, w_{k-1}), u_k, w_k)`` contracts the box
   of ``ζ_{k-1}`` (the model's forward-backward contractors of ``h ∘ f``,
   :func:`~ivobs.estimators._meanvalue.contract_back`): when ``y_k`` does not determine the
   states of step ``k`` but does those of step ``k - 1`` (Hénon with ``y = x2``), the box over
   which ``f`` is linearised stays small (without it the remainder grows like the square of
   the width and the set diverges).
1. **Prediction.** ``f`` is linearised over that box at the centre ``z`` of ``Z`` (clipped into
   the box) by the mean-value form (:mod:`ivobs.estimators._meanvalue`, [Rego2020]; first
   order with the Lagrange remainder bounded by the interval Jacobian over the box,
   [Althoff2008]): ``f(ζ) ∈ f0 + J (ζ - c) ± ρ``, so
   ``x_k ∈ <p, H> = <f0 + J (z - c), [J H_z, diag(ρ + |J| acc + err)]>`` (the remainder as
   box generators), and ``x_k ∈ [lo, hi]``, the natural inclusion of ``f`` over the box
   tightened by the centred form and by monotonicity. Then the joint set of
   ``(x_k, w_k)``: ``z = (p, c_w)``, ``H_z = blkdiag(H, R_w)``, ``B = ([lo, hi] ∩ hull) × W``.
2. **Order reduction** of ``<p, H>`` to ``order`` generators (the parallelotope rule of
   [Chisci1998], :func:`ivobs.czonotope.reduce_generators`), its rounding kept in the box
   ``e`` aside; in batches, when more than ``1.5 order`` generators have accumulated.
3. **Measurement update.** ``B`` is contracted by the model's forward-backward contractor of
   ``h(x, u, w) = y_k``; ``h`` is linearised over ``B``, ``h(ζ) ∈ h0 + J (ζ - c) ± ρ``, so
   each measured ``y_i`` gives the strip ``|J_i ζ - t_i| <= σ_i``, ``t_i = y_i - h0_i + J_i c``,
   ``σ_i = ρ_i`` plus the rounding of ``t_i``. ``Z`` is intersected with each strip by the
   F-radius optimal section of [Alamo2005] (``λ* = H_z s / (sᵀ s + σ²)``, ``s = H_zᵀ J_iᵀ``),
   and ``B`` is contracted by the section's interval hull and by propagating the strip over
   ``B`` (the exact enclosures of the ``strip`` method). A measurement found inconsistent is
   reported and not used (the strips of that step undone).
4. **Box of x[k]**: the ``x`` part of ``B``.

Option ``box_strips``: also cut ``Z`` with ``|x_j - mid_j| <= rad_j`` where the box
``[lo, hi]`` is tighter than the hull of ``Z``.

**Soundness under rounding (proof).** Invariant: the true ``ζ_{k-1}`` is in the stored
``<z, H_z> ⊕ box(acc)`` and box, in exact arithmetic on the stored floats; then the true
``x_k`` is in ``<p, H> ⊕ box(e)`` and ``[lo, hi]`` (steps (v)-(vi)); the contractors of step 0
and 3 only remove points that cannot explain ``y_k``. (i) ``Z``, ``B``: the hull is
``p ± (|H| 1 + e)`` enlarged by ``γ_{m+2} (|p| + |H| 1)`` (the rounding of the sums);
``W`` is re-centred by :func:`~ivobs.sets.rounding.mid_rad` (``[wl, wh] ⊆ c_w ± R_w``
exactly). (ii) Linearisation: :func:`~ivobs.estimators._meanvalue.linearise` returns
``(g0, J, ρ)`` with ``|g(ζ) - g0 - J(ζ - c)| <= ρ`` exactly for every ``ζ ∈ B``, from the
model's outward-rounded enclosures (its docstring bounds its own rounding). (iii) A strip
``|J_i ζ - t| <= σ`` holds for the true ``ζ`` once ``σ >= ρ_i + |fl(t) - t|``, and
``|fl(t) - t| <= γ_{n+3} (|y_i| + |h0_i| + |J_i| |c|)`` ([Higham2002, Section 3.1]). (iv) Strip
on ``Z``: the point ``ζ - ε`` (``|ε| <= acc``) is ``z + H_z ξ`` with ``|sᵀξ - e| <= σ_z``,
``e = t - J_i z``, ``s = H_zᵀ J_iᵀ``, where the *computed* ``e``, ``s`` are used and ``σ_z``
adds ``|J_i| acc`` and their rounding ``γ_{n+1} (|t| + |J_i| |z|) + γ_n |J_i| |H_z| 1``; then
for *any* ``λ``, ``z + H_z ξ = (z + λ e) + (H_z - λ sᵀ) ξ + λ σ_z τ`` with
``τ = (sᵀξ - e)/σ_z ∈ [-1, 1]`` — an identity, so the computed ``λ`` needs no error bound; the
rounding of ``z + λ e``, ``H_z - λ sᵀ`` and ``σ_z λ`` (``γ_3`` times the sums of the absolute
terms) is added to ``acc``. (v) Prediction: with ``ζ = z + H_z ξ + ε``,
``f(ζ) ∈ f0 + J (z - c) + J H_z ξ + J ε ± ρ``; the computed ``fl(f0 + J fl(z - c))`` and
``fl(J H_z)`` differ from the exact ones by at most ``2 γ_{n+3} (|f0| + |J| (|z - c| + |H_z| 1))``
and ``|J ε| <= |J| acc (1 + γ_{n+1})``; these and ``ρ`` form the box appended as generators
(their sum rounded up by ``1 + γ_4``), plus the library's data margin ``ROUNDING`` relative to
the same terms (:mod:`ivobs.estimators.rounding`), and ``ROUNDING (1 + |y_i|)`` is added to
each ``σ_i``: a record simulated in float64 (every step rounded) is covered as with the linear
methods. (vi) The reduction returns a superset with its rounding
in ``e`` (:func:`ivobs.czonotope.reduce_generators`). The base class then widens every
returned bound by ``ROUNDING (1 + |bound|)``: the data margin is in the recursion, relative to
the terms it combines, not to the largest bound of ``w`` (a parameter ``k0 ~ 7e10`` would
otherwise widen every bound by ``~7``; :class:`~ivobs.estimators._meanvalue.TermwiseMargin`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from typing import Any

import numpy as np

from .._validate import as_int
from ..errors import IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..sets import Box
from ..sets.czonotope import (
    UNIT_ROUNDOFF,
    gamma,
    mid_rad,
    reduce_generators,
)
from . import register
from ._meanvalue import TermwiseMargin, contract_back_lists, linearise_lists
from ._strip_hull import _add, propagate_lists, section_hull
from .base import ROUNDING, Design, Estimator, check_size
from .state import OnlineState, Step

__all__ = ["NonlinearZonotopeDesign", "NonlinearZonotopeEstimator", "NonlinearZonotopeState"]

_any = np.logical_or.reduce
_g = cache(gamma)  # γ_n of the few sizes of one model, looked up every step

BOX_STRIP_RATIO = 0.9
"""A box strip is applied to ``Z`` where the stored box is narrower than this fraction of the
zonotope's hull (a strip that barely cuts costs a generator and gains nothing)."""


@dataclass(frozen=True)
class NonlinearZonotopeDesign(Design):
    """``order``: generators kept by the reduction; ``box_strips``: whether the natural
    inclusion box cuts the zonotope (step 1 of the module docstring)."""

    order: int
    box_strips: bool


@dataclass(frozen=True)
class NonlinearZonotopeState(OnlineState):
    """``ζ = (x, w) ∈ <z, Hz> ⊕ box(acc)`` and ``ζ ∈ [lo, hi]``: the joint set of the last
    step after its measurement update (``back=True``; ``u``: its input), or at step 0 the prior
    ``x0 × W`` (``back=False``). The prediction to the next step is done in the next step, once
    its measurement has contracted ``[lo, hi]`` one step back (step 0 of the module docstring)."""

    z: np.ndarray
    Hz: np.ndarray
    acc: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    u: np.ndarray
    back: bool = False

    bounds = (("lo", "hi"),)


_UP2 = 1.0 + 2.0 * UNIT_ROUNDOFF


@dataclass
class _Joint:
    """``ζ = (x_k, w_k) ∈ <z, Hz> ⊕ box(acc)`` and ``ζ ∈ [lo, hi]`` during one step (the box
    as lists: it is worked on one scalar at a time, by the contractors and the linearisations).
    The lists are replaced, never changed in place (a saved ``_Joint`` shares them)."""

    z: np.ndarray
    Hz: np.ndarray
    acc: np.ndarray
    lo: list[float]
    hi: list[float]

    def strip(self, h: np.ndarray, t: float, sigma: float, nx: int) -> bool:
        """Intersect with ``|hᵀζ - t| <= σ`` (σ already holds the true ``ζ``): the F-radius
        section of [Alamo2005] on the zonotope, the exact contractions on the box (step (iv)
        of the proof). False when the strip certainly misses the set (nothing changed)."""
        z, Hz, acc = self.z, self.Hz, self.acc
        n = z.shape[0]
        ah = np.abs(h)
        s = h @ Hz
        rs = _add(np.abs(Hz), axis=1)  # ‖Hz_j‖₁, for σ_z, the section hull and acc
        e = float(t - h @ z)
        az = np.abs(z)
        sigma_z = (
            sigma + float(ah @ acc) + _g(n + 1) * (abs(t) + float(ah @ az)) + _g(n) * float(ah @ rs)
        ) * (1.0 + _g(n + 4))
        s1 = float(_add(np.abs(s)))
        if abs(e) > (s1 + sigma_z) * (1.0 + _g(s.size + 2)):
            return False
        contracted = propagate_lists(h.tolist(), t, self.lo, self.hi, sigma)
        if contracted is None:
            return False
        lo, hi = contracted
        lo_j, hi_j = section_hull(z[:nx], Hz[:nx], s, e, sigma_z, rs[:nx])
        for j, a, p, q in zip(range(nx), acc.tolist(), lo_j.tolist(), hi_j.tolist()):
            pad = a * _UP2
            lo[j] = max(lo[j], p - pad)
            hi[j] = min(hi[j], q + pad)
            if lo[j] > hi[j]:
                return False
        self.lo, self.hi = lo, hi
        den = float(s @ s) + sigma_z * sigma_z
        if s1 == 0.0 or not den > 0.0:
            return True
        lam = Hz @ s / den
        self.acc = acc + _g(3) * (az + rs + np.abs(lam) * (abs(e) + s1 + sigma_z))
        self.z = z + lam * e
        out = np.empty((n, s.shape[0] + 1))
        body = out[:, :-1]
        np.multiply(lam[:, None], s, out=body)  # the outer product λ sᵀ
        np.subtract(Hz, body, out=body)
        out[:, -1] = sigma_z * lam
        self.Hz = out
        return True


@register
class NonlinearZonotopeEstimator(TermwiseMargin, Estimator):
    """Zonotopic filter for nonlinear systems: mean-value linearisation with the remainder as
    box generators, strips of the linearised outputs [Alamo2005], order reduction.

    Uses ``u[0..k]`` and ``y[0..k]`` (the box of ``x[k]`` is filtered with ``y[k]``). Needs the
    prior box ``x0``. Per step: two interval Jacobians, ``ny`` closed-form intersections, one
    order reduction; no optimisation.

    Parameters
    ----------
    sys : NonlinearSystem (discrete time), or a time-invariant LinearSystem (converted)
    x0 : Box, the prior box on ``x[0]``
    order : int, optional
        Generators kept by the reduction (default ``10 nx``, as ``strip``; at least ``nx``);
        the set is reduced when it holds more than ``1.5 order``.
    box_strips : bool
        Cut the zonotope with the natural-inclusion box where it is tighter (default False:
        on the six-tank benchmark the extra generators cost more than the cut gains).
    """

    name = "nl-zonotope"
    order = 910
    summary = "nonlinear zonotopic filter: mean-value linearisation, strips"
    reference = "[Alamo2005]; [Althoff2008]; [Rego2020]"
    data_used = "filter"
    supports_nonlinear = True
    needs_x0 = True
    design: NonlinearZonotopeDesign

    def __init__(
        self,
        sys: Any,
        x0: Box | None = None,
        *,
        order: int | None = None,
        box_strips: bool = False,
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        # a linear model is converted; self.sys stays the model given (the monitor reads it)
        if isinstance(sys, LinearSystem):
            sys = NonlinearSystem.from_linear(sys, who=self.name)
        self.model: NonlinearSystem = sys
        check_size(self.name, sys.nx, "multiplies and reduces a dense nx x q generator matrix")
        q = 10 * sys.nx if order is None else as_int("order", order, 1)
        if q < sys.nx:
            raise IvobsError(
                f"order: the reduction keeps at least nx = {sys.nx} generators, got {q}"
            )
        if not isinstance(box_strips, bool):
            raise IvobsError(f"box_strips: expected True or False, got {box_strips!r}")
        self.design = NonlinearZonotopeDesign(order=q, box_strips=box_strips)
        cw, rw = mid_rad(sys.w_box.lo, sys.w_box.hi)
        self._cw, self._rw = cw, rw
        self._wcols = np.flatnonzero(rw > 0)
        self._wblock = np.diag(rw)[:, self._wcols]
        self._zw = np.zeros(cw.shape[0])
        self._wlo, self._whi = sys.w_box.lo.tolist(), sys.w_box.hi.tolist()
        self._hf = bool(sys.ny) and hasattr(sys, "hf_contractors")

    # -- online ---------------------------------------------------------------------------------
    def _initial_state(self) -> NonlinearZonotopeState:
        assert self.x0 is not None
        p, r = mid_rad(self.x0.lo, self.x0.hi)
        x0lo, x0hi = self.x0.lo.tolist(), self.x0.hi.tolist()
        j = self._joint(p, np.diag(r)[:, r > 0], np.zeros(self.model.nx), x0lo, x0hi)
        nu = self.model.nu
        return NonlinearZonotopeState(
            z=j.z,
            Hz=j.Hz,
            acc=j.acc,
            lo=np.array(j.lo),
            hi=np.array(j.hi),
            u=np.zeros(nu),
            back=False,
        )

    def _step(
        self, state: NonlinearZonotopeState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[NonlinearZonotopeState]:
        nx = self.model.nx
        inconsistent = False
        yl = y_k.tolist()
        lo, hi = state.lo.tolist(), state.hi.tolist()
        if state.back:
            prev = _Joint(z=state.z, Hz=state.Hz, acc=state.acc, lo=lo, hi=hi)
            wlo, whi = self._wlo, self._whi
            if self._hf and not all(v != v for v in yl):
                back = contract_back_lists(self.model, lo, hi, state.u, u_k, wlo, whi, y_k)
                if back is None:
                    inconsistent = True
                else:
                    prev.lo, prev.hi, wlo, whi = back
            p, H, e, plo, phi = self._predict(state.k, prev, state.u)
            joint = self._joint(p, H, e, plo, phi, wlo, whi)
        else:
            joint = _Joint(z=state.z, Hz=state.Hz, acc=state.acc, lo=lo, hi=hi)
        if self.design.box_strips and state.back:
            self._box_strips(joint, np.array(plo), np.array(phi))
        if not inconsistent:
            saved = _Joint(joint.z, joint.Hz, joint.acc, joint.lo, joint.hi)  # never mutated
            inconsistent = not self._update(joint, u_k, yl)
            if inconsistent:  # y_k contradicts the model: not used (the strips before undone)
                joint = saved
        acc = joint.acc * (1.0 + _g(len(yl) + 4))  # rounding of acc's sums
        Hz = joint.Hz if joint.Hz.flags.c_contiguous else np.ascontiguousarray(joint.Hz)
        new = NonlinearZonotopeState(
            k=state.k,
            scale=state.scale,
            inconsistent=state.inconsistent,
            z=joint.z,
            Hz=Hz,
            acc=acc,
            lo=np.array(joint.lo),
            hi=np.array(joint.hi),
            u=u_k.copy(),
            back=True,
        )
        return Step(new, np.array(joint.lo[:nx]), np.array(joint.hi[:nx]), inconsistent)

    def _joint(
        self,
        p: np.ndarray,
        H: np.ndarray,
        e: np.ndarray,
        xlo: list[float],
        xhi: list[float],
        wlo: list[float] | None = None,
        whi: list[float] | None = None,
    ) -> _Joint:
        """The joint zonotope of ``(x_k, w_k)`` from ``x_k ∈ <p, H> ⊕ box(e)``, ``x_k ∈ [xlo,
        xhi]`` and ``w_k ∈ [wlo, whi] ⊆ W`` (default ``W``), and its box (step (i) of the
        proof)."""
        nx = self.model.nx
        m = H.shape[1]
        Hz = np.zeros((nx + self._cw.shape[0], m + self._wcols.size))
        Hz[:nx, :m] = H
        Hz[nx:, m:] = self._wblock  # diag(R_w) of the uncertain w (zero columns dropped)
        g, g2 = _g(m + 2), 1.0 + _g(2)
        r0 = _add(np.abs(H), axis=1).tolist()
        hull_lo, hull_hi = [], []
        for pi, ri, ei in zip(p.tolist(), r0, e.tolist()):
            rad = ri + g * (abs(pi) + ri) + ei * g2
            hull_lo.append(pi - rad)
            hull_hi.append(pi + rad)
        lo = [max(a, b) for a, b in zip(xlo, hull_lo)]
        hi = [min(a, b) for a, b in zip(xhi, hull_hi)]
        if any(a > b for a, b in zip(lo, hi)):  # only by rounding (both hold the state)
            lo, hi = hull_lo, hull_hi  # keep the hull
        return _Joint(
            z=np.concatenate([p, self._cw]),
            Hz=Hz,
            acc=np.concatenate([e, self._zw]),
            lo=lo + (self._wlo if wlo is None else wlo),
            hi=hi + (self._whi if whi is None else whi),
        )

    def _box_strips(self, joint: _Joint, lo: np.ndarray, hi: np.ndarray) -> None:
        """Cut ``Z`` by ``|x_j - mid_j| <= rad_j`` where the box ``[lo, hi]`` is tighter
        (step 1)."""
        nx = self.model.nx
        hull = np.abs(joint.Hz[:nx]).sum(axis=1) + joint.acc[:nx]
        m, r = mid_rad(lo, hi)
        for j in np.flatnonzero(r < BOX_STRIP_RATIO * hull):
            h = np.zeros(joint.z.shape[0])
            h[j] = 1.0
            joint.strip(h, float(m[j]), float(r[j]), nx)

    def _update(self, joint: _Joint, u_k: np.ndarray, yl: list[float]) -> bool:
        """Strips of the linearised measured outputs (steps 2 and (iii)); False when ``y_k``
        certainly contradicts the model (the set is then predicted without the rest of it)."""
        obs = [i for i, v in enumerate(yl) if v == v]
        if not obs:
            return True
        nx = self.model.nx
        # the model's forward-backward contractor of h(x, u, w) = y on the box first: a
        # smaller box, a smaller remainder of the linearised h
        vl, vh = list(joint.lo), list(joint.hi)
        if not self.model.contract_lists(vl, vh, u_k.tolist(), yl, yl):
            return False
        joint.lo, joint.hi = vl, vh
        lin = linearise_lists(self.model.evaluators("h"), vl, vh, joint.z, u_k, nx, False)
        n = joint.z.shape[0]
        mag = (np.abs(lin.J) @ np.abs(lin.c)).tolist()
        g0s, rhos = lin.g0, lin.rho
        for i in obs:
            Ji, yi, h0 = lin.J[i], yl[i], g0s[i]
            t = yi - h0 + float(Ji @ lin.c)
            err = _g(n + 3) * (abs(yi) + abs(h0) + mag[i])
            err += ROUNDING * (1.0 + abs(yi))  # the data margin of a float64 record
            sigma = (rhos[i] + err) * (1.0 + _g(2))
            if not joint.strip(Ji, t, sigma, nx):
                return False
        return True

    def _predict(
        self, k: int, joint: _Joint, u_k: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[float], list[float]]:
        """``(p, H, e, lo, hi)`` of ``x[k+1]`` (steps 4-5 and (v)-(vi) of the proof)."""
        nx = self.model.nx
        z, Hz, acc = joint.z, joint.Hz, joint.acc
        lin = linearise_lists(self.model.evaluators("f"), joint.lo, joint.hi, z, u_k, nx)
        J, aJ = lin.J, np.abs(lin.J)
        d = z - lin.c
        p = np.array(lin.g0) + J @ d
        JH = J @ Hz
        n = z.shape[0]
        # + the data margin of a float64 simulation of f, relative to its terms over the set
        # (TermwiseMargin); the products by |J| as arrays (as BLAS sums them), the rest on
        # floats in the order of the expression
        terms = (aJ @ (np.abs(d) + _add(np.abs(Hz), axis=1))).tolist()
        accs = (aJ @ acc).tolist()
        c1, c2, c3 = 2.0 * _g(n + 3) + ROUNDING, 1.0 + _g(n + 1), 1.0 + _g(4)
        err = [
            ((c1 * (1.0 + abs(g) + a) + b * c2) + r) * c3
            for g, a, b, r in zip(lin.g0, terms, accs, lin.rho)
        ]
        cols = _any(JH, axis=0)  # drop zero columns (unknowns that f does not see)
        if not cols.all():
            JH = JH[:, cols]
        # H = [JH, diag(err)] (the nonzero entries of err as columns): box_generators, in one
        # array
        m = JH.shape[1]
        rows = [i for i, v in enumerate(err) if v > 0]
        H = np.zeros((nx, m + len(rows)))
        H[:, :m] = JH
        if len(rows) == nx:  # the whole diagonal: H[i, m + i], a strided slice of H's buffer
            H.ravel()[m :: m + nx + 1] = err
        else:
            H[rows, range(m, m + len(rows))] = [err[i] for i in rows]
        # one sum is finite only if every term is (else the full check)
        if not math.isfinite(float(_add(H, axis=None)) + sum(p.tolist())):
            self._check_overflow(k, p, H)
        nlo, nhi = lin.nat_lo, lin.nat_hi
        q = self.design.order
        if H.shape[1] <= q + q // 2:  # reduce in batches: a QR every few steps, not every step
            return p, H, np.zeros(nx), nlo, nhi
        none = np.zeros((0, H.shape[1]))
        out = reduce_generators(p, H, none, np.zeros(0), q, True)
        return out[0], np.ascontiguousarray(out[1]), out[4], nlo, nhi
