"""Shared input validation (the scikit-learn ``check_array`` idea): one place, clear messages.

All helpers raise :class:`ivobs.IvobsError` naming the argument, the expected shape or property
and the received one.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import IvobsError


def _shape_str(shape: tuple[Any, ...]) -> str:
    return "(" + ", ".join(str(s) for s in shape) + (",)" if len(shape) == 1 else ")")


def as_float_array(name: str, value: Any) -> np.ndarray:
    """Convert to a float array or raise an error naming ``name``. The masked entries of a
    ``numpy.ma`` array become NaN (a missing sample where NaN means one, refused elsewhere)."""
    if callable(value):
        raise IvobsError(f"{name}: expected an array, got a callable {value!r}")
    if np.iscomplexobj(value):
        raise IvobsError(
            f"{name}: expected real numbers, got complex values (the imaginary part would be "
            "dropped silently); pass the real part explicitly if that is what you mean"
        )
    try:
        if isinstance(value, np.ma.MaskedArray):  # a masked sample is a missing one: NaN
            return np.ma.filled(value.astype(float), np.nan)
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise IvobsError(f"{name}: expected numbers, got {type(value).__name__} ({exc})") from None
    return arr


def check_finite(name: str, arr: np.ndarray, *, allow_inf: bool = False) -> np.ndarray:
    """Reject NaN (and infinities unless ``allow_inf``)."""
    bad = np.isnan(arr) if allow_inf else ~np.isfinite(arr)
    if np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        what = "NaN" if allow_inf else "non-finite"
        raise IvobsError(
            f"{name}: expected finite numbers, found {what} value {arr[idx]} at index {idx}"
        )
    return arr


def as_matrix(
    name: str,
    value: Any,
    rows: int | None = None,
    cols: int | None = None,
    *,
    vector: str = "col",
) -> np.ndarray:
    """Return a finite 2-D float matrix.

    A scalar becomes ``1 x 1``; a 1-D array becomes a column (``vector="col"``) or a row
    (``vector="row"``). ``rows``/``cols`` (when given) are checked.
    """
    arr = as_float_array(name, value)
    given = arr.shape  # reported in errors: the shape the caller passed, not the reshaped one
    if arr.ndim == 0:
        arr = arr.reshape(1, 1)
    elif arr.ndim == 1:
        arr = arr.reshape(-1, 1) if vector == "col" else arr.reshape(1, -1)
    if arr.ndim != 2:
        raise IvobsError(f"{name}: expected a 2-D matrix, got an array of shape {arr.shape}")
    check_finite(name, arr)
    exp = (rows if rows is not None else "any", cols if cols is not None else "any")
    if (rows is not None and arr.shape[0] != rows) or (cols is not None and arr.shape[1] != cols):
        got = _shape_str(given)
        if given != arr.shape:
            how = "a column" if vector == "col" else "a row"
            got += f" (read as {how} {_shape_str(arr.shape)})"
        raise IvobsError(f"{name}: expected shape {_shape_str(exp)}, got {got}")
    return arr


def as_vector(name: str, value: Any, n: int | None = None) -> np.ndarray:
    """Return a finite 1-D float vector of length ``n`` (scalars are broadcast when ``n``)."""
    arr = as_float_array(name, value)
    if arr.ndim == 0 and n is not None:
        arr = np.full(n, float(arr))
    if arr.ndim == 2 and 1 in arr.shape:
        arr = arr.ravel()
    if arr.ndim != 1:
        raise IvobsError(f"{name}: expected a vector, got an array of shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise IvobsError(f"{name}: expected a vector of length {n}, got length {arr.shape[0]}")
    return check_finite(name, arr)


def as_signal(
    name: str,
    value: Any,
    n: int,
    T: int | None = None,
    *,
    allow_nan: bool = False,
    allow_batch: bool = True,
) -> np.ndarray:
    """Return a signal as a ``(T, n)`` (or batched ``(B, T, n)``) float array.

    ``None`` is accepted for ``n == 0`` (and gives ``(T, 0)``); a 1-D array is accepted when
    ``n == 1`` (one sample per row). NaN marks a missing sample only when ``allow_nan``.
    """
    if value is None:
        if n == 0:
            if T is None:
                raise IvobsError(f"{name}: cannot infer the number of samples from None")
            return np.zeros((T, 0))
        raise IvobsError(f"{name}: expected an array with {n} column(s), got None")
    arr = as_float_array(name, value)
    if arr.ndim == 1 and n == 1:
        arr = arr.reshape(-1, 1)
    elif arr.ndim == 1 and n == 0:
        arr = arr.reshape(-1, 0)
    if arr.ndim == 3 and not allow_batch:
        raise IvobsError(f"{name}: expected shape (T, {n}), got a batch of shape {arr.shape}")
    if arr.ndim not in (2, 3) or arr.shape[-1] != n:
        exp = f"(T, {n})" + (f" or (B, T, {n})" if allow_batch else "")
        raise IvobsError(f"{name}: expected shape {exp}, got {_shape_str(arr.shape)}")
    if T is not None and arr.shape[-2] != T:
        raise IvobsError(
            f"{name}: expected {T} samples (rows) to match the other signals, got {arr.shape[-2]}"
        )
    if np.any(np.isinf(arr)):
        raise IvobsError(f"{name}: infinite values are not valid samples")
    if not allow_nan and np.any(np.isnan(arr)):
        idx = tuple(int(i) for i in np.argwhere(np.isnan(arr))[0])
        raise IvobsError(f"{name}: NaN at index {idx}; this signal must be known at every step")
    return arr


def as_int(name: str, value: Any, minimum: int | None = None) -> int:
    """Return an int (rejecting floats with a fractional part and booleans)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        if isinstance(value, (float, np.floating)) and float(value).is_integer():
            value = int(value)
        else:
            raise IvobsError(f"{name}: expected an integer, got {value!r}")
    n = int(value)
    if minimum is not None and n < minimum:
        raise IvobsError(f"{name}: expected an integer >= {minimum}, got {n}")
    return n


def as_bool(name: str, value: Any) -> bool:
    """Return a bool (``True``/``False`` or a NumPy bool only: a string such as ``"no"`` is
    truthy and would silently mean the opposite)."""
    if not isinstance(value, (bool, np.bool_)):
        raise IvobsError(f"{name}: expected True or False, got {value!r}")
    return bool(value)
