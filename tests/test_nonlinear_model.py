"""NonlinearSystem: the expression language (whitelist, exact decimals, errors that point into
the text), callables, validation of every argument, the contract's evaluations, conversions."""

from __future__ import annotations

import math
import pickle
from fractions import Fraction

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError, nlmath


def _sys(**kw: object) -> ivobs.NonlinearSystem:
    args: dict = {
        "f": ["1 - a*x1**2 + x2 + w1", "b*x1"],
        "h": ["x1 + v1"],
        "states": ["x1", "x2"],
        "params": {"a": (1.39, 1.41), "b": 0.3},
        "d": {"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    }
    args.update(kw)
    return ivobs.NonlinearSystem(**args)


def test_the_contract_members() -> None:
    s = _sys()
    assert (s.nx, s.nu, s.ny, s.nd, s.nw) == (2, 0, 1, 2, 3)
    assert s.param_names == ["a"] and s.signal_names == ["w1", "v1"]
    assert s.state_names == ["x1", "x2"] and s.output_names == ["y1"]
    assert s.is_discrete and not s.is_continuous and not s.is_time_varying
    assert s.has_constant_bounds and s.sampling_period == 1.0 and s.dt is True
    assert s.w_box.lo[0] <= 1.39 and s.w_box.hi[0] >= 1.41 and s.d.dim == 2
    assert s.d_at(7) is s.d
    lo, hi = s.f_box([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi)
    # 1 - a x1^2 + x2 + w1 over the box: [1 - 1.41*0.16 - 0.005, 1 - 1.39*0.04 + 0.2 + 0.005]
    assert lo[0] <= 1 - 1.41 * 0.16 - 0.005 and hi[0] >= 1 - 1.39 * 0.04 + 0.205
    assert hi[0] - lo[0] < (1 - 1.39 * 0.04 + 0.205) - (1 - 1.41 * 0.16 - 0.005) + 1e-14
    Jx_lo, Jx_hi, Jw_lo, Jw_hi = s.f_jac_box([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi)
    assert Jx_lo.shape == (2, 2) and Jw_lo.shape == (2, 3)
    assert Jx_lo[0, 0] <= -2 * 1.41 * 0.4 and Jx_hi[0, 0] >= -2 * 1.39 * 0.2
    assert (Jx_lo[0, 1], Jx_hi[0, 1], Jw_lo[0, 1], Jw_hi[1, 2]) == (1.0, 1.0, 1.0, 0.0)
    hl, hh = s.h_box([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi)
    assert hl[0] <= 0.18 and hh[0] >= 0.42
    Hx_lo, _, Hw_lo, _ = s.h_jac_box([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi)
    assert Hx_lo.tolist() == [[1.0, 0.0]] and Hw_lo.tolist() == [[0.0, 0.0, 1.0]]
    out = s.h_contract([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi, [0.3])
    assert out is not None
    assert out[0][0] <= 0.28 and out[1][0] >= 0.32 and out[1][0] - out[0][0] < 0.0400001
    assert s.h_contract([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi, [0.5]) is None
    assert s.h_contract([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi, [np.nan]) is not None


def test_outputs_that_share_a_state_pass_their_contraction_on() -> None:
    # y1 = x1 + x2 narrows x2 only once y2 = x1 has narrowed x1: a second pass over the outputs
    s = ivobs.NonlinearSystem(f=["x1", "x2"], h=["x1 + x2", "x1"], states=["x1", "x2"])
    out = s.h_contract([0.0, 0.0], [1.0, 1.0], [], [], [], [1.0, 0.5], [1.0, 0.5])
    assert out is not None and out[1][0] - out[0][0] < 1e-12
    assert abs(out[0][1] - 0.5) < 1e-12 and abs(out[1][1] - 0.5) < 1e-12
    # outputs over disjoint states: one pass contracts each as far as it goes
    d = ivobs.NonlinearSystem(f=["x1", "x2"], h=["2*x1", "x2**2"], states=["x1", "x2"])
    out = d.h_contract([0.0, 0.0], [1.0, 1.0], [], [], [], [1.0, 0.25], [1.0, 0.25])
    assert out is not None
    assert abs(out[0][0] - 0.5) < 1e-12 and abs(out[1][0] - 0.5) < 1e-12
    assert abs(out[0][1] - 0.5) < 1e-12 and abs(out[1][1] - 0.5) < 1e-12


def test_the_f_contractor_narrows_a_box_by_the_next_state_and_keeps_every_solution() -> None:
    # x1 + x2 = 3 and sqrt(x1) x2 = 2 share x1, x2 (one DAG, sqrt(x1) evaluated once)
    s = ivobs.NonlinearSystem(f=["x1 + x2", "sqrt(x1)*x2"], h=["x1"], states=["x1", "x2"])
    fc, _ = s.f_contractor()
    vl, vh = [0.0, 1.5], [4.0, 4.0]
    assert fc(vl, vh, [], [3.0, 2.0], [3.0, 2.0])
    assert vl[0] <= 1.0 <= vh[0] and vl[1] <= 2.0 <= vh[1]  # the solution (1, 2) is kept
    assert vh[0] <= 1.5 + 1e-12 and vh[1] - vl[1] < 2.5
    # no point of the box maps into the next state's box
    assert not fc([0.0, 0.0], [1.0, 1.0], [], [3.0, 2.0], [3.0, 2.0])


def test_decimal_literals_are_enclosed_exactly() -> None:
    s = ivobs.NonlinearSystem(f=["0.1*x1", "x1 + 0.3 - 0.1 - 0.2"], h=["x1"], states=["x1", "x2"])
    lo, hi = s.f_box([1.0, 0.0], [1.0, 0.0], [], [], [])
    assert Fraction(lo[0]) <= Fraction(1, 10) <= Fraction(hi[0]) and lo[0] < hi[0]
    assert Fraction(lo[1]) <= 1 <= Fraction(hi[1])  # 1 + 0.3 - 0.1 - 0.2 is exactly 1
    assert s.f_text[1] == "x1 + 1" or "x1" in s.f_text[1]


@pytest.mark.parametrize(
    ("expr", "match"),
    [
        ("x1 + z", r"f\[0\] = 'x1 \+ z': unknown name 'z' at column 6"),
        ("x1 +", r"f\[0\] = 'x1 \+': not a valid expression at"),
        ("__import__('os').system('x')", r"only calls of the listed functions"),
        ("__import__('os')", r"unknown function '__import__' at column 1 \(allowed: sin"),
        ("x1.real", r"Attribute is not allowed .* at column 1"),
        ("x1[0]", r"Subscript is not allowed"),
        ("(lambda: 1)()", r"only calls of the listed functions"),
        ("sin(x1, x2)", r"sin\(\) takes 1 argument\(s\), got 2"),
        ("max(x1)", r"max\(\) takes at least 2 argument\(s\), got 1"),
        ("sin(x=x1)", r"takes no keyword arguments"),
        ("x1 // 2", r"operator '//' is not allowed"),
        ("x1 if x2 else 1", r"IfExp is not allowed"),
        ("x1 < 2", r"Compare is not allowed"),
        ("'x1'", r"literal 'x1' is not a real number"),
        ("1j*x1", r"is not a real number"),
        ("True", r"is not a real number"),
        ("x1**100000", r"integer exponent 100000 beyond"),
        ("1/0", r"undefined"),
        ("sin", r"function 'sin' used without arguments"),
        ("", r"f\[0\]: empty expression"),
    ],
)
def test_malformed_expressions_name_the_expression_position_and_symbol(
    expr: str, match: str
) -> None:
    with pytest.raises(IvobsError, match=match):
        _sys(f=[expr, "b*x1"])


@pytest.mark.parametrize(
    ("kw", "match"),
    [
        ({"f": ["x1"]}, r"f: expected 2 expressions \(one per state\), got 1"),
        ({"f": "x1"}, r"f: expected a list of expressions"),
        ({"h": 3}, r"h: expected a list of expressions"),
        ({"states": []}, r"states: expected at least one state name"),
        ({"states": ["x1", "x 2"]}, r"states: expected names"),
        ({"states": ["x1", "sin"]}, r"reserved name"),
        ({"params": {"a": (1.41, 1.39), "b": 0.3}}, r"params\['a'\]: lower bound 1.41 > upper"),
        ({"params": {"a": (1.39, np.inf), "b": 0.3}}, r"params\['a'\]\[1\]: expected a finite"),
        ({"params": {"a": (1.39, 1.41), "b": np.nan}}, r"params\['b'\]: expected a finite"),
        ({"params": {"a": (1.39, 1.41), "b": "0.3"}}, r"params\['b'\]: expected a number"),
        ({"params": {"a": (1, 2, 3), "b": 0.3}}, r"params\['a'\]: expected a pair"),
        ({"d": {"w1": (0.1, -0.1), "v1": (-1, 1)}}, r"d\['w1'\]: lower bound 0.1 > upper"),
        ({"d": [("w1", 1)]}, r"d: expected a dict"),
        ({"params": {"x1": 1.0, "a": (1, 2), "b": 0.3}}, r"'x1' used twice"),
        ({"dt": -1.0}, r"dt: expected True, a period > 0, or 0"),
        ({"dt": math.inf}, r"dt: expected True, a period > 0, or 0"),
        ({"outputs": ["y1", "y2"]}, r"outputs: expected 1 names, got 2"),
    ],
)
def test_bad_arguments_are_refused_by_name(kw: dict, match: str) -> None:
    with pytest.raises(IvobsError, match=match):
        _sys(**kw)


def test_callables_are_traced_with_ivobs_math() -> None:
    def f(x, u, p, d):  # type: ignore[no-untyped-def]
        return [x[0] + 0.1 * nlmath.sin(x[1]) + u[0], nlmath.max(x[0], x[1]) * nlmath.pi]

    s = ivobs.NonlinearSystem(
        f=f, h=lambda x, u, p, d: [nlmath.sqrt(x[0])], states=["x1", "x2"], inputs=["u1"]
    )
    assert "sin(x2)" in s.f_text[0] and "max(" in s.f_text[1] and "pi" in s.f_text[1]
    lo, hi = s.f_box([1.0, 2.0], [1.0, 2.0], [0.5], [], [])
    assert lo[1] <= 2 * np.pi <= hi[1]
    assert lo[0] <= 1.5 + 0.1 * np.sin(2.0) <= hi[0]
    # the same callable evaluates numbers (for simulation)
    assert f([1.0, 2.0], [0.5], {}, {})[0] == pytest.approx(1.5 + 0.1 * np.sin(2.0))
    with pytest.raises(IvobsError, match=r"numpy and math functions cannot be traced|failed"):
        ivobs.NonlinearSystem(f=lambda x, u, p, d: [np.sin(x[0])], h=["x1"], states=["x1"])
    with pytest.raises(IvobsError, match=r"h: calling .* failed \(KeyError"):
        ivobs.NonlinearSystem(f=["x1"], h=lambda x, u, p, d: [p["nope"]], states=["x1"])


def test_systems_pickle_and_rebuild_from_their_text() -> None:
    s = _sys()
    t = pickle.loads(pickle.dumps(s))
    assert t.f_text == s.f_text and t.h_text == s.h_text
    box = ([0.2, 0.0], [0.4, 0.2], [], s.w_box.lo, s.w_box.hi)
    for a, b in zip(s.f_tight_box(*box), t.f_tight_box(*box)):
        np.testing.assert_array_equal(a, b)


def test_a_linear_system_converts_exactly() -> None:
    sc = ivobs.scenarios.get("servo-motor")
    lin = sc.system
    nl = ivobs.NonlinearSystem.from_linear(lin)
    A, B, _C, _D, E, _F = lin.matrices_at(0)
    rng = np.random.default_rng(0)
    for _ in range(20):
        x, u, d = rng.normal(size=lin.nx), rng.normal(size=lin.nu), rng.uniform(-1, 1, lin.nd)
        lo, hi = nl.f_box(x, x, u, d, d)
        exact = A @ x + B @ u + E @ d
        assert np.all(lo <= exact + 1e-12) and np.all(exact - 1e-12 <= hi)
        assert np.all(hi - lo <= 1e-13 * (1 + np.abs(exact)))
    tv = ivobs.LinearSystem(lambda k: np.eye(2), C=np.eye(2))
    with pytest.raises(IvobsError, match="time-invariant discrete-time"):
        ivobs.NonlinearSystem.from_linear(tv)


def test_evaluations_check_their_arguments() -> None:
    s = _sys()
    w = (s.w_box.lo, s.w_box.hi)
    with pytest.raises(IvobsError, match=r"xlo: expected 2 values, got 3"):
        s.f_box([0, 0, 0], [1, 1], [], *w)
    with pytest.raises(IvobsError, match=r"u: expected 0 values, got 1"):
        s.h_box([0, 0], [1, 1], [1.0], *w)
    with pytest.raises(IvobsError, match=r"wlo: expected 3 values, got 2"):
        s.f_jac_box([0, 0], [1, 1], [], [0, 0], [1, 1, 1])
    with pytest.raises(IvobsError, match=r"y: expected 1 values, got 2"):
        s.h_contract([0, 0], [1, 1], [], *w, [0.1, 0.2])


def test_the_mean_value_form_tightens_repeated_variables_only() -> None:
    s = ivobs.NonlinearSystem(f=["x1 - x1**2", "x2**2"], h=["x1"], states=["x1", "x2"])
    nat = s.f_box([0.4, 0.4], [0.6, 0.6], [], [], [])
    tight = s.f_tight_box([0.4, 0.4], [0.6, 0.6], [], [], [])
    # natural [0.4 - 0.36, 0.6 - 0.16]; centred 0.25 + [-0.2, 0.2] [-0.1, 0.1] = [0.23, 0.27]
    assert nat[0][0] == pytest.approx(0.04) and nat[1][0] == pytest.approx(0.44)
    assert tight[0][0] == pytest.approx(0.23) and tight[1][0] == pytest.approx(0.27)
    assert tight[0][0] <= 0.23 and tight[1][0] >= 0.27  # outward
    assert (tight[0][1], tight[1][1]) == (nat[0][1], nat[1][1])  # single use: exact already


def test_sympy_expressions_are_read_through_the_same_whitelist():
    sp = pytest.importorskip("sympy")
    x1, x2, a, w1, v1 = sp.symbols("x1 x2 a w1 v1")
    kw = dict(states=["x1", "x2"], params={"a": (1.39, 1.41)},
              d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)})  # fmt: skip
    from_sympy = ivobs.NonlinearSystem(
        f=[1 - a * x1**2 + x2 + w1 + 0 * sp.Abs(x2), sp.Rational(3, 10) * x1], h=[x1 + v1], **kw
    )
    from_text = ivobs.NonlinearSystem(f=["1 - a*x1**2 + x2 + w1", "0.3*x1"], h=["x1 + v1"], **kw)
    lo, hi, w = np.array([0.1, 0.2]), np.array([0.3, 0.25]), from_text.w_box
    for got, want in zip(
        from_sympy.f_box(lo, hi, np.zeros(0), w.lo, w.hi),
        from_text.f_box(lo, hi, np.zeros(0), w.lo, w.hi),
    ):
        np.testing.assert_array_equal(got, want)
    with pytest.raises(ivobs.IvobsError, match="unknown function 'gamma'"):
        ivobs.NonlinearSystem(f=[sp.gamma(x2), x1], h=[x1], states=["x1", "x2"])
