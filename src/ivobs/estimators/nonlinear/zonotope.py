"""Zonotopic filter for nonlinear systems by conservative linearisation, with strips.

For ``x[k+1] = f(x, u, w)``, ``y[k] = h(x, u, w)`` (a :class:`~ivobs.NonlinearSystem`; ``w``:
the uncertain parameters and bounded signals of the step, ``w ∈ W``), the filter works, like
the linear ``strip`` method, on the joint vector ``ζ = (x_k, w_k)`` (the same ``w_k`` enters
``h`` and ``f``): ``ζ ∈ Z = <z, H_z> ⊕ box(acc)`` and ``ζ ∈ B``, a box (``acc``: the rounding
errors, kept aside as a box). Between steps it keeps the joint set of the last step *after* its
measurement update; the prediction is done at the start of the next step, once that step's
measurement is known.

0. **One step back.** ``y_k = h(f(x_{k-1}, u_{k-1}, w_{k-1}), u_k, w_k)`` contracts the box
   of ``ζ_{k-1}`` (:func:`~ivobs.estimators.nonlinear.meanvalue.contract_back`): when ``y_k``
   does not determine the states of step ``k`` but does those of step ``k - 1`` (Hénon with
   ``y = x2``), the box over which ``f`` is linearised stays small (without it the remainder
   grows like the square of the width and the set diverges).
1. **Prediction.** ``f`` is linearised over that box at the centre ``z`` of ``Z`` (clipped into
   the box) by the mean-value form (:mod:`~ivobs.estimators.nonlinear.meanvalue`,
   [Rego2020]; first order with the Lagrange remainder bounded by the interval Jacobian over
   the box, [Althoff2008]): ``f(ζ) ∈ f0 + J (ζ - c) ± ρ``, so
   ``x_k ∈ <p, H> = <f0 + J (z - c), [J H_z, diag(ρ + |J| acc + err)]>`` (the remainder as
   box generators), and ``x_k ∈ [lo, hi]``, the natural inclusion of ``f`` over the box
   tightened by the centred form and by monotonicity. Then the joint set of
   ``(x_k, w_k)``: ``z = (p, c_w)``, ``H_z = blkdiag(H, R_w)``, ``B = ([lo, hi] ∩ hull) × W``.
2. **Order reduction** of ``<p, H>`` to ``order`` generators (the parallelotope rule of
   [Chisci1998], :func:`ivobs.czonotope.reduce_generators`), in batches: when more than
   ``1.5 order`` generators have accumulated.
3. **Measurement update.** ``B`` is contracted by the model's forward-backward contractor of
   ``h(x, u, w) ∈ [y_k]`` (``[y_k]``: the reals the recorded double stands for,
   :func:`~ivobs.estimators.nonlinear.meanvalue.measurement`); ``h`` is linearised over ``B``,
   ``h(ζ) ∈ h0 + J (ζ - c) ± ρ``, so each measured ``y_i`` gives the strip
   ``|J_i ζ - t_i| <= σ_i``, ``t_i = y_i - h0_i + J_i c``. ``Z`` is intersected with each strip
   by the F-radius optimal section of [Alamo2005] (``λ* = H_z s / (sᵀ s + σ²)``,
   ``s = H_zᵀ J_iᵀ``), and ``B`` is contracted by the section's interval hull and by
   propagating the strip over ``B`` (the enclosures of the ``strip`` method). A measurement
   found inconsistent is reported and not used (the strips of that step undone).
4. **Box of x[k]**: the ``x`` part of ``B``.

**Rounding (proof).** Invariant: the true ``ζ_{k-1}`` is in the stored ``<z, H_z> ⊕ box(acc)``
and in the stored box, in exact arithmetic on the stored doubles. Every bound below follows the
model of :mod:`ivobs.sets.rounding` ([Higham2002, Lemma 3.1 and Section 3.1]: a dot product of
``n`` terms is within ``γ_n`` of the sum of their magnitudes, plus ``n η`` of underflow;
``product_error`` and ``upper`` carry a factor 2 on ``γ`` that absorbs their own rounding), and
each bound after a single rounded operation is moved outward by one ulp (``up``, ``down``).

(i) *Joint set.* The hull of ``<p, H> ⊕ box(e)`` is ``p ± upper(|H| 1 + e)``, rounded outward;
``W ⊆ c_w ± R_w`` exactly (:func:`~ivobs.sets.rounding.mid_rad`). (ii) *Linearisation*:
``|g(ζ) - g0 - J (ζ - c)| <= ρ`` exactly for every ``ζ ∈ B``
(:func:`~ivobs.estimators.nonlinear.meanvalue.linearise` proves its own rounding). (iii)
*Strip*: the exact measurement ``y*_i ∈ [y_i]``, ``|y*_i - y_i| <= |[y_i]|``; the computed
``t_i = fl(y_i - h0_i + J_i c)`` is within ``γ_{n+2} (|y_i| + |h0_i| + |J_i| |c|) + n η`` of
``y_i - h0_i + J_i c``, so ``σ_i = ρ_i + |y*_i - y_i| + `` that bound holds the true ``ζ``. (iv)
*Strip on Z*: the true ``ζ = z + H_z ξ + ε`` (``|ξ| <= 1``, ``|ε| <= acc``) satisfies
``|sᵀ ξ - e| <= σ_z`` with the *computed* ``s = fl(H_zᵀ h)``, ``e = fl(t - hᵀ z)``, once
``σ_z >= σ + |h| acc + γ_{n+1} (|t| + |h| |z|) + γ_n |h| |H_z| 1 + (m + 1) n η``. For *any*
``λ``, ``z + H_z ξ = (z + λ e) + (H_z - λ sᵀ) ξ + λ σ_z τ`` with ``τ = (sᵀξ - e)/σ_z ∈
[-1, 1]``: an identity, so the computed ``λ`` needs no error bound; the rounding of
``z + λ e``, ``H_z - λ sᵀ`` and ``σ_z λ`` is at most ``γ_2 (|z| + |H_z| 1 + |λ| (|e| + ‖s‖₁ +
σ_z)) + (m + 2) η``, added to ``acc``. (v) *Prediction*: with ``ζ = z + H_z ξ + ε``,
``f(ζ) ∈ f0 + J (z - c) + J H_z ξ + J ε ± ρ``; the computed ``p = fl(f0 + J fl(z - c))`` and
``fl(J H_z)`` differ from the exact ones by at most ``γ_{n+2} (|f0| + |J| |z - c|)`` and
``γ_n |J| |H_z| 1`` (plus ``(m + 1) n η``), ``|J ε| <= |J| acc``: these and ``ρ`` form the box
appended as generators. (vi) The reduction returns a superset in exact arithmetic
(:func:`ivobs.czonotope.reduce_generators`). The box enclosures of the strip (the section hull
and the propagation over ``B``) are the strip method's, which bound their own rounding. By
induction the returned box contains the true ``x[k]`` at every magnitude, and no margin is
added (``proven_rounding``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._validate import as_bool, as_int
from ...sets import Box
from ...sets.czonotope import reduce_generators
from ...sets.rounding import ETA, mid_rad, product_error, up, upper
from ...sets.strip import contract_box, section_hull
from ...sets.zonotope import box_generators
from .. import register
from ..base import Design, Estimator, check_size
from ..state import OnlineState, Step
from .meanvalue import contract_back, joint_box, linearise, measurement

__all__ = ["NonlinearZonotopeDesign", "NonlinearZonotopeEstimator", "NonlinearZonotopeState"]

_INF = math.inf
_add = np.add.reduce  # the ufunc's reduction called directly: ndarray.sum adds a Python wrapper

BOX_STRIP_RATIO = 0.9
"""A box strip (``box_strips=True``) is applied to ``Z`` where the box is narrower than this
fraction of the zonotope's hull (a strip that barely cuts costs a generator and gains
nothing)."""


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


@dataclass(frozen=True)
class _Joint:
    """``ζ = (x_k, w_k) ∈ <z, Hz> ⊕ box(acc)`` and ``ζ ∈ [lo, hi]`` during one step. The box is
    kept as lists of floats: the model's generated contractors narrow it one bound at a time."""

    z: np.ndarray
    Hz: np.ndarray
    acc: np.ndarray
    lo: list[float]
    hi: list[float]

    def strip(self, h: np.ndarray, t: float, sigma: float, nx: int) -> _Joint | None:
        """The set intersected with ``|hᵀζ - t| <= σ`` (``σ`` holds the true ``ζ``): the
        F-radius optimal section of [Alamo2005] on the zonotope, the box contracted by the
        section's hull and by propagating the strip (step (iv) of the proof). ``None`` when the
        strip certainly misses the set."""
        z, Hz, acc = self.z, self.Hz, self.acc
        n, m = Hz.shape
        ah, az = np.abs(h), np.abs(z)
        s = h @ Hz  # s = H_zᵀ h
        e = float(t - h @ z)
        rs = _add(np.abs(Hz), axis=1)  # ‖(H_z)_j‖₁
        # |sᵀξ - e| <= σ_z for the true factors ξ: the box aside, the rounding of s and e
        sigma_z = float(
            upper(
                sigma
                + ah @ acc
                + product_error(abs(t) + ah @ (az + rs), n + m + 1)
                + (m * n) * ETA,
                n + 3,
            )
        )
        s1 = float(_add(np.abs(s)))
        if abs(e) > upper(s1 + sigma_z, m + 1):  # |sᵀξ - e| > σ_z for every |ξ| <= 1
            return None
        box = np.array([self.lo, self.hi], dtype=np.float64)
        hc = np.ascontiguousarray(h, dtype=np.float64)
        if not contract_box(hc, float(t), float(sigma), box[0], box[1]):
            return None
        lo, hi = box.tolist()
        Hx = np.ascontiguousarray(Hz[:nx])  # the compiled kernel's layout
        sec_lo, sec_hi = section_hull(z[:nx], Hx, m, nx, s, e, sigma_z, rs[:nx])
        for j, a, p, q in zip(range(nx), acc.tolist(), sec_lo.tolist(), sec_hi.tolist()):
            lo[j] = max(lo[j], math.nextafter(p - a, -_INF))  # the hull plus the box aside
            hi[j] = min(hi[j], math.nextafter(q + a, _INF))
            if lo[j] > hi[j]:
                return None
        den = float(s @ s) + sigma_z * sigma_z
        if s1 == 0.0 or not den > 0.0:  # the strip does not cut the zonotope
            return _Joint(z, Hz, acc, lo, hi)
        lam = Hz @ s / den  # λ* of [Alamo2005]
        rounding = product_error(az + rs + np.abs(lam) * (abs(e) + s1 + sigma_z), m + 2)
        return _Joint(
            z=z + lam * e,
            Hz=np.concatenate((Hz - np.outer(lam, s), (sigma_z * lam)[:, None]), axis=1),
            acc=up(acc + rounding),
            lo=lo,
            hi=hi,
        )


def _state(j: _Joint, u: np.ndarray, back: bool) -> NonlinearZonotopeState:
    """The state holding the joint set ``j`` (fresh: cheaper than replace; the base sets k)."""
    Hz, lo, hi = np.ascontiguousarray(j.Hz), np.array(j.lo), np.array(j.hi)
    return NonlinearZonotopeState(z=j.z, Hz=Hz, acc=j.acc, lo=lo, hi=hi, u=u, back=back)


@register
class NonlinearZonotopeEstimator(Estimator):
    """Zonotopic filter for nonlinear systems: mean-value linearisation with the remainder as
    box generators, strips of the linearised outputs [Alamo2005], order reduction.

    Uses ``u[0..k]`` and ``y[0..k]`` (the box of ``x[k]`` is filtered with ``y[k]``). Needs the
    prior box ``x0``. Per step: two interval Jacobians, ``ny`` closed-form intersections, one
    order reduction every few steps; no optimisation.

    Parameters
    ----------
    sys : NonlinearSystem (discrete time), or a time-invariant LinearSystem (converted)
    x0 : Box, the prior box on ``x[0]``
    order : int, optional
        Generators kept by the reduction (default ``10 nx``, as ``strip``; at least ``nx``);
        the set is reduced when it holds more than ``1.5 order``. Raise it when the widths
        are far above ``nl-constrained-zonotope``'s on a model with many states (each
        generator costs time at every step); lower it for speed.
    box_strips : bool
        Also cut the zonotope with the natural-inclusion box where that box is tighter
        (default False). Worth it on strongly curved maps whose natural inclusion is sharp
        (the Hénon map: slightly tighter); on the six-tank benchmark the extra generators cost
        more than the cut gains.
    """

    name = "nl-zonotope"
    order = 910
    summary = "nonlinear zonotopic filter: mean-value linearisation, strips"
    reference = "[Alamo2005]; [Althoff2008]; [Rego2020]"
    data_used = "filter"
    supports_nonlinear = True
    needs_x0 = True
    proven_rounding = True
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
        sys = self.model  # (a linear model converted: Estimator.__init__)
        check_size(self.name, sys.nx, "multiplies and reduces a dense nx x q generator matrix")
        q = 10 * sys.nx if order is None else as_int("order", order, sys.nx)  # nx at least
        box_strips = as_bool("box_strips", box_strips)
        self.design = NonlinearZonotopeDesign(order=q, box_strips=box_strips)
        w = sys.w_box
        self._cw, rw = mid_rad(w.lo, w.hi)  # W ⊆ <c_w, diag(R_w)>
        self._Rw = box_generators(rw)
        self._wlo, self._whi = w.lo.tolist(), w.hi.tolist()

    # -- online ---------------------------------------------------------------------------------
    def _initial_state(self) -> NonlinearZonotopeState:
        assert self.x0 is not None
        p, r = mid_rad(self.x0.lo, self.x0.hi)  # x0 ⊆ <p, diag(r)>
        nx = self.model.nx
        j = self._joint(p, box_generators(r), np.zeros(nx), self.x0.lo, self.x0.hi)
        return _state(j, np.zeros(self.model.nu), back=False)

    def _step(
        self, state: NonlinearZonotopeState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[NonlinearZonotopeState]:
        nx = self.model.nx
        inconsistent = False
        measured = not np.isnan(y_k).all()
        prev = _Joint(state.z, state.Hz, state.acc, state.lo.tolist(), state.hi.tolist())
        if state.back:
            wlo, whi = self._wlo, self._whi
            back = contract_back(self.model, prev.lo, prev.hi, state.u, u_k, wlo, whi, y_k)
            inconsistent = back is None  # 0. one step back through h∘f
            if back is not None:
                lo, hi, wlo, whi = (v.tolist() for v in back)
                prev = _Joint(prev.z, prev.Hz, prev.acc, lo, hi)
            joint = self._predict(state.k, prev, state.u, wlo, whi)  # 1.-2.
        else:
            joint = prev
        if measured and not inconsistent:  # 3. measurement update
            updated = self._update(joint, u_k, y_k)
            if updated is None:  # y_k contradicts the model: not used
                inconsistent = True
            else:
                joint = updated
        new = _state(joint, u_k.copy(), back=True)
        return Step(new, new.lo[:nx].copy(), new.hi[:nx].copy(), inconsistent)  # 4.

    def _predict(
        self, k: int, prev: _Joint, u: np.ndarray, wlo: list[float], whi: list[float]
    ) -> _Joint:
        """The joint set of ``(x_{k+1}, w_{k+1})`` from that of ``(x_k, w_k)`` (steps 1-2 and
        (v)-(vi) of the proof), ``w_{k+1} ∈ [wlo, whi]``."""
        nx = self.model.nx
        z, Hz = prev.z, prev.Hz
        n, m = Hz.shape
        lin = linearise(self.model.evaluators("f"), prev.lo, prev.hi, z, u, nx)
        J, aJ = lin.J, np.abs(lin.J)
        d = z - lin.c
        p = lin.g0 + J @ d  # f0 + J (z - c)
        JH = J @ Hz
        seen = JH.any(axis=0)
        if not seen.all():  # the unknowns that f does not see: no generator
            JH = JH[:, seen]
        rs = _add(np.abs(Hz), axis=1)
        err = upper(  # ρ + |J| acc + the rounding of p and J H_z
            lin.rho
            + aJ @ prev.acc
            + product_error(np.abs(lin.g0) + aJ @ (np.abs(d) + rs), n + m + 1)
            + (m * n) * ETA,
            n + 3,
        )
        H = np.concatenate((JH, box_generators(err)), axis=1)
        if not math.isfinite(float(_add(H, axis=None)) + float(_add(p))):  # (else all finite)
            self._check_overflow(k, p, H)
        q = self.design.order
        if H.shape[1] > q + q // 2:  # reduce in batches: a QR every few steps, not every step
            p, H = reduce_generators(p, H, np.zeros((0, H.shape[1])), np.zeros(0), q)[:2]
        joint = self._joint(p, H, np.zeros(nx), lin.nat_lo, lin.nat_hi, wlo, whi)
        if self.design.box_strips:
            joint = self._box_strips(joint, lin.nat_lo, lin.nat_hi)
        return joint

    def _joint(
        self,
        p: np.ndarray,
        H: np.ndarray,
        e: np.ndarray,
        xlo: np.ndarray,
        xhi: np.ndarray,
        wlo: list[float] | None = None,
        whi: list[float] | None = None,
    ) -> _Joint:
        """The joint set of ``(x_k, w_k)`` from ``x_k ∈ <p, H> ⊕ box(e)``, ``x_k ∈ [xlo, xhi]``
        and ``w_k ∈ [wlo, whi] ⊆ W`` (default ``W``), and its box (step (i) of the proof)."""
        nx, m = H.shape
        Hz = np.zeros((nx + self._cw.shape[0], m + self._Rw.shape[1]))
        Hz[:nx, :m] = H
        Hz[nx:, m:] = self._Rw
        lo, hi = joint_box(p, H, e, xlo, xhi)
        return _Joint(
            z=np.concatenate([p, self._cw]),
            Hz=Hz,
            acc=np.concatenate([e, np.zeros(self._cw.shape[0])]),
            lo=lo.tolist() + (self._wlo if wlo is None else wlo),
            hi=hi.tolist() + (self._whi if whi is None else whi),
        )

    def _box_strips(self, joint: _Joint, lo: np.ndarray, hi: np.ndarray) -> _Joint:
        """``Z`` cut by ``|x_j - mid_j| <= rad_j`` where the box ``[lo, hi]`` is tighter than
        the hull of ``Z`` (option ``box_strips``)."""
        nx = self.model.nx
        hull = _add(np.abs(joint.Hz[:nx]), axis=1) + joint.acc[:nx]
        mid, rad = mid_rad(lo, hi)
        for j in np.flatnonzero(rad < BOX_STRIP_RATIO * hull).tolist():
            h = np.zeros(joint.z.shape[0])
            h[j] = 1.0
            cut = joint.strip(h, float(mid[j]), float(rad[j]), nx)
            if cut is not None:  # (never None: the box holds the state)
                joint = cut
        return joint

    def _update(self, joint: _Joint, u_k: np.ndarray, y_k: np.ndarray) -> _Joint | None:
        """The joint set intersected with the strips of the linearised measured outputs
        (step 3 and (iii) of the proof); ``None`` when ``y_k`` certainly contradicts the
        model."""
        nx = self.model.nx
        ylo, yhi = measurement(y_k)
        # the model's forward-backward contractor of h(x, u, w) ∈ [y] on the box first: a
        # smaller box, a smaller remainder of the linearised h
        vl, vh = list(joint.lo), list(joint.hi)
        if not self.model.contract_lists(vl, vh, u_k.tolist(), ylo, yhi):
            return None
        joint = _Joint(joint.z, joint.Hz, joint.acc, vl, vh)
        lin = linearise(self.model.evaluators("h"), vl, vh, joint.z, u_k, nx, False)
        n = lin.c.shape[0]
        Jc, mag_Jc = (lin.J @ lin.c).tolist(), (np.abs(lin.J) @ np.abs(lin.c)).tolist()
        g0, rho = lin.g0.tolist(), lin.rho.tolist()
        for i, y in enumerate(y_k.tolist()):
            if y != y:  # missing
                continue
            t = y - g0[i] + Jc[i]  # y - h0 + J c, and its rounding
            spread = max(yhi[i] - y, y - ylo[i])  # |y* - y| (exact: neighbouring doubles)
            err = product_error(abs(y) + abs(g0[i]) + mag_Jc[i], n + 2)
            cut = joint.strip(lin.J[i], t, upper(rho[i] + spread + err, 2), nx)
            if cut is None:
                return None
            joint = cut
        return joint
