"""Constrained-zonotope filter for nonlinear systems: the mean-value extension of [Rego2020].

For ``x[k+1] = f(x, u, w)``, ``y[k] = h(x, u, w)`` (a :class:`~ivobs.NonlinearSystem`, ``w ∈ W``
the uncertain parameters and bounded signals of the step), the filter keeps
``x[k] ∈ X_k = <c, G, A, b> ⊕ box(e)`` ([Scott2016, Definition 3]) and a box ``[lo, hi]`` of
``x[k]``, and works on the joint vector ``ζ = (x_k, w_k)`` (the same ``w_k`` enters ``h`` and
``f``): ``ζ ∈ Z = <(c, c_w), blkdiag(G, R_w), [A 0], b> ⊕ box(e, 0)``, ``ζ ∈ B``.

Between steps the filter keeps the joint set of the last step after its measurement update;
the prediction is done at the start of the next step, after that step's measurement has
contracted the box of ``ζ_{k-1}`` one step back through ``h ∘ f`` (step 0 of
:mod:`ivobs.estimators.nl_zonotope`); the measurement update first contracts ``B`` with the
model's forward-backward contractor of ``h = y_k``.

* **Measurement update** ([Rego2020], with the mean-value extension of ``h``,
  [Rego2020]): over ``B``, ``h(ζ) ∈ h0 + J (ζ - c̄) ± ρ``
  (:mod:`ivobs.estimators.nonlinear.meanvalue`); each measured ``y_i`` adds the constraint

      J_i G_z ξ + σ_i τ_i = y_i - h0_i + J_i c̄ - J_i z,        τ_i ∈ [-1, 1]

  (the generalised intersection of [Scott2016, Proposition 1] with the strip; ``σ_i``: the
  remainder ``ρ_i``, the box aside ``|J_i| e`` and the rounding of the row and the right-hand
  side). The box of ``x[k]`` is the certified LP hull of the ``x`` part
  (:func:`ivobs.czonotope.hull_certificates`) intersected with ``B``.
* **Prediction** (the mean-value extension for constrained zonotopes, [Rego2020]):
  over the filtered box ``B'`` at its centre ``c̄``,
  ``f(Z) ⊆ f0 + J (z - c̄) + J G_z ξ ⊕ box(ρ)``, i.e.
  ``X_{k+1} = <f0 + J (z - c̄), [J G_z, diag(ρ + |J| e + err)], A_z, b_z>`` (the same factors
  and constraints: the linear part keeps the correlations the constraints carry), and
  ``[lo, hi]`` of ``x[k+1]`` is the natural inclusion of ``f`` over ``B'`` tightened by
  monotonicity.
* **Reduction** [Scott2016, Section 4]: constraint elimination and generator reduction
  (:func:`ivobs.czonotope.eliminate_constraints`, :func:`ivobs.czonotope.reduce_generators`).

**Soundness under rounding (proof).** Every floating-point error of the recursion is bounded where
it occurs (``proven_rounding``: the base class adds no margin). The linearisation bounds its own
rounding (:mod:`.meanvalue`); a measured row is computed in floating point, and for the true factors
``ξ`` the computed row satisfies ``|fl(J_i G_z) ξ - fl(t_i - J_i z)| <= σ_i``, ``σ_i`` including
``γ_n |J_i| |G_z| 1`` and ``γ_{n+1} (|t_i| + |J_i| |z|)`` (the errors of the row and of the
right-hand side, [Higham2002, Section 3.1]) besides ``ρ_i + |t̃_i - t_i|`` and ``|J_i| e``, the sum
enlarged by ``(1 + γ_{n+6})`` for its own rounding; the row is then scaled by a power of two
(exact). The hull bounds are proven by weak duality at the solver's multipliers
(:func:`ivobs.czonotope.hull_certificates`), then ``∓ e``, rounded outward. The prediction's box of
generators holds the rounding of ``f0 + J (z - c̄)`` and ``J G_z`` and the image of the box aside;
the reduction returns supersets, its own rounding included, and the rounding of the re-centring goes
to ``e``. A float64 record of the model is covered by data margins in the recursion, relative to the
terms of ``f`` and ``h`` (``RECORD_MARGIN (1 + |f0| + |J| (|z - c| + |G_z| 1))`` in the prediction's
box, ``RECORD_MARGIN (1 + |y_i|)`` in each measured row).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._validate import as_int
from ...sets import Box
from ...sets.czonotope import (
    eliminate_constraints,
    gamma,
    hull_certificates,
    mid_rad,
    reduce_consolidated,
    soften,
)
from ...sets.rounding import UNIT_ROUNDOFF, down, up
from .. import register
from ..base import Design, Estimator, check_size
from ..constrained_zonotope import TOLS, default_limits
from ..state import OnlineState, Step
from .meanvalue import Linearisation, contract_back, joint_box, linearise, measurement

__all__ = [
    "NonlinearConstrainedZonotopeDesign",
    "NonlinearConstrainedZonotopeEstimator",
    "NonlinearConstrainedZonotopeState",
]

RECORD_MARGIN = 1e-10
"""Relative allowance for a record of the model computed in float64 (a simulation whose state
differs from the exact model's by its own rounding): added to the prediction's box and to each
measured row, relative to the terms involved."""


@dataclass(frozen=True)
class NonlinearConstrainedZonotopeDesign(Design):
    """Complexity limits kept between steps: ``max_constraints`` (``n_c``) and
    ``max_generators`` (``n_g``) [Scott2016, Section 4]."""

    max_constraints: int
    max_generators: int


@dataclass(frozen=True)
class NonlinearConstrainedZonotopeState(OnlineState):
    """``ζ = (x, w) ∈ <z, Gz, A, b> ⊕ box(acc)`` and ``ζ ∈ [lo, hi]``: the joint set of the
    last step after its measurement update (``back=True``; ``u``: its input), or at step 0 the
    prior ``x0 × W`` (``back=False``); the prediction is done in the next step, after its
    measurement contracted ``[lo, hi]`` one step back."""

    z: np.ndarray
    Gz: np.ndarray
    A: np.ndarray
    b: np.ndarray
    acc: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    u: np.ndarray
    back: bool = False

    bounds = (("lo", "hi"),)


@dataclass
class _Joint:
    """``ζ = (x_k, w_k) ∈ <z, Gz, A, b> ⊕ box(acc)`` and ``ζ ∈ [lo, hi]`` during one step."""

    z: np.ndarray
    Gz: np.ndarray
    A: np.ndarray
    b: np.ndarray
    acc: np.ndarray
    lo: np.ndarray
    hi: np.ndarray


def _pad(M: np.ndarray, rows: int, cols: int) -> np.ndarray:
    """``[[M, 0], [0, 0]]`` of shape ``(rows, cols)``, C-ordered (what ``np.hstack`` /
    ``np.vstack`` with zero blocks give, filled in place: cheaper than the stacks here)."""
    out = np.zeros((rows, cols))
    out[: M.shape[0], : M.shape[1]] = M
    return out


@register
class NonlinearConstrainedZonotopeEstimator(Estimator):
    """Constrained-zonotope filter for nonlinear systems: the mean-value extension of
    [Rego2020] for prediction and measurement update, reduction of [Scott2016].

    Uses ``u[0..k]`` and ``y[0..k]`` (the box of ``x[k]`` is filtered with ``y[k]``). Needs the
    prior box ``x0``. Per step: two interval Jacobians and ``2 nx`` linear programs.

    Parameters
    ----------
    sys : NonlinearSystem (discrete time), or a time-invariant LinearSystem (converted)
    x0 : Box, the prior box on ``x[0]``
    max_constraints, max_generators : int, optional
        Complexity kept between steps (defaults ``2 nx`` and ``16 nx``, as the linear
        ``constrained-zonotope`` method).
    """

    name = "nl-constrained-zonotope"
    order = 920
    summary = "nonlinear constrained-zonotope filter: mean-value extension, hull by LP"
    reference = "[Rego2020]; [Scott2016, Sections 4-5]"
    data_used = "filter"
    supports_nonlinear = True
    needs_x0 = True
    proven_rounding = True  # see "Soundness under rounding" in the module docstring
    design: NonlinearConstrainedZonotopeDesign

    def __init__(
        self,
        sys: Any,
        x0: Box | None = None,
        *,
        max_constraints: int | None = None,
        max_generators: int | None = None,
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        sys = self.model  # (a linear model converted: Estimator.__init__)
        check_size(self.name, sys.nx, "reduces a constrained zonotope and solves 2 nx LPs")
        nc_def, ng_def = default_limits(sys.nx)
        nc = nc_def if max_constraints is None else as_int("max_constraints", max_constraints, 0)
        ng = ng_def if max_generators is None else as_int("max_generators", max_generators, 1)
        self.design = NonlinearConstrainedZonotopeDesign(max_constraints=nc, max_generators=ng)
        self._cw, self._rw = mid_rad(sys.w_box.lo, sys.w_box.hi)
        self._wcols = np.flatnonzero(self._rw > 0)

    # -- online ---------------------------------------------------------------------------------
    def _initial_state(self) -> NonlinearConstrainedZonotopeState:
        assert self.x0 is not None
        c, r = mid_rad(self.x0.lo, self.x0.hi)
        G = np.diag(r)[:, r > 0]
        j = self._joint(
            c,
            G,
            np.zeros((0, G.shape[1])),
            np.zeros(0),
            np.zeros(c.shape[0]),
            self.x0.lo,
            self.x0.hi,
        )
        return NonlinearConstrainedZonotopeState(u=np.zeros(self.model.nu), **vars(j))

    def _step(
        self,
        state: NonlinearConstrainedZonotopeState,
        u_k: np.ndarray,
        y_k: np.ndarray,
        t_k: float | None,
    ) -> Step[NonlinearConstrainedZonotopeState]:
        nx = self.model.nx
        inconsistent = False
        prev = _Joint(
            state.z, state.Gz, state.A, state.b, state.acc, state.lo.copy(), state.hi.copy()
        )
        if state.back:
            wlo, whi = self.model.w_box.lo, self.model.w_box.hi
            back = contract_back(self.model, prev.lo, prev.hi, state.u, u_k, wlo, whi, y_k)
            inconsistent = back is None
            if back is not None:
                prev.lo, prev.hi, wlo, whi = back
            lin = linearise(self.model.evaluators("f"), prev.lo, prev.hi, prev.z, state.u, nx)
            c, G, A, b, e = self._predict(state.k, prev, lin)
            joint = self._joint(c, G, A, b, e, lin.nat_lo, lin.nat_hi, wlo, whi)
        else:
            joint = prev
        if not inconsistent:
            inconsistent = not self._update(joint, u_k, y_k)
        else:
            self._update(joint, u_k, np.full_like(y_k, np.nan))
        lo, hi = joint.lo[:nx].copy(), joint.hi[:nx].copy()
        joint.Gz, joint.A = np.ascontiguousarray(joint.Gz), np.ascontiguousarray(joint.A)
        # not dataclasses.replace (10x cheaper); the base sets the counters
        new = NonlinearConstrainedZonotopeState(u=u_k.copy(), back=True, **vars(joint))
        return Step(new, lo, hi, inconsistent)

    def _joint(
        self,
        c: np.ndarray,
        G: np.ndarray,
        A: np.ndarray,
        b: np.ndarray,
        e: np.ndarray,
        xlo: np.ndarray,
        xhi: np.ndarray,
        wlo: np.ndarray | None = None,
        whi: np.ndarray | None = None,
    ) -> _Joint:
        """The joint set of ``(x_k, w_k)`` from ``x_k ∈ <c, G, A, b> ⊕ box(e)``, ``x_k ∈ [xlo,
        xhi]`` and ``w_k ∈ [wlo, whi] ⊆ W`` (default ``W``)."""
        nx = self.model.nx
        cols = self._wcols
        m = G.shape[1]
        Gz = np.zeros((nx + self._cw.shape[0], m + cols.size))
        Gz[:nx, :m] = G
        Gz[nx + cols, m + np.arange(cols.size)] = self._rw[cols]
        Az = _pad(A, A.shape[0], m + cols.size)  # [A 0]
        lo, hi = joint_box(c, G, e, xlo, xhi)
        wlo = self.model.w_box.lo if wlo is None else wlo
        whi = self.model.w_box.hi if whi is None else whi
        return _Joint(
            np.concatenate([c, self._cw]),
            Gz,
            Az,
            b.copy(),
            np.concatenate([e, np.zeros(self._cw.shape[0])]),
            np.concatenate([lo, wlo]),
            np.concatenate([hi, whi]),
        )

    def _update(self, joint: _Joint, u_k: np.ndarray, y_k: np.ndarray) -> bool:
        """Constraints of the linearised measured outputs, then the certified hull of ``x``;
        False when ``y_k`` certainly contradicts the set (then not used)."""
        nx = self.model.nx
        obs = np.flatnonzero(~np.isnan(y_k))
        rows = rhs = None
        inconsistent = False
        lo0, hi0 = joint.lo, joint.hi  # restored if y_k is found inconsistent (not used)
        if obs.size:
            # the model's forward-backward contractor of h(x, u, w) ∈ [y] on the box first,
            # [y] the reals the recorded doubles stand for (meanvalue.measurement)
            vl, vh = joint.lo.tolist(), joint.hi.tolist()
            ylo, yhi = measurement(y_k)
            if not self.model.contract_lists(vl, vh, u_k.tolist(), ylo, yhi):
                inconsistent = True
            else:
                joint.lo, joint.hi = np.array(vl), np.array(vh)
                rows, rhs = self._rows(joint, u_k, y_k, obs)
        if rows is not None and rhs is not None:
            # [Gz 0] and [[A 0]; rows] (the same C-ordered arrays as the stacks)
            nc = joint.A.shape[0]
            Gz = _pad(joint.Gz, joint.Gz.shape[0], rows.shape[1])
            A = _pad(joint.A, nc + rows.shape[0], rows.shape[1])
            A[nc:] = rows
            b = np.concatenate([joint.b, rhs])
            hull = hull_certificates(joint.z[:nx], Gz[:nx], A, b)
            if hull is not None:
                joint.Gz, joint.A, joint.b = Gz, A, b
            inconsistent = hull is None
        if inconsistent:
            joint.lo, joint.hi = lo0, hi0
        if rows is None or inconsistent:
            hull = hull_certificates(joint.z[:nx], joint.Gz[:nx], joint.A, joint.b)
        if hull is None:  # pragma: no cover - the predicted set is never certainly empty
            return not inconsistent
        lo, hi, cert = hull
        if cert.softened:  # see hull_certificates: keep the larger set
            joint.Gz, joint.A, err = soften(joint.Gz, joint.A, cert.radius, cert.slack)
            joint.acc = up(joint.acc + err)
        acc = joint.acc[:nx]
        new_lo = np.maximum(joint.lo[:nx], down(lo - acc))
        new_hi = np.minimum(joint.hi[:nx], up(hi + acc))
        if (new_lo <= new_hi).all():
            joint.lo[:nx], joint.hi[:nx] = new_lo, new_hi
        return not inconsistent

    def _rows(
        self, joint: _Joint, u_k: np.ndarray, y_k: np.ndarray, obs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``[J_i G_z, σ_i e_i] (ξ, τ) = t_i - J_i z`` for the measured outputs, each row
        divided by a power of two near its largest coefficient (exact)."""
        nx = self.model.nx
        lin = linearise(self.model.evaluators("h"), joint.lo, joint.hi, joint.z, u_k, nx, False)
        J = lin.J[obs]
        aJ = np.abs(J)
        n = joint.z.shape[0]
        yo, go = y_k[obs], lin.g0[obs]
        t = yo - go + J @ lin.c
        t_err = gamma(n + 3) * (np.abs(yo) + np.abs(go) + aJ @ np.abs(lin.c))
        t_err += RECORD_MARGIN * (1.0 + np.abs(yo))  # the data margin of a float64 record
        rhs = t - J @ joint.z
        coeff = J @ joint.Gz
        sigma = (
            lin.rho[obs]
            + t_err
            + aJ @ joint.acc
            + gamma(n + 1) * (np.abs(t) + aJ @ np.abs(joint.z))
            + gamma(n) * (aJ @ np.abs(joint.Gz)).sum(axis=1)
        ) * (1.0 + gamma(n + 6))
        p, mg = coeff.shape
        rows = _pad(coeff, p, mg + p)  # [coeff, diag(sigma)]
        rows[np.arange(p), mg + np.arange(p)] = sigma
        top = np.maximum(np.abs(rows).max(axis=1), np.finfo(float).tiny)
        scale = np.exp2(np.round(np.log2(top)))  # a power of two: dividing by it is exact
        return rows / scale[:, None], rhs / scale

    def _predict(
        self, k: int, joint: _Joint, lin: Linearisation
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(c, G, A, b, e)`` of ``x[k+1]``: the mean-value extension, then the reduction."""
        z, Gz = joint.z, joint.Gz
        J, aJ = lin.J, np.abs(lin.J)
        d = z - lin.c
        c = lin.g0 + J @ d
        n = z.shape[0]
        err = (
            # + the data margin of a float64 simulation of f, relative to its terms over the
            # set
            (2.0 * gamma(n + 3) + RECORD_MARGIN)
            * (1.0 + np.abs(lin.g0) + aJ @ (np.abs(d) + np.abs(Gz).sum(axis=1)))
            + (aJ @ joint.acc) * (1.0 + gamma(n + 1))
            + lin.rho
        ) * (1.0 + gamma(4))
        # [J G_z, diag(err)] (nonzero radii only) and [A 0], filled in place (box_generators
        # and two stacks cost more than the arithmetic here)
        nz = np.flatnonzero(err > 0)
        mg = Gz.shape[1]
        G = _pad(J @ Gz, err.shape[0], mg + nz.size)
        G[nz, mg + np.arange(nz.size)] = err[nz]
        A = _pad(joint.A, joint.A.shape[0], mg + nz.size)
        self._check_overflow(k, c, G)
        return self._reduce(c, G, A, joint.b, lin)

    def _reduce(
        self, c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray, lin: Linearisation
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """At most ``max_constraints`` constraints, then ``max_generators`` generators
        [Scott2016, Section 4], in coordinates centred at ``c`` (the shift's rounding in
        ``e``)."""
        nx = c.shape[0]
        e = np.zeros(nx)
        out = eliminate_constraints(np.zeros(nx), G, A, b, self.design.max_constraints)
        if out is None:  # numerically empty: restart from the natural box (sound)
            c, r = mid_rad(lin.nat_lo, lin.nat_hi)
            G = np.diag(r)[:, r > 0]
            A, b = np.zeros((0, G.shape[1])), np.zeros(0)
        else:
            c = c + out.c
            G, A, b, e = out.G, out.A, out.b, up(out.e + UNIT_ROUNDOFF * np.abs(c))
        return (*reduce_consolidated(c, G, A, b, self.design.max_generators, TOLS), e)
