"""Math functions for model callables of :class:`~ivobs.NonlinearSystem`.

Write ``f(x, u, p, d)`` with these instead of ``math``/``numpy``: on SymPy symbols (while the
system traces the callable once) they build the expression; on floats they compute as ``math``
does, so the same callable also simulates. ``nlmath.pi`` and ``nlmath.e`` are exact (SymPy's)
constants (a float ``math.pi`` would be taken as the double it is).

>>> from ivobs import nlmath as m
>>> def f(x, u, p, d):
...     return [x[0] + 0.1 * x[1], x[1] - 0.1 * p["g"] * m.sin(x[0])]
"""

from __future__ import annotations

import math
from typing import Any

__all__ = [
    "abs",
    "acos",
    "asin",
    "atan",
    "cos",
    "cosh",
    "exp",
    "log",
    "max",
    "min",
    "sin",
    "sinh",
    "sqrt",
    "tan",
    "tanh",
]

_builtin_abs, _builtin_min, _builtin_max = abs, min, max


def _symbolic(*xs: Any) -> bool:
    return any(type(x).__module__.startswith("sympy") for x in xs)


def _unary(name: str, fallback: Any) -> Any:
    def fn(x: Any) -> Any:
        if _symbolic(x):
            import sympy as sp

            return getattr(sp, name)(x)
        return fallback(x)

    fn.__name__ = fn.__qualname__ = name if name != "Abs" else "abs"
    fn.__doc__ = f"``{fn.__name__}(x)``: SymPy on symbols, ``math`` on numbers."
    return fn


sin = _unary("sin", math.sin)
cos = _unary("cos", math.cos)
tan = _unary("tan", math.tan)
exp = _unary("exp", math.exp)
log = _unary("log", math.log)
sqrt = _unary("sqrt", math.sqrt)
tanh = _unary("tanh", math.tanh)
sinh = _unary("sinh", math.sinh)
cosh = _unary("cosh", math.cosh)
atan = _unary("atan", math.atan)
asin = _unary("asin", math.asin)
acos = _unary("acos", math.acos)
abs = _unary("Abs", _builtin_abs)


def min(*xs: Any) -> Any:
    """``min(a, b, ...)``."""
    if _symbolic(*xs):
        import sympy as sp

        return sp.Min(*xs)
    return _builtin_min(xs)


def max(*xs: Any) -> Any:
    """``max(a, b, ...)``."""
    if _symbolic(*xs):
        import sympy as sp

        return sp.Max(*xs)
    return _builtin_max(xs)


def __getattr__(name: str) -> Any:
    if name in ("pi", "e"):
        import sympy as sp

        return sp.pi if name == "pi" else sp.E
    raise AttributeError(name)
