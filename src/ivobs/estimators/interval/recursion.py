"""One step of the interval observers, written once for the three methods (package docstring):

    z̄+ = Q⁺ z̄ − Q⁻ z̲ + B_z u + L_z y + G⁺ d̄ − G⁻ d̲
    z̲+ = Q⁺ z̲ − Q⁻ z̄ + B_z u + L_z y + G⁺ d̲ − G⁻ d̄          (Q = S (A − L_k C) S⁻¹, ...)

after the consistency test of ``y[k]`` (an inconsistent measurement is not used), every bound
on the safe side of its exact value (:mod:`.rounding`): one product of the step matrix of the
pattern of observed outputs (:class:`~.operators.StepOperator`), dense or sparse. The box of
``x[k]`` is then met with the finite-memory bound of the ``N`` steps before ``k`` when they were
complete, and the window of the last steps kept (:mod:`.window`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar

import numpy as np

from .. import _uncertain as uncertain
from ..state import Step, evolve
from .operators import Operators
from .window import CooperativeState, memory_box, remember

__all__ = ["CooperativeState", "IntervalState", "SplitState", "TransformedState", "interval_step"]


@dataclass(frozen=True)
class IntervalState(CooperativeState):
    """The state of ``interval``: bounds of ``x[k]`` ([Tang2019, eq. (36)])."""


@dataclass(frozen=True)
class SplitState(CooperativeState):
    """The state of ``interval-split``: bounds of ``x[k]`` ([Efimov2013, eq. (5)])."""


@dataclass(frozen=True)
class TransformedState(CooperativeState):
    """The state of ``interval-transformed``: bounds of ``z[k] = S x[k]`` ([Tang2019,
    eqs. (42)-(43)])."""


S = TypeVar("S", bound=CooperativeState)


def interval_step(ops: Operators, state: S, u_k: np.ndarray, y_k: np.ndarray) -> Step[S]:
    """From the bounds of ``z[k]``: the box of ``x[k]`` and the bounds of ``z[k+1]``."""
    n, ny = ops.nx, ops.ny
    s = y_k.dot(y_k)
    complete = s == s  # (NaN: a missing component)
    dhi, dlo = ops.d_const if ops.d_const is not None else ops.disturbance(state.k, y_k)
    if complete:
        op, y_obs = ops.full, y_k
    else:
        obs = ~np.isnan(y_k)
        op, y_obs = ops.pattern(obs), np.where(obs, y_k, 0.0)
    b = op.bounds(np.concatenate((state.hi, state.lo, u_k, y_obs, dhi, dlo)))
    h, xr = op.h, ops.xrows  # upper rows [z̄+; x̄; p̄ − y; y − p̲], lower rows [z̲+; x̲]
    if not xr:
        xlo, xhi = state.lo, state.hi
    elif state.k == 0:  # [Tang2019, eq. (42)]: the prior box itself at k = 0
        xlo, xhi = ops.x0.lo, ops.x0.hi
    else:
        xlo, xhi = b[h + n :], b[n : n + xr]
    test = b[n + xr : h]  # upper bounds of p̄ − y and y − p̲ (observed outputs)
    if ops.unc is not None:  # interval matrices: w = ΔA x + ΔB u, v = ΔC x + ΔD u (_uncertain)
        w, v = uncertain.terms(ops.unc, xlo, xhi, u_k)
        vo = v[~np.isnan(y_k)]
        test = np.nextafter(test + np.concatenate((vo, vo)), np.inf)
    # y[k] outside the bounds of C x + D_u u + F d: a fault, not used (a few floats)
    inconsistent = any(t < 0.0 for t in test.tolist())
    if inconsistent:
        op = ops.pattern(np.zeros(ny, dtype=bool))
        b = op.bounds(np.concatenate((state.hi, state.lo, u_k, np.zeros(ny), dhi, dlo)))
        h = op.h
    zhi, zlo = b[:n], b[h : h + n]
    if ops.unc is not None:  # S (w − L_k v) enters z[k+1] as a bounded input
        zlo, zhi = uncertain.widen(zlo, zhi, uncertain.observer_term(w, v, op.Lmag, ops.S))
    new = evolve(state, lo=zlo, hi=zhi)
    if ops.window is not None:  # the finite-memory bound (:mod:`.window`)
        new = remember(ops.window, ops.S, new, state, u_k, y_k, complete and not inconsistent)
        if ops.memory:
            xlo, xhi = memory_box(ops.window, state, xlo, xhi)
    return Step(new, xlo, xhi, inconsistent)
