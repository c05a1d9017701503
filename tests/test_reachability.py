"""`reachability`: [Tang2019, Algorithm 1, Theorem 2] with the H∞ gain of [Tang2019, Theorem 1]."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ivobs
from ivobs import Box, DesignError, IvobsError, LinearSystem, make_estimator
from ivobs.testing import adversarial_run, assert_contains, random_system

CASES = [  # (seed, invertible A, symmetric bounds, D feedthrough, ny)
    (0, True, True, False, 1),
    (1, False, True, True, 2),
    (2, True, False, True, 1),
    (3, False, False, False, 2),
    (4, True, False, True, 2),
    (5, False, False, True, 1),
]


def _system(case):
    seed, inv, sym, ft, ny = case
    sys = random_system(
        seed, nx=3, ny=ny, nu=1, invertible=inv, symmetric_bounds=sym, feedthrough=ft
    )
    x0 = Box(-np.ones(3), np.ones(3) * 1.5)
    return sys, x0


def _errors(est, sys):
    """``M = A - LC`` and ``G = E - LF`` of the estimator's gain."""
    L = est.design.L
    return sys.A - L @ sys.C, sys.E - L @ sys.F


def _exact_radius(M, G, h0, r_rows):
    """ρ[k] = |M^k| h0 + Σ_{i<k} |M^i G| r[k-1-i] by brute force [Tang2019, eq. (21)]."""
    T = r_rows.shape[0]
    out = np.zeros((T, M.shape[0]))
    pw = [np.eye(M.shape[0])]
    for _ in range(T):
        pw.append(M @ pw[-1])
    for k in range(T):
        out[k] = np.abs(pw[k]) @ h0
        for i in range(k):
            out[k] += np.abs(pw[i] @ G) @ r_rows[k - 1 - i]
    return out


# --- [Tang2019], Example 2 -----------------------------------------------------------------
def test_tang_example2_gain_and_containment():
    sc = ivobs.scenarios.get("tang-example2", horizon=60)
    est = make_estimator("reachability", sc.system, x0=sc.x0, gain="hinf-lmi")
    np.testing.assert_allclose(est.design.L, sc.reference["L"], atol=1e-3)
    assert est.design.gamma == pytest.approx(3.4368, abs=1e-3)
    assert est.design.spectral_radius == pytest.approx(0.3258, abs=1e-3)
    for kind in ("paper", "vertex"):
        tr = sc.simulate(kind, seed=4)
        res = est.run(tr.u, tr.y)
        assert_contains(res, tr.x)
    # steady widths: ρ∞ = Σ_i |M^i G| r, the exact interval hull
    w = res.upper[-1] - res.lower[-1]
    M = sc.system.A - est.design.L @ sc.system.C
    G = sc.system.E - est.design.L @ sc.system.F
    r = sc.system.d.radius
    rho_inf = sum(np.abs(np.linalg.matrix_power(M, i) @ G) @ r for i in range(200))
    np.testing.assert_allclose(w, 2 * rho_inf, rtol=1e-6)


def test_box_is_the_exact_interval_hull_theorem2():
    """Eq. (26): [e_k] = Box(Ω_k). A worst-case x0 and disturbance reach the bound exactly."""
    sc = ivobs.scenarios.get("tang-example2")
    s = sc.system
    est = make_estimator("reachability", s, x0=sc.x0)
    L = est.design.L
    M, G = s.A - L @ s.C, s.E - L @ s.F
    c, r = s.d.center, s.d.radius
    k, T = 40, 45
    for i in range(2):
        for sgn in (1.0, -1.0):
            Mk = np.linalg.matrix_power(M, k)
            x0 = sc.x0.center + sgn * np.sign(Mk[i]) * sc.x0.radius
            d = np.tile(c, (T, 1))
            for j in range(k):
                row = (np.linalg.matrix_power(M, k - 1 - j) @ G)[i]
                d[j] = c + sgn * np.sign(row) * r
            tr = ivobs.simulate(s, x0, np.zeros((T, 1)), d)
            res = est.run(tr.u, tr.y)
            assert_contains(res, tr.x)
            bound = res.upper[k, i] if sgn > 0 else res.lower[k, i]
            # attained up to the proven rounding (a few ulps of the state per step)
            assert abs(bound - tr.x[k, i]) <= 2e-13 * (1 + abs(tr.x[k, i]))


# --- [Tang2019], Example 1: servo motor ---------------------------------------------------
def test_servo_hinf_design_and_containment():
    sc = ivobs.scenarios.get("servo-motor", horizon=300)
    est = make_estimator("reachability", sc.system, x0=sc.x0, gain="hinf-lmi")
    assert est.design.gamma == pytest.approx(3.2415, abs=1e-3)
    for kind in ("paper", "vertex"):
        tr = sc.simulate(kind, seed=2)
        assert_contains(est.run(tr.u, tr.y), tr.x)


def test_servo_L1_is_much_tighter_than_L2_for_speed_and_current():
    """[Tang2019, Section VII]: with L1 (H∞) the bounds of n and i are much tighter than with L2."""
    sc = ivobs.scenarios.get("servo-motor", horizon=200)
    tr = sc.simulate("paper")
    w = {}
    for key in ("L1", "L2"):
        res = make_estimator("reachability", sc.system, x0=sc.x0, L=sc.reference[key]).run(
            tr.u, tr.y
        )
        assert_contains(res, tr.x)
        w[key] = (res.upper - res.lower)[100:].mean(axis=0)
    np.testing.assert_allclose(w["L1"], [0.16909, 0.39012, 0.57744], atol=2e-5)
    assert w["L1"][1] < 0.5 * w["L2"][1] and w["L1"][2] < 0.5 * w["L2"][2]


def _interval_observer_36(sys, x0, L, u, y):
    """Interval observer [Tang2019, eqs. (36)-(37)], written out here: A - LC ≥ 0 is required."""
    M = sys.A - L @ sys.C
    assert (M >= 0).all()
    G = sys.E - L @ sys.F
    c, r = sys.d.center, sys.d.radius
    lo, hi = x0.lo.copy(), x0.hi.copy()
    out_lo, out_hi = [], []
    for k in range(y.shape[0]):
        out_lo.append(lo.copy())
        out_hi.append(hi.copy())
        known = sys.B @ u[k] + L @ (y[k] - sys.D @ u[k]) + G @ c
        lo, hi = M @ lo + known - np.abs(G) @ r, M @ hi + known + np.abs(G) @ r
    return np.array(out_lo), np.array(out_hi)


def test_theorem7_reachability_inside_interval_observer_same_gain_L2():
    sc = ivobs.scenarios.get("servo-motor", horizon=150)
    L2 = sc.reference["L2"]
    for kind in ("paper", "vertex"):
        tr = sc.simulate(kind, seed=5)
        res = make_estimator("reachability", sc.system, x0=sc.x0, L=L2).run(tr.u, tr.y)
        lo, hi = _interval_observer_36(sc.system, sc.x0, L2, tr.u, tr.y)
        assert (res.lower >= lo - 1e-9).all() and (res.upper <= hi + 1e-9).all()
        assert ((hi - lo) - (res.upper - res.lower)).max() > 1e-3  # strictly tighter somewhere
        assert_contains(res, tr.x)


def test_theorem7_against_the_interval_estimator():
    if "interval" not in ivobs.methods():
        pytest.skip("the 'interval' estimator ([Tang2019, eqs. (36)-(37)]) is not available yet")
    sc = ivobs.scenarios.get("servo-motor", horizon=150)
    L2 = sc.reference["L2"]
    for kind in ("paper", "vertex"):
        tr = sc.simulate(kind, seed=6)
        reach = make_estimator("reachability", sc.system, x0=sc.x0, L=L2).run(tr.u, tr.y)
        # the paper's interval observer (36): its own boxes, not met with the window bound
        itv = make_estimator("interval", sc.system, x0=sc.x0, L=L2, finite_memory=False).run(
            tr.u, tr.y
        )
        assert_contains(itv, tr.x)
        tol = 1e-8 * (1 + np.abs(itv.upper))
        assert (reach.lower >= itv.lower - tol).all()
        assert (reach.upper <= itv.upper + tol).all()


# --- random systems: soundness, the paths agree within rounding ----------------------------
@pytest.mark.parametrize("case", CASES)
def test_random_systems_contain_the_truth_and_the_radius_is_algorithm_1s(case):
    sys, x0 = _system(case)
    est = make_estimator("reachability", sys, x0=x0)
    tr = adversarial_run(sys, x0, 150, seed=case[0])
    res = est.run(tr.u, tr.y, vectorize=False)
    assert_contains(res, tr.x)
    vec = est.run(tr.u, tr.y, vectorize=True)
    np.testing.assert_allclose(vec.lower, res.lower, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(vec.upper, res.upper, rtol=1e-12, atol=1e-12)
    est.reset()
    boxes = [est.step(tr.u[k], tr.y[k]) for k in range(40)]
    np.testing.assert_allclose([b.lo for b in boxes], res.lower[:40], rtol=1e-14, atol=1e-14)
    # the radius is data-independent and, up to the proven rounding, the brute-force sum
    # [Tang2019, eq. (21)]
    M, G = _errors(est, sys)
    exact = _exact_radius(M, G, x0.radius, np.tile(sys.d.radius, (30, 1)))
    half = 0.5 * (res.upper - res.lower)[:30]
    assert (half >= exact).all()
    np.testing.assert_allclose(half, exact, rtol=1e-11)


SIZES = [(1, 1, 0), (2, 1, 2), (4, 2, 1), (5, 3, 0), (6, 2, 2)]  # (nx, ny, nu)


@pytest.mark.parametrize("method", ["reachability", "zonotope"])
@pytest.mark.parametrize("size", SIZES)
def test_vectorised_path_equals_the_loop_on_random_systems_of_several_sizes(method, size):
    """The vectorised run (the observer by the shared linear-filter kernel, data-independent
    radii) against the loop over the step, for one record and for a batch of records."""
    nx, ny, nu = size
    sys = random_system(
        100 + nx, nx=nx, ny=ny, nu=nu, symmetric_bounds=nx % 2 == 0, feedthrough=nu > 0
    )
    x0 = Box(-np.ones(nx), 2.0 * np.ones(nx))
    trs = [adversarial_run(sys, x0, 120, seed=s) for s in range(2)]
    est = make_estimator(method, sys, x0=x0)
    batch = est.run(np.stack([t.u for t in trs]), np.stack([t.y for t in trs]), vectorize=True)
    for b, tr in enumerate(trs):
        loop = est.run(tr.u, tr.y, vectorize=False)
        assert_contains(loop, tr.x)
        single = est.run(tr.u, tr.y, vectorize=True)
        for lo, hi in ((single.lower, single.upper), (batch.lower[b], batch.upper[b])):
            np.testing.assert_allclose(lo, loop.lower, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(hi, loop.upper, rtol=1e-12, atol=1e-12)
    assert batch.contains(np.stack([t.x for t in trs])).all()


@pytest.mark.parametrize("method", ["reachability", "zonotope"])
def test_vectorised_path_equals_the_loop_on_a_badly_scaled_plant(method):
    """States of magnitudes 1e6, 1, 1e-3: the rounding is measured in the scaled norm of
    ``Channels`` on both paths, so the vectorised boxes contain the exact state and have the
    loop's widths (an ∞-norm would let the large state's rounding widen the small ones)."""
    from ivobs.simulate import vertex_disturbance
    from ivobs.testing.conformance import conformance_plants
    from ivobs.testing.exact import exact_misses, exact_run

    sys, x0 = conformance_plants()["scaled"]
    rng = np.random.default_rng(0)
    T = 150
    start = np.where(rng.integers(0, 2, sys.nx).astype(bool), x0.hi, x0.lo)
    U = rng.uniform(-1, 1, size=(T, sys.nu))
    Y, X = exact_run(sys, start, U, vertex_disturbance(sys.d_at(0), T, rng))
    est = make_estimator(method, sys, x0=x0)
    vec = est.run(U, Y, vectorize=True)
    loop = est.run(U, Y, vectorize=False)
    assert not exact_misses(vec.lower, vec.upper, X).size
    assert not exact_misses(loop.lower, loop.upper, X).size
    widths = [np.mean(r.upper - r.lower, axis=0) for r in (vec, loop)]
    np.testing.assert_allclose(widths[0], widths[1], rtol=1e-6, atol=0)


@pytest.mark.parametrize("case", CASES[:4])
def test_missing_samples_random_and_gap(case):
    sys, x0 = _system(case)
    est = make_estimator("reachability", sys, x0=x0)
    T = 200
    tr = adversarial_run(sys, x0, T, seed=10 + case[0])
    full = est.run(tr.u, tr.y)
    rng = np.random.default_rng(case[0])
    y = tr.y.copy()
    y[rng.random(T) < 0.1] = np.nan
    if sys.ny > 1:  # and some single components
        y[rng.random(T) < 0.1, 0] = np.nan
    res = est.run(tr.u, y)
    assert np.isfinite(res.lower).all() and res.missing.sum() >= 10
    assert_contains(res, tr.x)
    y = tr.y.copy()
    y[50:70] = np.nan
    gap = est.run(tr.u, y)
    assert_contains(gap, tr.x)
    w_gap, w_full = gap.upper - gap.lower, full.upper - full.lower
    assert (w_gap[69] > w_full[69]).all()  # predicted through the gap: wider
    np.testing.assert_allclose(w_gap[:51], w_full[:51], rtol=1e-12)  # Algorithm 1 until the gap
    # recovered: within 1 % of the exact Algorithm 1 widths long after the gap
    np.testing.assert_allclose(w_gap[150:], w_full[150:], rtol=1e-2)
    assert (w_gap[150:] >= w_full[150:] - 1e-12).all()


def test_time_varying_bounds_window_is_sound_and_nearly_exact():
    sys0, x0 = _system(CASES[2])
    T = 120
    k = np.arange(T)[:, None]
    c = sys0.d.center
    r = sys0.d.radius * (1.0 + 0.6 * np.sin(0.17 * k + np.arange(sys0.nd)))
    box = Box(c - r, c + r)
    sys = LinearSystem(sys0.A, sys0.B, sys0.C, D=sys0.D, E=sys0.E, F=sys0.F, d=box)
    est = make_estimator("reachability", sys, x0=x0, memory=12)
    assert est.design.memory == 12
    tr = ivobs.simulate(sys, x0.hi, np.ones((T, 1)), ivobs.vertex_disturbance(box, T, seed=1))
    res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    exact = _exact_radius(*_errors(est, sys0), x0.radius, r)
    half = 0.5 * (res.upper - res.lower)
    assert (half >= exact - 1e-12).all()  # Box(Ω_k) is attained: never below it
    np.testing.assert_allclose(half, exact, rtol=1e-2)


def test_henon_long_run_contains_the_truth():
    sc = ivobs.scenarios.get("henon", horizon=2000)
    est = make_estimator("reachability", sc.system, x0=sc.x0)
    assert est.design.spectral_radius < 1e-3  # H∞ gain makes A - LC (nearly) nilpotent
    for kind, seed in (("paper", None), ("vertex", 7)):
        tr = sc.simulate(kind, seed=seed)
        res = est.run(tr.u, tr.y)
        assert_contains(res, tr.x)
        assert np.isfinite(res.upper).all() and (res.upper - res.lower)[10:, 0].max() < 4.0


def test_batch_equals_single_runs():
    sys, x0 = _system(CASES[1])
    est = make_estimator("reachability", sys, x0=x0)
    trs = [adversarial_run(sys, x0, 80, seed=s) for s in range(3)]
    U = np.stack([t.u for t in trs])
    Y = np.stack([t.y for t in trs])
    res = est.run(U, Y)
    assert res.lower.shape == (3, 80, 3)
    assert res.contains(np.stack([t.x for t in trs])).all()
    for b, t in enumerate(trs):
        single = est.run(t.u, t.y)
        np.testing.assert_allclose(res.lower[b], single.lower, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(res.upper[b], single.upper, rtol=1e-9, atol=1e-12)
    Y[1, 10:15] = np.nan  # missing samples in one stream: loop fallback, same per stream
    res = est.run(U, Y)
    np.testing.assert_allclose(res.lower[1], est.run(U[1], Y[1]).lower, rtol=1e-12)
    assert res.contains(np.stack([t.x for t in trs])).all()


def test_inconsistent_measurement_is_reported_and_skipped():
    sc = ivobs.scenarios.get("servo-motor", horizon=60)
    tr = sc.simulate("vertex", seed=1)
    y = tr.y.copy()
    y[30, 0] += 5.0
    est = make_estimator("reachability", sc.system, x0=sc.x0)
    with pytest.warns(UserWarning, match=r"step\(s\) \[30\]"):
        res = est.run(tr.u, y, vectorize=True)
    assert res.inconsistent.tolist() == [k == 30 for k in range(60)]
    assert_contains(res, tr.x)
    with pytest.warns(UserWarning):
        loop = est.run(tr.u, y, vectorize=False)
    np.testing.assert_allclose(loop.lower, res.lower, rtol=1e-12)


@pytest.mark.parametrize("gap", [False, True])
def test_state_restore_through_json_continues_identically(gap):
    """Algorithm 1's state (no gap: x̂ and the rounding so far) and the window's (a gap)."""
    sys, x0 = _system(CASES[3])
    tr = adversarial_run(sys, x0, 60, seed=3)
    y = tr.y.copy()
    if gap:
        y[10:13] = np.nan
    est = make_estimator("reachability", sys, x0=x0)
    est.reset()
    for k in range(25):
        est.step(tr.u[k], y[k])
    saved = json.loads(json.dumps(est.state()))
    rest = [est.step(tr.u[k], y[k]) for k in range(25, 60)]
    other = make_estimator("reachability", sys, x0=x0)
    other.restore(saved)
    for k, box in zip(range(25, 60), rest):
        b2 = other.step(tr.u[k], y[k])
        np.testing.assert_array_equal(b2.lo, box.lo)
        np.testing.assert_array_equal(b2.hi, box.hi)
    assert_contains(est.run(tr.u, y), tr.x)


def test_bad_inputs():
    sc = ivobs.scenarios.get("servo-motor")
    s = sc.system
    with pytest.raises(DesignError, match="spectral radius"):
        make_estimator("reachability", s, x0=sc.x0, L=np.zeros((3, 2)))
    with pytest.raises(IvobsError, match=r"L: expected shape \(3, 2\), got \(2, 3\)"):
        make_estimator("reachability", s, x0=sc.x0, L=np.zeros((2, 3)))
    with pytest.raises(IvobsError, match="memory: expected an integer >= 1"):
        make_estimator("reachability", s, x0=sc.x0, L=sc.reference["L1"], memory=0)
    with pytest.raises(IvobsError, match="needs a prior box"):
        make_estimator("reachability", s, L=sc.reference["L1"])
    est = make_estimator("reachability", s, x0=sc.x0, L=sc.reference["L1"])
    assert est.design.gamma is None and est.design.P is None
    with pytest.raises(IvobsError, match="y: expected shape"):
        est.run(np.ones((5, 1)), np.ones((5, 3)))


def test_no_disturbance_box_shrinks_onto_the_state():
    A = np.array([[1.0, 0.2], [-0.3, 0.9]])
    sys = LinearSystem(A, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]))
    x0 = Box([-1.0, -1.0], [1.0, 1.0])
    tr = ivobs.simulate(sys, [0.7, -0.4], np.ones((80, 1)))
    est = make_estimator("reachability", sys, x0=x0, gain="hinf")
    assert est.design.gamma == 0.0
    for vec in (False, True):
        res = est.run(tr.u, tr.y, vectorize=vec)
        assert_contains(res, tr.x)
        assert (res.upper - res.lower)[-1].max() < 1e-7  # from 2: |M^79| h0, no margin


@settings(max_examples=15, deadline=None, derandomize=True)
@given(
    seed=st.integers(0, 10_000),
    nx=st.integers(2, 4),
    ny=st.integers(1, 2),
    invertible=st.booleans(),
    symmetric=st.booleans(),
    feedthrough=st.booleans(),
    missing=st.booleans(),
)
def test_property_containment_and_theorem6(
    seed, nx, ny, invertible, symmetric, feedthrough, missing
):
    sys = random_system(
        seed,
        nx=nx,
        ny=ny,
        nu=1,
        invertible=invertible,
        symmetric_bounds=symmetric,
        feedthrough=feedthrough,
    )
    x0 = Box(-np.ones(nx), np.ones(nx))
    tr = adversarial_run(sys, x0, 80, seed=seed)
    y = tr.y.copy()
    if missing:
        y[np.random.default_rng(seed).random(80) < 0.15] = np.nan
    reach = make_estimator("reachability", sys, x0=x0)
    res = reach.run(tr.u, y)
    assert_contains(res, tr.x)
    zono = make_estimator("zonotope", sys, x0=x0, L=reach.design.L).run(tr.u, y)
    assert_contains(zono, tr.x)
    if not missing:  # Theorem 6: same gain, same initial set => Algorithm 1 is inside
        # (the two bounds of their rounding differ, by the rounding of the largest magnitudes:
        # seed 3890 has bounds up to 264 and differs by 1e-9 on a bound near 0)
        tol = 1e-11 * (1 + max(np.abs(zono.upper).max(), np.abs(zono.lower).max()))
        assert (res.upper <= zono.upper + tol).all() and (res.lower >= zono.lower - tol).all()
