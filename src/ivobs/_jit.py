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
import sys
from collections.abc import Callable, Iterable
from typing import Any, TypeVar, cast

__all__ = ["ENV", "compiled", "first_use_notice", "jit", "kernels_in"]

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


_NOTICED: set[str] = set()


def _cached(kernel: Any) -> bool:
    """Whether numba's on-disk cache holds ``kernel`` (its index file exists). Read through
    numba's cache object; any surprise in it counts as "not cached" (the notice then says
    "compiling or loading")."""
    try:
        cache = kernel._cache
        base = cache._impl.filename_base
        return os.path.exists(os.path.join(cache.cache_path, base + ".nbi"))
    except (AttributeError, OSError, TypeError):
        return False


def first_use_notice(who: str, kernels: Iterable[Any]) -> None:
    """One line on stderr before ``who``'s kernels are first compiled on this machine (numba
    compiles on the first call, which can take a minute of CPU: the user is told why nothing
    happens yet). Silent when kernels are interpreted, already compiled in this process or in
    numba's cache, and after the first notice for ``who``."""
    if _COMPILE is None or who in _NOTICED:
        return
    _NOTICED.add(who)
    todo = [k for k in kernels if not getattr(k, "signatures", None) and not _cached(k)]
    if todo:
        print(
            f"ivobs: {who}: compiling {len(todo)} numba kernel(s) on first use (up to a minute; "
            "cached for later runs; IVOBS_NUMBA=0 runs them interpreted)",
            file=sys.stderr,
            flush=True,
        )


def kernels_in(*modules: Any) -> list[Any]:
    """The compiled kernels in ``modules`` (numba dispatchers: they keep ``py_func``)."""
    found = [v for m in modules for v in vars(m).values() if hasattr(v, "py_func")]
    return list({id(v): v for v in found}.values())  # each once (a module imports some)
