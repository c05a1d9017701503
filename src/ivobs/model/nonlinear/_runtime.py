"""The interval operations that the generated code of a :class:`NonlinearSystem` calls.

Not a general interval library: the few operations that the expression whitelist
(:mod:`.parse`) admits, each on ``(lo, hi)`` pairs of Python floats, each returning a pair that
contains the exact real result for every point of its arguments, floating-point rounding
included:

* ``+ - * /`` and integer powers round each bound outward by one ulp (``math.nextafter``): the
  IEEE result of one operation is within half an ulp of the exact one;
* ``sqrt`` is correctly rounded (IEEE): one ulp;
* the other elementary functions come from the platform libm, whose documented error is at most
  2 ulps (glibc's ``libm-test-ulps`` for x86-64 and aarch64: ``tanh``, ``sinh``, ``cosh`` 2; the
  others 1); their bounds are widened by :data:`LIBM_REL` ``= 2**-49`` relative (8 to 16 ulps)
  plus :data:`LIBM_ABS` absolute (subnormal results);
* ``abs``, ``min``, ``max`` and negation are exact.

A range that reaches outside a function's domain is clipped to the domain (the model is only
defined there, so the true state is inside it); a range entirely outside raises
:class:`DomainError`, which the system turns into an :class:`~ivobs.IvobsError` naming the
expression. Division by a range containing 0 gives the (possibly infinite) hull of the quotients,
never NaN; division by exactly ``[0, 0]`` is a domain error.

``tests/test_nonlinear_enclosures.py`` checks every operation against 60-digit mpmath values on
thin and wide, adversarial arguments.
"""

from __future__ import annotations

import math
from collections.abc import Callable

INF = math.inf
NINF = -math.inf
LIBM_REL = 2.0**-49
"""Relative widening of a libm result (>= 8 ulps, 4x the largest documented glibc error)."""
LIBM_ABS = 1e-300
"""Absolute widening of a libm result (covers subnormal results)."""

_nx = math.nextafter


class DomainError(ValueError):
    """A range entirely outside a function's domain (``site``: which call in the generated
    code)."""

    def __init__(self, site: int, what: str, lo: float, hi: float):
        super().__init__(what)
        self.site, self.what, self.lo, self.hi = site, what, lo, hi


def dn(v: float) -> float:
    """A lower bound of the exact value of one IEEE operation whose result is ``v``."""
    return _nx(v, NINF)


def up(v: float) -> float:
    """An upper bound of the exact value of one IEEE operation whose result is ``v``."""
    return _nx(v, INF)


def ldn(v: float) -> float:
    """A lower bound of the exact value of a libm function whose result is ``v`` (an overflow
    to ``inf`` stands for a value above the largest float)."""
    r = v - (abs(v) * LIBM_REL + LIBM_ABS)
    return r if r == r else _nx(v, NINF)


def lup(v: float) -> float:
    """An upper bound of the exact value of a libm function whose result is ``v``."""
    r = v + (abs(v) * LIBM_REL + LIBM_ABS)
    return r if r == r else _nx(v, INF)


def _fix(v: float) -> float:
    # 0 * inf corners (a zero bound times an unbounded one) count as 0 (IEEE 1788)
    return v if v == v else 0.0


def mul(al: float, ah: float, bl: float, bh: float) -> tuple[float, float]:
    """``[a] * [b]`` by sign cases (two products where the signs are known); a ``0 * inf``
    corner (a zero bound times an unbounded one) counts as 0 (IEEE 1788)."""
    if al >= 0.0:
        if bl >= 0.0:
            lo, hi = al * bl, ah * bh
        elif bh <= 0.0:
            lo, hi = ah * bl, al * bh
        else:
            lo, hi = ah * bl, ah * bh
    elif ah <= 0.0:
        if bl >= 0.0:
            lo, hi = al * bh, ah * bl
        elif bh <= 0.0:
            lo, hi = ah * bh, al * bl
        else:
            lo, hi = al * bh, al * bl
    elif bl >= 0.0:
        lo, hi = al * bh, ah * bh
    elif bh <= 0.0:
        lo, hi = ah * bl, al * bl
    else:
        lo = min(_fix(al * bh), _fix(ah * bl))
        hi = max(_fix(al * bl), _fix(ah * bh))
    if lo != lo:
        lo = 0.0
    if hi != hi:
        hi = 0.0
    return _nx(lo, NINF), _nx(hi, INF)


def recip(bl: float, bh: float, site: int) -> tuple[float, float]:
    """``1 / [b]``: the hull of the reciprocals (infinite when ``[b]`` reaches 0)."""
    if bl > 0.0 or bh < 0.0:
        return _nx(1.0 / bh, NINF), _nx(1.0 / bl, INF)
    if bl == 0.0 and bh == 0.0:
        raise DomainError(site, "division by a range that is exactly 0", bl, bh)
    if bl == 0.0:
        return _nx(1.0 / bh, NINF), INF
    if bh == 0.0:
        return NINF, _nx(1.0 / bl, INF)
    return NINF, INF


def div(al: float, ah: float, bl: float, bh: float, site: int) -> tuple[float, float]:
    """``[a] / [b]``: the four quotients where ``[b]`` excludes 0 and all is finite, else
    ``[a] * (1/[b])``."""
    if (bl > 0.0 or bh < 0.0) and -INF < al and ah < INF and -INF < bl and bh < INF:
        q1, q2, q3, q4 = al / bl, al / bh, ah / bl, ah / bh
        return _nx(min(q1, q2, q3, q4), NINF), _nx(max(q1, q2, q3, q4), INF)
    rl, rh = recip(bl, bh, site)
    return mul(al, ah, rl, rh)


def _pos_pow(v: float, n: int, down: bool) -> float:
    """``v**n`` for ``v >= 0`` rounded down or up at every product (monotone, so a bound)."""
    r = v
    step = NINF if down else INF
    for _ in range(n - 1):
        r = _nx(r * v, step)
    return max(r, 0.0) if down else r


def ipow(al: float, ah: float, n: int, site: int) -> tuple[float, float]:
    """``[a]**n`` for an integer ``n`` (even powers of a range around 0 start at 0)."""
    if n == 0:
        return 1.0, 1.0
    if n < 0:
        pl, ph = ipow(al, ah, -n, site)
        return recip(pl, ph, site)
    if n == 1:
        return al, ah
    if n % 2 == 0:
        if al >= 0.0:
            return _pos_pow(al, n, True), _pos_pow(ah, n, False)
        if ah <= 0.0:
            return _pos_pow(-ah, n, True), _pos_pow(-al, n, False)
        return 0.0, _pos_pow(max(-al, ah), n, False)
    lo = _pos_pow(al, n, True) if al >= 0.0 else -_pos_pow(-al, n, False)
    hi = _pos_pow(ah, n, False) if ah >= 0.0 else -_pos_pow(-ah, n, True)
    return lo, hi


def sqr(al: float, ah: float) -> tuple[float, float]:
    """``[a]**2`` (the common case of :func:`ipow`)."""
    if al >= 0.0:
        return max(_nx(al * al, NINF), 0.0), _nx(ah * ah, INF)
    if ah <= 0.0:
        return max(_nx(ah * ah, NINF), 0.0), _nx(al * al, INF)
    m = max(-al, ah)
    return 0.0, _nx(m * m, INF)


def sqrt(al: float, ah: float, site: int) -> tuple[float, float]:
    """``sqrt([a])`` on the part of ``[a]`` at or above 0."""
    if ah < 0.0:
        raise DomainError(site, "sqrt of a range entirely below 0", al, ah)
    lo = max(_nx(math.sqrt(al), NINF), 0.0) if al > 0.0 else 0.0
    return lo, _nx(math.sqrt(ah), INF)


def _big(f: Callable[[float], float], v: float) -> float:
    """``f(v)`` for ``f`` = exp, sinh or cosh, an overflow as the infinity of its sign."""
    try:
        return f(v)
    except OverflowError:
        return NINF if v < 0.0 and f is math.sinh else INF


def exp(al: float, ah: float) -> tuple[float, float]:
    """``exp([a])`` (increasing, positive)."""
    return max(ldn(_big(math.exp, al)), 0.0), lup(_big(math.exp, ah))


def log(al: float, ah: float, site: int) -> tuple[float, float]:
    """``log([a])`` on the part of ``[a]`` above 0."""
    if ah <= 0.0:
        raise DomainError(site, "log of a range entirely at or below 0", al, ah)
    lo = ldn(math.log(al)) if al > 0.0 else NINF
    return lo, lup(math.log(ah))


def _pw(x: float, e: float) -> float:
    """``x**e`` for ``x >= 0`` (libm pow), 0**negative = inf, overflow = inf."""
    if x == 0.0:
        return 0.0 if e > 0.0 else (1.0 if e == 0.0 else INF)
    if x == INF:
        return INF if e > 0.0 else (1.0 if e == 0.0 else 0.0)
    try:
        return math.pow(x, e)
    except OverflowError:
        return INF


def rpow(al: float, ah: float, el: float, eh: float, site: int) -> tuple[float, float]:
    """``[a]**[e]`` for a real exponent: on the part of ``[a]`` at or above 0, where
    ``x**e = exp(e log x)`` is monotone in ``e`` and in ``log x`` (bilinear under exp), so the
    extremes are at the corners."""
    if ah < 0.0:
        raise DomainError(site, "a real power of a range entirely below 0", al, ah)
    al = max(al, 0.0)
    c = (_pw(al, el), _pw(al, eh), _pw(ah, el), _pw(ah, eh))
    return max(ldn(min(c)), 0.0), lup(max(c))


def _monotone(f, al: float, ah: float, lo_cap: float, hi_cap: float) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    return max(ldn(f(al)), lo_cap), min(lup(f(ah)), hi_cap)


PI_HI = math.nextafter(math.pi, INF)
HALF_PI_HI = math.nextafter(math.pi / 2, INF)  # fl(pi/2) < pi/2 < next


def atan(al: float, ah: float) -> tuple[float, float]:
    return _monotone(math.atan, al, ah, -HALF_PI_HI, HALF_PI_HI)


def tanh(al: float, ah: float) -> tuple[float, float]:
    return _monotone(math.tanh, al, ah, -1.0, 1.0)


def sinh(al: float, ah: float) -> tuple[float, float]:
    return ldn(_big(math.sinh, al)), lup(_big(math.sinh, ah))


def cosh(al: float, ah: float) -> tuple[float, float]:
    """``cosh([a])``: even, minimum 1 at 0."""
    lo_c = 1.0 if al <= 0.0 <= ah else max(ldn(_big(math.cosh, min(abs(al), abs(ah)))), 1.0)
    return lo_c, lup(_big(math.cosh, max(abs(al), abs(ah))))


def asin(al: float, ah: float, site: int) -> tuple[float, float]:
    if ah < -1.0 or al > 1.0:
        raise DomainError(site, "asin of a range entirely outside [-1, 1]", al, ah)
    return _monotone(math.asin, max(al, -1.0), min(ah, 1.0), -HALF_PI_HI, HALF_PI_HI)


def acos(al: float, ah: float, site: int) -> tuple[float, float]:
    if ah < -1.0 or al > 1.0:
        raise DomainError(site, "acos of a range entirely outside [-1, 1]", al, ah)
    lo, hi = max(al, -1.0), min(ah, 1.0)
    return max(ldn(math.acos(hi)), 0.0), min(lup(math.acos(lo)), PI_HI)


def _periodic(f, df, al: float, ah: float) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """``sin`` or ``cos`` of ``[a]`` (``df`` its derivative): the hull of the end values, plus
    the maximum 1 / minimum -1 where ``df`` changes sign inside. On a range narrower than 3 (<
    pi) there is at most one critical point, and libm's relative accuracy gives the sign of a
    non-zero ``df`` exactly; an end where ``df`` rounds to 0 may be a critical point of the sign
    of ``f`` there."""
    if not (ah - al < 6.0):  # also inf, nan
        return -1.0, 1.0
    if ah - al >= 3.0:
        m = al + (ah - al) * 0.5
        l1, h1 = _periodic(f, df, al, m)
        l2, h2 = _periodic(f, df, m, ah)
        return min(l1, l2), max(h1, h2)
    fa, fb = f(al), f(ah)
    lo, hi = min(fa, fb), max(fa, fb)
    lo, hi = max(ldn(lo), -1.0), min(lup(hi), 1.0)
    da, db = df(al), df(ah)
    if da > 0.0 and db < 0.0:
        hi = 1.0
    elif da < 0.0 and db > 0.0:
        lo = -1.0
    if da == 0.0:
        lo, hi = (lo, 1.0) if fa > 0 else (-1.0, hi)
    if db == 0.0:
        lo, hi = (lo, 1.0) if fb > 0 else (-1.0, hi)
    return lo, hi


def _neg_sin(v: float) -> float:
    return -math.sin(v)


def sin(al: float, ah: float) -> tuple[float, float]:
    return _periodic(math.sin, math.cos, al, ah)


def cos(al: float, ah: float) -> tuple[float, float]:
    return _periodic(math.cos, _neg_sin, al, ah)


def tan(al: float, ah: float) -> tuple[float, float]:
    """``tan([a])``: increasing between poles; a pole may lie inside when ``cos`` changes sign
    (or rounds to 0) over a range narrower than 3 (< pi): then the whole line."""
    if not (ah - al < 3.0):
        return NINF, INF
    ca, cb = math.cos(al), math.cos(ah)
    if ca == 0.0 or cb == 0.0 or (ca > 0.0) != (cb > 0.0):
        return NINF, INF
    return ldn(math.tan(al)), lup(math.tan(ah))


def iabs(al: float, ah: float) -> tuple[float, float]:
    if al >= 0.0:
        return al, ah
    if ah <= 0.0:
        return -ah, -al
    return 0.0, max(-al, ah)


def sign(al: float, ah: float) -> tuple[float, float]:
    """Generalised derivative of ``abs`` (Clarke): ``[-1, 1]`` wherever the range reaches 0."""
    return (1.0 if al > 0.0 else -1.0), (-1.0 if ah < 0.0 else 1.0)


def heaviside(al: float, ah: float) -> tuple[float, float]:
    """Generalised derivative of ``max``/``min`` in one argument: ``[0, 1]`` at 0."""
    return (1.0 if al > 0.0 else 0.0), (0.0 if ah < 0.0 else 1.0)


NAMESPACE = {
    **{f"_{f.__name__}": f for f in (mul, div, recip, ipow, sqr, sqrt, exp, log, rpow, atan, tanh,
                                     sinh, cosh, asin, acos, sin, cos, tan, sign, heaviside, min,
                                     max)},
    "_abs": iabs, "_nx": _nx, "_NI": NINF, "_PI": INF, "_math": math,
}  # fmt: skip
"""Names the generated code may use (its only globals)."""
