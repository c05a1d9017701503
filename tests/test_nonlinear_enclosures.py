"""Every operation of the generated interval code against 40-digit mpmath truths: each bound
must contain the exact range of the function over the box (thin boxes: the exact value), on
thousands of thin and wide, adversarial arguments per function (near 0 and subnormals, near
multiples of pi/2, huge arguments, near overflow, near the edges of the domains), and be tight
on thin boxes (a few ulps)."""

from __future__ import annotations

import math
import re

import mpmath as mp
import numpy as np
import pytest

import ivobs
from ivobs.model.nonlinear import _runtime as rt

mp.mp.dps = 40
RNG = np.random.default_rng(20261125)
PI = mp.pi


def _ulps(x: float, n: int) -> list[float]:
    out = [x]
    lo = hi = x
    for _ in range(n):
        lo, hi = math.nextafter(lo, -math.inf), math.nextafter(hi, math.inf)
        out += [lo, hi]
    return out


def _points(kind: str) -> list[float]:
    """Adversarial and random arguments for a family of functions."""
    base = [0.0, 5e-324, -5e-324, 1e-310, -1e-310, 1e-300, -1e-300, 1e-20, -1e-20, 1e-8, -1e-8]
    base += [0.5, -0.5, 1.0, -1.0, 2.0, -3.0]
    if kind == "periodic":
        for k in [*list(range(-40, 41)), 10**5, -(10**5), 10**9, 10**12]:
            base += _ulps(float(k * PI / 2), 2)
        base += [1e10, -1e10, 1e15, 1e22, -1e22, 1e100, 1e300, -1e300, 1.7e308, 6.28, 3.14159]
        base += RNG.uniform(-20, 20, 1200).tolist() + RNG.uniform(-1e6, 1e6, 200).tolist()
    elif kind == "tanh":
        base += RNG.uniform(-20, 20, 1500).tolist() + RNG.uniform(-1, 1, 500).tolist()
        base += [19.06, 22.0, 40.0, -40.0, 1e300, -1e300]
    elif kind == "exp":
        base += _ulps(709.782712893384, 3) + _ulps(-745.1332191019411, 3) + [710.0, -746.0]
        base += RNG.uniform(-750, 712, 1200).tolist() + RNG.uniform(-2, 2, 400).tolist()
        base += [1e300, -1e300]
    elif kind == "positive":
        base = [5e-324, 1e-310, 1e-300, 1e-20, 1e-8, 0.5, 2.0, 1e22, 1e300, 1.7e308]
        base += _ulps(1.0, 4) + _ulps(math.e, 2)
        base += (10.0 ** RNG.uniform(-300, 300, 1200)).tolist() + RNG.uniform(0, 3, 400).tolist()
    elif kind == "unit":
        base += _ulps(1.0, 4) + _ulps(-1.0, 4) + _ulps(0.5, 2)
        base += RNG.uniform(-1, 1, 1500).tolist()
        base = [b for b in base if -1.0 <= b <= 1.0]
    elif kind == "wide":
        base += [1e10, -1e10, 1e22, 1e300, -1e300, 1e100]
        base += RNG.uniform(-50, 50, 1200).tolist() + (10.0 ** RNG.uniform(-300, 300, 300)).tolist()
    return base


WIDTHS = [0.0, 0.0, 1e-12, 1e-6, 1e-3, 0.1, 0.7, 1.5, 2.9, 3.2, 5.0, 6.1, 7.0, 30.0]


def _boxes(points: list[float], domain: tuple[float, float] | None = None) -> list[tuple]:
    boxes = []
    for i, a in enumerate(points):
        w = WIDTHS[i % len(WIDTHS)] * (1.0 + abs(a) * (i % 3 == 0) * 1e-3)
        b = a + w
        if not math.isfinite(b):
            b = a
        if domain is not None:
            a, b = max(a, domain[0]), min(b, domain[1])
            if a > b:
                continue
        boxes.append((a, b))
        boxes.append((a, a))
    return boxes


def _range_monotone(fm, a: float, b: float, increasing: bool = True) -> tuple:
    va, vb = fm(mp.mpf(a)), fm(mp.mpf(b))
    return (va, vb) if increasing else (vb, va)


def _crit(A, B, phase) -> tuple[int, int]:
    """First and last ``k`` with ``phase + k pi`` in ``[A, B]`` (enough digits for 1e308)."""
    with mp.workdps(400):
        ph = mp.pi / 2 if phase != 0 else mp.mpf(0)
        return int(mp.ceil((A - ph) / mp.pi)), int(mp.floor((B - ph) / mp.pi))


def _range_periodic(fm, a: float, b: float, phase) -> tuple:
    """Exact range of sin/cos over [a, b]: the ends and the critical points
    ``phase + k pi`` inside."""
    A, B = mp.mpf(a), mp.mpf(b)
    vals = [fm(A), fm(B)]
    k0, k1 = _crit(A, B, phase)
    if k1 - k0 >= 2:
        return mp.mpf(-1), mp.mpf(1)
    vals += [mp.mpf(-1) ** k for k in range(k0, k1 + 1)]  # sin(pi/2 + k pi) = cos(k pi)
    return min(vals), max(vals)


def _check(name: str, got: tuple[float, float], truth: tuple, a: float, b: float) -> None:
    lo, hi = got
    assert lo == lo and hi == hi, f"{name}[{a!r}, {b!r}]: NaN bound"
    assert mp.mpf(lo) <= truth[0], f"{name}[{a!r}, {b!r}]: lower {lo!r} > {truth[0]}"
    assert truth[1] <= mp.mpf(hi), f"{name}[{a!r}, {b!r}]: upper {hi!r} < {truth[1]}"


def _tight(name: str, got: tuple[float, float], truth: tuple, a: float) -> None:
    """On a thin box: a few ulps of the value (16 ulps of the libm widening, plus one)."""
    lo, hi = got
    v = max(abs(float(truth[0])), abs(float(truth[1])))
    assert hi - lo <= 2.0**-44 * v + 1e-299, f"{name}({a!r}): width {hi - lo} of value {v}"


MONOTONE = {  # name: (runtime, mpmath, points, domain, increasing)
    "exp": (rt.exp, mp.exp, "exp", None, True),
    "tanh": (rt.tanh, mp.tanh, "tanh", None, True),
    "sinh": (rt.sinh, mp.sinh, "exp", None, True),
    "atan": (rt.atan, mp.atan, "wide", None, True),
    "log": (lambda a, b: rt.log(a, b, 0), mp.log, "positive", (5e-324, math.inf), True),
    "sqrt": (lambda a, b: rt.sqrt(a, b, 0), mp.sqrt, "positive", (0.0, math.inf), True),
    "asin": (lambda a, b: rt.asin(a, b, 0), mp.asin, "unit", (-1.0, 1.0), True),
    "acos": (lambda a, b: rt.acos(a, b, 0), mp.acos, "unit", (-1.0, 1.0), False),
}


def _overflows(fm, x: float) -> bool:
    return abs(fm(mp.mpf(x))) > mp.mpf(1.7976931348623157e308)


@pytest.mark.parametrize("name", sorted(MONOTONE))
def test_monotone_functions_enclose_the_exact_range(name: str) -> None:
    fn, fm, kind, domain, inc = MONOTONE[name]
    boxes = _boxes(_points(kind), domain)
    assert len(boxes) >= 2000
    for a, b in boxes:
        got = fn(a, b)
        truth = _range_monotone(fm, a, b, inc)
        _check(name, got, truth, a, b)
        if a == b and not _overflows(fm, a):
            _tight(name, got, truth, a)


@pytest.mark.parametrize("name", ["sin", "cos"])
def test_sin_and_cos_enclose_the_exact_range_including_huge_arguments(name: str) -> None:
    fn = rt.sin if name == "sin" else rt.cos
    fm = mp.sin if name == "sin" else mp.cos
    phase = PI / 2 if name == "sin" else mp.mpf(0)
    boxes = _boxes(_points("periodic"))
    assert len(boxes) >= 2000
    for a, b in boxes:
        got = fn(a, b)
        truth = _range_periodic(fm, a, b, phase)
        _check(name, got, truth, a, b)
        if a == b:
            _tight(name, got, truth, a)


def test_tan_is_whole_line_over_a_pole_and_tight_between() -> None:
    boxes = _boxes(_points("periodic"))
    for a, b in boxes:
        lo, hi = rt.tan(a, b)
        A, B = mp.mpf(a), mp.mpf(b)
        k0, k1 = _crit(A, B, PI / 2)
        if k1 >= k0:  # a pole inside
            assert (lo, hi) == (-math.inf, math.inf), (a, b)
            continue
        truth = (mp.tan(A), mp.tan(B))
        _check("tan", (lo, hi), truth, a, b)
        if a == b and lo != -math.inf:
            _tight("tan", (lo, hi), truth, a)
    # a thin box on either side of pi/2 (fl(pi/2) < pi/2): finite and huge, one sign
    x = math.pi / 2
    lo, hi = rt.tan(x, x)
    assert mp.mpf(lo) <= mp.tan(mp.mpf(x)) <= mp.mpf(hi)


def test_cosh_and_abs_are_even_with_their_minimum_inside() -> None:
    for a, b in _boxes(_points("exp")):
        A, B = mp.mpf(a), mp.mpf(b)
        inner = mp.mpf(0) if a <= 0 <= b else min(abs(A), abs(B))
        _check("cosh", rt.cosh(a, b), (mp.cosh(inner), max(mp.cosh(A), mp.cosh(B))), a, b)
        assert rt.iabs(a, b) == (float(inner), float(max(abs(A), abs(B))))  # exact


def test_arithmetic_is_outward_rounded_and_never_nan() -> None:
    vals = [*_points("wide"), math.inf, -math.inf]
    pairs = []
    for i in range(3000):
        a, b = sorted(RNG.choice(vals, 2))
        c, d = sorted(RNG.choice(vals, 2))
        if i % 4 == 0:  # a bound exactly 0 (0 * inf corners)
            a, b = (0.0, b) if b >= 0 else (a, 0.0)
        pairs.append((float(a), float(b), float(c), float(d)))
    pairs += [
        (0.0, math.inf, 0.0, 0.0),
        (-math.inf, 0.0, 0.0, 1.0),
        (0.0, 0.0, -math.inf, math.inf),
    ]
    for a, b, c, d in pairs:
        lo, hi = rt.mul(a, b, c, d)
        assert lo == lo and hi == hi and lo <= hi
        fin = [x for x in (a, b) if math.isfinite(x)], [x for x in (c, d) if math.isfinite(x)]
        for x in fin[0]:
            for y in fin[1]:
                assert mp.mpf(lo) <= mp.mpf(x) * mp.mpf(y) <= mp.mpf(hi)
        if c > 0 or d < 0:
            lo, hi = rt.div(a, b, c, d, 0)
            assert lo == lo and hi == hi
            for x in fin[0]:
                for y in fin[1]:
                    assert mp.mpf(lo) <= mp.mpf(x) / mp.mpf(y) <= mp.mpf(hi)
        for n in (2, 3, 4, 7):
            lo, hi = rt.ipow(a, b, n, 0)
            assert lo == lo and hi == hi
            for x in fin[0]:
                assert mp.mpf(lo) <= mp.mpf(x) ** n <= mp.mpf(hi), (a, b, n)


def test_products_and_quotients_by_a_constant_are_the_runtimes() -> None:
    # the code written for a factor of known sign picks the products mul picks (the same
    # bounds); the quotient is div's where the dividend is finite and encloses it elsewhere
    from ivobs.model.nonlinear.codegen import product, quotient

    ns = dict(rt.NAMESPACE)
    vals = [*_points("wide"), math.inf, -math.inf, -0.0]
    consts = [(0.5, 0.5), (0.03322085188552512, 0.033220851885525184), (1e-300, 3.0)]
    consts += [(-b, -a) for a, b in consts] + [(2.5e-310, 7e-310)]
    codes = []
    for cl, ch in consts:
        code = product((repr(cl), repr(ch)), ("al", "ah"))
        assert not code.startswith("_mul")
        div = quotient(("al", "ah"), (repr(cl), repr(ch)))
        assert div is not None
        codes.append((cl, ch, compile(code, "product", "eval"), compile(div, "quotient", "eval")))
    for i in range(1000):
        a, b = sorted(RNG.choice(vals, 2))
        if i % 5 == 0:
            a, b = (0.0, b) if b >= 0 else (a, 0.0)
        a, b = float(a), float(b)
        cl, ch, mul, div = codes[i % len(codes)]
        ns.update(al=a, ah=b)
        assert eval(mul, ns) == rt.mul(cl, ch, a, b) == rt.mul(a, b, cl, ch), (cl, ch, a, b)
        lo, hi = eval(div, ns)
        if math.isfinite(a) and math.isfinite(b):
            assert (lo, hi) == rt.div(a, b, cl, ch, 0), (cl, ch, a, b)
        fin = [x for x in (a, b) if math.isfinite(x)]
        for x in fin:
            for y in (cl, ch):
                assert mp.mpf(lo) <= mp.mpf(x) / mp.mpf(y) <= mp.mpf(hi)
    assert quotient(("al", "ah"), ("-1.0", "1.0")) is None  # a constant around 0: div's job


def test_generated_code_encloses_decimals_constants_and_real_powers() -> None:
    sys = ivobs.NonlinearSystem(
        f=["0.1*x1 + pi", "x1**2.5 + x2**(1/3)", "x1/x2 - e*x2**-2", "sqrt(x1)*log(x2)"],
        h=["x1"],
        states=["x1", "x2", "x3", "x4"],
    )
    f = [
        lambda x1, x2: mp.mpf(1) / 10 * x1 + PI,
        lambda x1, x2: x1 ** mp.mpf(2.5) + x2 ** (mp.mpf(1) / 3),
        lambda x1, x2: x1 / x2 - mp.e * x2**-2,
        lambda x1, x2: mp.sqrt(x1) * mp.log(x2),
    ]
    # the width allowed is relative to the terms' magnitudes: a difference of two terms can
    # cancel to a value far below the rounding of either (x1/x2 - e/x2**2 near x1 x2 = e)
    mags = [
        lambda x1, x2: 0.1 * x1 + math.pi,
        lambda x1, x2: x1**2.5 + x2 ** (1 / 3),
        lambda x1, x2: x1 / x2 + math.e * x2**-2,
        lambda x1, x2: abs(math.sqrt(x1) * math.log(x2)),
    ]
    rng = np.random.default_rng(11)  # its own draws, whatever ran before in the worker
    for _ in range(600):
        x1, x2 = rng.uniform(0.01, 50, 2) ** rng.choice([1, 3])
        lo, hi = sys.f_box([x1, x2, 0, 0], [x1, x2, 0, 0], [], [], [])
        for i, fm in enumerate(f):
            v = fm(mp.mpf(x1), mp.mpf(x2))
            assert mp.mpf(lo[i]) <= v <= mp.mpf(hi[i]), (i, x1, x2)
            assert hi[i] - lo[i] <= 1e-13 * mags[i](x1, x2) + 1e-300
    lo, hi = sys.f_box([1, 1, 0, 0], [1, 1, 0, 0], [], [], [])
    assert lo[0] < 0.1 + math.pi < hi[0] and lo[0] < 1.1 + math.pi


def test_domain_edges_clip_or_name_the_expression() -> None:
    sys = ivobs.NonlinearSystem(
        f=["sqrt(x1)", "log(x1)", "1/x1"], h=["x1"], states=["x1", "x2", "x3"]
    )
    lo, hi = sys.f_box([-1, 0, 0], [4, 0, 0], [], [], [])
    assert lo[0] == 0.0 and hi[0] >= 2.0  # sqrt on the part >= 0
    assert lo[1] == -math.inf and hi[1] >= math.log(4)  # log reaching 0: unbounded below
    assert (lo[2], hi[2]) == (-math.inf, math.inf)  # 1/x over a range around 0
    with pytest.raises(ivobs.IvobsError, match=r"f\[0\] = 'sqrt\(x1\)'.*sqrt of a range"):
        sys.f_box([-2, 0, 0], [-1, 0, 0], [], [], [])
    div = ivobs.NonlinearSystem(f=["x2", "1/x1"], h=["x1"], states=["x1", "x2"])
    with pytest.raises(ivobs.IvobsError, match=r"f\[1\] = '1/x1'.*division by a range that is "):
        div.f_box([0, 0], [0, 0], [], [], [])


def test_constants_are_folded_where_the_code_is_written_and_still_enclose() -> None:
    # k*sqrt(2)*sqrt(g) and sin(g) are constants (known parameters): evaluated once, when the
    # code is written, by the runtime's own operations; the bounds still hold the exact values
    sys = ivobs.NonlinearSystem(
        f=["x1 - k*sqrt(2)*sqrt(g)*sqrt(x1) + sin(g)*x1"],
        h=["2*k", "x1*sin(k)"],
        states=["x1"],
        params={"k": 0.3, "g": 9.81},
    )
    literal = re.compile(r"_(sqrt|sin|mul)\((-?[\d.e+-]+, )+-?[\d.e+-]+(, \d+)?\)")
    assert not literal.search(sys._f.source)
    k, g = mp.mpf(3) / 10, mp.mpf(981) / 100
    for x in [1.0, 2.0, 17.25]:
        lo, hi = sys.f_box([x], [x], [], [], [])
        v = x - k * mp.sqrt(2) * mp.sqrt(g) * mp.sqrt(x) + mp.sin(g) * x
        assert mp.mpf(lo[0]) <= v <= mp.mpf(hi[0])
    # a constant output is intersected with its measurement like any other
    box = sys.h_contract([1.0], [2.0], [], [], [], [0.6, 0.3], [0.6000001, 0.5])
    assert box is not None and 1.0 < box[0][0] and box[1][0] < 2.0
    assert sys.h_contract([1.0], [2.0], [], [], [], [0.7, 0.3], [0.8, 0.5]) is None
