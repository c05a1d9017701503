"""Python callables as models: traced once with SymPy symbols, and expressions back to text.

A callable ``f(x, u, p, d)`` receives the state and input symbols as tuples and the parameter
and signal symbols as dicts by name; it must return one value per state (output), built with
``+ - * / **`` and the functions of :mod:`ivobs.nlmath` (which act on symbols while tracing and
on floats otherwise). Float constants in the callable are the doubles Python made of them (taken
exactly); the traced expression is checked against the same whitelist as text expressions.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from ...errors import IvobsError

if TYPE_CHECKING:
    from .system import NonlinearSystem

__all__ = ["expression_text", "trace_callable"]


FLOAT_FUNCTIONS: dict[str, Any] = {
    "sin": math.sin, "cos": math.cos, "tan": math.tan, "exp": math.exp, "log": math.log,
    "tanh": math.tanh, "sinh": math.sinh, "cosh": math.cosh, "atan": math.atan,
    "asin": math.asin, "acos": math.acos, "Abs": abs, "Min": min, "Max": max,
}  # fmt: skip
"""The functions of expressions (:data:`~.parse.FUNCTIONS`, but ``sqrt``: a power in SymPy) in
floating point, by SymPy's name."""


def _check(what: str, i: int, e: Any) -> Any:
    import sympy as sp

    if isinstance(e, bool) or not isinstance(e, (int, float, sp.Basic)):
        raise IvobsError(
            f"{what}: value {i} returned by the callable is {type(e).__name__}, not an "
            "expression; build it with + - * / ** and ivobs.nlmath functions (numpy and math "
            "functions cannot be traced)"
        )
    e = sp.sympify(e) if isinstance(e, (int, float)) else e  # a number, not text
    floats = {a: sp.Rational(a) for a in e.atoms(sp.Float)}  # exact doubles
    e = e.xreplace(floats)
    allowed = tuple(getattr(sp, name) for name in FLOAT_FUNCTIONS)
    for node in sp.preorder_traversal(e):
        ok = (
            node.is_Symbol
            or node.is_Number
            or node.is_NumberSymbol
            or node.is_Add
            or node.is_Mul
            or node.is_Pow
            or isinstance(node, allowed)
        )
        if not ok or node.has(sp.I):
            raise IvobsError(f"{what}[{i}]: {type(node).__name__} is not supported ({node})")
        if node.is_Number and not node.is_finite:
            raise IvobsError(f"{what}[{i}]: the expression is undefined ({e})")
    return e


def trace_callable(what: str, fn: Any, sys: NonlinearSystem) -> list[Any]:
    """The SymPy expressions ``fn`` returns on the system's symbols."""
    s = sys._sym
    x = tuple(s[n] for n in sys.state_names)
    u = tuple(s[n] for n in sys.input_names)
    p = {n: s[n] for n in list(sys.known_params) + list(sys.param_bounds)}
    d = {n: s[n] for n in sys.signal_bounds}
    try:
        out = fn(x, u, p, d)
    except IvobsError:
        raise
    except Exception as exc:  # the user's code failed on symbols: say how to write it
        raise IvobsError(
            f"{what}: calling {getattr(fn, '__name__', 'the callable')}(x, u, p, d) with symbols "
            f"failed ({type(exc).__name__}: {exc}); write it with + - * / ** and ivobs.nlmath "
            "functions (x, u are tuples, p, d dicts by name)"
        ) from None
    if not isinstance(out, (list, tuple)):
        try:
            out = list(out)
        except TypeError:
            out = [out]
    return [_check(what, i, e) for i, e in enumerate(out)]


def expression_text(e: Any) -> str:
    """``e`` as an expression string that :func:`~.parse.parse_expression` reads back to the
    same expression (exact rationals as ``p/q``, floats with all their digits, ``abs``,
    ``min``, ``max``, ``e``; the same whitelist applies to it: nothing SymPy can express beyond
    it is accepted)."""
    from sympy.printing.str import StrPrinter

    class _Printer(StrPrinter):  # type: ignore[misc]
        def _print_Abs(self, expr: Any) -> str:
            return f"abs({self._print(expr.args[0])})"

        def _print_Min(self, expr: Any) -> str:
            return f"min({', '.join(self._print(a) for a in expr.args)})"

        def _print_Max(self, expr: Any) -> str:
            return f"max({', '.join(self._print(a) for a in expr.args)})"

        def _print_Exp1(self, expr: Any) -> str:
            return "e"

        def _print_Rational(self, expr: Any) -> str:
            return f"({expr.p}/{expr.q})"

    return str(_Printer({"order": "none", "full_prec": True}).doprint(e))
