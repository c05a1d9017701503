"""The interval-observer family: `interval` ([Tang2019, eq. (36)] / [Efimov2013, eq. (3)]),
`interval-transformed` ([Tang2019, Theorem 5] / [Efimov2013, Theorem 2]) and `interval-split`
([Efimov2013, Theorem 3]): the papers' examples, soundness under vertex disturbances at every
step, step/run/vectorised agreement, missing samples, batches, the ordering theorems 7-8 of
[Tang2019] and the error messages."""

import json
import warnings
from functools import cache

import numpy as np
import pytest

import ivobs
from ivobs import Box, DesignError, IvobsError, LinearSystem, scenarios
from ivobs.testing import adversarial_run, assert_contains, random_system

FAMILY = ("interval", "interval-split", "interval-transformed")
POLES = {2: [0.2, 0.5], 3: [0.15, 0.4, 0.6], 4: [0.1, 0.3, 0.5, 0.7]}


def build_servo(method):
    sc = scenarios.get("servo-motor", horizon=300)
    opts = {"L": sc.reference["L2"]} if method == "interval" else {}
    if method == "interval-transformed":
        opts = {"poles": POLES[3]}
    return sc, ivobs.make_estimator(method, sc.system, x0=sc.x0, **opts)


@cache
def servo(method):
    return build_servo(method)


def check_paths(est, tr, rtol=1e-9):
    """Sound at every step on the loop and the vectorised path, which agree."""
    loop = est.run(tr.u, tr.y, vectorize=False)
    vec = est.run(tr.u, tr.y, vectorize=True)
    assert_contains(loop, tr.x)
    assert_contains(vec, tr.x)
    scale = 1.0 + np.abs(loop.upper) + np.abs(loop.lower)
    assert np.max(np.abs(vec.upper - loop.upper) / scale) < rtol
    assert np.max(np.abs(vec.lower - loop.lower) / scale) < rtol
    return loop


# -- paper examples -------------------------------------------------------------------------------
def test_servo_with_the_papers_lmi41_gain():
    """[Tang2019, Example 1]: L2 from LMI (41) makes A − L2 C nonnegative with ρ ≈ 0.99977."""
    sc, est = servo("interval")
    assert est.design.D.min() >= 0
    assert est.design.spectral_radius == pytest.approx(0.99977, abs=5e-6)
    for kind in ("paper", "vertex"):
        tr = sc.simulate(kind, seed=3)
        res = check_paths(est, tr)
        assert np.all(np.isfinite(res.lower))
    # the interval observer is a cooperative special case of the split one: same numbers
    split = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, L=sc.reference["L2"])
    res_s = split.run(tr.u, tr.y, vectorize=False)
    np.testing.assert_array_equal(res_s.upper, res.upper)


def test_servo_default_gain_beats_the_papers_gain():
    """LMI (41) is feasible on the servo motor; ivobs' width refinement keeps A − LC >= 0 and
    gives a smaller steady-state width than the paper's L2 in every state."""
    sc = scenarios.get("servo-motor", horizon=200)
    # the observers' own boxes, without the finite-memory bound (which both would meet)
    est = ivobs.make_estimator("interval", sc.system, x0=sc.x0, finite_memory=False)
    assert est.design.gain == "width" and est.design.D.min() >= -1e-9
    paper = ivobs.make_estimator(
        "interval", sc.system, x0=sc.x0, L=sc.reference["L2"], finite_memory=False
    )
    assert np.all(est.design.steady_width < paper.design.steady_width)
    # A[3,3] = 0.9995 sits in the unmeasured column: 0.0808 / (1 − 0.9995) bounds w3 from below
    assert est.design.steady_width[2] > 0.0808 / 0.0005
    tr = sc.simulate("vertex", seed=0)
    res, ref = check_paths(est, tr), paper.run(tr.u, tr.y)
    assert np.all(res.width[-1] < ref.width[-1])
    lmi = ivobs.make_estimator("interval", sc.system, x0=sc.x0, gain="lmi")
    assert lmi.design.gain == "lmi" and np.all(lmi.design.steady_width >= est.design.steady_width)


@pytest.mark.parametrize("name", ["tang-example2", "efimov-planar"])
def test_no_cooperative_gain_for_the_papers_counterexamples(name):
    sc = scenarios.get(name)
    with pytest.raises(DesignError, match=r"no gain L makes A − LC nonnegative; row \d: no L_"):
        ivobs.make_estimator("interval", sc.system, x0=sc.x0)


def test_tang_example2_has_no_split_observer_either():
    sc = scenarios.get("tang-example2")
    msg = r"no gain L makes \|A − LC\| Schur .*proved by .*no gain can do better than 1"
    with pytest.raises(DesignError, match=msg):
        ivobs.make_estimator("interval-split", sc.system, x0=sc.x0)


def test_tang_example2_transformed_with_the_papers_design():
    sc = scenarios.get("tang-example2", horizon=200)
    ref = sc.reference
    est = ivobs.make_estimator(
        "interval-transformed",
        sc.system,
        x0=sc.x0,
        L=ref["L"],
        R=ref["R"],
        e1=ref["e1"],
        e2=ref["e2"],
    )
    np.testing.assert_allclose(est.design.S, ref["S"], atol=2.2e-3)  # see test_similarity
    np.testing.assert_allclose(np.sort(est.design.poles.real), [0.000153, 0.325947], atol=1e-6)
    for kind in ("paper", "vertex"):
        check_paths(est, sc.simulate(kind, seed=1))


def test_planar_example_split_observer_with_the_papers_gain():
    """[Efimov2013, Section IV.A]: L = (0.3, 0.6) gives λ(D) = {0, −0.5}, λ(|D|) = {0, 0.5}."""
    sc = scenarios.get("efimov-planar", horizon=150)
    est = ivobs.make_estimator(  # the paper's observer (no finite-memory bound)
        "interval-split", sc.system, x0=sc.x0, L=sc.reference["L"], finite_memory=False
    )
    assert est.design.spectral_radius == pytest.approx(0.5, abs=1e-12)
    np.testing.assert_allclose(
        np.sort(np.linalg.eigvals(est.design.D).real), [-0.5, 0.0], atol=1e-12
    )
    tr = sc.simulate()  # the paper's state-dependent δb(t, x)
    res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    # the width converges to (I − |D|)⁻¹ |E − LF| Δ = (2.628, 2.24) (ρ = 0.5: fast)
    np.testing.assert_allclose(res.width[-1], est.design.steady_width, rtol=1e-9)
    np.testing.assert_allclose(est.design.steady_width, [0.7 * 2.24 + 1.06, 2.24], rtol=1e-12)
    check_paths(est, sc.simulate("vertex", seed=4))
    # the default design finds the same spectral radius
    auto = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, gain="margin")
    assert auto.design.spectral_radius == pytest.approx(0.5, abs=1e-7)


def test_planar_example_transformed_default_design():
    """The default design of `interval-transformed` succeeds where the paper's R is invalid, and
    is not much looser than the split observer (the paper: 'a similar performance')."""
    sc = scenarios.get("efimov-planar", horizon=150)
    est = ivobs.make_estimator("interval-transformed", sc.system, x0=sc.x0)
    assert est.design.gain == "search" and est.design.R.min() >= -1e-9
    assert est.design.spectral_radius < 1
    split = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, L=sc.reference["L"])
    assert est.design.steady_width.sum() < 2 * split.design.steady_width.sum()
    tr = sc.simulate("vertex", seed=5)
    check_paths(est, tr)


@pytest.mark.parametrize("method", ["interval", "interval-split"])
def test_henon_bounds_from_measurements_long_vertex_run(method):
    """[Efimov2013, Section IV.B, Remark 1]: b(t) bounded from y(t); the paper's
    L = (−0.1, 0.1) for Theorem 1; adversarial a(t), d(t), v(t) on their vertices for 1500 steps."""
    sc = scenarios.get("henon", horizon=1500)
    L = sc.reference["L"]
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, L=L)
    np.testing.assert_allclose(np.sort(np.linalg.eigvals(est.design.D).real), [-0.4, 0.5])
    for seed in (0, 1):
        tr = sc.simulate("vertex", seed=seed)
        res = est.run(tr.u, tr.y)  # callable bounds: the loop
        assert_contains(res, tr.x)
        assert np.all(res.width[100:] < 2.0) and np.all(res.mean_width(100) < 1.0)
    auto = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    res_auto = auto.run(tr.u, tr.y)
    assert_contains(res_auto, tr.x)
    assert np.all(res_auto.mean_width(100) < res.mean_width(100))  # ivobs' gain is tighter


# -- random systems, vertex disturbances, every step --------------------------------------------
def cooperative_system(seed):
    """Random systems that admit A − LC >= 0 Schur: C invertible (ny = nx; odd seeds, with
    feedthrough, some with singular A), or A >= 0 and Schur with one output (even seeds)."""
    rng = np.random.default_rng(seed)
    if seed % 2:
        return random_system(
            seed,
            nx=2,
            ny=2,
            nu=1,
            symmetric_bounds=bool(seed % 3),
            feedthrough=True,
            invertible=seed % 4 != 1,
        )
    n = int(rng.integers(2, 5))
    A = rng.uniform(0, 1, (n, n)) * (rng.random((n, n)) < 0.7)
    A *= rng.uniform(0.5, 0.98) / max(np.max(np.abs(np.linalg.eigvals(A))), 1e-3)
    C = rng.normal(size=(1, n))
    r = rng.uniform(0.1, 1.0, n + 1)
    c = rng.uniform(-0.5, 0.5, n + 1) * r
    return LinearSystem(
        A,
        rng.normal(size=(n, 1)),
        C,
        D=rng.normal(size=(1, 1)),
        E=rng.normal(size=(n, n + 1)) * 0.3,
        F=rng.normal(size=(1, n + 1)) * 0.1,
        d=Box(c - r, c + r),
    )


@pytest.mark.parametrize("seed", range(6))
def test_interval_random_systems_vertex_disturbances(seed):
    sys = cooperative_system(seed)
    x0 = Box(-np.ones(sys.nx), np.ones(sys.nx))
    est = ivobs.make_estimator("interval", sys, x0=x0)
    assert est.design.D.min() >= -1e-9
    check_paths(est, adversarial_run(sys, x0, 120, seed=seed))


@pytest.mark.parametrize("seed", range(8))
def test_split_and_transformed_random_systems_vertex_disturbances(seed):
    kw = dict(
        nx=2 + seed % 3,
        ny=1 + seed % 2,
        nu=1,
        invertible=seed % 3 != 0,
        symmetric_bounds=seed % 2 == 0,
        feedthrough=seed % 4 == 1,
    )
    sys = random_system(100 + seed, **kw)
    x0 = Box(-np.ones(sys.nx), 2 * np.ones(sys.nx))
    tr = adversarial_run(sys, x0, 120, seed=seed, hold=1 + seed % 3)
    est = ivobs.make_estimator("interval-transformed", sys, x0=x0, poles=POLES[sys.nx])
    check_paths(est, tr)
    try:
        split = ivobs.make_estimator("interval-split", sys, x0=x0)
    except DesignError as exc:
        assert "no gain L makes |A − LC| Schur" in str(exc) and "proved by" in str(exc)
        return
    assert split.design.spectral_radius < 1
    check_paths(split, tr)


def test_split_design_succeeds_on_most_random_systems():
    ok = 0
    for seed in range(12):
        try:
            ivobs.make_estimator(
                "interval-split",
                random_system(200 + seed, nx=3, ny=2),
                x0=Box(-np.ones(3), np.ones(3)),
            )
            ok += 1
        except DesignError:
            pass
    assert ok >= 6


def test_time_varying_bounds_vectorised_equals_loop():
    sys0 = random_system(7, nx=2, ny=2, nu=1)
    T = 80
    k = np.arange(T)[:, None]
    r = (0.5 + 0.4 * np.sin(0.1 * k)) * np.ones((1, sys0.nd))
    sys = LinearSystem(sys0.A, sys0.B, sys0.C, E=sys0.E, F=sys0.F, d=Box(-r, r))
    x0 = Box(-np.ones(2), np.ones(2))
    tr = adversarial_run(sys, x0, T, seed=2)
    for method in FAMILY:
        opts = {"poles": POLES[2]} if method == "interval-transformed" else {}
        est = ivobs.make_estimator(method, sys, x0=x0, **opts)
        check_paths(est, tr)


# -- protocol: step, state, batches, missing samples ---------------------------------------------
@pytest.mark.parametrize("method", FAMILY)
def test_step_reproduces_run_and_state_restores(method):
    sc, est = servo(method)
    tr = sc.simulate("vertex", seed=8)
    res = est.run(tr.u[:60], tr.y[:60], vectorize=False)  # the loop: step()'s recursion
    est.reset()
    for k in range(30):
        box = est.step(tr.u[k], tr.y[k])
        np.testing.assert_array_equal(box.lo, res.lower[k])
        np.testing.assert_array_equal(box.hi, res.upper[k])
    saved = json.loads(json.dumps(est.state()))
    other = build_servo(method)[1]  # designed again: same options, same design
    other.restore(saved)
    for k in range(30, 60):
        np.testing.assert_allclose(other.step(tr.u[k], tr.y[k]).hi, res.upper[k], rtol=1e-12)


@pytest.mark.parametrize("method", FAMILY)
def test_batches_equal_single_runs(method):
    sc, est = servo(method)
    trs = [sc.simulate("vertex", seed=s) for s in (1, 2, 3)]
    U = np.stack([t.u[:200] for t in trs])
    Y = np.stack([t.y[:200] for t in trs])
    X = np.stack([t.x[:200] for t in trs])
    res = est.run(U, Y)  # batches take the vectorised path
    assert res.lower.shape == (3, 200, 3)
    assert res.contains(X).all()
    for b in range(3):
        single = est.run(trs[b].u[:200], trs[b].y[:200], vectorize=False)
        # two algorithms, each with its own rounding bound: equal within rounding
        np.testing.assert_allclose(res.upper[b], single.upper, rtol=1e-8, atol=1e-8)
        np.testing.assert_allclose(res.lower[b], single.lower, rtol=1e-8, atol=1e-8)
    Y[1, 50] = np.nan  # a missing sample: the loop, per stream
    res_m = est.run(U, Y)
    assert res.contains(X).all() and np.isfinite(res_m.upper).all()


@pytest.mark.parametrize("method", FAMILY)
def test_missing_samples_random_and_gap(method):
    sc, est = servo(method)
    tr = sc.simulate("vertex", seed=21)
    rng = np.random.default_rng(0)
    y = tr.y.copy()
    y[rng.random(tr.T) < 0.1] = np.nan
    y[rng.random(y.shape) < 0.1] = np.nan
    y[100:120] = np.nan
    res = est.run(tr.u, y)
    assert_contains(res, tr.x)
    assert np.all(np.isfinite(res.upper))
    full = est.run(tr.u, tr.y)
    # the measured states widen in the gap; the current i can be narrower than without gaps:
    # after earlier missing samples the bounds were intersected with a finite-memory bound
    # (ivobs.estimators.interval.window), tighter on i than the complete observer
    assert np.all(res.width[119, :2] > full.width[119, :2])
    # in the gap the prediction is the model's: x+ ∈ A[x] + B u + E[d] (gain zero)
    A, B, _, _, E, _ = sc.system.matrices_at(0)
    k = 110
    lo, hi = ivobs.image_bounds(A, res.lower[k], res.upper[k])
    elo, ehi = ivobs.image_bounds(E, sc.system.d.lo, sc.system.d.hi)
    if method != "interval-transformed":  # (its box is the image of the z box, not of this one)
        # (atol: the reported bounds carry the outward margin ROUNDING s_k, s_k ~ 40 here)
        np.testing.assert_allclose(res.upper[k + 1], hi + B @ tr.u[k] + ehi, rtol=1e-9, atol=1e-8)
        np.testing.assert_allclose(res.lower[k + 1], lo + B @ tr.u[k] + elo, rtol=1e-9, atol=1e-8)


def test_missing_component_breaks_nonnegativity_and_stays_sound():
    """Servo, L2: dropping the speed sensor leaves A − L2[:, :1] C with negative entries; the
    D⁺/D⁻ step keeps the box sound."""
    sc, est = servo("interval")
    L = sc.reference["L2"].copy()
    L[:, 1] = 0
    A, _, C, *_ = sc.system.matrices_at(0)
    assert (A - L @ C).min() < 0
    for seed in range(3):
        tr = sc.simulate("vertex", seed=seed)
        y = tr.y.copy()
        y[::2, 1] = np.nan
        assert_contains(est.run(tr.u, y), tr.x)


def test_inconsistent_measurement_is_reported_and_ignored():
    sc, est = servo("interval-split")
    tr = sc.simulate("vertex", seed=2)
    y = tr.y.copy()
    y[40, 0] += 3.0  # a sensor fault
    with pytest.warns(UserWarning, match=r"step\(s\) \[40\] is inconsistent"):
        res = est.run(tr.u, y, vectorize=True)
    assert res.inconsistent[40] and res.inconsistent.sum() == 1
    y2 = y.copy()
    y2[40] = np.nan
    # the same bounds; the outward margin differs by ROUNDING * 3: the faulty sample enters the
    # data scale s_k (base.py) while the missing one does not
    np.testing.assert_allclose(est.run(tr.u, y2).upper, res.upper, rtol=0, atol=1e-9)
    with pytest.raises(ivobs.InconsistentDataError):
        ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, on_inconsistent="raise").run(
            tr.u, y
        )


# -- ordering theorems 7 and 8 of [Tang2019] ---------------------------------------------------
def _reachability(sys, x0, L):
    if "reachability" not in ivobs.methods():
        pytest.skip("the reachability method is not available")
    return ivobs.make_estimator("reachability", sys, x0=x0, L=L)


def test_theorem7_reachability_inside_interval_with_the_same_gain():
    """The theorem compares the paper's observer (36): without the finite-memory bound."""
    sc, _ = servo("interval")
    est = ivobs.make_estimator(
        "interval", sc.system, x0=sc.x0, L=sc.reference["L2"], finite_memory=False
    )
    reach = _reachability(sc.system, sc.x0, sc.reference["L2"])
    tr = sc.simulate("vertex", seed=6)
    a, b = est.run(tr.u, tr.y), reach.run(tr.u, tr.y)
    tol = 1e-8 * (1 + np.abs(a.upper))
    assert np.all(b.upper <= a.upper + tol) and np.all(b.lower >= a.lower - tol)


def test_theorem8_reachability_inside_transformed_with_the_same_gain():
    """The theorem compares the paper's observer: without the finite-memory bound (with it the
    transformed observer's boxes are the tighter ones here)."""
    sc = scenarios.get("tang-example2", horizon=100)
    ref = sc.reference
    est = ivobs.make_estimator(
        "interval-transformed",
        sc.system,
        x0=sc.x0,
        L=ref["L"],
        R=ref["R"],
        e1=ref["e1"],
        e2=ref["e2"],
        finite_memory=False,
    )
    reach = _reachability(sc.system, sc.x0, ref["L"])
    tr = sc.simulate("vertex", seed=7)
    a, b = est.run(tr.u, tr.y), reach.run(tr.u, tr.y)
    tol = 1e-8 * (1 + np.abs(a.upper))
    assert np.all(b.upper <= a.upper + tol) and np.all(b.lower >= a.lower - tol)
    assert a.mean_width(20).sum() > 2 * b.mean_width(20).sum()  # [Tang2019, Fig. 4]: much looser


# -- bad input ------------------------------------------------------------------------------------
def test_bad_inputs_name_the_argument():
    sc = scenarios.get("servo-motor")
    sys, x0 = sc.system, sc.x0
    with pytest.raises(IvobsError, match=r"L: expected shape \(3, 2\)"):
        ivobs.make_estimator("interval", sys, x0=x0, L=np.ones((2, 2)))
    with pytest.raises(IvobsError, match="gain: expected 'width', 'lmi\\+width' or 'lmi'"):
        ivobs.make_estimator("interval", sys, x0=x0, gain="fast")
    with pytest.raises(
        IvobsError, match="gain: expected 'width', 'margin\\+width', 'margin' or 'lmi'"
    ):
        ivobs.make_estimator("interval-split", sys, x0=x0, gain="fast")
    with pytest.raises(IvobsError, match="x0: the interval method needs a prior box"):
        ivobs.make_estimator("interval", sys)
    with pytest.raises(IvobsError, match="L, poles: give the gain L or the poles"):
        ivobs.make_estimator(
            "interval-transformed", sys, x0=x0, L=sc.reference["L1"], poles=POLES[3]
        )
    with pytest.raises(IvobsError, match="e1, e2: they only serve to compute S"):
        ivobs.make_estimator("interval-transformed", sys, x0=x0, S=np.eye(3), e1=np.ones(3))
    with pytest.raises(IvobsError, match=r"poles: expected values inside"):
        ivobs.make_estimator("interval-transformed", sys, x0=x0, poles=[0.2, 0.5, 1.5])
    with pytest.raises(DesignError, match=r"A − LC is not nonnegative: entry \(3, 2\) = -1.381"):
        ivobs.make_estimator("interval", sys, x0=x0, L=sc.reference["L1"])
    with pytest.raises(DesignError, match=r"\|A − LC\| = D⁺ \+ D⁻ is not Schur: spectral radius"):
        ivobs.make_estimator("interval-split", sys, x0=x0, L=np.zeros((3, 2)))
    with pytest.raises(DesignError, match=r"S \(A − LC\) S⁻¹ is not nonnegative"):
        ivobs.make_estimator("interval-transformed", sys, x0=x0, L=sc.reference["L1"], S=np.eye(3))
    with pytest.raises(DesignError, match="S is singular"):
        ivobs.make_estimator(
            "interval-transformed", sys, x0=x0, L=sc.reference["L2"], S=np.zeros((3, 3))
        )
    with pytest.raises(DesignError, match="S does not transform A − LC into R"):
        ivobs.make_estimator(
            "interval-transformed", sys, x0=x0, L=sc.reference["L2"], S=np.eye(3), R=np.eye(3) * 0.5
        )
    ct = LinearSystem(-np.eye(2), None, np.eye(2), dt=0)
    with pytest.raises(IvobsError, match="discrete-time"):
        ivobs.make_estimator("interval-split", ct, x0=Box(-np.ones(2), np.ones(2)))


def test_given_S_and_R_from_a_nonnegative_gain():
    """With L2 (A − L2 C >= 0) S = I is a valid transformation: the transformed observer then
    equals the interval observer (after step 0, where both return x0)."""
    sc, est = servo("interval")
    tr_ = ivobs.make_estimator(
        "interval-transformed", sc.system, x0=sc.x0, L=sc.reference["L2"], S=np.eye(3)
    )
    assert tr_.design.e1 is None and tr_.design.gain == "given"
    tr = sc.simulate("vertex", seed=9)
    # same recursion; the margins differ at rounding level: interval's covers the terms of its
    # gain (rounding_bound: mu = 1.67, nu = 2.18 with L2, kappa = 4432), transformed's does not
    np.testing.assert_allclose(tr_.run(tr.u, tr.y).upper, est.run(tr.u, tr.y).upper, rtol=1e-8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        tr_.run(tr.u, tr.y, vectorize=True)


# -- redundant noise-free outputs, gaps, large gains and rounding -------------------------
def redundant_system(seed, zero_width=False):
    """ny > nx: every state is read by two (scaled) sensors; F = 0 (noise-free) or zero-width
    bounds, the layouts where the width objective leaves part of L free."""
    rng = np.random.default_rng(seed)
    n = 1 + seed % 2
    A = rng.uniform(0.05, 1.0, (n, n))
    A *= rng.uniform(0.5, 0.95) / np.max(np.abs(np.linalg.eigvals(A)))
    C0 = np.eye(n) + 0.2 * rng.uniform(0, 1, (n, n))
    C = np.vstack([C0, C0 * rng.uniform(0.5, 2.0, (n, 1))])
    nd = n + 2 * n
    E = np.hstack([0.2 * rng.normal(size=(n, n)), np.zeros((n, 2 * n))])
    F = np.hstack([np.zeros((2 * n, n)), 0.1 * np.eye(2 * n)])
    if zero_width:
        c = rng.uniform(-0.5, 0.5, nd)
        d = Box(c, c)
    else:
        F = np.zeros_like(F)
        d = Box(-np.ones(nd), np.ones(nd))
    return LinearSystem(A, rng.normal(size=(n, 1)), C, E=E, F=F, d=d)


@pytest.mark.parametrize("method", ["interval", "interval-split"])
def test_redundant_noise_free_sensors_with_a_gap(method):
    """Two noise-free sensors of one state: a gap of sensor 2 used to take the width
    0.2 -> 2e17 (|L| = 1e6)."""
    sys = LinearSystem(
        [[0.9]], [[1.0]], [[1.0], [1.0]], E=[[0.1]], F=[[0.0], [0.0]], d=Box([-1.0], [1.0])
    )
    x0 = Box([-1.0], [1.0])
    est = ivobs.make_estimator(method, sys, x0=x0)
    np.testing.assert_allclose(est.design.L, [[0.45, 0.45]], atol=1e-9)
    np.testing.assert_allclose(est.design.missing_radius, [0.45, 0.45], atol=1e-9)
    tr = adversarial_run(sys, x0, 60, seed=1)
    y = tr.y.copy()
    y[10:30, 1] = np.nan
    res = est.run(tr.u, y)
    assert_contains(res, tr.x)
    assert not res.inconsistent.any()
    # a gap of sensor 2: x+ = 0.45 x + 0.45 y1 + ..., width 0.2 / (1 - 0.45) in the gap
    assert np.max(res.width[1:]) < 0.2 / 0.55 + 1e-6


@pytest.mark.parametrize("seed", range(8))
def test_redundant_sensors_random_systems_gaps_vertex_disturbances(seed):
    """Property test around the weak spot: bounded gains, containment at every step and no
    false inconsistency with 10% missing components and a 20-step gap of one sensor."""
    sys = redundant_system(seed, zero_width=seed % 3 == 0)
    x0 = Box(-np.ones(sys.nx), np.ones(sys.nx))
    rng = np.random.default_rng(seed)
    tr = adversarial_run(sys, x0, 120, seed=seed)
    y = tr.y.copy()
    y[rng.random(y.shape) < 0.1] = np.nan
    y[40:60, seed % sys.ny] = np.nan
    for method in ("interval", "interval-split"):
        try:
            est = ivobs.make_estimator(method, sys, x0=x0)
        except DesignError:
            assert method == "interval"
            continue
        assert np.abs(est.design.L).max() < 100.0
        res = est.run(tr.u, y)
        assert_contains(res, tr.x)
        assert not res.inconsistent.any()
        assert np.all(np.isfinite(res.width)) and res.width.max() < 1e3
        check_paths(est, tr)


@pytest.mark.parametrize("method", ["interval", "interval-split"])
def test_a_large_given_gain_stays_sound_under_a_gap(method):
    """The gain the old design returned, given explicitly, with zero-width bounds: a gap of
    sensor 2 makes |A − L_k C| = 1e6, which amplified the rounding of L y (|L||y| ~ 1e6) into a
    miss of 3.5e-6 and a permanent false inconsistency. Every step bounds its own rounding
    (the terms scale with |L||y|), in both run paths."""
    sys = LinearSystem(
        [[0.9]], [[1.0]], [[1.0], [1.0]], E=[[0.1]], F=[[0.2], [-0.1]], d=Box([0.5], [0.5])
    )
    x0 = Box([-1.0], [1.0])
    T = 40
    tr = ivobs.simulate(sys, [0.7], u=np.sin(np.arange(T))[:, None], d=np.full((T, 1), 0.5))
    est = ivobs.make_estimator(method, sys, x0=x0, L=[[-999999.1, 1e6]])  # A − LC ~ 0
    y = tr.y.copy()
    y[2:5, 1] = np.nan
    for vectorize in (False, True):
        res = est.run(tr.u, y, vectorize=vectorize)
        assert_contains(res, tr.x)
        assert not res.inconsistent.any()
    res = est.run(tr.u[None], tr.y[None])  # complete data: the vectorised path
    assert res.contains(tr.x[None]).all() and not res.inconsistent.any()


@pytest.mark.parametrize("big", [1.5e6, 3e6, 6e6])
def test_vectorised_margin_covers_the_terms_of_a_large_gain(big):
    """Complete data, batches (the vectorised path), |L| ~ 1e6 and |x| ~ 1e3: the terms L y
    are ~1e9; a relative margin of 1e-10 (1 + |x| + |y|) missed by 4e-8 ... 4e-7. The
    vectorised path's bound scales with the gain and the data."""
    rng = np.random.default_rng(int(big))
    sys = LinearSystem(
        [[0.9]], [[1.0]], [[1.0], [1.0]], E=[[0.1]], F=[[0.2], [-0.1]], d=Box([0.5], [0.5 + 1e-10])
    )
    x0 = Box([1e3 - 1.0], [1e3 + 1.0])
    est = ivobs.make_estimator("interval-split", sys, x0=x0, L=[[0.9 - big, big]])
    trs = [
        ivobs.simulate(
            sys, [1e3 + rng.uniform(-1, 1)], rng.normal(size=(50, 1)) * 100, np.full((50, 1), 0.5)
        )
        for _ in range(20)
    ]
    res = est.run(np.stack([t.u for t in trs]), np.stack([t.y for t in trs]))
    assert_contains(res, np.stack([t.x for t in trs]))
    assert not res.inconsistent.any()


def _nearly_unobservable(seed: int) -> tuple[LinearSystem, Box, ivobs.Trajectory]:
    """A stable system whose ``C`` is ``eps`` away from orthogonal to an eigenvector, far from
    the origin: the default design of interval-transformed then takes a large gain and an
    ill-conditioned ``S`` (the case that once lost the true state by 3.6 box widths)."""
    rng = np.random.default_rng(seed)
    nx = 2 + seed % 2
    V = rng.normal(size=(nx, nx))
    A = V @ np.diag(rng.uniform(-0.9, 0.9, nx)) @ np.linalg.inv(V)
    v0 = V[:, 0] / np.linalg.norm(V[:, 0])
    c = rng.normal(size=nx)
    c += (float(rng.choice([1e-5, 1e-7])) - c @ v0) * v0
    r = rng.uniform(0.2, 1.0, 2) * 1e-4
    sys = LinearSystem(A, None, c[None, :], E=0.3 * rng.normal(size=(nx, 2)),
                       F=0.1 * rng.normal(size=(1, 2)), d=Box(-r, r))  # fmt: skip
    centre = float(rng.choice([1e5, 1e7])) * rng.choice([-1.0, 1.0], nx)
    x0 = Box(centre - 1e-6, centre + 1e-6)
    d = np.where(rng.random((30, 2)) < 0.5, -r, r)
    return sys, x0, ivobs.simulate(sys, np.where(rng.random(nx) < 0.5, x0.lo, x0.hi), None, d)


@pytest.mark.parametrize("seed", range(10))
def test_transformed_contains_the_state_with_a_large_gain_and_ill_conditioned_S(seed):
    """The recursion in ``z = S x`` bounds its own rounding (the residual ``Q S − S M̂`` acting
    on ``x``, the computed ``S⁻¹``, the products with ``S``) in both run paths."""
    sys, x0, tr = _nearly_unobservable(seed)
    try:
        est = ivobs.make_estimator("interval-transformed", sys, x0=x0)
    except DesignError:
        pytest.skip("no transformed design for this system")
    for vectorize in (True, False):
        res = est.run(None, tr.y, vectorize=vectorize)
        assert not res.inconsistent.any()
        assert_contains(res, tr.x)


def test_transformed_rounding_bound_is_negligible_on_the_paper_example():
    """On the servo motor of [Tang2019] the proven rounding terms of ``z = S x`` change
    nothing visible: the width converges to the exact steady state
    ``|S⁻¹| (I − |R|)⁻¹ |S (E − LF)| Δ`` of the design (relative difference below 1e-8; the
    observer's own boxes: the finite-memory bound would cut them below it)."""
    sc = scenarios.get("servo-motor", horizon=3000)
    est = ivobs.make_estimator("interval-transformed", sc.system, x0=sc.x0, finite_memory=False)
    tr = sc.simulate("vertex", seed=0)
    for vectorize in (False, True):
        res = est.run(sc.u, tr.y, vectorize=vectorize)
        assert_contains(res, tr.x)
        np.testing.assert_allclose(res.width[-1], est.design.steady_width, rtol=1e-8)


def test_transformed_regression_large_gain_far_from_the_origin():
    """A large default gain far from the origin: ``L ≈ (5.4e6, −1.8e6)``, ``cond(S) ≈ 1.2e7``,
    ``|x| ≈ 1e6``: the true state was 4231 outside a box 1164 wide at step 2."""
    A = [[0.021076483834902654, 1.296600609653334], [0.05440529898189982, -0.2652197859523413]]
    C = [[-0.6981669039978192, -2.034870354896757]]
    E = [[-0.4361806017959113, -0.5284829050220129], [0.13777619470524255, -0.4373513334001146]]
    F = [[0.05347979189606259, 0.03640272926732858]]
    r = np.array([5.6966072933002644e-05, 7.835263952421959e-05])
    sys = LinearSystem(A, None, C, E=E, F=F, d=Box(-r, r))
    x0 = Box([1e6 - 1e-6, -1e6 - 1e-6], [1e6 + 1e-6, -1e6 + 1e-6])
    d = np.where(np.random.default_rng(0).random((10, 2)) < 0.5, -r, r)
    tr = ivobs.simulate(sys, x0.lo, None, d)
    est = ivobs.make_estimator("interval-transformed", sys, x0=x0)
    assert np.abs(est.design.L).max() > 1e6  # the default design's large gain
    for vectorize in (True, False):
        assert_contains(est.run(None, tr.y, vectorize=vectorize), tr.x)
