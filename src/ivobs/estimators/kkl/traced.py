"""Functions of time between samples, traced once so that they can be enclosed over intervals.

The continuous-time observer needs, between two samples, guaranteed bounds of the time-varying
matrices ``A(t)``, ``B(t)``, ``E(t)`` (and of the input ``u(t)`` given as a callable) over whole
intervals of time, with their Taylor coefficients: point evaluations of a Python function say
nothing about its values in between. So the callable is called once on a SymPy symbol ``t`` (as
the callables of :class:`~ivobs.NonlinearSystem` are): it must be written with ``+ - * / **``
and the functions of :mod:`ivobs.nlmath` (``nlmath.sin(t)``, not ``np.sin(t)``); NumPy arrays
of the resulting expressions are fine. Its float constants are the doubles the function holds
(taken exactly). The Taylor coefficients ``f^(i)(t) / i!`` are differentiated symbolically and
compiled into straight-line interval code with outward rounding (the generator of the nonlinear
models, :mod:`ivobs.model.nonlinear.codegen`), evaluated on ``[t_lo, t_hi]``: every returned
``(mid, rad)`` contains the exact coefficient at every ``t`` of the interval.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import IvobsError
from ...sets.rounding import mid_rad

__all__ = ["SMOOTH", "TimeFunction", "trace"]

SMOOTH = ("sin", "cos", "tan", "exp", "log", "tanh", "sinh", "cosh", "atan", "asin", "acos")
"""The functions of ``t`` admitted (smooth where defined: Taylor coefficients exist)."""


class TimeFunction:
    """``f(t)`` (a ``shape`` array of functions of ``t``) and its Taylor coefficients up to
    ``order`` (:meth:`coefficients`), enclosed over intervals of time."""

    def __init__(self, name: str, exprs: list[Any], shape: tuple[int, ...], order: int):
        import sympy as sp

        from ...model.nonlinear.codegen import Emitter, compile_source

        self.name, self.shape, self.order = name, shape, order
        t = sp.Symbol("t", real=True)
        sites: list[str] = []
        em = Emitter(sites)
        em.lines.append("def coefficients(tl, th):")
        em.scope({t: ("tl", "th")})
        pairs = []
        for i in range(order + 1):
            if i:
                exprs = [sp.diff(e, t) / i for e in exprs]  # f^(i) / i!
            em.label = f"{name}^({i})"
            pairs += [em.emit(e) for e in exprs]
        em.line(f"return [{', '.join(p[0] for p in pairs)}], [{', '.join(p[1] for p in pairs)}]")
        self._code = compile_source("\n".join(em.lines) + "\n", "coefficients")

    def coefficients(self, tl: float, th: float) -> tuple[np.ndarray, np.ndarray]:
        """``(mid, rad)`` of shape ``(order + 1, *shape)``: enclosures of ``f^(i)(t) / i!`` for
        every ``t`` in ``[tl, th]``."""
        try:
            lo, hi = self._code(float(tl), float(th))
        except (ValueError, ArithmeticError) as exc:
            raise IvobsError(
                f"{self.name}: the function of t is undefined or unbounded on [{tl}, {th}] ({exc})"
            ) from None
        c, r = mid_rad(np.array(lo), np.array(hi))
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(r))):
            raise IvobsError(f"{self.name}: the function of t is unbounded on [{tl}, {th}]")
        shape = (self.order + 1, *self.shape)
        return c.reshape(shape), r.reshape(shape)


def trace(name: str, fn: Any, shape: tuple[int, ...], order: int) -> TimeFunction:
    """``fn(t)`` traced on a symbol ``t`` (module docstring), as a :class:`TimeFunction` with
    Taylor coefficients up to ``order``; an :class:`~ivobs.IvobsError` naming ``name`` when it
    cannot be traced."""
    import sympy as sp

    t = sp.Symbol("t", real=True)
    how = (
        "; write it with + - * / ** and the functions of ivobs.nlmath (nlmath.sin(t), not "
        "np.sin(t) or math.sin(t)), so that it can be bounded between samples"
    )
    try:
        value = fn(t)
        arr = np.asarray(value, dtype=object)
    except Exception as exc:  # the user's function cannot take a symbol
        raise IvobsError(
            f"{name}: calling {name}(t) on a symbolic t failed ({exc!r}){how}"
        ) from None
    if arr.size != int(np.prod(shape)):
        raise IvobsError(
            f"{name}: {name}(t) on a symbolic t gave shape {arr.shape}, expected {shape}"
        )
    exprs = []
    for v in arr.ravel():
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.number, sp.Basic)):
            raise IvobsError(f"{name}: {name}(t) returned {type(v).__name__}{how}")
        e = sp.sympify(float(v) if isinstance(v, np.number) else v)
        e = e.xreplace({a: sp.Rational(a) for a in e.atoms(sp.Float)})  # the doubles, exactly
        smooth = tuple(getattr(sp, f) for f in SMOOTH)
        bad = [
            n
            for n in sp.preorder_traversal(e)
            if not (n.is_Symbol or n.is_Number or n.is_NumberSymbol or n.is_Add or n.is_Mul)
            and not (n.is_Pow or isinstance(n, smooth))
        ]
        if bad or e.free_symbols - {t}:
            raise IvobsError(f"{name}: {name}(t) contains {bad[0] if bad else e} {how}")
        exprs.append(e)
    return TimeFunction(name, exprs, shape, order)
