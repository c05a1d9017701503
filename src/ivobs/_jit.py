"""Optional compilation of loop-written kernels with numba (``pip install ivobs[fast]``).

A kernel is written once, as plain Python loops over NumPy arrays (the subset of Python that
numba compiles). :func:`jit` compiles it with ``numba.njit(cache=True)`` when numba is
installed, and returns it unchanged otherwise: the same source runs either way, compiled
(fast) or interpreted (slow, for small problems and for tests of the source itself through the
compiled function's ``py_func``). No ``fastmath``: IEEE semantics, no reassociation and no
contraction of ``a * b + c`` into a fused multiply-add, so the rounding-error bounds written
for the source hold for the compiled code.

numba is imported by the first module that defines a kernel (never by ``import ivobs``). The
environment variable ``IVOBS_NUMBA=0``, set before that import, keeps every kernel interpreted.
The first call of a kernel compiles it (a few seconds) or loads it from numba's cache.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any, TypeVar, cast

__all__ = ["ENV", "compiled", "jit"]

F = TypeVar("F", bound=Callable[..., Any])

ENV = "IVOBS_NUMBA"
"""The environment variable that keeps kernels interpreted when ``"0"``."""


def _njit() -> Callable[[Any], Any] | None:
    if os.environ.get(ENV, "") == "0":
        return None
    try:
        from numba import njit
    except ImportError:  # numba not installed (or broken): interpreted kernels
        return None
    return cast(Callable[[Any], Any], njit(cache=True))


_COMPILE = _njit()


def compiled() -> bool:
    """Whether kernels are compiled (numba installed and not disabled by :data:`ENV`)."""
    return _COMPILE is not None


def jit(f: F) -> F:
    """``f`` compiled by numba when it is installed, ``f`` itself otherwise."""
    return f if _COMPILE is None else cast(F, _COMPILE(f))
