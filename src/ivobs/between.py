"""The state between samples: boxes that contain ``x(t)`` over each whole sampling period of a
continuous-time plant, from the boxes an estimator returned at the samples (docs/continuous.md,
"Between samples").

An estimate bounds ``x(t_k)``; the plant moves on between ``t_k`` and ``t_k + Ts`` with ``u_k``
held and ``d(t)`` anywhere in its bounds. :func:`between_samples` encloses every such path from
every point of the box at ``t_k``: for a :class:`~ivobs.LinearSystem` with validated matrix
exponentials over sub-intervals of the period (:func:`ivobs.model.sampling.period_hull`), for a
:class:`~ivobs.NonlinearSystem` with the a priori enclosures of the validated flow
(:meth:`~ivobs.model.nonlinear.flow.FlowSystem.period_box`). Every estimator's output works:
the sample boxes are all it needs.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ._validate import as_signal
from .errors import IvobsError
from .result import Estimate
from .sets import Box

__all__ = ["between_samples"]


def between_samples(
    system: Any,
    estimate: Estimate,
    u: Any = None,
    *,
    Ts: float | None = None,
    disturbances: str = "varying",
) -> Estimate:
    """Boxes ``lower[k] <= x(t) <= upper[k]`` for every ``t`` in ``[t_k, t_k + Ts]``.

    ``system``: the continuous-time plant (``dt=0``), a :class:`~ivobs.LinearSystem` or a
    :class:`~ivobs.NonlinearSystem`, or the sampled model ``NonlinearSystem.discretize`` made
    (its period and signals are then its own). ``estimate``: the boxes at the samples (any
    method's). ``u``: the inputs ``(T, nu)`` held over each period (None: zero or no input).
    ``Ts``: the period (default: the sampled model's, else the spacing of ``estimate.t``).
    ``disturbances``: ``"varying"`` (any ``d(t)`` in its bounds) or ``"held"``.
    """
    if not isinstance(estimate, Estimate) or estimate.is_batch:
        raise IvobsError(f"estimate: expected an ivobs.Estimate of one stream, got {estimate!r}")
    if disturbances not in ("varying", "held"):
        raise IvobsError(f"disturbances: expected 'varying' or 'held', got {disturbances!r}")
    from .model import LinearSystem, NonlinearSystem

    flow = getattr(system, "continuous", None) is not None  # a sampled nonlinear model
    plant = isinstance(system, (LinearSystem, NonlinearSystem)) and system.is_continuous
    if not (flow or plant):
        raise IvobsError(
            "system: expected the continuous-time plant (dt=0), LinearSystem or "
            f"NonlinearSystem, or NonlinearSystem.discretize(Ts)'s model; got {system!r}"
        )
    T, nx = estimate.lower.shape
    if nx != system.nx:
        raise IvobsError(f"estimate: {nx} states, the system has {system.nx}")
    period = _period(system if flow else None, estimate, Ts)
    U = (
        np.zeros((T, system.nu))
        if u is None
        else as_signal("u", u, system.nu, T, allow_batch=False)
    )
    lo, hi = estimate.lower, estimate.upper
    valid = np.all(np.isfinite(lo), axis=1) & np.all(np.isfinite(hi), axis=1)
    out_lo = np.full((T, nx), np.nan)
    out_hi = np.full((T, nx), np.nan)
    if isinstance(system, LinearSystem):
        out_lo[valid], out_hi[valid] = _linear(system, period, lo, hi, U, valid)
    else:
        sampled = system if flow else system.discretize(period, disturbances=disturbances)
        wl, wh = sampled.w_box.lo, sampled.w_box.hi
        for k in np.flatnonzero(valid):
            out_lo[k], out_hi[k] = sampled.period_box(lo[k], hi[k], U[k], wl, wh)
    return Estimate(
        out_lo,
        out_hi,
        valid_from=estimate.valid_from,
        method=f"{estimate.method} (between samples)",
        t=estimate.t,
        missing=estimate.missing,
        inconsistent=estimate.inconsistent,
        info={"between_samples": True, "Ts": period, "disturbances": disturbances},
    )


def _period(sampled: Any, estimate: Estimate, Ts: Any) -> float:
    if sampled is not None:
        if Ts is not None and Ts != sampled.dt:
            raise IvobsError(f"Ts: the sampled model's period is {sampled.dt}, got {Ts!r}")
        return float(sampled.dt)
    if Ts is None:
        t = estimate.t
        if t is None or len(t) < 2:
            raise IvobsError("Ts: give the sampling period (the estimate has no sample times)")
        steps = np.diff(np.asarray(t, dtype=float))
        if not np.allclose(steps, steps[0], rtol=1e-9, atol=0.0):
            raise IvobsError("Ts: the estimate's sample times are not evenly spaced; give Ts")
        Ts = float(steps[0])
    if isinstance(Ts, bool) or not isinstance(Ts, (int, float)) or not 0 < Ts < math.inf:
        raise IvobsError(f"Ts: expected a sampling period > 0, got {Ts!r}")
    return float(Ts)


def _linear(
    system: Any, Ts: float, lo: np.ndarray, hi: np.ndarray, U: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`~ivobs.model.sampling.period_hull` on the valid rows (a held ``d`` is one of
    the paths a varying ``d`` takes: the same enclosure holds for both)."""
    from .model.sampling import period_hull

    system._require_lti("between_samples")
    A, B, _, _, E, _ = system.matrices_at(0)  # dense (a sparse matrix densified)
    d = system.d if system.nd else None
    if d is not None and not isinstance(d, Box):
        raise IvobsError("system: between samples, the disturbance bounds must be a Box")
    if d is not None and d.is_time_varying:
        d = Box(np.asarray(d.lo)[: len(valid)][valid], np.asarray(d.hi)[: len(valid)][valid])
    return period_hull(A, B, E, d, Ts, lo[valid], hi[valid], U[valid])
