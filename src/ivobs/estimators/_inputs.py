"""Checks of the per-step and per-record arguments of an estimator (they name the argument)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_float_array, as_vector
from ..errors import IvobsError

__all__ = [
    "check_option_types",
    "check_t",
    "check_t_k",
    "check_u_k",
    "check_y_k",
    "keyword_options",
    "lean_u_y",
]

_F64 = np.dtype(np.float64)
_NO_INPUT = np.zeros(0)
_NO_INPUT.flags.writeable = False


def lean_u_y(sys: Any, u_k: Any, y_k: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``(u_k, y_k)`` when they are already what :func:`check_u_k` and :func:`check_y_k` would
    return (float vectors of the right lengths, both finite: a cheap test for the common case
    of one step), else ``None`` (then the full checks run and name what is wrong). A finite sum
    of the values means every value is finite (NaN and infinities propagate; an overflow of the
    sum only sends the call to the full checks)."""
    # (``dtype is _F64``: the canonical float64 descriptor; any other goes the full way)
    if type(y_k) is not np.ndarray or y_k.dtype is not _F64 or y_k.ndim != 1:
        return None
    if u_k is None:
        if sys.nu:
            return None
        u_k = _NO_INPUT
    elif type(u_k) is not np.ndarray or u_k.dtype is not _F64 or u_k.ndim != 1:
        return None
    if y_k.shape[0] != sys.ny or u_k.shape[0] != sys.nu:
        return None
    ys, us = y_k.tolist(), u_k.tolist()
    total = sum(ys) + sum(us)
    if total - total != 0.0:  # NaN or an infinity somewhere (or an overflow): full checks
        return None
    return u_k, y_k


def check_u_k(sys: Any, u_k: Any) -> np.ndarray:
    """``u[k]``: ``nu`` numbers (``None`` when the system has no input)."""
    if u_k is None:
        if sys.nu:
            raise IvobsError(f"u_k: expected {sys.nu} input value(s), got None")
        return np.zeros(0)
    return as_vector("u_k", u_k, sys.nu)


def check_y_k(sys: Any, y_k: Any) -> np.ndarray:
    """``y[k]``: ``ny`` numbers, NaN for a missing component (``None``: all missing)."""
    if y_k is None:
        return np.full(sys.ny, np.nan)
    arr = as_float_array("y_k", y_k).ravel()
    if arr.shape[0] != sys.ny:
        raise IvobsError(f"y_k: expected {sys.ny} measurement value(s), got {arr.shape[0]}")
    if np.any(np.isinf(arr)):
        raise IvobsError("y_k: infinite measurement; use NaN for a missing sample")
    return arr


def check_t_k(sys: Any, t: Any) -> float | None:
    """The sample time of one step: needed in continuous time, refused in discrete time (the
    step counter ``k`` is the time there)."""
    if t is None:
        if sys.is_continuous:
            raise IvobsError("t: continuous-time estimation needs the sample time of each step")
        return None
    if not sys.is_continuous:  # (it would be ignored)
        dt = "" if getattr(sys, "dt", True) is True else f" (dt = {sys.dt})"
        raise IvobsError(
            f"t: this system is discrete-time{dt}: its steps are counted by k, and t, the sample "
            "time of the step, applies to continuous-time systems (dt = 0) only; leave t out"
        )
    arr = as_float_array("t", t)
    if arr.size != 1 or not np.isfinite(arr).all():
        raise IvobsError(f"t: expected one finite sample time, got {t!r}")
    return float(arr.reshape(()))


def check_t(sys: Any, t: Any, T: int) -> tuple[np.ndarray | None, np.ndarray | None]:
    """``(times the method uses, times the result is labelled with)`` for a record of ``T``
    steps.

    Continuous time: the sample times are needed, and are both. Discrete time: the method counts
    steps (it gets None); the labels are ``t`` when given, else ``k dt`` for a sampled system
    (None for ``dt=True``). A given ``t`` must step by the sampling period: a record whose times
    jump by two periods has lost a row, and its steps would be renumbered (keep a row of NaN
    for a missing sample)."""
    if sys.is_continuous:
        if t is None:
            raise IvobsError("t: continuous-time estimation needs the sample times t (T,)")
        t_arr = _times(t, T)
        return t_arr, t_arr
    dt = getattr(sys, "dt", True)
    period = None if dt is True or not dt else float(dt)
    if t is None:
        return None, None if period is None else np.arange(T) * period
    t_arr = _times(t, T)
    if period is not None and T > 1:
        gaps = np.diff(t_arr)
        off = np.abs(gaps - period) > 1e-6 * period + 4 * np.spacing(np.abs(t_arr[1:]))
        if off.any():
            j = int(np.argmax(off))
            a, b = float(t_arr[j]), float(t_arr[j + 1])
            raise IvobsError(
                f"t: the steps of this sampled system are dt = {period:g} apart, but t[{j}] = "
                f"{a!r} and t[{j + 1}] = {b!r} are {gaps[j]:g} apart (a dropped sample? keep "
                "its row with NaN measurements, so the steps are not renumbered)"
            )
    return None, t_arr


def _times(t: Any, T: int) -> np.ndarray:
    t_arr = as_float_array("t", t).ravel()
    if t_arr.shape[0] != T or np.any(~np.isfinite(t_arr)) or np.any(np.diff(t_arr) <= 0):
        raise IvobsError(f"t: expected {T} finite, strictly increasing sample times")
    return t_arr


def keyword_options(cls: Any) -> dict[str, Any]:
    """The keyword options of the method ``cls``: each name's ``inspect.Parameter`` from the
    nearest ``__init__`` along its bases that declares it (the class's own first)."""
    import inspect

    out: dict[str, Any] = {}
    for klass in cls.__mro__:
        init = vars(klass).get("__init__")
        for p in inspect.signature(init).parameters.values() if init is not None else ():
            if p.kind is p.KEYWORD_ONLY and p.name not in out:
                out[p.name] = p
    return out


_SCALARS = {"str": "a string", "bool": "True or False", "int": "an integer", "float": "a number"}
"""The declared option types that are one value, and how an error names them."""


def check_option_types(cls: Any, options: dict[str, Any]) -> dict[str, Any]:
    """Options declared as one value (a string, a flag, a number; see the method's signature)
    refuse a NumPy array, naming the option (``order=np.array([6, 12])`` is no order, and a
    method's ``if order < 1`` would raise NumPy's "truth value of an array is ambiguous"
    instead of saying so); NumPy scalars become Python ones. Other values are left to the
    method's own checks, and options declared ``Any`` (matrices, boxes) to the method."""
    kinds = {n: str(p.annotation) for n, p in keyword_options(cls).items()}
    out = dict(options)
    for name, value in options.items():
        parts = [p.strip() for p in kinds.get(name, "Any").split("|")]
        single = [_SCALARS[p] for p in parts if p in _SCALARS]
        if not single:
            continue
        if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "biuf":
            out[name] = value.item()  # a 0-d array of a number is that number
            continue
        if isinstance(value, np.ndarray):
            expected = " or ".join(single + (["None"] if "None" in parts else []))
            raise IvobsError(f"{name}: expected {expected}, got an array of shape {value.shape}")
        if isinstance(value, np.generic):
            out[name] = value.item()
    return out
