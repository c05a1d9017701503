"""A whole record (or a batch of records) through an estimator: the vectorised path where the
method has one, else the loop over its one recursion; then NaN before ``valid_from``, and a clear
error for bounds that left the float range.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import as_signal
from ..errors import IvobsError
from ..sets.rounding import overflowed

if TYPE_CHECKING:
    from .base import Estimator

__all__ = ["BATCH_CHUNK", "VECTOR_MIN_STEPS", "check_record", "finalize", "run_record"]

BATCH_CHUNK = 2_000_000
"""Batches are processed in chunks of about this many floats per signal (cache-sized)."""

VECTOR_MIN_STEPS = 50
"""``run()`` uses a method's vectorised path from this many steps on (or for batches). Below it the
vectorised path's fixed cost (the powers of the error dynamics, the envelopes of the whole
record) exceeds the loop's per-step cost, and ``run()`` loops over ``step()``'s recursion. The two
paths give the same sets up to rounding, each with its own proven rounding."""

Arrays = tuple[np.ndarray, np.ndarray, np.ndarray]


def check_record(sys: Any, u: Any, y: Any) -> tuple[np.ndarray, np.ndarray]:
    """``u`` ``(T, nu)`` and ``y`` ``(T, ny)``, or batches ``(B, T, ·)`` (a single record of one
    broadcast against the batch of the other)."""
    y = as_signal("y", y, sys.ny, allow_nan=True)
    T = y.shape[-2]
    u = as_signal("u", u, sys.nu, T if u is None else None)
    if u.shape[-2] != T:
        raise IvobsError(
            f"u and y: expected the same number of samples (rows), got u: {u.shape[-2]}, y: {T}"
        )
    if u.ndim == 3 or y.ndim == 3:
        B = (u if u.ndim == 3 else y).shape[0]
        if u.ndim == 3 and y.ndim == 3 and u.shape[0] != y.shape[0]:
            raise IvobsError(f"u, y: batch sizes differ ({u.shape[0]} and {y.shape[0]})")
        u = np.broadcast_to(u, (B, T, sys.nu)) if u.ndim == 2 else u
        y = np.broadcast_to(y, (B, T, sys.ny)) if y.ndim == 2 else y
    return u, y


def run_record(
    est: Estimator, u: np.ndarray, y: np.ndarray, t: np.ndarray | None, vectorize: bool, bar: Any
) -> Arrays:
    """Bounds ``(lo, hi)`` and the inconsistency flags of a record or batch."""
    if y.ndim == 2:
        lo, hi, inc = _block(est, u, y, t, vectorize, bar)
        lo, hi = _owned(lo), _owned(hi)
        finalize(est, lo, hi)
        return lo, hi, inc
    # streams in cache-sized chunks written into one output: large fresh temporaries cost more
    # in page faults than the arithmetic itself
    B, T, nx = y.shape[0], y.shape[1], est.sys.nx
    lo, hi = np.empty((B, T, nx)), np.empty((B, T, nx))
    inc = np.zeros((B, T), dtype=bool)
    chunk = max(1, BATCH_CHUNK // (max(1, T) * max(nx, est.sys.ny, est.sys.nu, 1)))
    for b0 in range(0, B, chunk):
        sl = slice(b0, min(B, b0 + chunk))
        lo[sl], hi[sl], inc[sl] = _block(est, u[sl], y[sl], t, vectorize, bar)
        finalize(est, lo[sl], hi[sl])
    return lo, hi, inc


def _block(
    est: Estimator, u: np.ndarray, y: np.ndarray, t: np.ndarray | None, vectorize: bool, bar: Any
) -> Arrays:
    """The method's vectorised path, or the loop, for one record or a chunk of streams."""
    out = est._run(u, y, t) if vectorize else None
    if out is not None:
        inc = np.zeros(y.shape[:-1], dtype=bool)
        if len(out) == 3 and out[2] is not None:
            inc = np.asarray(out[2], dtype=bool).reshape(y.shape[:-1])
        if bar is not None:
            bar.update(int(np.prod(y.shape[:-1])))
        return _with_strips(est, out[0], out[1], inc, u, y, t)
    if y.ndim == 2:
        return _with_strips(est, *est._loop(u, y, t, bar), u, y, t)
    parts = zip(*(est._loop(u[b], y[b], t, bar) for b in range(y.shape[0])), strict=True)
    lo, hi, inc = (np.stack(p) for p in parts)
    return _with_strips(est, lo, hi, inc, u, y, t)


def _with_strips(
    est: Estimator, lo: Any, hi: Any, inc: np.ndarray, u: np.ndarray, y: np.ndarray, t: Any
) -> Arrays:
    """Either path's bounds met with the measurement strips (when the method uses them), once
    per record: the method's recursion may itself run the loop for some streams."""
    if est._strips is None:
        return lo, hi, inc
    lo, hi = _owned(lo), _owned(hi)
    return lo, hi, inc | _meet_strips(est, lo, hi, u, y, t)


def _meet_strips(
    est: Estimator, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, y: np.ndarray, t: Any
) -> np.ndarray:
    """The measurement strips on the boxes of a whole record or batch, in place, from
    ``valid_from`` on (:mod:`ivobs.estimators.measured`); the rows they find inconsistent."""
    strips, vf = est._strips, est.valid_from
    assert strips is not None
    keys = np.arange(y.shape[-2]) if t is None else np.asarray(t)
    bad = np.zeros(y.shape[:-1], dtype=bool)
    for b in np.ndindex(y.shape[:-2]):  # every stream (the record itself: b = ())
        bad[b][vf:] = strips.meet(lo[b][vf:], hi[b][vf:], u[b][vf:], y[b][vf:], keys[vf:])
    return bad


def finalize(est: Estimator, lo: np.ndarray, hi: np.ndarray) -> None:
    """In place: NaN before ``valid_from``, no non-finite bound after."""
    vf = est.valid_from
    lo[..., :vf, :] = np.nan
    hi[..., :vf, :] = np.nan
    with np.errstate(over="ignore"):  # a sum of finite bounds may overflow: looked at below
        total = np.sum(lo[..., vf:, :]) + np.sum(hi[..., vf:, :])
    if not np.isfinite(total):
        bad = ~(np.isfinite(lo[..., vf:, :]) & np.isfinite(hi[..., vf:, :]))
        stopped = getattr(est, "_stopped", None)
        if stopped is not None:  # a diverged run: the rows from the step it stopped at
            bad[..., stopped[0] - vf :, :] = False
            bad &= ~(np.isnan(lo[..., vf:, :]) & np.isnan(hi[..., vf:, :]))
        if not bad.any():  # finite bounds near the float range whose sum overflowed
            return
        first = np.argwhere(bad)[0]
        k = int(first[-2]) + vf
        row = tuple(int(i) for i in first[:-2])  # the stream of a batch
        prev = max(k - 1, vf)  # finite: k is the first non-finite step
        raise est._non_finite_error(
            k, overflowed(lo[row][k], hi[row][k], lo[row][prev], hi[row][prev])
        )


def _owned(a: Any) -> np.ndarray:
    """A float array safe to modify in place: ``_run`` returns fresh arrays (or views of fresh
    arrays), so only read-only or foreign-typed results are copied."""
    if isinstance(a, np.ndarray) and a.dtype == float and a.flags.writeable:
        return a
    return np.array(a, dtype=float)
