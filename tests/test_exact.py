"""The exact LP reference: brute force agreement, soundness, moving window, faults, missing data,
callable and time-varying bounds, persistence, progress bar, and the ordering "exact is contained
in every other method's box" (parametrised over the methods registered at collection)."""

import io
import itertools
import json
import subprocess
import sys
import warnings
from functools import cache

import numpy as np
import pytest
from scipy.optimize import linprog

import ivobs
from ivobs import Box, DesignError, InconsistentDataError, IvobsError, LinearSystem, scenarios
from ivobs._progress import Progress
from ivobs.testing import adversarial_run, assert_contains, random_system

LP_TOL = 1e-7  # agreement with independent computations / other methods, relative to 1 + |x|


def exact(sys, x0, **options):
    return ivobs.make_estimator("exact", sys, x0=x0, progress=False, **options)


# -- brute force ---------------------------------------------------------------------------
def test_prediction_only_matches_vertex_enumeration():
    """No measurement (all missing): the exact box is the hull of the reachable set, attained on
    trajectories from vertices of x0 with vertex disturbance sequences."""
    A = np.array([[0.9, 0.4], [-0.3, 0.7]])
    B = np.array([[1.0], [0.5]])
    C = np.array([[1.0, 0.0]])
    E = np.array([[0.2], [-0.5]])
    sys = LinearSystem(A, B, C, E=E, F=np.zeros((1, 1)), d=Box([-0.3], [0.5]))
    x0 = Box([-1.0, 0.5], [0.5, 1.0])
    T = 6
    u = np.linspace(-1.0, 1.0, T)[:, None]
    res = exact(sys, x0).run(u, np.full((T, 1), np.nan))
    for k in range(T):
        ends = []
        for xv in x0.vertices():
            for ds in itertools.product([-0.3, 0.5], repeat=k):
                x = xv.copy()
                for j, dj in enumerate(ds):
                    x = A @ x + B @ u[j] + E[:, 0] * dj
                ends.append(x)
        ends = np.array(ends)
        np.testing.assert_allclose(res.lower[k], ends.min(axis=0), atol=1e-9)
        np.testing.assert_allclose(res.upper[k], ends.max(axis=0), atol=1e-9)


def dense_reference(sys, x0, u, y, k):
    """The hull at step k from an independent condensed LP: variables (x0, d_0..d_k), one
    dense equality per measurement, solved with scipy's linprog."""
    A, B, C, D, E, F = sys.matrices_at(0)
    nx, nd = sys.nx, sys.nd
    n = nx + (k + 1) * nd
    maps, consts = [np.hstack([np.eye(nx), np.zeros((nx, n - nx))])], [np.zeros(nx)]
    for j in range(k):
        M = A @ maps[-1]
        M[:, nx + j * nd : nx + (j + 1) * nd] += E
        maps.append(M)
        consts.append(A @ consts[-1] + B @ u[j])
    rows, rhs = [], []
    for j in range(k + 1):
        M = C @ maps[j]
        M[:, nx + j * nd : nx + (j + 1) * nd] += F
        rows.append(M)
        rhs.append(y[j] - D @ u[j] - C @ consts[j])
    bounds = list(zip(x0.lo, x0.hi)) + list(zip(sys.d.lo, sys.d.hi)) * (k + 1)
    opts = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}
    lo, hi = [], []
    for i in range(nx):
        for sign, out in ((1, lo), (-1, hi)):
            r = linprog(sign * maps[k][i], A_eq=np.vstack(rows), b_eq=np.concatenate(rhs),
                        bounds=bounds, options=opts)  # fmt: skip
            assert r.status == 0
            out.append(sign * r.fun + consts[k][i])
    return np.array(lo), np.array(hi)


@pytest.mark.parametrize("seed", [0, 1])
def test_matches_an_independent_dense_lp(seed):
    sys = random_system(seed, nx=2, ny=1, nu=1, feedthrough=True, symmetric_bounds=False)
    x0 = Box([-1.0, -1.0], [1.0, 1.0])
    tr = adversarial_run(sys, x0, 8, seed=seed)
    res = exact(sys, x0).run(tr.u, tr.y)
    for k in (0, 1, 4, 7):
        lo, hi = dense_reference(sys, x0, tr.u, tr.y, k)
        tol = LP_TOL * (1 + np.abs(lo))
        np.testing.assert_array_less(np.abs(res.lower[k] - lo), tol)
        np.testing.assert_array_less(np.abs(res.upper[k] - hi), tol)
    # measurements tighten the reachable set
    assert np.all(res.width[-1] < exact(sys, x0).run(tr.u, np.nan * tr.y).width[-1])


# -- soundness -----------------------------------------------------------------------------
@pytest.mark.parametrize(
    "seed, invertible, symmetric, feedthrough, ny",
    [
        (0, True, True, False, 1),
        (1, False, True, True, 1),
        (2, True, False, True, 2),
        (3, False, False, False, 2),
    ],
)
def test_contains_the_truth_under_vertex_disturbances(seed, invertible, symmetric, feedthrough,
                                                      ny):  # fmt: skip
    sys = random_system(seed, nx=3, ny=ny, nu=1, invertible=invertible,
                        symmetric_bounds=symmetric, feedthrough=feedthrough)  # fmt: skip
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 30, seed=seed + 10)
    res = exact(sys, x0).run(tr.u, tr.y)
    assert_contains(res, tr.x)
    assert not res.inconsistent.any()
    assert np.all(res.width > 0)
    # the truth is often on the boundary: the hull is tight, not just sound
    gap = np.minimum(tr.x - res.lower, res.upper - tr.x)
    assert np.min(gap) < 1e-6


def test_window_contains_the_full_horizon_and_the_truth():
    sys = random_system(4, nx=3, ny=1, nu=1)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 40, seed=2)
    full = exact(sys, x0).run(tr.u, tr.y)
    win = exact(sys, x0, window=3).run(tr.u, tr.y)
    assert_contains(full, tr.x)
    assert_contains(win, tr.x)
    tol = 1e-9 * (1 + np.abs(full.lower))
    assert np.all(win.lower <= full.lower + tol) and np.all(win.upper >= full.upper - tol)
    assert np.mean(win.width) > np.mean(full.width) * (1 + 1e-6)  # the window forgets
    # a window longer than the record is the full horizon
    long = exact(sys, x0, window=50).run(tr.u, tr.y)
    np.testing.assert_allclose(long.lower, full.lower, atol=1e-9)
    np.testing.assert_allclose(long.upper, full.upper, atol=1e-9)


def test_step_reproduces_run():
    sys = random_system(6, nx=3, ny=2, nu=1, feedthrough=True)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 15, seed=1)
    for window in (None, 4):
        est = exact(sys, x0, window=window)
        res = est.run(tr.u, tr.y)
        est.reset()
        boxes = [est.step(tr.u[k], tr.y[k]) for k in range(tr.T)]
        assert np.array_equal(np.array([b.lo for b in boxes]), res.lower)
        assert np.array_equal(np.array([b.hi for b in boxes]), res.upper)


def test_warm_start_follows_the_state_through_advance_predict_and_run():
    """The warm-started program is a cache outside the online state: advance() from the state
    it returned, step() after predict() or after a run() all reproduce run()."""
    sys = random_system(6, nx=3, ny=2, nu=1, feedthrough=True)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 12, seed=2)
    y = tr.y.copy()
    y[5] = np.nan
    for window in (None, 4):
        est = exact(sys, x0, window=window)
        res = est.run(tr.u, y)
        state, lo = est.initial_state(), []
        for k in range(tr.T):
            state, box = est.advance(state, tr.u[k], y[k])
            lo.append(box.lo)
        assert np.array_equal(np.array(lo), res.lower)
        est.reset()
        lo = []
        for k in range(tr.T):
            est.predict(tr.u[k])
            if k == 6:
                est.run(tr.u, y)
            lo.append(est.step(tr.u[k], y[k]).lo)
        assert np.array_equal(np.array(lo), res.lower)


# -- faults and missing data ---------------------------------------------------------------
@cache
def biased_record():
    sys = random_system(7, nx=3, ny=2, nu=1)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 20, seed=3)
    y = tr.y.copy()
    y[10, 0] += 50.0  # a sensor fault at step 10
    return sys, x0, tr, y


@pytest.mark.parametrize("window", [None, 4])
def test_inconsistent_measurement_is_flagged_and_dropped(window):
    sys, x0, tr, y = biased_record()
    est = exact(sys, x0, window=window)
    with pytest.warns(UserWarning, match=r"step\(s\) \[10\].*inconsistent"):
        res = est.run(tr.u, y)
    assert res.inconsistent.tolist() == [k == 10 for k in range(tr.T)]
    assert np.all(res.lower <= res.upper)
    assert_contains(res, tr.x)  # the faulty sample was dropped: the state is still enclosed
    # at the fault the box is the prediction without y[10]: wider than with the true sample
    clean = exact(sys, x0, window=window).run(tr.u, tr.y)
    assert np.all(res.width[10] >= clean.width[10] - 1e-9)


def test_inconsistency_raise_and_ignore_and_online():
    sys, x0, tr, y = biased_record()
    with pytest.raises(InconsistentDataError) as info:
        exact(sys, x0, on_inconsistent="raise").run(tr.u, y)
    assert info.value.step == 10
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = exact(sys, x0, on_inconsistent="ignore").run(tr.u, y)
    assert res.inconsistent[10]
    est = exact(sys, x0)
    for k in range(10):
        est.step(tr.u[k], y[k])
    with pytest.warns(UserWarning, match="inconsistent"):
        box = est.step(tr.u[10], y[10])
    assert box.contains(tr.x[10])


def test_missing_samples_and_a_gap():
    sys = random_system(8, nx=3, ny=2, nu=1, feedthrough=True, symmetric_bounds=False)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 45, seed=4)
    rng = np.random.default_rng(0)
    y = tr.y.copy()
    y[rng.random(tr.T) < 0.1] = np.nan
    y[rng.random(y.shape) < 0.1] = np.nan
    y[15:35] = np.nan  # a gap of 20 steps
    res = exact(sys, x0, window=6).run(tr.u, y)
    full = exact(sys, x0).run(tr.u, y)
    clean = exact(sys, x0).run(tr.u, tr.y)
    for r in (res, full):
        assert_contains(r, tr.x)
        assert np.all(np.isfinite(r.lower)) and np.all(np.isfinite(r.upper))
    assert res.missing[15:35].all()
    assert np.all(full.width >= clean.width - 1e-9)  # less data, never tighter
    assert np.mean(full.width[30:35]) > np.mean(clean.width[30:35])  # the gap widens the box


def test_callable_bounds_henon():
    sc = scenarios.get("henon", horizon=40)
    tr = sc.simulate("vertex", seed=2)
    res = exact(sc.system, sc.x0).run(tr.u, tr.y)
    assert_contains(res, tr.x)
    win = exact(sc.system, sc.x0, window=5).run(tr.u, tr.y)
    assert_contains(win, tr.x)
    assert np.all(res.width[5:] < 1.0)


def test_time_varying_matrices_and_bounds():
    T = 25

    def A(k):
        th = 0.3 + 0.1 * np.sin(0.4 * k)
        return 0.95 * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])

    lo = -0.1 - 0.05 * np.abs(np.sin(np.arange(T)))[:, None] * np.ones((1, 2))
    sys = LinearSystem(A, None, [[1.0, 0.0]], E=[[1.0, 0.0], [0.0, 0.0]],
                       F=[[0.0, 1.0]], d=Box(lo, -lo))  # fmt: skip
    x0 = Box([-1.0, -1.0], [1.0, 1.0])
    tr = adversarial_run(sys, x0, T, seed=5)
    est = exact(sys, x0, window=6)
    res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    assert_contains(exact(sys, x0).run(tr.u, tr.y), tr.x)
    est.reset()
    again = np.array([est.step(tr.u[k], tr.y[k]).lo for k in range(T)])
    assert np.array_equal(again, res.lower)


# -- persistence, options ------------------------------------------------------------------
@pytest.mark.parametrize("window", [None, 5])
def test_state_and_restore(window):
    sys = random_system(9, nx=3, ny=1, nu=1)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 20, seed=6)
    y = tr.y.copy()
    y[4] = np.nan
    ref = exact(sys, x0, window=window).run(tr.u, y)
    est = exact(sys, x0, window=window)
    for k in range(10):
        est.step(tr.u[k], y[k])
    saved = json.loads(json.dumps(est.state()))
    other = exact(sys, x0, window=window)
    other.restore(saved)
    assert other.k == 10
    rest = np.array([other.step(tr.u[k], y[k]).lo for k in range(10, 20)])
    np.testing.assert_allclose(rest, ref.lower[10:], atol=1e-8)
    with pytest.raises(IvobsError, match="same design"):
        exact(sys, x0, window=3).restore(saved)


def test_bad_options():
    sys = random_system(0, nx=2, ny=1, nu=1)
    x0 = Box(-np.ones(2), np.ones(2))
    for bad in (0, -3, 2.5, True, "10"):
        with pytest.raises(IvobsError, match="window"):
            exact(sys, x0, window=bad)
    with pytest.raises(IvobsError, match="progress"):
        ivobs.make_estimator("exact", sys, x0=x0, progress="yes")
    with pytest.raises(IvobsError, match="x0"):
        ivobs.make_estimator("exact", sys)
    ct = LinearSystem([[-1.0]], None, [[1.0]], dt=0)
    with pytest.raises(IvobsError, match="discrete-time"):
        ivobs.make_estimator("exact", ct, x0=Box([-1.0], [1.0]))


def test_progress_bar():
    out = io.StringIO()
    with Progress(5, "demo", enabled=True, stream=out, interval=0.0) as bar:
        for _ in range(5):
            bar.update()
    text = out.getvalue()
    assert "demo" in text and "5/5" in text and text.endswith("\n")
    quiet = io.StringIO()  # not a terminal: silent by default
    with Progress(5, "demo", stream=quiet) as bar:
        bar.update(5)
    assert quiet.getvalue() == ""


def test_progress_in_run(capsys):
    sys = random_system(0, nx=2, ny=1, nu=1)
    x0 = Box(-np.ones(2), np.ones(2))
    tr = adversarial_run(sys, x0, 6, seed=0)
    ivobs.make_estimator("exact", sys, x0=x0, progress=True).run(tr.u, tr.y)
    assert "6/6" in capsys.readouterr().err
    ivobs.make_estimator("exact", sys, x0=x0).run(tr.u, tr.y)  # auto: stderr is not a TTY
    assert capsys.readouterr().err == ""


# -- exact is contained in every other method's box -----------------------------------------
OTHERS = [m for m in ivobs.methods() if m not in ("exact", "intersect")]


@cache
def case(which):
    if which == "servo-motor":
        sc = scenarios.get("servo-motor", horizon=40)
        sys, x0, tr = sc.system, sc.x0, sc.simulate("vertex", seed=1)
    else:
        sys = random_system(12, nx=3, ny=2, nu=1, feedthrough=True, symmetric_bounds=False)
        x0 = Box(-np.ones(3), np.ones(3))
        tr = adversarial_run(sys, x0, 40, seed=12)
    return sys, x0, tr, exact(sys, x0).run(tr.u, tr.y)


@pytest.mark.parametrize("which", ["servo-motor", "random"])
@pytest.mark.parametrize("method", OTHERS)
def test_exact_is_contained_in_every_other_method(method, which):
    sys, x0, tr, ref = case(which)
    try:
        est = ivobs.make_estimator(method, sys, x0=x0)
    except DesignError as exc:
        pytest.skip(f"{method} cannot be designed for the {which} system: {exc}")
    res = est.run(tr.u, tr.y)
    assert_contains(ref, tr.x)
    k0 = res.valid_from
    tol = LP_TOL * (1 + np.abs(ref.lower[k0:]))
    assert np.all(ref.lower[k0:] >= res.lower[k0:] - tol), f"{method} is below exact"
    assert np.all(ref.upper[k0:] <= res.upper[k0:] + tol), f"{method} is above exact"


def test_no_solver_banner_on_standard_output():
    """HiGHS >= 1.15 prints "Running HiGHS ..." from C++ at construction: ivobs silences it (a
    table written by ``ivobs compare > file`` must hold only the table)."""
    code = (
        "import numpy as np, ivobs\n"
        "sys = ivobs.scenarios.get('servo-motor', horizon=5)\n"
        "tr = sys.simulate('vertex', seed=0)\n"
        "est = ivobs.make_estimator('exact', sys.system, x0=sys.x0, progress=False)\n"
        "print('width', est.run(tr.u, tr.y).width.sum() > 0)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout == "width True\n"
    assert "HiGHS" not in out.stderr


@pytest.mark.parametrize("factor", [1e12, 1e300])
def test_gross_faults_are_reported_even_beyond_the_solvers_infinite_bound(factor):
    """Measurements multiplied by ``factor``: every sample is inconsistent. Right-hand sides
    above HiGHS's infinite bound (1e20) would be free rows in the LP; the interval test on the
    prediction certifies them first. The boxes stay guaranteed (the model's predictions)."""
    sc = scenarios.get("servo-motor", horizon=20)
    tr = sc.simulate("vertex", seed=0)
    est = ivobs.make_estimator("exact", sc.system, x0=sc.x0, progress=False,
                               on_inconsistent="ignore")  # fmt: skip
    res = est.run(sc.u, tr.y * factor)
    assert res.inconsistent.all()
    assert res.contains(tr.x).all()


def test_a_solver_stopped_by_its_iteration_limit_still_gives_guaranteed_boxes(monkeypatch):
    """Every program stopped after 3 simplex iterations (as a stalled solve would be): the
    safe bound (S) of whatever multipliers HiGHS has, or the interval prediction, is returned:
    wider than the exact hull, never missing the true state, never a false alarm."""
    import ivobs.estimators.exact.highs as exact_mod

    sys = random_system(12, nx=3, ny=2, nu=1)
    x0 = Box.symmetric(np.ones(3))
    tr = adversarial_run(sys, x0, 25, seed=3)
    ref = ivobs.make_estimator("exact", sys, x0=x0, progress=False).run(tr.u, tr.y)
    monkeypatch.setattr(exact_mod, "ITERATION_LIMIT", 3)
    est = ivobs.make_estimator("exact", sys, x0=x0, progress=False, on_inconsistent="raise")
    with pytest.warns(RuntimeWarning, match="stopped at the iteration budget"):
        res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    assert not res.inconsistent.any()
    assert np.all(res.lower <= ref.lower + 1e-9) and np.all(res.upper >= ref.upper - 1e-9)
    assert np.mean(res.width) > np.mean(ref.width)  # the limit did bite


def test_state_with_a_missing_sample_is_strict_json():
    """A missing sample kept in exact's history is saved as null (strict JSON, e.g. for other
    languages' parsers) and restored as missing: the same boxes afterwards."""
    sys = random_system(3, nx=3, ny=2, nu=1)
    x0 = Box.symmetric(np.ones(3))
    tr = adversarial_run(sys, x0, 6, seed=0)
    est = ivobs.make_estimator("exact", sys, x0=x0, progress=False)
    est.step(tr.u[0], tr.y[0])
    est.step(tr.u[1], None)
    text = json.dumps(est.state(), allow_nan=False)
    other = ivobs.make_estimator("exact", sys, x0=x0, progress=False)
    other.restore(json.loads(text))
    for k in range(2, 6):
        a, b = est.step(tr.u[k], tr.y[k]), other.step(tr.u[k], tr.y[k])
        np.testing.assert_allclose(a.lo, b.lo, rtol=1e-9, atol=1e-8)
        np.testing.assert_allclose(a.hi, b.hi, rtol=1e-9, atol=1e-8)
