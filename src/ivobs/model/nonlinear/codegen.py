"""SymPy expressions -> straight-line Python code over ``(lo, hi)`` float pairs, outward rounded.

The generated source is ours: it is written from SymPy trees whose leaves are the model's
symbols and exact numbers (read from a whitelisted AST, :mod:`.parse`), and calls only the
operations of :mod:`._runtime`. It is compiled once per system. Identical subexpressions are
computed once per function (the natural form, the Jacobian and the contractor share them).

Numbers: an exact rational is enclosed by the floats around it (``0.1`` -> ``[fl(0.1),
next(fl(0.1))]``), other constants (``pi``, ``sqrt(2)``) by the floats around a 60-digit value.
An operation on constants only (a known parameter times ``sqrt(2)``) is evaluated once, when the
code is written, by the same runtime operation the code would call (:meth:`Emitter.fold`): the
code holds the resulting enclosure as literals (``repr`` of a double reads back exactly), so it
computes the same bounds with fewer operations per call.
"""

from __future__ import annotations

import keyword
import math
import re
from fractions import Fraction
from typing import Any

from ...errors import IvobsError
from ._runtime import NAMESPACE

__all__ = [
    "Emitter",
    "compile_source",
    "enclose_constant",
    "is_literal",
    "lower_of",
    "product",
    "quotient",
    "upper_of",
]

Pair = tuple[str, str]

_NAME = re.compile(r"(?<![\w.])[A-Za-z_]\w*")
"""A name in code (an exponent's ``e`` follows a digit: not one)."""


def _reads_variable(code: str) -> bool:
    """Whether ``code`` reads a variable of the generated code: a name that is neither the
    runtime's (they start with ``_``) nor a keyword (``if``, ``else``)."""
    return any(not (n.startswith("_") or keyword.iskeyword(n)) for n in _NAME.findall(code))


def is_literal(p: Pair) -> bool:
    """Whether the pair is code over literals and the runtime's names only (no variable)."""
    return not (_reads_variable(p[0]) or _reads_variable(p[1]))


def lower_of(a: str, b: str) -> str:
    """Code of ``max(a, b)`` for names or literals (each read twice) with the builtin's result,
    ``a`` unless ``b > a`` (so a NaN ``b`` leaves ``a``), without its call."""
    return f"{b} if {b} > {a} else {a}"


def upper_of(a: str, b: str) -> str:
    """Code of ``min(a, b)`` likewise: ``a`` unless ``b < a``."""
    return f"{b} if {b} < {a} else {a}"


def _sign(p: Pair) -> int:
    """1 or -1 for a literal pair of finite bounds above or below 0, else 0."""
    if not is_literal(p):
        return 0
    try:
        lo, hi = float(p[0]), float(p[1])
    except ValueError:  # _PI, _NI
        return 0
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return 0
    return 1 if lo > 0.0 else -1 if hi < 0.0 else 0


def product(a: Pair, b: Pair) -> str:
    """Code of the pair ``a * b``, outward rounded. Where one factor is a constant of known sign
    ``[cl, ch]`` the sign of the other's bound picks each product inline (``c > 0``: ``lo =
    cl o_lo`` if ``o_lo >= 0`` else ``ch o_lo``, and so on): the products
    :func:`._runtime.mul` picks in the same cases, the same two bounds, without its call and
    tests; otherwise :func:`._runtime.mul`."""
    for c, o in ((a, b), (b, a)):
        sign = _sign(c)
        if sign > 0:
            return (
                f"_nx(({c[0]} * {o[0]}) if {o[0]} >= 0.0 else ({c[1]} * {o[0]}), _NI), "
                f"_nx(({c[1]} * {o[1]}) if {o[1]} >= 0.0 else ({c[0]} * {o[1]}), _PI)"
            )
        if sign < 0:
            return (
                f"_nx(({c[0]} * {o[1]}) if {o[1]} >= 0.0 else ({c[1]} * {o[1]}), _NI), "
                f"_nx(({c[0]} * {o[0]}) if {o[0]} <= 0.0 else ({c[1]} * {o[0]}), _PI)"
            )
    return f"_mul({a[0]}, {a[1]}, {b[0]}, {b[1]})"


def quotient(r: Pair, c: Pair) -> str | None:
    """Code of the pair ``r / c`` for a constant ``c`` of known sign, outward rounded: the
    extreme quotients picked by the signs of ``r``'s bounds (``c > 0``: ``lo = r_lo / ch`` if
    ``r_lo >= 0`` else ``r_lo / cl``, and so on), as :func:`._runtime.div` finds them among
    the four where ``r`` is finite (an infinite bound of ``r`` gives the exact quotient's
    correctly rounded neighbour, no wider than ``div``'s). None for any other ``c``."""
    sign = _sign(c)
    if sign > 0:
        return (
            f"_nx(({r[0]} / {c[1]}) if {r[0]} >= 0.0 else ({r[0]} / {c[0]}), _NI), "
            f"_nx(({r[1]} / {c[0]}) if {r[1]} >= 0.0 else ({r[1]} / {c[1]}), _PI)"
        )
    if sign < 0:
        return (
            f"_nx(({r[1]} / {c[1]}) if {r[1]} >= 0.0 else ({r[1]} / {c[0]}), _NI), "
            f"_nx(({r[0]} / {c[0]}) if {r[0]} >= 0.0 else ({r[0]} / {c[1]}), _PI)"
        )
    return None


def _lit(v: float) -> str:
    if v == math.inf:
        return "_PI"
    if v == -math.inf:
        return "_NI"
    return repr(float(v))


def _exact(p: Pair) -> bool:
    """A pair of equal finite non-zero literals (a thin constant)."""
    if p[0] != p[1] or p[0].startswith(("t", "x", "u", "w", "c", "d", "v", "_")):
        return False
    try:
        v = float(p[0])
    except ValueError:
        return False
    return math.isfinite(v) and v != 0.0


def _enclose_fraction(q: Fraction) -> tuple[float, float]:
    try:
        f = float(q)  # correctly rounded
    except OverflowError:
        return (math.nextafter(math.inf, 0.0), math.inf) if q > 0 else (-math.inf, -1.7e308)
    exact = Fraction(f) if math.isfinite(f) else None
    if exact == q:
        return f, f
    if exact is not None and exact < q:
        return f, math.nextafter(f, math.inf)
    return math.nextafter(f, -math.inf), f


def enclose_constant(expr: Any) -> tuple[float, float]:
    """Floats ``lo <= expr <= hi`` for a constant SymPy expression."""
    import sympy as sp

    if expr.is_Rational:
        return _enclose_fraction(Fraction(int(expr.p), int(expr.q)))
    val = sp.N(expr, 60)
    if not val.is_real or not val.is_finite:
        raise IvobsError(f"constant {expr} is not a finite real number")
    f = float(val)
    return math.nextafter(f, -math.inf), math.nextafter(f, math.inf)


def enclose_float(v: float) -> tuple[float, float]:
    """The hull of a float and the decimal it prints as (a number a user typed: ``0.3`` is
    both the double and 3/10)."""
    dec = Fraction(repr(float(v)))
    lo, hi = _enclose_fraction(dec)
    return min(lo, v), max(hi, v)


class Emitter:
    """Writes the code of one function; ``env`` maps a symbol to its ``(lo, hi)`` variables or
    literals; ``label`` names the expression being emitted (for domain errors)."""

    def __init__(self, sites: list[str]):
        import sympy as sp

        self.sp = sp
        self.lines: list[str] = []
        self.sites = sites
        self.label = ""
        self._n = 0
        self.cache: dict[Any, Pair] = {}
        self.env: dict[Any, Pair] = {}

    def new(self) -> Pair:
        self._n += 1
        return f"t{self._n}l", f"t{self._n}h"

    def line(self, text: str) -> None:
        self.lines.append("    " + text)

    def site(self) -> int:
        self.sites.append(self.label)
        return len(self.sites) - 1

    def scope(self, env: dict[Any, Pair]) -> None:
        """Start emitting over another environment (a new cache)."""
        self.env, self.cache = env, {}

    def emit(self, expr: Any) -> Pair:
        """Variables (or literals) holding an enclosure of ``expr``."""
        if expr in self.cache:
            return self.cache[expr]
        out = self._emit(expr)
        self.cache[expr] = out
        return out

    def fold(self, call: str) -> Pair | None:
        """The literals of the pair that ``call`` evaluates to when it reads no variable: the
        runtime operation done once here instead of at every call of the generated code (the
        same operation on the same doubles, so the same enclosure). None when ``call`` reads a
        variable, or when its value is not a pair of numbers (a domain error, a NaN: left to
        the generated code, which reports it where it occurs)."""
        if _reads_variable(call):
            return None
        try:
            v = eval(call, {**NAMESPACE, "__builtins__": {}})  # our code, literals only
        except Exception:  # any failure: not folded, the call stays
            return None
        if not isinstance(v, tuple) or len(v) != 2:
            return None
        lo, hi = v
        if not (isinstance(lo, float) and isinstance(hi, float)) or lo != lo or hi != hi:
            return None
        return _lit(lo), _lit(hi)

    def assign(self, call: str) -> Pair:
        folded = self.fold(call)
        if folded is not None:
            return folded
        lo, hi = self.new()
        self.line(f"{lo}, {hi} = {call}")
        return lo, hi

    def _emit(self, e: Any) -> Pair:
        sp = self.sp
        if e.is_Symbol:
            if e not in self.env:
                raise IvobsError(f"{self.label}: symbol {e} has no value here (a bug)")
            return self.env[e]
        if not e.free_symbols:
            c = enclose_constant(e)
            return _lit(c[0]), _lit(c[1])
        if e.is_Add:
            return self._sum([self.emit(a) for a in e.args])
        if e.is_Mul:
            return self._product(e)
        if e.is_Pow:
            return self._pow(e.base, e.exp)
        fn = type(e)
        a = self.emit(e.args[0])
        call = f"_{fn.__name__.lower()}"  # its function in the runtime (_runtime.NAMESPACE)
        simple = (sp.sin, sp.cos, sp.tan, sp.exp, sp.tanh, sp.sinh, sp.cosh, sp.atan, sp.Abs)
        if fn in simple or fn in (sp.sign, sp.Heaviside):
            return self.assign(f"{call}({a[0]}, {a[1]})")
        if fn in (sp.log, sp.asin, sp.acos):  # defined on part of the line: a site for errors
            return self.assign(f"{call}({a[0]}, {a[1]}, {self.site()})")
        if fn in (sp.Min, sp.Max):
            parts = [a] + [self.emit(x) for x in e.args[1:]]
            which = "_min" if fn is sp.Min else "_max"
            return self.assign(
                f"{which}({', '.join(p[0] for p in parts)}), "
                f"{which}({', '.join(p[1] for p in parts)})"
            )
        raise IvobsError(
            f"{self.label}: {fn.__name__} is not supported by the interval code generator"
        )

    def _sum(self, terms: list[Pair]) -> Pair:
        acc = terms[0]
        for t in terms[1:]:
            acc = self.assign(f"_nx({acc[0]} + {t[0]}, _NI), _nx({acc[1]} + {t[1]}, _PI)")
        return acc

    def mul(self, a: Pair, b: Pair) -> Pair:
        if a == ("1.0", "1.0"):
            return b
        if b == ("1.0", "1.0"):
            return a
        if a == ("-1.0", "-1.0") or b == ("-1.0", "-1.0"):
            o = b if a == ("-1.0", "-1.0") else a
            return self.assign(f"-{o[1]}, -{o[0]}")
        c, o = (a, b) if _exact(a) else (b, a)
        if _exact(c):  # a thin constant: its sign decides which bound is which
            v = float(c[0])
            lo, hi = (o[0], o[1]) if v > 0 else (o[1], o[0])
            return self.assign(f"_nx({v!r} * {lo}, _NI), _nx({v!r} * {hi}, _PI)")
        return self.assign(product(a, b))

    def _product(self, e: Any) -> Pair:
        sp = self.sp
        negate = False
        num: list[Pair] = []
        den: list[Any] = []
        for f in e.args:
            if f == sp.Integer(-1):
                negate = not negate
            elif f.is_Pow and f.exp.is_Integer and f.exp < 0:
                den.append(sp.Pow(f.base, -f.exp))
            else:
                num.append(self.emit(f))
        acc: Pair | None = None
        for p in num:
            acc = p if acc is None else self.mul(acc, p)
        if den:
            d = self.emit(sp.Mul(*den)) if len(den) > 1 else self.emit(den[0])
            if acc is None:
                acc = self.assign(f"_recip({d[0]}, {d[1]}, {self.site()})")
            else:
                acc = self.assign(f"_div({acc[0]}, {acc[1]}, {d[0]}, {d[1]}, {self.site()})")
        assert acc is not None
        if negate:
            acc = self.assign(f"-{acc[1]}, -{acc[0]}")
        return acc

    def _pow(self, base: Any, ex: Any) -> Pair:
        sp = self.sp
        b = self.emit(base)
        if ex.is_Integer:
            n = int(ex)
            if n == 2:
                return self.assign(f"_sqr({b[0]}, {b[1]})")
            if n == -1:
                return self.assign(f"_recip({b[0]}, {b[1]}, {self.site()})")
            return self.assign(f"_ipow({b[0]}, {b[1]}, {n}, {self.site()})")
        if ex == sp.Rational(1, 2):
            return self.assign(f"_sqrt({b[0]}, {b[1]}, {self.site()})")
        if ex == sp.Rational(-1, 2):  # 1/sqrt(b): the square root the function may have already
            s = self.emit(sp.sqrt(base))
            return self.assign(f"_recip({s[0]}, {s[1]}, {self.site()})")
        x = self.emit(ex)
        return self.assign(f"_rpow({b[0]}, {b[1]}, {x[0]}, {x[1]}, {self.site()})")


def compile_source(source: str, name: str, extra: dict[str, Any] | None = None) -> Any:
    """Compile generated ``source`` defining function ``name`` with the runtime (and
    ``extra``) as its only globals."""
    namespace: dict[str, Any] = dict(NAMESPACE)
    namespace.update(extra or {})
    namespace["__builtins__"] = {}
    exec(compile(source, f"<ivobs generated {name}>", "exec"), namespace)
    return namespace[name]
