"""The nonlinear scenarios (ivobs.scenarios.nonlinear): each simulates inside its bounds, every
nonlinear method contains the true state at every step with parameters and disturbances on the
vertices of their bounds (tests/exactsim.py: the exact trajectory from the model's own
expressions, not ivobs' simulator), and widths stay bounded over long runs."""

from __future__ import annotations

from functools import cache

import mpmath as mp
import numpy as np
import pytest
import sympy as sp

import ivobs
from nlsystems import Record, simulate

NL_SCENARIOS = ["henon-nl", "pendulum-nl", "cora-tank6-nl", "cstr", "unicycle-range", "range-only",
                "chain10-nl"]  # fmt: skip
NL_METHODS = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"]
HORIZON = {"henon-nl": 1000, "pendulum-nl": 600, "cora-tank6-nl": 200, "cstr": 600,
           "unicycle-range": 200, "range-only": 300, "chain10-nl": 100}  # fmt: skip
"""Short enough for each test to stay within a few seconds (constrained zonotopes are slow);
the long runs are benchmarks/bench_nl_sound.py."""


@cache
def _truth(name: str, T: int, seed: int = 0) -> tuple[ivobs.scenarios.Scenario, Record]:
    sc = ivobs.scenarios.get(name, horizon=T)
    u = sc.u if sc.system.nu else None
    return sc, simulate(sc.system, sc.x_true0, T, u, seed=seed)


@pytest.mark.parametrize("name", NL_SCENARIOS)
def test_scenario_simulates_inside_its_bounds(name: str) -> None:
    sc = ivobs.scenarios.get(name)
    assert isinstance(sc.system, ivobs.NonlinearSystem)
    assert sc.source and sc.description and sc.x0.contains(sc.x_true0)
    for kind in ("vertex", "uniform", "zero", "paper"):
        tr = sc.simulate(kind, seed=3)
        assert tr.x.shape == (sc.horizon, sc.system.nx) and np.isfinite(tr.x).all()
        assert tr.p is not None and tr.p.shape == (sc.horizon, len(sc.system.param_names))
        d, box = tr.d, sc.system.d
        assert np.all((box.lo <= d) & (d <= box.hi))
        if kind == "vertex":
            assert np.all((d == box.lo) | (d == box.hi))


def test_float_simulator_agrees_with_the_exact_one_over_a_few_steps() -> None:
    """On the (non-chaotic) tanks the float64 simulator stays within 1e-12 of the model
    evaluated at 50 digits (SymPy's lambdify on mpmath) fed the same signals."""
    sc = ivobs.scenarios.get("cora-tank6-nl", horizon=50)
    sys = sc.system
    tr = sc.simulate("vertex", seed=5)
    names = [*sys.state_names, *sys.input_names, *sys.signal_names]
    plain = {q: sp.Symbol(q.name) for e in sys.f_exprs for q in e.free_symbols}
    known = {sp.Symbol(n): sp.Rational(repr(v)) for n, v in sys.known_params.items()}
    exprs = [e.xreplace(plain).xreplace(known) for e in sys.f_exprs]
    f = sp.lambdify([sp.Symbol(n) for n in names], exprs, "mpmath")
    with mp.workdps(50):
        x = [mp.mpf(float(v)) for v in sc.x_true0]
        for k in range(49):
            args = [*x, *(mp.mpf(float(v)) for v in tr.u[k]), *(mp.mpf(float(v)) for v in tr.d[k])]
            x = f(*args)
            assert max(abs(float(a) - b) for a, b in zip(x, tr.x[k + 1])) < 1e-12


def test_recorded_tank_data() -> None:
    sc = ivobs.scenarios.get("cora-tank6-nl")
    rec = sc.simulate("recorded")
    assert rec.y.shape == (20, 3) and not rec.has_truth
    res = ivobs.make_estimator("nl-constrained-zonotope", sc.system, x0=sc.x0).run(rec.u, rec.y)
    saved = sc.reference["saved_hi"][0] - sc.reference["saved_lo"][0]  # CORA's FRad-A
    assert np.all(res.upper[-1] - res.lower[-1] <= saved)


@pytest.mark.parametrize("method", NL_METHODS)
@pytest.mark.parametrize("name", NL_SCENARIOS)
def test_methods_contain_the_exact_vertex_trajectory(name: str, method: str) -> None:
    T = HORIZON[name] if method != "nl-constrained-zonotope" else HORIZON[name] // 4
    sc, rec = _truth(name, T, seed=7)
    res = ivobs.make_estimator(method, sc.system, x0=sc.x0).run(sc.u, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    assert not res.inconsistent.any()
    w = res.upper - res.lower
    assert np.isfinite(w[1:]).all()


# range-only is weakly observable on purpose: nl-interval's box grows slowly there (its late
# position widths about 1.3 times the early ones over 3,000 steps); nl-horizon's 10^4-step run
# is in benchmarks/bench_nl_sound.py
@pytest.mark.slow
@pytest.mark.parametrize("name", [n for n in NL_SCENARIOS if n != "range-only"])
def test_widths_stay_bounded_over_long_runs(name: str) -> None:
    T = 3000
    sc, rec = _truth(name, T, seed=11)
    res = ivobs.make_estimator("nl-interval", sc.system, x0=sc.x0).run(sc.u, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    w = res.upper - res.lower
    early, late = w[200:1000].mean(axis=0), w[-800:].mean(axis=0)
    assert np.isfinite(w).all()
    assert np.all(late <= 1.2 * early + 1e-3)


def test_compare_runs_the_nonlinear_methods_and_refuses_the_linear_ones() -> None:
    from ivobs.report.comparison import compare, markdown_table

    sc = ivobs.scenarios.get("henon-nl", horizon=60)
    _, results = compare(sc, ["nl-interval", "zonotope", "nl-zonotope"], disturbance="vertex")
    by = {r.method: r for r in results}
    assert by["nl-interval"].contains and by["nl-zonotope"].contains
    assert by["zonotope"].error is not None and "nl-interval" in by["zonotope"].error
    assert by["nl-interval"].mean_width is not None
    assert np.all(by["nl-interval"].mean_width < 0.05)
    assert "for linear systems" in markdown_table(results)


def test_simulate_nonlinear_checks_its_arguments() -> None:
    sys = ivobs.scenarios.get("henon-nl").system
    with pytest.raises(ivobs.IvobsError, match="p: the value at step 0"):
        ivobs.simulate_nonlinear(sys, [0.3, 0.1], p=np.full((5, 1), 2.0))
    with pytest.raises(ivobs.IvobsError, match="simulate_nonlinear"):
        ivobs.simulate(sys, [0.3, 0.1], T=5)
    with pytest.raises(ivobs.IvobsError, match="x0"):
        ivobs.simulate_nonlinear(sys, [0.3], T=5)


def test_inner_hull_lies_inside_every_method_and_is_not_a_point() -> None:
    from ivobs.report.inner import inner_hull

    k = 6
    sc = ivobs.scenarios.get("pendulum-nl", horizon=k + 1)
    tr = sc.simulate("paper", 0)
    lo, hi, n = inner_hull(sc.system, sc.x0, tr.u, tr.y, k, truth=tr, starts=1)
    assert n >= 2 and np.all(lo <= tr.x[k]) and np.all(tr.x[k] <= hi)
    assert np.all(hi - lo > 1e-4)  # the optimiser moved away from the truth
    for m in NL_METHODS:
        res = ivobs.make_estimator(m, sc.system, x0=sc.x0).run(tr.u, tr.y)
        assert np.all(res.lower[k] <= lo + 1e-6) and np.all(hi - 1e-6 <= res.upper[k])
        assert np.all(res.upper[k] - res.lower[k] < 3.0 * (hi - lo))
    with pytest.raises(ivobs.IvobsError, match="NonlinearSystem"):
        inner_hull(ivobs.scenarios.get("dinh2019").system, sc.x0, tr.u, tr.y, k)
