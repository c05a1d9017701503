"""Soundness property test: every guaranteed method contains the *exact* true state at every
step on random nonlinear systems (polynomial, sin/cos/tanh/exp terms, uncertain parameters,
nonlinear outputs; tests/randsys.py), on the chaotic Hénon map and on random interval-matrix
linear systems, with every parameter, disturbance and matrix entry switching between the
vertices of its bounds at every step.

The records come from tests/exactsim.py (60-digit interval arithmetic, each state and
measurement an exact value of the model with admissible unknowns), not from ivobs.simulate:
the check relies on no margin of the estimators. The long runs (10^5 steps per method) are
benchmarks/bench_nl_sound.py; this is the short guard.
"""

from __future__ import annotations

from functools import cache

import mpmath as mp
import numpy as np
import pytest

import ivobs
from exactsim import Record, simulate, simulate_linear
from randsys import Case, random_interval_linear, random_nonlinear

NL_METHODS = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"]
SEEDS = (0, 1, 2)
T = {"nl-interval": 2000, "nl-zonotope": 1000, "nl-constrained-zonotope": 500}
"""Steps per system, for the file to stay under a minute of CPU (the constrained zonotope's
LPs make it the slow one; the 10^5-step runs are in the benchmark)."""


@cache
def _nonlinear(seed: int) -> tuple[Case, Record]:
    """The system of ``seed`` and its exact record (simulated once for the three methods)."""
    case = random_nonlinear(seed, 2000)
    return case, simulate(case.system, case.x_true0, 2000, case.u, seed=seed)


@cache
def _nonlinear_long(seed: int) -> tuple[Case, Record]:
    case = random_nonlinear(seed, 3000)
    return case, simulate(case.system, case.x_true0, 3000, case.u, seed=seed)


@cache
def _linear(seed: int, cooperative: bool) -> tuple[Case, Record]:
    case = random_interval_linear(seed, 1000, cooperative=cooperative)
    return case, simulate_linear(case.system, case.x_true0, 1000, case.u, seed=seed)


def _check(case: Case, rec: Record, method: str, steps: int) -> np.ndarray:
    u = None if case.u is None else case.u[:steps]
    res = ivobs.make_estimator(method, case.system, x0=case.x0).run(u, rec.Y[:steps])
    lo, hi = rec.X_lo[:steps], rec.X_hi[:steps]
    assert Record(lo, hi, rec.Y, None).misses(res.lower, res.upper).tolist() == []
    assert not res.inconsistent.any()  # the data are the model's: never a fault
    return res.upper - res.lower


@pytest.mark.parametrize("method", NL_METHODS)
@pytest.mark.parametrize("seed", SEEDS)
def test_random_nonlinear_systems_contain_the_exact_state(seed: int, method: str) -> None:
    case, rec = _nonlinear(seed)
    w = _check(case, rec, method, T[method])
    # the maps contract on an invariant box |x| <= 2 (randsys): the widths stay bounded
    assert np.isfinite(w).all() and w[100:].max() < 1.0
    half = len(w) // 2
    assert w[half:].mean() <= 1.2 * w[100:half].mean()


@pytest.mark.slow
@pytest.mark.parametrize("method", ["nl-interval", "nl-zonotope"])
def test_missing_samples_keep_the_widths_bounded(method: str) -> None:
    """10 % of the output components missing at random over 3,000 steps of a random
    contracting map: every box still contains the exact state, and the mean width stays
    within 20 times the complete-data width (the set methods keep no gain, so a missing
    output only skips its correction)."""
    case, rec = _nonlinear_long(2)
    u = case.u
    full = ivobs.make_estimator(method, case.system, x0=case.x0).run(u, rec.Y)
    Y = rec.Y.copy()
    Y[np.random.default_rng(3).random(Y.shape) < 0.1] = np.nan
    res = ivobs.make_estimator(method, case.system, x0=case.x0).run(u, Y)
    assert rec.misses(res.lower, res.upper).tolist() == []
    assert not res.inconsistent.any()
    w, w_full = (res.upper - res.lower)[100:].mean(), (full.upper - full.lower)[100:].mean()
    assert w_full <= w <= 20.0 * w_full


@pytest.mark.parametrize("method", NL_METHODS)
def test_chaotic_henon_contains_the_exact_state(method: str) -> None:
    """``x2+ = 0.3 x1`` has no disturbance of its own: the simulator keeps its 60-digit
    enclosure and the box must contain all of it."""
    sc = ivobs.scenarios.get("henon-nl")
    rec = simulate(sc.system, sc.x_true0, 500, seed=5)
    assert np.all(rec.X_hi[1:, 1] > rec.X_lo[1:, 1])  # an enclosure, not a point
    assert np.all(rec.X_hi[:, 1] - rec.X_lo[:, 1] < 1e-15)
    assert np.array_equal(rec.X_lo[:, 0], rec.X_hi[:, 0])  # x1 absorbs w1: exact doubles
    case = Case(sc.system, sc.x_true0, sc.x0, None, "henon-nl")
    w = _check(case, rec, method, 500)
    assert w[100:].max() < 0.05


def test_simulator_puts_the_unknowns_on_their_vertices() -> None:
    """Recomputed in 50-digit mpmath (SymPy's lambdify, not the simulator's interval code):
    for one vertex of the parameters, every implied disturbance ``x[k+1] - f(x[k]) |_{w=0}`` and
    noise ``y[k] - h(x[k]) |_{v=0}`` lies inside its bounds and within 1e-12 of a vertex, so the
    record is a vertex trajectory of the model. A record shifted by 1e-9 is caught as a miss."""
    import itertools

    import sympy as sp

    case, rec = _nonlinear(1)
    sys = case.system
    names = [*sys.state_names, *sys.input_names, *sys.param_names, *sys.signal_names]
    syms = [sp.Symbol(n) for n in names]
    sub = {q: sp.Symbol(q.name) for e in (*sys.f_exprs, *sys.h_exprs) for q in e.free_symbols}
    f = sp.lambdify(syms, [e.xreplace(sub) for e in sys.f_exprs], "mpmath")
    h = sp.lambdify(syms, [e.xreplace(sub) for e in sys.h_exprs], "mpmath")
    with mp.workdps(50):  # the decimal bounds read at 50 digits, not as doubles
        vertices = [
            [mp.mpf(repr(b)) for b in combo]
            for combo in itertools.product(*(sys.param_bounds[n] for n in sys.param_names))
        ]
        zeros = [mp.mpf(0)] * len(sys.signal_names)
        w_bar = [mp.mpf(repr(sys.signal_bounds[n][1])) for n in sys.signal_names]
        for k in range(300):
            x = [mp.mpf(float(v)) for v in rec.X_lo[k]]
            u = [] if case.u is None else [mp.mpf(float(case.u[k, 0]))]
            implied = [
                mp.mpf(float(y)) - g for y, g in zip(rec.Y[k], h(*x, *u, *vertices[0], *zeros))
            ]
            ok = []
            for p in vertices:
                nxt = f(*x, *u, *p, *zeros)
                ok.append([mp.mpf(float(v)) - g for v, g in zip(rec.X_lo[k + 1], nxt)])
            for wk in ok:  # one parameter vertex must explain every row
                if all(abs(abs(a) - b) < 1e-12 and abs(a) <= b for a, b in zip(wk, w_bar)):
                    break
            else:
                raise AssertionError(f"step {k}: no parameter vertex explains {ok}")
            v_bar = w_bar[sys.nx :]
            assert all(abs(abs(a) - b) < 1e-12 and abs(a) <= b for a, b in zip(implied, v_bar))
    shifted = Record(rec.X_lo + 1e-9, rec.X_hi + 1e-9, rec.Y, None)
    assert shifted.misses(rec.X_lo, rec.X_hi).size == len(rec.X_lo)


@pytest.mark.parametrize(
    "method", ["reachability", "zonotope", "interval", "interval-split", "strip"]
)
def test_random_interval_matrix_systems_contain_the_exact_state(method: str) -> None:
    for seed in (0, 1):
        case, rec = _linear(seed, cooperative=method == "interval")
        w = _check(case, rec, method, 1000)
        assert np.isfinite(w).all() and w[100:].max() < 1.0
