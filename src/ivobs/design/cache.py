"""An in-process cache of designs keyed by a fingerprint of the system and the options.

``intersect`` builds ``reachability`` and ``zonotope`` on the same system, ``compare`` and
campaigns build the same method on the same system many times: each design (a Riccati
bisection, an LMI, a descent) is solved once per process. The key is a SHA-256 of the arrays'
shapes, dtypes and bytes and of the options; the cache keeps the :data:`SIZE` most recently used
designs, and hands out copies (a caller may not change a cached array).
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

__all__ = ["SIZE", "cached", "clear", "fingerprint"]

SIZE = 64
"""Designs kept (least recently used first out)."""

T = TypeVar("T")
_CACHE: OrderedDict[str, Any] = OrderedDict()


def fingerprint(*parts: Any) -> str:
    """SHA-256 of arrays (shape, dtype, bytes) and other values (their ``repr``)."""
    h = hashlib.sha256()
    for p in parts:
        if isinstance(p, np.ndarray):
            a = np.ascontiguousarray(p)
            h.update(f"{a.shape}{a.dtype.str}".encode())
            h.update(a.tobytes())
        else:
            h.update(repr(p).encode())
        h.update(b"|")
    return h.hexdigest()


def _copy(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.copy()
    if isinstance(value, tuple):
        return tuple(_copy(v) for v in value)
    return value


def cached(key: str, compute: Callable[[], T]) -> T:
    """``compute()`` once per ``key`` (a :func:`fingerprint`); later calls get a copy. A
    design that raises is not cached (the next call raises again)."""
    if key in _CACHE:
        _CACHE.move_to_end(key)
        out: T = _copy(_CACHE[key])
        return out
    value = compute()
    _CACHE[key] = _copy(value)
    while len(_CACHE) > SIZE:
        _CACHE.popitem(last=False)
    return value


def clear() -> None:
    """Forget every cached design (tests and benchmarks that time a design)."""
    _CACHE.clear()
