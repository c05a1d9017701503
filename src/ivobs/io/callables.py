"""Callables by import path: a matrix or a bound of a system file may name a module-level
function (``{ python = "package.module:function", params = {...} }``).

**Security**: resolving a path imports its module, which runs its code.
"""

from __future__ import annotations

import functools
import importlib
from typing import Any

import numpy as np

from ..errors import IvobsError

__all__ = ["callable_ref", "make_callable", "plain"]


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


def make_callable(path: str, params: dict[str, Any]) -> Any:
    fn = resolve(path)
    return functools.partial(fn, **params) if params else fn
