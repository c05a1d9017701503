"""The strip estimator: options, design, online state; its step is :mod:`.recursion`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._jit import first_use_notice
from ..._validate import as_int, as_matrix
from ...errors import IvobsError
from ...linalg import gamma
from ...model import LinearSystem
from ...sets import Box, Zonotope
from ...sets.rounding import mid_rad
from .. import _uncertain as uncertain
from .. import register
from ..base import Design, Estimator, check_size
from ..state import OnlineState, Step, evolve
from .recursion import (
    GIRARD,
    NONE,
    PARALLELOTOPE,
    joint_set,
    kernels,
    measure,
    predict,
    reduce_step,
    state_box,
    step,
)

__all__ = ["REDUCTIONS", "StripDesign", "StripEstimator", "StripState"]

REDUCTIONS = ("parallelotope", "girard", "box")
_CODE = {"parallelotope": PARALLELOTOPE, "girard": GIRARD, "box": NONE}

Model = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
              np.ndarray, np.ndarray]  # fmt: skip


@dataclass(frozen=True)
class StripDesign(Design):
    """``order``: generators kept by the reduction (the zonotope order ``q`` of [Tang2019,
    Remark 2]); ``reduction``: one of :data:`REDUCTIONS`; ``weight``: the weight ``W`` of the
    box reduction (identity when None)."""

    order: int
    reduction: str
    weight: np.ndarray | None


@dataclass(frozen=True)
class StripState(OnlineState):
    """``x[k] ∈ <p, H> ⊕ box(e)``: the zonotope of ``x[k]`` predicted from ``y[0..k-1]``
    (centre ``p``, generators ``H``) and ``e``, the box of what the last reduction could not
    absorb into the generators."""

    p: np.ndarray
    H: np.ndarray
    e: np.ndarray


def structure(sys: LinearSystem, k: int) -> Model:
    """What the step needs of the model at step ``k``: ``(D, h, jc, pc, mc, M, E_pc, B)`` with
    ``jc`` the components of ``d`` that enter a measurement (``F`` column nonzero: part of the
    joint set), ``pc`` those that enter only the state equation (added at the prediction: the
    strips never touch them), ``h = [C F_jc]`` (one strip per row), ``M = [A E_jc]`` on its
    nonzero columns ``mc``. C-contiguous float64 (int64 indices): one compiled specialisation
    serves every system."""
    A, B, C, D, E, F = sys.matrices_at(k)
    f_used = np.any(F != 0, axis=0)
    jc = np.flatnonzero(f_used)
    pc = np.flatnonzero(~f_used & np.any(E != 0, axis=0))
    M = np.hstack([A, E[:, jc]])
    mc = np.flatnonzero(np.any(M != 0, axis=0))

    def f64(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=np.float64)

    def i64(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=np.int64)

    return (f64(D), f64(np.hstack([C, F[:, jc]])), i64(jc), i64(pc), i64(mc), f64(M[:, mc]),
            f64(E[:, pc]), f64(B))  # fmt: skip


@register
class StripEstimator(Estimator):
    """Zonotopic filter with strip intersection and F-radius gain [Alamo2005].

    Uses ``u[0..k]`` and ``y[0..k]``: the box at step ``k`` is the filtered set, after the
    intersection with the strips of ``y[k]``. Needs the prior box ``x0``. Per step: ``ny``
    closed-form intersections and one order reduction, no optimisation; the cost is bounded by
    ``order``. Missing components of ``y[k]`` (NaN) are not intersected; a measurement that
    certainly misses the set is reported inconsistent and not used.

    Parameters
    ----------
    sys : LinearSystem (discrete time; matrices and bounds may vary with ``k``)
    x0 : Box, the prior box on ``x[0]``
    order : int, optional
        Generators kept between steps (default ``10 nx``; at least ``nx``). More generators
        give tighter boxes at a cost per step growing with ``order`` (``O(ny nx order)``).
        Change it to trade width for time: ``order = nx`` is the cheapest, ``40 nx`` rarely
        tighter than ``10 nx``.
    reduction : ``"parallelotope"`` (default), ``"girard"`` or ``"box"``
        Order reduction: the parallelotope absorption of [Chisci1998] with a conditioned basis
        (Girard's box on the steps where the basis is ill-conditioned), the box of
        [Girard2005] (CORA's default) or the box of [Combastel2015]. The two boxes refuse
        ``order < 2 nx`` (they diverge there) and can diverge above it where ``|A|`` expands
        (a random 7-state system at ``2 nx``): the default is the one that stayed bounded on
        every system tried; the others reproduce other tools' results.
    weight : (nx, nx) array, optional
        Positive definite weight of the box reduction (which generators are kept).

    Notes
    -----
    **Interval matrices** (``supports_uncertain``; docs/uncertain.md): the plant is the nominal
    one plus ``w = ΔA x + ΔB u`` in the state and ``v = ΔC x + ΔD u`` in the output. Each strip
    is that of the nominal row widened by ``v̄_i >= |v_i|`` (bounded from the box of the joint
    set before the strips), and the prediction adds the box ``diag(w̄)`` (``w̄ >= |w|`` from the
    filtered box) as generators, which later strips can contract
    (:mod:`ivobs.estimators._uncertain`).
    """

    name = "strip"
    order = 80
    summary = "zonotopic set-membership filter, strip intersection"
    reference = "[Alamo2005]"
    data_used = "filter"
    supports_time_varying = True
    supports_uncertain = True  # see "Interval matrices" in the docstring
    proven_rounding = True  # every rounding bounded in .recursion and ivobs.sets.strip
    design: StripDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        order: int | None = None,
        reduction: str = "parallelotope",
        weight: Any = None,
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        # the first step compiles the kernels (numba): say so before the wait
        first_use_notice(self.name, kernels())
        check_size(
            self.name,
            sys.nx,
            "multiplies and reduces a dense nx x q generator matrix "
            "(q = 10 nx by default, O(nx^3) work)",
        )
        if reduction not in REDUCTIONS:
            raise IvobsError(
                f"reduction: expected one of {', '.join(map(repr, REDUCTIONS))}, got {reduction!r}"
            )
        q = 10 * sys.nx if order is None else as_int("order", order, sys.nx)  # nx at least
        if reduction != "parallelotope" and q < 2 * sys.nx:
            raise IvobsError(
                f"order: the {reduction!r} reduction needs order >= 2 nx = {2 * sys.nx}, got "
                f"{q}: with fewer than nx generators kept beside its box the boxes diverge "
                "(a kept generator is never reduced and Alamo's update does not keep it "
                "bounded: CORA's vehicle6 at order nx + 1 reached 1e16; a plain box, "
                "order = nx, grows like |A| where the strips do not cut it: 1e82 on a random "
                "system); use reduction='parallelotope'"
            )
        W = None
        if weight is not None:
            W = as_matrix("weight", weight, sys.nx, sys.nx)
            if not np.allclose(W, W.T) or np.min(np.linalg.eigvalsh(0.5 * (W + W.T))) <= 0:
                raise IvobsError(
                    "weight: expected a symmetric positive definite (nx, nx) matrix, got one "
                    f"with eigenvalues {np.linalg.eigvalsh(0.5 * (W + W.T))}"
                )
        if W is not None and reduction != "box":
            raise IvobsError(
                f"weight: only the 'box' reduction takes a weight, got reduction={reduction!r}"
            )
        self.design = StripDesign(order=q, reduction=reduction, weight=W)
        self._model = None if sys.is_time_varying else structure(sys, 0)
        self._d = None if not sys.has_constant_bounds else self._disturbance(sys.d_at(0))
        # rounding of t_i and of a float64 plant: the dot products of nx + nd + nu terms
        self._n_plant = sys.nx + sys.nd + sys.nu + 1
        self._g_meas = 2.0 * gamma(self._n_plant + 1)

    @staticmethod
    def _disturbance(box: Box) -> tuple[np.ndarray, ...]:
        """``(c_d, r_d, d_lo, d_hi)`` with ``[d_lo, d_hi] ⊆ <c_d, diag(r_d)>`` (exactly)."""
        lo = np.ascontiguousarray(box.lo, dtype=np.float64)
        hi = np.ascontiguousarray(box.hi, dtype=np.float64)
        return (*mid_rad(lo, hi), lo, hi)

    # -- online --------------------------------------------------------------------------------
    def _initial_state(self) -> StripState:
        assert self.x0 is not None
        p, r = mid_rad(self.x0.lo, self.x0.hi)
        return StripState(p=p, H=np.diag(r)[:, r > 0], e=np.zeros(self.sys.nx))

    def _step(
        self, state: StripState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[StripState]:
        k = state.k
        model = self._model if self._model is not None else structure(self.sys, k)
        cd, rd, dlo, dhi = self._d if self._d is not None else self._disturbance(
            self.sys.d_at(k, y_k)
        )  # fmt: skip
        u, y = np.ascontiguousarray(u_k, dtype=np.float64), np.ascontiguousarray(y_k, np.float64)
        H = np.ascontiguousarray(state.H)
        args = (state.p, H, state.e, u, y, cd, rd, dlo, dhi, model, self.design.order)
        if self.sys.uncertainty is None:
            code = _CODE[self.design.reduction]
            p, H, e, lo, hi, inconsistent, finite = step(*args, code, self._g_meas, self._n_plant)
        else:
            p, H, e, lo, hi, inconsistent, finite = self._uncertain_step(*args)
        if not finite:
            self._check_overflow(k + 1, p, H)
        if self.design.reduction == "box":
            zp = Zonotope._trusted(p, H).reduce(self.design.order, self.design.weight)
            p, H = zp.c, np.ascontiguousarray(zp.G)
        return Step(evolve(state, p=p, H=H, e=e), lo, hi, inconsistent)

    def _uncertain_step(
        self, p: np.ndarray, H: np.ndarray, e: np.ndarray, u: np.ndarray, y: np.ndarray,
        cd: np.ndarray, rd: np.ndarray, dlo: np.ndarray, dhi: np.ndarray, model: Model,
        order: int,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool, bool]:  # fmt: skip
        """:func:`.recursion.step` with the interval matrices' terms (class docstring):
        ``v̄`` from the box of ``x[k]`` before the strips widens them, ``w̄`` from the
        filtered box is added by the prediction."""
        unc = self.sys.uncertainty
        assert unc is not None
        D, h, jc, pc, mc, M, Ep, B = model
        nx = self.sys.nx
        z, Hz, m, acc, rows, lo, hi = joint_set(p, H, e, jc, cd, rd, dlo, dhi, y.shape[0])
        v = uncertain.terms(unc, lo[:nx], hi[:nx], u)[1]
        m, inconsistent = measure(z, Hz, m, acc, rows, lo, hi, y, u, v, D, h, nx,
                                      self._g_meas)  # fmt: skip
        xlo, xhi, crossed = state_box(z, rows, acc, m, lo, hi, nx)
        w = uncertain.terms(unc, xlo, xhi, u)[0]
        pn, Hn = predict(z, Hz, m, rows, acc, u, cd, rd, w, M, mc, Ep, pc, B, self._n_plant)
        code = _CODE[self.design.reduction]
        return reduce_step(pn, Hn, xlo, xhi, inconsistent or crossed, order, code)
