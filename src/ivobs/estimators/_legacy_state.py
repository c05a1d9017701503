"""Dict-shaped online states (the protocol before typed states), kept while every method moves
to a :class:`~ivobs.estimators.state.OnlineState` dataclass; removed when none is left."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from .._validate import _shape_str
from ..errors import IvobsError

_TAMPERED = "; the state was altered or is not from Estimator.state() of this estimator"


def _check_restored(st: dict[str, Any], ref: dict[str, Any]) -> None:
    """Check a restored online state against a fresh one (``ref``, from ``_initial_state()``):
    the step counter, the data scale, and every entry of ``ref`` (arrays: dimensions, fixed
    axes, finite values, ``lo <= hi``; scalars: their type). Axes that grow while running
    (generators: the last axis of a matrix; histories: an axis empty at step 0) may differ."""
    k = st.get("k")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise IvobsError(
            f"state: entry 'k': expected the step count (an integer >= 0), got {k!r}" + _TAMPERED
        )
    scale = st.get("_scale", 0.0)
    if (
        isinstance(scale, bool)
        or not isinstance(scale, (int, float, np.number))
        or not np.isfinite(scale)
        or scale < 0
    ):
        raise IvobsError(
            f"state: entry '_scale': expected the data scale (a finite number >= 0), got "
            f"{scale!r}" + _TAMPERED
        )
    for key, fresh in ref.items():
        val = st[key]
        if isinstance(fresh, np.ndarray):
            _check_restored_array(key, val, fresh)
        elif isinstance(fresh, (bool, np.bool_)):
            if not isinstance(val, (bool, np.bool_)):
                raise IvobsError(
                    f"state: entry {key!r}: expected True or False, got {val!r}" + _TAMPERED
                )
        elif isinstance(fresh, (int, np.integer)):
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)):
                raise IvobsError(
                    f"state: entry {key!r}: expected an integer, got {val!r}" + _TAMPERED
                )
        elif isinstance(fresh, (float, np.floating)) or fresh is None:  # None: not yet known
            number = not isinstance(val, bool) and isinstance(val, (int, float, np.number))
            finite_ok = number and (
                bool(np.isfinite(val)) or (fresh is not None and not np.isfinite(fresh))
            )
            if not (finite_ok or (fresh is None and val is None)):
                raise IvobsError(
                    f"state: entry {key!r}: expected a finite number"
                    f"{' or None' if fresh is None else ''}, got {val!r}" + _TAMPERED
                )
    for key in ref:  # bounds kept in pairs: <name>lo <= <name>hi
        if key.endswith("lo") and key[:-2] + "hi" in ref:
            lo, hi = st[key], st[key[:-2] + "hi"]
            if lo.shape != hi.shape:
                raise IvobsError(
                    f"state: entries {key!r} and {key[:-2] + 'hi'!r}: expected bounds of the same "
                    f"shape, got {_shape_str(lo.shape)} and {_shape_str(hi.shape)}" + _TAMPERED
                )
            if np.any(lo > hi):
                idx = tuple(int(i) for i in np.argwhere(lo > hi)[0])
                raise IvobsError(
                    f"state: entries {key!r} and {key[:-2] + 'hi'!r}: expected lower <= upper "
                    f"bounds, got {lo[idx]} > {hi[idx]} at index {idx}" + _TAMPERED
                )


def _check_restored_array(key: str, val: Any, fresh: np.ndarray) -> None:
    """One array entry of a restored state against its fresh counterpart (see
    :func:`_check_restored`)."""
    if not isinstance(val, np.ndarray):
        raise IvobsError(
            f"state: entry {key!r}: expected a saved array, got {type(val).__name__} "
            f"{val!r:.60}" + _TAMPERED
        )
    pattern = tuple(
        "any" if (i == 0 and n == 0) or (i == fresh.ndim - 1 and fresh.ndim >= 2) else n
        for i, n in enumerate(fresh.shape)
    )
    if val.ndim != fresh.ndim or any(p != "any" and p != n for p, n in zip(pattern, val.shape)):
        raise IvobsError(
            f"state: entry {key!r}: expected an array of shape {_shape_str(pattern)}, got "
            f"{_shape_str(val.shape)}" + _TAMPERED
        )
    # non-finite values only in an entry that has them in a fresh state, and NaN in a kept
    # measurement record "y" (a missing sample, as in step())
    bad = np.isinf(val) if key == "y" else ~np.isfinite(val)
    if np.all(np.isfinite(fresh)) and np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise IvobsError(
            f"state: entry {key!r}: expected finite numbers, got {val[idx]} at index {idx}"
            + _TAMPERED
        )


def _copy_state(state: Any) -> Any:
    """A deep copy of an online state (fast path for the usual dict of arrays and numbers)."""
    if isinstance(state, dict):
        # exact's warm-started LP is a cache, rebuilt from the history when absent
        return {k: (None if k == "lp" else _copy_state(v)) for k, v in state.items()}
    if isinstance(state, list):
        return [_copy_state(v) for v in state]
    if isinstance(state, np.ndarray):
        return state.copy()
    if isinstance(state, (int, float, str, bool, type(None), np.generic)):
        return state
    try:
        return copy.deepcopy(state)
    except TypeError as exc:
        raise IvobsError(f"predict: this method's online state cannot be copied ({exc})") from None
