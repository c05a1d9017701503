"""Expressions of a nonlinear model: Python syntax read by :mod:`ast` with a whitelist, turned
into SymPy expressions (never ``eval`` or ``sympify`` of the text: a system file never runs code).

Admitted: numbers (decimal literals taken exactly: ``0.1`` is 1/10), the model's names, ``pi``,
``e``, ``+ - * / **`` (unary ``-``/``+``), and the calls of :data:`FUNCTIONS`. Anything else (an
attribute, a subscript, a lambda, a comparison, a keyword argument...) is refused with the
expression, the column and what was found.
"""

from __future__ import annotations

import ast
from fractions import Fraction
from typing import Any

from ...errors import IvobsError

__all__ = ["FUNCTIONS", "MAX_POWER", "RESERVED", "parse_expression"]

FUNCTIONS = {
    "sin": 1,
    "cos": 1,
    "tan": 1,
    "exp": 1,
    "log": 1,
    "sqrt": 1,
    "tanh": 1,
    "sinh": 1,
    "cosh": 1,
    "atan": 1,
    "asin": 1,
    "acos": 1,
    "abs": 1,
    "min": -2,
    "max": -2,
}
"""Function name -> number of arguments (``-2``: two or more)."""

RESERVED = frozenset(FUNCTIONS) | {"pi", "e"}
"""Names a state, input, parameter or signal may not take."""

MAX_POWER = 1000
"""Largest integer exponent ``|n|`` (a larger one is almost surely a typo)."""

MAX_LENGTH = 20_000
"""Longest expression text accepted."""


def _sympy_functions() -> dict[str, Any]:
    import sympy as sp

    return {
        "sin": sp.sin,
        "cos": sp.cos,
        "tan": sp.tan,
        "exp": sp.exp,
        "log": sp.log,
        "sqrt": sp.sqrt,
        "tanh": sp.tanh,
        "sinh": sp.sinh,
        "cosh": sp.cosh,
        "atan": sp.atan,
        "asin": sp.asin,
        "acos": sp.acos,
        "abs": sp.Abs,
        "min": sp.Min,
        "max": sp.Max,
    }


class _Reader:
    """One expression's AST -> SymPy, with errors that point into the text."""

    def __init__(self, text: str, names: dict[str, Any], where: str):
        import sympy as sp

        self.sp = sp
        self.text, self.names, self.where = text, names, where
        self.funcs = _sympy_functions()

    def fail(self, node: ast.AST | None, what: str, hint: str = "") -> IvobsError:
        col = getattr(node, "col_offset", None)
        at = f" at column {col + 1}" if col is not None else ""
        return IvobsError(f"{self.where} = {self.text!r}: {what}{at}{hint}")

    def read(self, node: ast.AST) -> Any:
        sp = self.sp
        if isinstance(node, ast.Expression):
            return self.read(node.body)
        if isinstance(node, ast.BinOp):
            a, b = self.read(node.left), self.read(node.right)
            op = type(node.op)
            if op is ast.Add:
                return a + b
            if op is ast.Sub:
                return a - b
            if op is ast.Mult:
                return a * b
            if op is ast.Div:
                return a / b
            if op is ast.Pow:
                if b.is_Integer and abs(int(b)) > MAX_POWER:
                    raise self.fail(node, f"integer exponent {b} beyond +-{MAX_POWER}")
                return sp.Pow(a, b)
            raise self.fail(node, f"operator {_op_text(node.op)!r} is not allowed")
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.USub):
                return -self.read(node.operand)
            if isinstance(node.op, ast.UAdd):
                return self.read(node.operand)
            raise self.fail(node, f"operator {_op_text(node.op)!r} is not allowed")
        if isinstance(node, ast.Constant):
            return self.number(node)
        if isinstance(node, ast.Name):
            if node.id in self.names:
                return self.names[node.id]
            if node.id == "pi":
                return sp.pi
            if node.id == "e":
                return sp.E
            if node.id in FUNCTIONS:
                raise self.fail(node, f"function {node.id!r} used without arguments")
            known = ", ".join(sorted(self.names)) or "(none)"
            raise self.fail(node, f"unknown name {node.id!r}", f" (known names: {known}; pi, e)")
        if isinstance(node, ast.Call):
            return self.call(node)
        raise self.fail(node, f"{type(node).__name__} is not allowed in an expression")

    def number(self, node: ast.Constant) -> Any:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(node, f"literal {v!r} is not a real number")
        if isinstance(v, int):
            return self.sp.Integer(v)
        src = ast.get_source_segment(self.text, node) or repr(v)
        exact = Fraction(src.replace("_", ""))  # the decimal as written, exactly
        return self.sp.Rational(exact.numerator, exact.denominator)

    def call(self, node: ast.Call) -> Any:
        fn = node.func
        if not isinstance(fn, ast.Name):
            raise self.fail(node, "only calls of the listed functions are allowed")
        if fn.id not in FUNCTIONS:
            allowed = ", ".join(FUNCTIONS)
            raise self.fail(node, f"unknown function {fn.id!r}", f" (allowed: {allowed})")
        if node.keywords:
            raise self.fail(node, f"{fn.id}() takes no keyword arguments")
        if any(isinstance(a, ast.Starred) for a in node.args):
            raise self.fail(node, f"{fn.id}() takes no *arguments")
        n, got = FUNCTIONS[fn.id], len(node.args)
        if (n > 0 and got != n) or (n < 0 and got < -n):
            want = f"{n}" if n > 0 else f"at least {-n}"
            raise self.fail(node, f"{fn.id}() takes {want} argument(s), got {got}")
        return self.funcs[fn.id](*(self.read(a) for a in node.args))


def _op_text(op: ast.AST) -> str:
    return {
        ast.FloorDiv: "//",
        ast.Mod: "%",
        ast.MatMult: "@",
        ast.BitAnd: "&",
        ast.BitOr: "|",
        ast.BitXor: "^",
        ast.LShift: "<<",
        ast.RShift: ">>",
        ast.Invert: "~",
        ast.Not: "not",
    }.get(type(op), type(op).__name__)


_SYMPY_NAMES = {"Abs": "abs", "Min": "min", "Max": "max", "E": "e"}


def _sympy_text(expr: Any) -> str:
    """A SymPy expression as the text this parser reads (the same whitelist applies: nothing
    SymPy can express beyond it is accepted); numbers keep their exact value."""
    import re

    import sympy

    text = sympy.sstr(expr, full_prec=True)
    return re.sub(r"\b(Abs|Min|Max|E)\b", lambda m: _SYMPY_NAMES[m.group(1)], text)


def parse_expression(text: Any, names: dict[str, Any], where: str) -> Any:
    """The SymPy expression of ``text`` (a string, a number or a SymPy expression) over the
    symbols ``names`` (name -> Symbol); errors name ``where`` (e.g. ``"f[1]"``), the text and
    the column."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        text = repr(text)
    if type(text).__module__.startswith("sympy"):  # a SymPy expression: read as its text
        text = _sympy_text(text)
    if not isinstance(text, str):
        raise IvobsError(f"{where}: expected an expression (str), got {type(text).__name__}")
    if len(text) > MAX_LENGTH:
        raise IvobsError(f"{where}: expression longer than {MAX_LENGTH} characters")
    stripped = text.strip()
    if not stripped:
        raise IvobsError(f"{where}: empty expression")
    try:
        tree = ast.parse(stripped, mode="eval")
    except SyntaxError as exc:
        col = f" at column {exc.offset}" if exc.offset else " at the end"
        raise IvobsError(f"{where} = {text!r}: not a valid expression{col} ({exc.msg})") from None
    except (ValueError, RecursionError, MemoryError) as exc:
        raise IvobsError(f"{where} = {text!r}: not a valid expression ({exc})") from None
    reader = _Reader(stripped, names, where)
    try:
        expr = reader.read(tree)
    except RecursionError:
        raise IvobsError(f"{where} = {text!r}: expression nested too deeply") from None
    if expr.has(reader.sp.zoo, reader.sp.nan, reader.sp.oo, -reader.sp.oo):
        raise IvobsError(f"{where} = {text!r}: the expression is undefined (e.g. a division by 0)")
    return expr
