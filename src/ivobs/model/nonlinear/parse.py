"""Expressions of a nonlinear model: Python syntax read by :mod:`ast` with a whitelist, turned
into SymPy expressions (never ``eval`` or ``sympify`` of the text: a system file never runs code).

Admitted: numbers (decimal literals taken exactly: ``0.1`` is 1/10), the model's names, ``pi``,
``e``, ``+ - * / **`` (unary ``-``/``+``), and the calls of :data:`FUNCTIONS`. Anything else (an
attribute, a subscript, a lambda, a comparison, a keyword argument...) is refused with the
expression, the column and what was found. A name must be written as Python reads it: Python
folds identifiers to their NFKC form (``ｘ1`` would mean ``x1``), so a name that folding
changes is refused.

**Bounded work.** SymPy computes with exact numbers and folds powers (``(x**a)**b`` is
``x**(a b)``), so a few characters could ask for a number of a billion digits. Every limit is
checked before the work it bounds, and an expression beyond one is refused naming it: decimal
exponents within ``±``:data:`MAX_DECIMAL_EXPONENT`, exact constants of at most
:data:`MAX_CONSTANT_BITS` bits (numerator and denominator, checked before a power is
computed), numeric exponents within ``±``:data:`MAX_POWER` after folding, and every constant
subexpression (``exp(1000)``, ``pi**700``) within ``±``:data:`MAX_CONSTANT` (evaluated in
floating point, which cannot hang: ``exp(exp(exp(100)))`` is refused at once).
"""

from __future__ import annotations

import ast
import math
import unicodedata
from decimal import Decimal, InvalidOperation
from fractions import Fraction
from typing import Any

from ...errors import IvobsError
from .trace import FLOAT_FUNCTIONS, expression_text

__all__ = [
    "FUNCTIONS",
    "MAX_CONSTANT",
    "MAX_CONSTANT_BITS",
    "MAX_DECIMAL_EXPONENT",
    "MAX_POWER",
    "RESERVED",
    "folded_name",
    "parse_expression",
]

FUNCTIONS = {n.lower(): -2 if n in ("Min", "Max") else 1 for n in FLOAT_FUNCTIONS} | {"sqrt": 1}
"""Function name -> number of arguments (``-2``: two or more)."""

RESERVED = frozenset(FUNCTIONS) | {"pi", "e"}
"""Names a state, input, parameter or signal may not take."""

MAX_POWER = 1000
"""Largest numeric exponent ``|n|``, also after SymPy folds powers (``(x**1000)**1000``)."""

MAX_DECIMAL_EXPONENT = 400
"""Largest decimal exponent of a literal (``1e400``; a float ends at about ``1e308``)."""

MAX_CONSTANT_BITS = 4096
"""Largest exact constant: numerator and denominator of at most this many bits (about 1233
digits; ``9**999`` has 3167 bits)."""

MAX_CONSTANT = 1e300
"""Largest magnitude of a constant subexpression (a float ends at about ``1.8e308``; the
outward-rounded code needs room above it)."""

MAX_LENGTH = 20_000
"""Longest expression text accepted."""


class _Reader:
    """One expression's AST -> SymPy, with errors that point into the text."""

    def __init__(self, text: str, names: dict[str, Any], where: str):
        import sympy as sp

        self.sp = sp
        self.text, self.names, self.where = text, names, where
        # FUNCTIONS by SymPy's names (Abs, Min, Max for abs, min, max)
        self.funcs = {n.lower(): getattr(sp, n) for n in FLOAT_FUNCTIONS} | {"sqrt": sp.sqrt}

    def limit(self, node: ast.AST, value: Any) -> Any:
        """``value``, refused when it is an exact constant of more than
        :data:`MAX_CONSTANT_BITS` bits or a power beyond :data:`MAX_POWER` (folded or not)."""
        if value.is_Rational:
            bits = max(int(value.p).bit_length(), int(value.q).bit_length())
            if bits > MAX_CONSTANT_BITS:
                raise self.fail(
                    node,
                    f"exact constant of {bits} bits, beyond the limit of {MAX_CONSTANT_BITS} "
                    "bits (far outside the float range)",
                )
            return value
        for term in (value, *(value.args if value.is_Mul else ())):
            exp = term.exp if term.is_Pow else None
            if exp is not None and exp.is_Rational and abs(exp) > MAX_POWER:
                raise self.fail(
                    node,
                    f"power with exponent {exp} (powers folded), beyond the limit of +-{MAX_POWER}",
                )
        return value

    def power(self, node: ast.AST, a: Any, b: Any) -> Any:
        """``a**b``, its size checked before SymPy computes it."""
        if b.is_Rational:
            if abs(b) > MAX_POWER:
                what = "integer exponent" if b.is_Integer else "exponent"
                raise self.fail(node, f"{what} {b} beyond the limit of +-{MAX_POWER}")
            if a.is_Rational and a != 0:
                bits = max(int(a.p).bit_length(), int(a.q).bit_length())
                if bits * abs(b) > MAX_CONSTANT_BITS:
                    raise self.fail(
                        node,
                        f"exact constant of about {int(bits * abs(b))} bits, beyond the limit "
                        f"of {MAX_CONSTANT_BITS} bits (far outside the float range)",
                    )
        return self.limit(node, self.sp.Pow(a, b))

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
                return self.limit(node, a + b)
            if op is ast.Sub:
                return self.limit(node, a - b)
            if op is ast.Mult:
                return self.limit(node, a * b)
            if op is ast.Div:
                return self.limit(node, a / b)
            if op is ast.Pow:
                return self.power(node, a, b)
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
            self.as_written(node, node.id)
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

    def as_written(self, node: ast.AST, name: str) -> None:
        """Refuse a name that Python's NFKC folding changed (``ｘ1`` read as ``x1``)."""
        written = ast.get_source_segment(self.text, node)
        if written is not None and written != name:
            raise self.fail(
                node,
                f"name {written!r} is read by Python as {name!r} (Unicode NFKC folding)",
                f"; write {name!r}",
            )

    def number(self, node: ast.Constant) -> Any:
        v = node.value
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise self.fail(node, f"literal {v!r} is not a real number")
        if isinstance(v, int):
            return self.limit(node, self.sp.Integer(v))
        src = (ast.get_source_segment(self.text, node) or repr(v)).replace("_", "")
        try:
            dec = Decimal(src)
        except InvalidOperation:  # pragma: no cover - ast gave a float literal
            raise self.fail(node, f"literal {src!r} is not a decimal number") from None
        if dec and abs(dec.adjusted()) > MAX_DECIMAL_EXPONENT:
            raise self.fail(
                node,
                f"decimal exponent of {src[:40]!r} beyond the limit of "
                f"+-{MAX_DECIMAL_EXPONENT} (a float ends at about 1e308)",
            )
        exact = Fraction(dec)  # the decimal as written, exactly
        return self.limit(node, self.sp.Rational(exact.numerator, exact.denominator))

    def call(self, node: ast.Call) -> Any:
        fn = node.func
        if not isinstance(fn, ast.Name):
            raise self.fail(node, "only calls of the listed functions are allowed")
        self.as_written(fn, fn.id)
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
        return self.limit(node, self.funcs[fn.id](*(self.read(a) for a in node.args)))


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


def parse_expression(text: Any, names: dict[str, Any], where: str) -> Any:
    """The SymPy expression of ``text`` (a string, a number or a SymPy expression) over the
    symbols ``names`` (name -> Symbol); errors name ``where`` (e.g. ``"f[1]"``), the text and
    the column."""
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        text = repr(text)
    if type(text).__module__.startswith("sympy"):  # a SymPy expression: read as its text
        text = expression_text(text)
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
        if expr.has(reader.sp.zoo, reader.sp.nan, reader.sp.oo, -reader.sp.oo):
            raise IvobsError(
                f"{where} = {text!r}: the expression is undefined (e.g. a division by 0)"
            )
        _check_constants(expr, f"{where} = {text!r}")
    except RecursionError:
        raise IvobsError(f"{where} = {text!r}: expression nested too deeply") from None
    return expr


def _check_constants(expr: Any, what: str) -> None:
    """Refuse a constant subexpression beyond :data:`MAX_CONSTANT` in magnitude (or not real):
    each is evaluated once, bottom-up, in floating point (an overflow is an error at once,
    where SymPy's exact evaluation of ``exp(exp(exp(100)))`` would not end)."""

    def value(e: Any) -> float | None:
        """The float value of ``e`` when it is constant, else None."""
        if e.is_Symbol:
            return None
        args = [value(a) for a in e.args]
        if any(a is None for a in args):
            return None
        try:
            if e.is_Rational:
                v = int(e.p) / int(e.q)
            elif e.is_NumberSymbol:
                v = float(e)
            elif e.is_Add:
                v = math.fsum(args)  # type: ignore[arg-type]
            elif e.is_Mul:
                v = math.prod(args)  # type: ignore[arg-type]
            elif e.is_Pow:
                v = math.pow(args[0], args[1])  # type: ignore[arg-type]
            elif type(e).__name__ in FLOAT_FUNCTIONS:
                v = FLOAT_FUNCTIONS[type(e).__name__](*args)
            else:
                raise ValueError(type(e).__name__)
        except OverflowError:
            v = math.inf
        except (ValueError, ZeroDivisionError, TypeError):
            raise IvobsError(f"{what}: the constant {e} is not a finite real number") from None
        if not abs(v) <= MAX_CONSTANT:  # NaN included
            raise IvobsError(
                f"{what}: the constant {str(e)[:60]} is beyond the limit of +-{MAX_CONSTANT:g} "
                "(floats end at about 1.8e308)"
            )
        return float(v)

    value(expr)


def folded_name(name: str) -> str:
    """``name`` as Python reads it in an expression (NFKC folding): a model's name must equal
    it, or no expression could refer to it (``ｘ1`` is read as ``x1``)."""
    return unicodedata.normalize("NFKC", name)
