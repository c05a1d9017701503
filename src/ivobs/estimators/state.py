"""The typed online state of an estimator, and its one serialisation.

Every method keeps what it carries from one step to the next in a frozen dataclass derived from
:class:`OnlineState` (arrays named as in its paper, plus the step counter ``k`` and whether the last
measurement was inconsistent). A step never
modifies a state: it returns a new one (so :meth:`Estimator.predict` needs no copy, and a saved
state cannot change behind the caller's back).

:func:`dump_state` and :func:`load_state` are the only (de)serialisation, for every method: a
JSON-ready dict of the dataclass fields, checked on the way back against a fresh state of the
same estimator (shapes, finite values, ``lo <= hi`` for the pairs a state declares in
:attr:`OnlineState.bounds`). The envelope (method, design fingerprint, format version) is
written by :meth:`Estimator.state`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Generic, NamedTuple, TypeVar

import numpy as np

from .._validate import _shape_str
from ..errors import IvobsError

__all__ = [
    "STATE_FORMAT",
    "STATE_VERSION",
    "OnlineState",
    "Step",
    "check_counters",
    "dump_state",
    "evolve",
    "load_state",
]

STATE_FORMAT = "ivobs.state"
STATE_VERSION = 2
"""Version of the saved-state layout: 2 = one entry per field of the method's state dataclass.
States saved by ivobs before typed states (no ``version`` entry) are refused by name."""


@dataclass(frozen=True, kw_only=True)
class OnlineState:
    """What every method's online state holds besides its own arrays.

    ``k``: steps processed; ``inconsistent``: whether the measurement of the last step
    contradicted the model (it was then not used)."""

    k: int = 0
    inconsistent: bool = False

    bounds: ClassVar[tuple[tuple[str, str], ...]] = ()
    """Pairs of fields ``(lower, upper)`` that must satisfy ``lower <= upper`` (checked on
    restore)."""
    optional: ClassVar[tuple[str, ...]] = ()
    """Fields added after states were first saved: absent from a saved state, they take the
    value of a fresh state."""


S = TypeVar("S", bound=OnlineState)


class Step(NamedTuple, Generic[S]):
    """What a method's recursion returns for one step: the next state, the bounds of ``x[k]``
    (before outward rounding) and whether ``y[k]`` was found inconsistent (and not used).
    ``lo``, ``hi``: arrays, or lists of Python floats (a fast step that computed the bounds in
    floats: the base rounds them without converting them to arrays and back)."""

    state: S
    lo: np.ndarray | list[float]
    hi: np.ndarray | list[float]
    inconsistent: bool = False


def evolve(state: S, **changes: Any) -> S:
    """A new state: ``state`` with the fields ``changes`` replaced (``dataclasses.replace``
    without its re-run of ``__init__``, a third of the cost: the per-step paths). States are
    frozen dataclasses without ``__post_init__`` or slots; nothing is checked or copied."""
    new = object.__new__(type(state))
    d = new.__dict__
    d.update(state.__dict__)
    d.update(changes)
    return new


MAX_STEPS = 2**53
"""Largest step count a saved state may hold (steps are counted one by one in floats too)."""

_TAMPERED = "; the state was altered or is not from Estimator.state() of this estimator"


# -- dump --------------------------------------------------------------------------------------
def dump_state(state: OnlineState) -> dict[str, Any]:
    """The fields of ``state`` as JSON-ready values (arrays as ``{"array", "shape"}`` with NaN
    saved as ``null``)."""
    return {f.name: _dump_value(getattr(state, f.name)) for f in dataclasses.fields(state)}


def _dump_value(val: Any) -> Any:
    if isinstance(val, np.ndarray):
        out: dict[str, Any] = {"shape": list(val.shape)}
        if val.dtype.kind == "f" and np.isnan(val).any():
            out["array"] = [None if v != v else v for v in val.ravel().tolist()]
        else:
            out["array"] = val.ravel().tolist()
        if val.dtype.kind != "f":
            out["dtype"] = val.dtype.str
        return out
    if isinstance(val, np.generic):
        return val.item()
    return val


# -- load --------------------------------------------------------------------------------------
def load_state(saved: Any, fresh: S) -> S:
    """The state saved by :func:`dump_state`, rebuilt with the types of ``fresh`` (a state of
    the same estimator at step 0) and checked against it: the step counter, every array
    (dimensions, fixed axes, finite values), scalars' types, and ``lower <= upper`` for the
    pairs in ``fresh.bounds``."""
    if not isinstance(saved, Mapping):
        raise IvobsError(
            "state: expected entry 'state' to be the dict of saved values from "
            f"Estimator.state(), got {type(saved).__name__}"
        )
    names = [f.name for f in dataclasses.fields(fresh)]
    names = [n for n in names if n in saved or n not in fresh.optional]
    missing = sorted(set(names) - set(saved))
    if missing:
        raise IvobsError(f"state: missing entries {missing}" + _TAMPERED)
    values = {name: _load_value(name, saved[name], getattr(fresh, name)) for name in names}
    check_counters(values)
    for lo_name, hi_name in fresh.bounds:
        _check_pair(lo_name, hi_name, values[lo_name], values[hi_name])
    return dataclasses.replace(fresh, **values)


def _load_value(key: str, val: Any, fresh: Any) -> Any:
    if isinstance(fresh, np.ndarray):
        return _load_array(key, val, fresh)
    if key == "k":
        return val  # checked by check_counters
    if isinstance(fresh, (bool, np.bool_)):
        if not isinstance(val, (bool, np.bool_)):
            raise IvobsError(
                f"state: entry {key!r}: expected True or False, got {val!r}" + _TAMPERED
            )
        return bool(val)
    if isinstance(fresh, (int, np.integer)):
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)):
            raise IvobsError(f"state: entry {key!r}: expected an integer, got {val!r}" + _TAMPERED)
        return int(val)
    if isinstance(fresh, (float, np.floating)) or fresh is None:  # None: not yet known
        number = not isinstance(val, bool) and isinstance(val, (int, float, np.number))
        finite_ok = number and (
            bool(np.isfinite(val)) or (fresh is not None and not np.isfinite(fresh))
        )
        if not (finite_ok or (fresh is None and val is None)):
            raise IvobsError(
                f"state: entry {key!r}: expected a finite number"
                f"{' or None' if fresh is None else ''}, got {val!r}" + _TAMPERED
            )
        return None if val is None else float(val)
    if isinstance(fresh, str):
        if not isinstance(val, str):
            raise IvobsError(f"state: entry {key!r}: expected a string, got {val!r}" + _TAMPERED)
        return val
    raise IvobsError(f"state: entry {key!r} cannot be restored ({type(fresh).__name__})")


def _load_array(key: str, val: Any, fresh: np.ndarray) -> np.ndarray:
    """One saved array, checked against its fresh counterpart: same number of axes; the axes
    that do not grow while running have the same length (a history's first axis, empty at step
    0, and the last axis of a matrix, e.g. generators, may grow); finite values where the fresh
    state is finite, except NaN (a missing sample) in a kept measurement record ``y``."""
    if not isinstance(val, Mapping) or "array" not in val:
        raise IvobsError(
            f"state: entry {key!r}: expected a saved array, got {type(val).__name__} "
            f"{val!r:.60}" + _TAMPERED
        )
    try:
        flat = [np.nan if v is None else v for v in val["array"]]
        arr = np.array(flat, dtype=val.get("dtype", fresh.dtype)).reshape(val["shape"])
    except (TypeError, ValueError, KeyError) as exc:
        raise IvobsError(
            f"state: entry {key!r} is not a valid saved array ({exc})" + _TAMPERED
        ) from None
    pattern = tuple(
        "any" if (i == 0 and n == 0) or (i == fresh.ndim - 1 and fresh.ndim >= 2) else n
        for i, n in enumerate(fresh.shape)
    )
    if arr.ndim != fresh.ndim or any(
        p != "any" and p != n for p, n in zip(pattern, arr.shape, strict=False)
    ):
        raise IvobsError(
            f"state: entry {key!r}: expected an array of shape {_shape_str(pattern)}, got "
            f"{_shape_str(arr.shape)}" + _TAMPERED
        )
    if arr.dtype.kind == "f":
        bad = np.isinf(arr) if key == "y" else ~np.isfinite(arr)
        if np.all(np.isfinite(fresh)) and np.any(bad):
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            raise IvobsError(
                f"state: entry {key!r}: expected finite numbers, got {arr[idx]} at index {idx}"
                + _TAMPERED
            )
    return arr


def check_counters(values: dict[str, Any]) -> None:
    """The step counter ``k`` of a saved state, checked and converted in place."""
    k = values["k"]
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k <= MAX_STEPS:
        beyond = " (more than 2**53 steps)" if isinstance(k, int) and k > MAX_STEPS else ""
        raise IvobsError(
            f"state: entry 'k': expected the step count (an integer >= 0), got {k!r}{beyond}"
            + _TAMPERED
        )
    values["k"] = int(k)


def _check_pair(lo_name: str, hi_name: str, lo: np.ndarray, hi: np.ndarray) -> None:
    if lo.shape != hi.shape:
        raise IvobsError(
            f"state: entries {lo_name!r} and {hi_name!r}: expected bounds of the same shape, got "
            f"{_shape_str(lo.shape)} and {_shape_str(hi.shape)}" + _TAMPERED
        )
    if np.any(lo > hi):
        idx = tuple(int(i) for i in np.argwhere(lo > hi)[0])
        raise IvobsError(
            f"state: entries {lo_name!r} and {hi_name!r}: expected lower <= upper bounds, got "
            f"{lo[idx]} > {hi[idx]} at index {idx}" + _TAMPERED
        )
