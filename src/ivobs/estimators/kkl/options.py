"""The options of the ``kkl`` method, each checked before use: an :class:`~ivobs.IvobsError`
naming the argument (and, for an option that does not apply to the system, what to use
instead)."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from ..._validate import as_bool
from ...errors import IvobsError
from ...model import LinearSystem

__all__ = ["check_options", "number"]


def number(name: str, val: Any, low: float, *, strict: bool, why: str = "") -> float:
    """A real, finite scalar option ``> low`` (``strict``) or ``>= low``, else
    :class:`IvobsError` naming it."""
    if isinstance(val, np.ndarray) and val.ndim == 0 and val.dtype.kind in "fiu":
        val = val.item()
    if isinstance(val, (bool, np.bool_)) or not isinstance(val, numbers.Real):
        raise IvobsError(f"{name}: expected a real number, got {val!r} ({type(val).__name__})")
    v = float(val)
    if not (np.isfinite(v) and (v > low if strict else v >= low)):
        rng = f"{'>' if strict else '>='} {low:g}"
        raise IvobsError(f"{name}: expected a finite number {rng}{why}, got {val!r}")
    return v


def check_options(
    sys: LinearSystem,
    *,
    A_z: Any,
    B_z: Any,
    T: Any,
    T0: Any,
    gamma: Any,
    ell: Any,
    max_cond: Any,
    tune: Any,
    input_hold: Any,
) -> None:
    """Every option of :class:`~ivobs.estimators.kkl.KKL` checked against the system's kind."""
    ct, tv = sys.is_continuous, sys.is_time_varying
    dt_ltv = tv and not ct
    if (A_z is None) != (B_z is None):
        raise IvobsError("A_z, B_z: give both target matrices or neither")
    if T is not None and (tv or A_z is None):
        raise IvobsError(
            "T: an explicit transformation is for time-invariant systems, together with the "
            "A_z and B_z it solves (4) for" + ("; use T0 for time-varying systems" if tv else "")
        )
    if T0 is not None and not tv:
        raise IvobsError("T0: only for time-varying systems (time-invariant: T solves (4))")
    if gamma is not None and not dt_ltv:
        raise IvobsError(
            "gamma: the factor of (16.a) is for discrete-time time-varying "
            "systems" + ("; use ell" if ct and tv else "")
        )
    if ell is not None and not (ct and tv):
        raise IvobsError(
            "ell: the factor of (11.a) is for continuous-time time-varying "
            "systems" + ("; use gamma" if dt_ltv else "")
        )
    for nm, val in (("gamma", gamma), ("ell", ell)):
        if val is not None:
            number(nm, val, 0.0, strict=True)
    number("max_cond", max_cond, 1.0, strict=False, why="; cond(T) >= 1 for every T")
    as_bool("tune", tune)
    hold_ok = isinstance(input_hold, str) and input_hold in ("linear", "zero")
    if not (callable(input_hold) or hold_ok):
        raise IvobsError(
            f"input_hold: expected 'linear', 'zero' or a callable t -> u(t), got {input_hold!r}"
        )
