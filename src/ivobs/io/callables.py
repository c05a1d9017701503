"""Callables by import path: a matrix or a bound of a system file may name a module-level
function (``{ python = "package.module:function", params = {...} }``).

**Trust**: resolving a path imports its module, which runs its code. Only the functions that
ivobs' own scenarios define (modules ``ivobs.scenarios`` and below: the callables
:func:`~ivobs.io.save_system` writes for the built-in scenarios) are resolved by default; any
other path needs ``allow_code=True`` (``--allow-code`` on the command line).
"""

from __future__ import annotations

import functools
import importlib
from typing import Any

import numpy as np

from ..errors import IvobsError

__all__ = ["TRUSTED", "callable_ref", "make_callable", "plain", "refused"]

TRUSTED = "ivobs.scenarios"
"""The package whose functions a file may name without ``allow_code`` (ivobs' own code)."""


def callable_ref(fn: Any) -> tuple[str, dict[str, Any]] | None:
    """``("module:qualname", params)`` for a module-level function or a ``functools.partial`` of
    one with keyword parameters; ``None`` for anything a file cannot name (lambdas, closures,
    positional partials, callable objects)."""
    params: dict[str, Any] = {}
    if isinstance(fn, functools.partial):
        if fn.args:
            return None
        params = {k: plain(v) for k, v in fn.keywords.items()}
        fn = fn.func
    module = getattr(fn, "__module__", None)
    qualname = getattr(fn, "__qualname__", None)
    if not module or not qualname or "<" in qualname:
        return None
    path = f"{module}:{qualname}"
    try:
        if resolve(path) is not fn:
            return None
    except IvobsError:
        return None
    return path, params


def plain(value: Any) -> Any:
    """Parameters as plain Python values (what a TOML file can hold and give back)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.generic,)):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def resolve(path: str) -> Any:
    if not isinstance(path, str) or path.count(":") != 1:
        raise IvobsError(f"expected 'package.module:function', got {path!r}")
    mod_name, qualname = path.split(":")
    try:
        obj: Any = importlib.import_module(mod_name)
    except Exception as exc:
        raise IvobsError(f"cannot import module {mod_name!r}: {exc!r}") from None
    for part in qualname.split("."):
        if not hasattr(obj, part):
            raise IvobsError(f"module {mod_name!r} has no attribute {qualname!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise IvobsError(f"{path!r} is not callable")
    return obj


def _trusted_module(name: str) -> bool:
    return name == TRUSTED or name.startswith(TRUSTED + ".")


def refused(path: str) -> str:
    """The message of a callable refused without ``allow_code``."""
    return (
        f"refers to Python code {path}; loading it would run that code: pass --allow-code "
        "(CLI) or allow_code=True (API) if you trust this file"
    )


def make_callable(path: str, params: dict[str, Any], *, allow_code: bool = False) -> Any:
    """The callable named by ``path`` (with keyword ``params``). Without ``allow_code`` only a
    function defined in ``ivobs.scenarios`` (or below) is resolved: no other module is
    imported, and no name re-exported there from elsewhere (``numpy``, ``os``) is reached."""
    if not allow_code:
        if not isinstance(path, str) or path.count(":") != 1:
            raise IvobsError(f"expected 'package.module:function', got {path!r}")
        mod_name, qualname = path.split(":")
        if not _trusted_module(mod_name):
            raise IvobsError(refused(path))
        fn = resolve(path)
        if not (
            _trusted_module(getattr(fn, "__module__", None) or "")
            and getattr(fn, "__qualname__", None) == qualname
        ):
            raise IvobsError(refused(path))
    else:
        fn = resolve(path)
    return functools.partial(fn, **params) if params else fn
