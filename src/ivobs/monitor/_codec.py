"""Arrays of the monitor's state as JSON lists, and its argument check of ``u_k``."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

from .._validate import as_vector
from ..errors import IvobsError


def _vector(name: str, v: Any, n: int) -> np.ndarray:
    if isinstance(v, np.ndarray) and v.shape == (n,) and v.dtype == float:
        if not np.all(np.isfinite(v)):
            raise IvobsError(f"{name}: expected finite numbers, got {v}")
        return v.copy()
    return as_vector(name, v, n)


def _encode(v: np.ndarray) -> list[Any]:
    """Arrays as lists, with non-finite values spelled out (strict JSON has no NaN/inf)."""
    return [x if np.isfinite(x) else str(x) for x in np.asarray(v, dtype=float).tolist()]


def _encode_prev(prev: dict[str, Any] | None) -> dict[str, Any] | None:
    return None if prev is None else {key: _encode(val) for key, val in prev.items()}


def _decode(v: list[Any]) -> np.ndarray:
    return np.array([float(x) for x in v], dtype=float)


@contextmanager
def saved_entry(expected: str) -> Iterator[None]:
    """Read an entry of a saved state: a missing key, a wrong type or value (raised as
    ``ValueError`` by the checks inside) becomes ``IvobsError("state: " + expected)``; the
    reader's own ``IvobsError`` passes unchanged."""
    try:
        yield
    except IvobsError:
        raise
    except (KeyError, TypeError, ValueError, IndexError):
        raise IvobsError(f"state: {expected}") from None
