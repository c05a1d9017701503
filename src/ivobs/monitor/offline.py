"""The offline consistency test of :meth:`Monitor.check <ivobs.monitor.Monitor.check>`:
vectorised over the steps of a whole record.

At every step ``k`` the band of the one-step prediction from the estimator's box of step
``k - 1`` ([Efimov2013, Lemma 1], [Dinh2024, Lemma 1]; at step 0, the prior box)::

    P_k = A[X_{k-1}] + B u[k-1] + E[d[k-1]],      y[k] ∈ C[P_k] + D u[k] + F[d[k]]

widened by the rounding margin.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem
from ..result import Estimate
from ..sets import Box, image_bounds
from .records import Fault, MonitorRecord

__all__ = ["check_record", "refuse_uncertain"]


def check_record(
    sys: LinearSystem,
    x0: Box | None,
    margin: float,
    method: str,
    u: np.ndarray,
    y: np.ndarray,
    tt: Any,
    res: Estimate,
) -> MonitorRecord:
    """The alarms of the record ``u``, ``y`` (times ``tt``) given the estimator's result
    ``res`` on it; ``method`` names the estimator in the reasons."""
    T = y.shape[0]
    X_lo, X_hi = res.lower, res.upper
    known = ~np.isnan(X_lo).any(axis=1)
    P_lo, P_hi = np.full((T, sys.nx), -np.inf), np.full((T, sys.nx), np.inf)
    if x0 is not None:
        P_lo[0], P_hi[0] = x0.lo, x0.hi
    steps = np.arange(T)
    if T > 1 and sys.is_discrete:
        prev_lo = np.where(known[:-1, None], X_lo[:-1], -np.inf)
        prev_hi = np.where(known[:-1, None], X_hi[:-1], np.inf)
        a_lo, a_hi = _images(sys, "A", steps[:-1], prev_lo, prev_hi)
        e_lo, e_hi = _disturbance_images(sys, "E", steps[:-1], y[:-1])
        bu = _products(sys, "B", steps[:-1], u[:-1])
        P_lo[1:], P_hi[1:] = a_lo + bu + e_lo, a_hi + bu + e_hi
    keys = tt if (sys.is_continuous and tt is not None) else steps
    c_lo, c_hi = _images(sys, "C", keys, P_lo, P_hi)
    f_lo, f_hi = _disturbance_images(sys, "F", steps, y)
    du = _products(sys, "D", keys, u)
    b_lo, b_hi = c_lo + du + f_lo, c_hi + du + f_hi
    b_lo, b_hi = b_lo - margin * (1 + np.abs(b_lo)), b_hi + margin * (1 + np.abs(b_hi))
    b_lo, b_hi = np.nan_to_num(b_lo, nan=-np.inf), np.nan_to_num(b_hi, nan=np.inf)
    out = (y < b_lo) | (y > b_hi)
    with np.errstate(invalid="ignore"):
        lo, hi = np.maximum(P_lo, X_lo), np.minimum(P_hi, X_hi)
        gap = lo - hi > margin * (1 + np.maximum(np.abs(lo), np.abs(hi)))
    disjoint = known & gap.any(axis=1)
    inconsistent = np.asarray(res.inconsistent, dtype=bool)
    alarm = out.any(axis=1) | disjoint | inconsistent
    reasons = [""] * T
    for k in np.flatnonzero(alarm):
        why = [
            f"y{i + 1} = {y[k, i]:.6g} outside the predicted band "
            f"[{b_lo[k, i]:.6g}, {b_hi[k, i]:.6g}]"
            for i in np.flatnonzero(out[k])[:3]
        ]
        if inconsistent[k]:
            why.append(f"{method}: measurement inconsistent with the model and bounds")
        if disjoint[k]:
            i = int(np.argmax(gap[k]))
            why.append(
                f"estimate disjoint from the model's prediction in x{i + 1} "
                f"([{X_lo[k, i]:.6g}, {X_hi[k, i]:.6g}] vs "
                f"[{P_lo[k, i]:.6g}, {P_hi[k, i]:.6g}])"
            )
        reasons[int(k)] = "; ".join(why)
    return MonitorRecord(
        X_lo.copy(), X_hi.copy(), alarm, reasons, b_lo, b_hi, faults=_episodes(alarm, out)
    )


def _episodes(alarm: np.ndarray, out: np.ndarray) -> list[Fault]:
    """The runs of consecutive alarmed steps as episodes, with the outputs outside their band
    (``end``: the first step after the run; None when the run reaches the last step)."""
    T = alarm.shape[0]
    edges = np.flatnonzero(np.diff(np.concatenate([[0], alarm.astype(np.int8), [0]])))
    faults = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        outputs = tuple(int(i) for i in np.flatnonzero(out[a:b].any(axis=0)))
        faults.append(Fault(int(a), outputs, None if b >= T else int(b), int(b) - 1))
    return faults


def refuse_uncertain(sys: LinearSystem) -> None:
    """The monitor's prediction and output band use the exact matrices (Lemma 1 of ``A`` and
    ``C``): with interval matrices they would not be guaranteed, so an alarm could be false."""
    if sys.is_uncertain:
        raise IvobsError(
            f"sys: the monitor's prediction and output band need exactly known matrices; this "
            f"system has interval matrices ({', '.join(sys.interval_matrices())}). Estimate "
            "with ivobs.make_estimator(...).run (methods that accept them: docs/uncertain.md)"
        )


def _images(
    sys: LinearSystem, name: str, keys: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """[Efimov2013, Lemma 1] for ``A`` or ``C`` over rows of boxes (one matrix per row when
    the system is time-varying)."""
    get = sys.A_at if name == "A" else sys.C_at
    if not sys.is_time_varying:
        return image_bounds(get(0), lo, hi)
    pairs = [image_bounds(get(k), lo[i], hi[i]) for i, k in enumerate(keys)]
    return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])


def _products(sys: LinearSystem, name: str, keys: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``B u`` or ``D u`` over rows."""
    get = sys.B_at if name == "B" else sys.D_at
    if not sys.is_time_varying:
        products: np.ndarray = u @ get(0).T
        return products
    return np.array([get(k) @ u[i] for i, k in enumerate(keys)])


def _disturbance_images(
    sys: LinearSystem, name: str, steps: np.ndarray, y: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``E[d[k]]`` or ``F[d[k]]`` over the steps (bounds from ``y[k]`` when callable)."""
    get = sys.E_at if name == "E" else sys.F_at
    n = sys.nx if name == "E" else sys.ny
    if sys.is_time_varying or callable(sys.d):
        boxes = [sys.d_at(k, y[i]) for i, k in enumerate(steps)]
        pairs = [image_bounds(get(k), b.lo, b.hi) for k, b in zip(steps, boxes)]
        return (
            np.array([p[0] for p in pairs]).reshape(-1, n),
            np.array([p[1] for p in pairs]).reshape(-1, n),
        )
    d = sys.d_at(0) if sys.has_constant_bounds else sys.d
    assert isinstance(d, Box)
    if d.is_time_varying:
        if steps.size:
            d.at(int(steps[-1]))  # raises when the record is longer than the bounds
        return image_bounds(get(0), d.lo[steps], d.hi[steps])
    lo, hi = image_bounds(get(0), d.lo, d.hi)
    return np.broadcast_to(lo, (steps.size, n)), np.broadcast_to(hi, (steps.size, n))
