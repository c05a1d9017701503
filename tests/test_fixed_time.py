"""The fixed-time parity-space estimator [Wang2020]: the paper's design and bounds, the
fixed-time property (Remark 3), per-step designs (Remark 4), the output injection (Remark 1),
missing samples, batches, online use, inconsistent data, errors. Containment with an exact
simulator: tests/test_fixed_time_containment.py; missing samples on random plants:
tests/test_fixed_time_missing_samples.py."""

import dataclasses
import json
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import Box, DesignError, InconsistentDataError, IvobsError, LinearSystem
from ivobs.estimators.fixed_time import FixedTimeEstimator, FixedTimeState
from ivobs.testing import adversarial_run, assert_contains, random_system


def _check(sys, tr, y=None, x0=None, **opts):
    """Run loop and vectorised paths; both contain the truth and agree to 1e-9."""
    est = ivobs.make_estimator("fixed-time", sys, x0=x0, **opts)
    y = tr.y if y is None else y
    loop = est.run(tr.u, y, vectorize=False)
    vec = est.run(tr.u, y, vectorize=True)
    assert_contains(loop, tr.x)
    assert_contains(vec, tr.x)
    v = est.valid_from
    assert np.isnan(loop.lower[:v]).all() and np.isfinite(loop.lower[v:]).all()
    scale = 1.0 + np.abs(loop.lower[v:])
    assert np.max(np.abs(vec.lower[v:] - loop.lower[v:]) / scale) < 1e-9
    assert np.max(np.abs(vec.upper[v:] - loop.upper[v:]) / scale) < 1e-9
    return est, loop


# -- the paper's example ---------------------------------------------------------------------
@pytest.fixture(scope="module")
def dinh():
    sc = ivobs.scenarios.get("dinh2019", horizon=60)
    return sc, sc.simulate()


def test_paper_design_through_make_estimator(dinh):
    sc, _ = dinh
    est = ivobs.make_estimator("fixed-time", sc.system, s=2)
    d = est.design
    assert d.s == 2 and est.valid_from == 2 and d.L is None and d.Mc is None
    for name in ("T", "Mx", "Mu", "Md", "Mx_pinv", "Mx_perp"):
        np.testing.assert_array_equal(np.round(getattr(d, name), 4), sc.reference[name])
    # H = -T Md blkdiag(Wd) of eq. (10), Wd = diag(1, 1)
    np.testing.assert_allclose(d.H, -d.T @ d.Md)


def test_paper_bounds_and_widths(dinh):
    sc, tr = dinh
    _est, res = _check(sc.system, tr, s=2, strips=False)  # the paper's box
    # eq. (11): constant width 2 Σ_j |H_ij| with the paper's T
    w = 2 * np.abs(np.array(sc.reference["T"]) @ sc.reference["Md"]).sum(axis=1)
    np.testing.assert_allclose(res.width[2:], np.broadcast_to(w, (58, 2)), atol=2e-4)
    np.testing.assert_allclose(res.mean_width(), [0.34737, 0.34272], atol=1e-5)
    # the paper's printed T (T Mx = I only to 1.8e-4) is projected onto T Mx = I and gives
    # the same boxes to its 4 decimals
    est_T = ivobs.make_estimator("fixed-time", sc.system, s=2, T=sc.reference["T"], strips=False)
    np.testing.assert_allclose(est_T.design.T, sc.reference["T"], atol=1e-4)
    np.testing.assert_allclose(est_T.design.T @ est_T.design.Mx, np.eye(2), atol=1e-12)
    res_T = est_T.run(tr.u, tr.y)
    assert_contains(res_T, tr.x)
    np.testing.assert_allclose(res_T.lower[2:], res.lower[2:], atol=1e-3)


def test_default_s_is_lemma2_minimum_and_x0_changes_nothing(dinh):
    sc, tr = dinh
    est = ivobs.make_estimator("fixed-time", sc.system)
    assert est.s == 1 and est.valid_from == 1 and not FixedTimeEstimator.needs_x0
    res = est.run(tr.u, tr.y)
    # s = nx - 1 with one output: Mx square, T = Mx⁻¹ is the only solution; x1 = y - D2 d
    np.testing.assert_allclose(res.mean_width(), [2 / 9, 0.3402778], atol=1e-6)
    res_x0 = ivobs.make_estimator("fixed-time", sc.system, x0=sc.x0).run(tr.u, tr.y)
    np.testing.assert_array_equal(res_x0.lower, res.lower)


def test_frobenius_norm_never_grows_with_s_but_width_criterion_is_narrower(dinh):
    sc, tr = dinh
    norms, widths = [], []
    for s in range(1, 7):
        d = ivobs.make_estimator("fixed-time", sc.system, s=s).design
        norms.append(np.linalg.norm(d.T @ d.Md))
        _est, res = _check(sc.system, tr, s=s, criterion="width")
        widths.append(res.mean_width(burn_in=6))
        fro = ivobs.make_estimator("fixed-time", sc.system, s=s, strips=False).run(tr.u, tr.y)
        assert np.all(widths[-1] <= fro.mean_width(burn_in=6) + 1e-9)
    assert np.all(np.diff(norms) <= 1e-12)
    assert np.all(np.diff(np.array(widths), axis=0) <= 1e-9)


@pytest.mark.parametrize(
    ("name", "ratio"), [("dinh2019", [1.40, 1.70]), ("servo-motor", [3.5, 2.1, 1.9])]
)
def test_width_against_the_exact_hull(name, ratio):
    """Tightness over 300 steps of vertex disturbances: the mean width of each state against
    the exact hull (``exact``, a moving window of 10 samples and the prior, so at least as much
    data as the fixed-time window) stays within the measured ratios (dinh2019 1.34 / 1.62, servo
    motor 3.37 / 2.00 / 1.84), and is never below it."""
    sc = ivobs.scenarios.get(name, horizon=300)
    tr = sc.simulate("vertex", seed=0)
    est = ivobs.make_estimator("fixed-time", sc.system)
    res = est.run(tr.u, tr.y)
    ex = ivobs.make_estimator("exact", sc.system, x0=sc.x0, window=10).run(tr.u, tr.y)
    vf = est.valid_from
    r = res.width[vf:].mean(axis=0) / ex.width[vf:].mean(axis=0)
    assert np.all(r <= ratio) and np.all(r >= 1.0)


# -- fixed-time convergence (Remark 3) -----------------------------------------------------------
CASES = [
    # (seed, nx, ny, invertible, symmetric, feedthrough, s_extra)
    (0, 2, 1, True, True, False, 0),
    (1, 3, 1, True, False, False, 1),
    (2, 3, 2, False, True, False, 0),
    (3, 3, 2, False, False, True, 2),
    (4, 4, 1, False, False, False, 0),
    (5, 4, 2, True, False, True, 1),
]


@pytest.mark.parametrize("case", CASES)
def test_fixed_time_property_without_disturbance(case):
    """Remark 3: with d at the centre of its bounds (δ = 0), x̂_k = x_k for every k >= s."""
    seed, nx, ny, inv, sym, ft, extra = case
    sys = random_system(
        seed, nx=nx, ny=ny, nu=2, invertible=inv, symmetric_bounds=sym, feedthrough=ft
    )
    rng = np.random.default_rng(seed)
    T = 40
    d = np.broadcast_to(sys.d.center, (T, sys.nd))
    tr = ivobs.simulate(sys, rng.normal(size=nx) * 3, rng.normal(size=(T, 2)), d)
    est = ivobs.make_estimator("fixed-time", sys, s=nx - 1 + extra)
    res = est.run(tr.u, tr.y)
    mid = 0.5 * (res.lower + res.upper)
    s = est.s
    np.testing.assert_allclose(mid[s:], tr.x[s:], atol=1e-8 * (1 + np.abs(tr.x).max()))
    # the bounds' radius is exactly |T Md| r (eq. 11), not more
    np.testing.assert_allclose(
        0.5 * res.width[s:],
        np.broadcast_to(
            np.abs(est.design.T @ est.design.Md) @ np.tile(sys.d.radius, s + 1), (T - s, nx)
        ),
        rtol=1e-6,
        atol=1e-8,
    )


def _ltv_system(singular_every=0, asymmetric=True):
    """Observable at every step: C(k) sees x1, A(k) couples x2 into x1."""

    def A(k):
        a = np.array(
            [
                [0.8, 0.5 + 0.3 * np.sin(0.2 * k), 0.0],
                [0.0, 0.9, 0.4 * np.cos(0.1 * k)],
                [0.1, 0.0, 0.7],
            ]
        )
        if singular_every and k % singular_every == 0:
            a[2] = 0.0  # a singular A(k): the step needs the output injection of Remark 1
        return a

    def C(k):
        return np.array([[1.0, 0.1 * np.sin(0.3 * k), 0.0]])

    lo = np.array([-0.5, -1.0]) if asymmetric else -np.ones(2)
    return LinearSystem(
        A,
        np.array([[0.0], [1.0], [0.5]]),
        C,
        D=lambda k: np.array([[0.2 * np.cos(k)]]),
        E=np.array([[0.1, 0.0], [0.0, 0.1], [0.05, 0.0]]),
        F=np.array([[0.0, 0.05]]),
        d=Box(lo, np.ones(2)),
    )


@pytest.mark.parametrize("singular_every", [0, 3])
def test_time_varying_containment_and_per_step_T(singular_every):
    sys = _ltv_system(singular_every)
    tr = adversarial_run(sys, Box(-np.ones(3), np.ones(3)), 120, seed=1)
    est, _res = _check(sys, tr, s=3)
    for k in (3, 17, 40):
        d = est.design_at(k)
        np.testing.assert_allclose(d.T @ d.Mx, np.eye(3), atol=1e-9)
    # the per-step designs differ (Remark 4), the time-invariant shortcut would be wrong
    assert not np.allclose(est.design_at(17).T, est.design_at(40).T)
    # no disturbance: exact from k = s
    d0 = np.broadcast_to(sys.d.center, (60, 2))
    tr0 = ivobs.simulate(sys, np.array([1.0, -2.0, 0.5]), tr.u[:60], d0)
    mid = 0.5 * (est.run(tr0.u, tr0.y).lower + est.run(tr0.u, tr0.y).upper)
    np.testing.assert_allclose(mid[3:], tr0.x[3:], atol=1e-8)


def test_time_varying_and_callable_bounds():
    base = random_system(11, nx=2, ny=1, nu=1, symmetric_bounds=False)
    T = 120
    k = np.arange(T)[:, None]
    lo = base.d.lo - 0.3 * (1 + np.sin(0.1 * k))
    hi = base.d.hi + 0.2 * (1 + np.cos(0.07 * k))
    tv = LinearSystem(base.A, base.B, base.C, E=base.E, F=base.F, d=Box(lo, hi))
    tr = adversarial_run(tv, Box(-np.ones(2), np.ones(2)), T, seed=3)
    _check(tv, tr)
    cb = LinearSystem(
        base.A, base.B, base.C, E=base.E, F=base.F, d=lambda kk, y: Box(lo[int(kk)], hi[int(kk)])
    )
    res = ivobs.make_estimator("fixed-time", cb).run(tr.u, tr.y, vectorize=True)
    assert_contains(res, tr.x)


# -- missing samples ---------------------------------------------------------------------------
def test_missing_samples_random_and_gap():
    sys = random_system(
        3, nx=3, ny=2, nu=1, invertible=False, symmetric_bounds=False, feedthrough=True
    )
    tr = adversarial_run(sys, Box(-np.ones(3), np.ones(3)), 300, seed=1)
    rng = np.random.default_rng(0)
    y = tr.y.copy()
    y[rng.random(y.shape) < 0.1] = np.nan
    y[100:120] = np.nan
    y[:4] = tr.y[:4]
    _est, res = _check(sys, tr, y=y)
    assert res.missing[100:120].all()
    assert np.all(res.width[101:120].max(axis=1) > res.width[99].max())  # predicted through
    assert np.all(res.width[130:140] < 5)  # and back to the fixed-time width after the gap


def test_reduced_stack_keeps_fixed_time_property():
    """One output missing in the window but Mx of the remaining rows has rank nx: the optimal
    T of the reduced stack (cached per pattern) reconstructs x exactly without disturbance."""
    sys = random_system(2, nx=2, ny=2, nu=1)
    rng = np.random.default_rng(2)
    d = np.zeros((30, sys.nd))
    tr = ivobs.simulate(sys, rng.normal(size=2), rng.normal(size=(30, 1)), d)
    y = tr.y.copy()
    y[::2, 0] = np.nan
    est = ivobs.make_estimator("fixed-time", sys, s=2)
    for vec in (False, True):
        res = est.run(tr.u, y, vectorize=vec)
        np.testing.assert_allclose(0.5 * (res.lower + res.upper)[2:], tr.x[2:], atol=1e-9)


def test_missing_first_windows_need_a_prior():
    sys = random_system(4, nx=2, ny=1, nu=1)
    x0 = Box(-np.ones(2), np.ones(2))
    tr = adversarial_run(sys, x0, 50, seed=4)
    y = tr.y.copy()
    y[:3] = np.nan
    est = ivobs.make_estimator("fixed-time", sys)
    with pytest.raises(IvobsError, match="no earlier box.*x0="):
        est.run(tr.u, y)
    with pytest.raises(IvobsError, match="no earlier box"):
        est.run(tr.u, y, vectorize=True)
    _check(sys, tr, y=y, x0=x0)


# -- batches, online use -----------------------------------------------------------------------
def test_batches_match_single_streams():
    sys = random_system(6, nx=3, ny=2, nu=1, symmetric_bounds=False)
    x0 = Box(-np.ones(3), np.ones(3))
    trs = [adversarial_run(sys, x0, 80, seed=s) for s in range(4)]
    u = np.stack([t.u for t in trs])
    y = np.stack([t.y for t in trs])
    y[1, 30:35] = np.nan
    est = ivobs.make_estimator("fixed-time", sys, x0=x0)
    res = est.run(u, y)
    assert res.lower.shape == (4, 80, 3)
    for b in range(4):
        one = est.run(u[b], y[b], vectorize=False)
        np.testing.assert_allclose(res.lower[b], one.lower, rtol=1e-10, atol=1e-12)
        assert_contains(one, trs[b].x)


def test_step_reproduces_run_and_state_restores():
    sys = random_system(8, nx=3, ny=1, nu=1, invertible=False)
    tr = adversarial_run(sys, Box(-np.ones(3), np.ones(3)), 60, seed=8)
    y = tr.y.copy()
    y[20:24] = np.nan
    est = ivobs.make_estimator("fixed-time", sys)
    res = est.run(tr.u, y, vectorize=False)  # the loop: step()'s recursion
    est.reset()
    for k in range(60):
        box = est.step(tr.u[k], None if np.isnan(y[k]).all() else y[k])
        if k < est.valid_from:
            assert box.is_unknown
        else:
            np.testing.assert_array_equal(box.lo, res.lower[k])
        if k == 30:
            saved = json.loads(json.dumps(est.state()))
    other = ivobs.make_estimator("fixed-time", sys)
    other.restore(saved)
    est.restore(saved)
    for k in range(31, 60):
        np.testing.assert_array_equal(other.step(tr.u[k], y[k]).hi, est.step(tr.u[k], y[k]).hi)


def test_advance_returns_a_new_state_and_leaves_the_given_one_unchanged():
    """The online state is a frozen FixedTimeState: a step builds a new window of samples and
    a new box, the given state and its arrays stay as they were (missing samples included)."""
    sys = random_system(8, nx=3, ny=1, nu=1, invertible=False)
    tr = adversarial_run(sys, Box(-np.ones(3), np.ones(3)), 16, seed=8)
    y = tr.y.copy()
    y[9:11] = np.nan
    est = ivobs.make_estimator("fixed-time", sys)
    loop = est.run(tr.u, y, vectorize=False)
    state = est.initial_state()
    assert isinstance(state, FixedTimeState) and not state.has_box
    assert state.z.shape == (est.memory, 2) and (state.ymiss == 1).all()  # no sample yet
    with pytest.raises(dataclasses.FrozenInstanceError):
        state.has_box = True
    names = ("z", "ymiss", "r", "lo", "hi")
    for k in range(16):
        before = {name: getattr(state, name).copy() for name in names}
        new, box = est.advance(state, tr.u[k], y[k])
        for name in names:
            np.testing.assert_array_equal(getattr(state, name), before[name])
        assert state.k == k and new.k == k + 1 and new.has_box == (k >= est.s)
        np.testing.assert_array_equal(new.z[0], np.concatenate([tr.u[k], np.nan_to_num(y[k])]))
        np.testing.assert_array_equal(new.ymiss[0], np.isnan(y[k]))
        if k >= est.s:
            np.testing.assert_allclose(box.lo, loop.lower[k], rtol=1e-14, atol=1e-14)
        state = new


# -- inconsistent data, errors ------------------------------------------------------------------
def test_parity_check_reports_inconsistent_measurements(dinh):
    sc, tr = dinh
    y = tr.y.copy()
    y[30] += 5.0
    est = ivobs.make_estimator("fixed-time", sc.system, s=2)
    with pytest.warns(UserWarning, match=r"inconsistent"):
        res = est.run(tr.u, y, vectorize=True)
    assert res.inconsistent[30] and not res.inconsistent[:30].any()
    assert np.isfinite(res.lower[2:]).all()
    with pytest.raises(InconsistentDataError):
        ivobs.make_estimator("fixed-time", sc.system, s=2, on_inconsistent="raise").run(tr.u, y)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ivobs.make_estimator("fixed-time", sc.system, s=2).run(tr.u, tr.y)  # clean data: quiet
        ivobs.make_estimator(
            "fixed-time", sc.system, s=2, check_consistency=False, strips=False
        ).run(tr.u, y)


def test_errors_name_the_condition(dinh):
    sc, _ = dinh
    sys = sc.system
    unobs = LinearSystem(np.diag([0.5, 0.7]), None, [[1.0, 0.0]])
    with pytest.raises(IvobsError, match="not observable: rank 1 of 2"):
        ivobs.make_estimator("fixed-time", unobs)
    with pytest.raises(IvobsError, match=r"\(s \+ 1\) ny >= nx, i.e. s >= 2 .*got s = 1"):
        ivobs.make_estimator("fixed-time", random_system(0, nx=3), s=1)
    with pytest.raises(IvobsError, match="at most one"):
        ivobs.make_estimator("fixed-time", sys, T=np.zeros((2, 3)), S=np.zeros((2, 3)))
    with pytest.raises(IvobsError, match=r"T: expected shape \(2, 3\)"):
        ivobs.make_estimator("fixed-time", sys, s=2, T=np.zeros((2, 2)))
    with pytest.raises(IvobsError, match="T Mx = I"):
        ivobs.make_estimator("fixed-time", sys, s=2, T=np.ones((2, 3)))
    with pytest.raises(IvobsError, match="time-varying"):
        ivobs.make_estimator("fixed-time", _ltv_system(), s=3, T=np.zeros((3, 4)))
    with pytest.raises(IvobsError, match="criterion"):
        ivobs.make_estimator("fixed-time", sys, criterion="l2")
    with pytest.raises(DesignError, match="not invertible"):
        ivobs.make_estimator("fixed-time", sys, L=np.array([[1.25], [-0.375]]))


def test_explicit_S_and_L(dinh):
    sc, tr = dinh
    d = ivobs.make_estimator("fixed-time", sc.system, s=2).design
    est = ivobs.make_estimator("fixed-time", sc.system, s=2, S=np.zeros((2, 3)))
    np.testing.assert_allclose(est.design.T, d.Mx_pinv)
    assert np.linalg.norm(est.design.T @ d.Md) >= np.linalg.norm(d.T @ d.Md)
    _check(sc.system, tr, s=2, S=np.ones((2, 3)))
    # an output injection on an invertible A is allowed (Remark 1 with a user L)
    est, _ = _check(sc.system, tr, s=2, L=np.array([[0.5], [0.1]]))
    np.testing.assert_allclose(est.design.L, [[0.5], [0.1]])
    assert est.design.My is not None


def test_vectorised_chunks_and_inconsistency_match_the_loop(monkeypatch):
    """Small chunks (so that every boundary is crossed), missing samples, a gap, inconsistent
    spikes, a batch: the whole-record path gives the loop's boxes to rounding, flags
    included."""
    import ivobs.estimators.fixed_time.batch as ft

    monkeypatch.setattr(ft, "_CHUNK", 37)
    sys = random_system(12, nx=3, ny=2, nu=1, symmetric_bounds=False, feedthrough=True)
    x0 = Box(-np.ones(3), np.ones(3))
    trs = [adversarial_run(sys, x0, 200, seed=s) for s in range(3)]
    u = np.stack([t.u for t in trs])
    y = np.stack([t.y for t in trs])
    rng = np.random.default_rng(3)
    y[rng.random(y.shape) < 0.08] = np.nan
    y[1, 60:75] = np.nan
    y[0, 2, 0] += 40.0  # inconsistent at the very first window (predicted from x0)
    y[2, 150, 1] -= 40.0
    est = ivobs.make_estimator("fixed-time", sys, x0=x0, on_inconsistent="ignore")
    vec = est.run(u, y, vectorize=True)
    for b in range(3):
        loop = est.run(u[b], y[b], vectorize=False)
        np.testing.assert_allclose(vec.lower[b], loop.lower, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(vec.upper[b], loop.upper, rtol=1e-10, atol=1e-12)
        np.testing.assert_array_equal(vec.inconsistent[b], loop.inconsistent)
    assert vec.inconsistent[0, 2] and vec.inconsistent[2, 150]
    # away from the faults the truth stays inside
    ok = vec.contains(np.stack([t.x for t in trs]))
    assert ok[1].all() and ok[0, 10:].all() and ok[2, :150].all()
    # time-varying system through the stacked per-step gains, across chunks
    ltv = _ltv_system(singular_every=4)
    tr = adversarial_run(ltv, x0, 100, seed=5)
    _check(ltv, tr, s=2)


def test_scalar_state_with_window_of_one_sample():
    """nx = 1: s = 0, x̂_k = T (y_k - D u_k - F c); a missing y_0 needs x0 (the prior itself)."""
    sys = LinearSystem(
        [[0.5]],
        [[1.0]],
        [[2.0]],
        D=[[0.3]],
        E=[[0.1, 0.0]],
        F=[[0.0, 0.2]],
        d=Box([-1.0, 0.0], [1.0, 1.0]),
    )
    x0 = Box([-3.0], [3.0])
    tr = adversarial_run(sys, x0, 40, seed=0)
    est, res = _check(sys, tr)
    assert est.s == 0 and est.valid_from == 0
    np.testing.assert_allclose(res.width, 0.1, atol=1e-8)  # 2 |T F| r = 2 · 0.5 · 0.2 · 0.5
    y = tr.y.copy()
    y[0] = np.nan
    with pytest.raises(IvobsError, match="no earlier box"):
        est.run(tr.u, y)
    _, res = _check(sys, tr, y=y, x0=x0)
    np.testing.assert_allclose(res.lower[0], x0.lo, atol=1e-9)


def test_weighted_criterion_and_S_for_time_varying_systems():
    sys = random_system(9, nx=3, ny=2, nu=1, nd=4, symmetric_bounds=False)
    tr = adversarial_run(sys, Box(-np.ones(3), np.ones(3)), 80, seed=9)
    est, _ = _check(sys, tr, s=3, weighted=True)
    plain = ivobs.make_estimator("fixed-time", sys, s=3).design
    W = np.tile(sys.d.radius, 4)
    assert est.design.weighted
    assert (
        np.linalg.norm(est.design.T @ est.design.Md * W)
        <= np.linalg.norm(plain.T @ plain.Md * W) + 1e-12
    )
    ltv = _ltv_system()
    S = np.full((3, 4), 0.1)
    est = ivobs.make_estimator("fixed-time", ltv, s=3, S=S)
    d = est.design_at(20)
    np.testing.assert_allclose(d.T, d.Mx_pinv + S @ d.Mx_perp, atol=1e-12)
    _check(ltv, adversarial_run(ltv, Box(-np.ones(3), np.ones(3)), 60, seed=2), s=3, S=S)
    with pytest.raises(IvobsError, match="weighted: needs constant bounds"):
        ivobs.make_estimator(
            "fixed-time",
            LinearSystem(sys.A, sys.B, sys.C, E=sys.E, F=sys.F, d=lambda k, y: sys.d),
            weighted=True,
        )


def test_reduced_windows_are_intersected_with_the_prediction():
    """Servo motor, speed sensor out for 20 steps: the position-only windows (rank 3, but they
    differentiate θ twice) are intersected with the model prediction from the previous box, so
    each box lies inside that prediction, and the gap is narrower than with both sensors out."""
    sc = ivobs.scenarios.get("servo-motor", horizon=80)
    sys = sc.system
    tr = adversarial_run(sys, sc.x0, 80, seed=1)
    est = ivobs.make_estimator("fixed-time", sys, strips=False)  # the recursion's own boxes
    both, part = tr.y.copy(), tr.y.copy()
    both[30:50] = np.nan
    part[30:50, 1] = np.nan
    rb, rp = est.run(tr.u, both), est.run(tr.u, part)
    rv = est.run(tr.u, part, vectorize=True)
    for r in (rb, rp, rv):
        assert_contains(r, tr.x)
    np.testing.assert_allclose(rv.lower, rp.lower, rtol=1e-10)
    for k in range(30, 52):
        p_lo, p_hi = ivobs.image_bounds(sys.A, rp.lower[k - 1], rp.upper[k - 1])
        e_lo, e_hi = ivobs.image_bounds(sys.E, sys.d.lo, sys.d.hi)
        bu = sys.B @ tr.u[k - 1]
        assert np.all(rp.lower[k] >= p_lo + bu + e_lo - 1e-8)
        assert np.all(rp.upper[k] <= p_hi + bu + e_hi + 1e-8)
    assert rp.width[32:50].mean() < rb.width[32:50].mean()


# -- a window of one sample, nearly singular and singular A -----------------------------------
def test_s0_predicts_a_missing_sample_with_the_previous_input():
    """nx = 1 (s = 0) keeps one sample per window; the prediction through a missing sample
    needs u[k-1] and the bounds of d[k-1], which a single ring slot had already overwritten
    with those of step k. Inputs alternating ±5 make the difference obvious."""
    sys = LinearSystem([[0.9]], [[1.0]], [[1.0]], E=[[0.2]], F=[[0.0]], d=Box([0.1], [0.5]))
    T = 30
    u = 5.0 * (-1.0) ** np.arange(T)[:, None]
    tr = adversarial_run(sys, Box([-1.0], [1.0]), T, seed=3)
    tr = ivobs.simulate(sys, tr.x[0], u, tr.d)
    y = tr.y.copy()
    y[[4, 11, 12, 13, 20]] = np.nan
    est = ivobs.make_estimator("fixed-time", sys)
    assert est.s == 0
    for vec in (False, True):
        res = est.run(tr.u, y, vectorize=vec)
        assert_contains(res, tr.x)
        # predicted: width 0.9 w[k-1] + 0.2 (0.5 - 0.1), the boxes with y are points (F = 0)
        np.testing.assert_allclose(
            res.width[[4, 11, 12, 13, 20], 0], [0.08, 0.08, 0.152, 0.2168, 0.08], atol=1e-8
        )
    est.reset()
    for k in range(T):
        box = est.step(tr.u[k], y[k])
        assert box.lo[0] <= tr.x[k, 0] <= box.hi[0]
    # the vectorised path and the loop agree through the gaps
    loop, vec = est.run(tr.u, y, vectorize=False), est.run(tr.u, y, vectorize=True)
    np.testing.assert_allclose(loop.lower, vec.lower, rtol=1e-10, atol=1e-12)


def _near_singular(seed, eig, nx=3, ny=1, nd=2):
    """A system whose A has one eigenvalue ``eig`` (tiny): rcond(A) ~ eig."""
    rng = np.random.default_rng(seed)
    V = rng.normal(size=(nx, nx))
    lam = rng.uniform(-0.95, 0.95, nx)
    lam[0] = eig
    A = V @ np.diag(lam) @ np.linalg.inv(V)
    r = rng.uniform(0.2, 1.0, nd)
    return LinearSystem(
        A,
        rng.normal(size=(nx, 1)),
        rng.normal(size=(ny, nx)),
        E=rng.normal(size=(nx, nd)),
        F=0.1 * rng.normal(size=(ny, nd)),
        d=Box(-r, r),
    )


def _max_excess(res, x):
    v = res.valid_from
    return float(np.max(np.maximum(res.lower - x, x - res.upper)[..., v:, :]))


def _nearly_singular_system():
    A = np.array(
        [
            [0.12609559714027987, 0.32010332880987175, -1.0651677453570858],
            [-0.05129062982893862, -0.1007573188128995, -0.7896390780376499],
            [-0.10299442591650111, -0.25134455581851856, 0.4499763881251059],
        ]
    )  # eigenvalues 1e-7, 0.83, -0.35
    C = np.array([[-0.4939342302351804, -0.3677137240199963, -1.8067903895865323]])
    E = np.array(
        [
            [0.5037622402465411, -0.06728726351786307],
            [0.40118322914862325, 0.12523967814215592],
            [0.5831888323874747, 0.46113299283844916],
        ]
    )
    F = np.array([[0.0318298439352904, 0.1480763419858435]])
    r = np.array([0.970565750012428, 0.20560291645898518])
    return LinearSystem(A, None, C, E=E, F=F, d=Box(-r, r)), r


def test_nearly_singular_A_is_sound_and_not_wider_than_an_injection():
    """rcond(A) ~ 1e-7 passes the invertibility test (1e-8), and the inverses of eq. (4)
    make Mx = [C; C A⁻¹; C A⁻²] (cond 1e14) inaccurate: the computed T misses T Mx = I by
    ~1e-2 and the boxes missed the state (3 of these 40 runs, by up to 0.035). Now the window
    gain is certified on the forward form (and refined), and an output injection replaces A
    when that is more accurate."""
    sys, r = _nearly_singular_system()
    est = ivobs.make_estimator("fixed-time", sys)
    x0 = np.stack([np.random.default_rng(seed).uniform(-10, 10, 3) for seed in range(40)])
    d = np.stack(
        [np.where(np.random.default_rng(seed).random((25, 2)) < 0.5, -r, r) for seed in range(40)]
    )
    x = np.stack([ivobs.simulate(sys, x0[b], None, d[b]).x for b in range(40)])
    y = np.stack([ivobs.simulate(sys, x0[b], None, d[b]).y for b in range(40)])
    res = est.run(None, y)
    assert _max_excess(res, x) <= 0.0 and not res.inconsistent.any()
    for b in (16, 19, 35):
        assert _max_excess(est.run(None, y[b], vectorize=False), x[b]) <= 0.0
    # the same widths as with a well-conditioned output injection (Remark 1), to 1e-9
    inj = ivobs.make_estimator(
        "fixed-time", sys, L=ivobs.design.injection.invertible_injection(sys.A, sys.C)
    )
    np.testing.assert_allclose(res.width[:, 2:], inj.run(None, y).width[:, 2:], rtol=1e-9)


def test_output_injection_rounding_is_covered():
    """Singular A; the gain placing the poles at 0.5 ... 0.9 had |L| = 156, and the
    rounding of the stacked matrices of A - LC (not in the margin) put the state outside by
    4e-6 at |x| = 200. Now |L| < 1, and any rounding of the window gain is certified."""
    base = random_system(44, nx=3, ny=1, nu=1, invertible=False, rho=0.99)
    sys = LinearSystem(
        base.A, base.B, base.C, E=base.E, F=base.F, d=Box.symmetric(np.full(base.nd, 1e-6))
    )
    est = ivobs.make_estimator("fixed-time", sys)
    assert est.design.L is not None and np.abs(est.design.L).max() < 1.0
    rng = np.random.default_rng(7)
    x0 = rng.uniform(-500, 500, size=(6, 3))
    d = np.where(rng.random((6, 200, sys.nd)) < 0.5, -1e-6, 1e-6)
    u = rng.normal(size=(6, 200, 1)) * 10
    trs = [ivobs.simulate(sys, x0[b], u[b], d[b]) for b in range(6)]
    x = np.stack([t.x for t in trs])
    y = np.stack([t.y for t in trs])
    assert np.abs(x).max() > 200
    assert _max_excess(est.run(u, y), x) <= 0.0
    for b in range(2):
        assert _max_excess(est.run(u[b], y[b], vectorize=False), x[b]) <= 0.0
    # the explicit large gain of the old design: sound too (its rounding is certified)
    big = ivobs.design.injection.injection_candidates(sys.A, sys.C)[-1]
    assert np.abs(big).max() > 100
    res = ivobs.make_estimator("fixed-time", sys, L=big).run(u, y)
    assert _max_excess(res, x) <= 0.0


@pytest.mark.parametrize("seed", range(12))
def test_property_near_singular_and_singular_A(seed):
    """Random systems (nx = 1 ... 4: s = 0 too, one sample per window) whose A has an eigenvalue
    10^-3 ... 10^-13 or exactly 0 (one output or two, s = nx - 1 or larger), vertex
    disturbances, initial states up to ±100: every box of the loop and of the vectorised path
    contains the state, also with 10 % missing samples, and no admissible sample is reported
    inconsistent."""
    rng = np.random.default_rng(100 + seed)
    nx, ny = int(rng.integers(1, 5)), int(rng.integers(1, 3))
    eig = 0.0 if seed % 4 == 0 else 10.0 ** -rng.uniform(3, 13)
    sys = _near_singular(seed, eig, nx=nx, ny=ny)
    try:
        est = ivobs.make_estimator("fixed-time", sys, s=nx - 1 + seed % 2)
    except IvobsError:  # a random draw not observable over the window
        return
    x0 = Box(-100 * np.ones(nx), 100 * np.ones(nx))
    tr = adversarial_run(sys, x0, 60, seed=seed)
    tr = ivobs.simulate(sys, rng.uniform(-100, 100, nx), tr.u, tr.d)  # not a vertex of x0
    y = tr.y.copy()
    y[rng.random(y.shape) < 0.1] = np.nan
    y[: est.s + 1] = tr.y[: est.s + 1]
    for yy in (tr.y, y):
        loop = est.run(tr.u, yy, vectorize=False)
        vec = est.run(tr.u, yy, vectorize=True)
        assert _max_excess(loop, tr.x) <= 0.0
        assert _max_excess(vec, tr.x) <= 0.0
        assert np.isfinite(loop.lower[est.s :]).all()
        assert not loop.inconsistent.any() and not vec.inconsistent.any()


def test_time_varying_with_nearly_singular_steps():
    """Remark 4 with A(k) nearly singular (rcond ~ 1e-7, no injection) at every third step:
    the per-step window gains are certified too."""
    base = _ltv_system()

    def A(k):
        a = base.A_at(k).copy()
        if k % 3 == 0:
            a[2] = 1e-7 * a[2] + a[1] * 0.5  # rows 1 and 2 nearly dependent
        return a

    sys = LinearSystem(
        A,
        base.matrices_at(0)[1],
        base.C_at,
        D=lambda k: base.matrices_at(k)[3],
        E=base.matrices_at(0)[4],
        F=base.matrices_at(0)[5],
        d=base.d,
    )
    assert np.linalg.cond(sys.A_at(3)) > 1e6
    tr = adversarial_run(sys, Box(-20 * np.ones(3), 20 * np.ones(3)), 60, seed=4)
    _check(sys, tr, s=3)


# -- [Wang2020, Remark 1]: a singular A through the output injection ----------------------------
def _remark1_system(noise):
    """A = [[0, 1], [0, 0.5]] (singular), C = [1, 0]: x_k lies in the range of A, so y_k alone
    gives x_k; the injected window (A - LC invertible) shows it through its parity relation."""
    A, C = np.array([[0.0, 1.0], [0.0, 0.5]]), np.array([[1.0, 0.0]])
    if not noise:
        return LinearSystem(A, None, C)
    return LinearSystem(
        A, None, C, E=0.01 * np.eye(2), F=[[0.0, 0.02]], d=Box.symmetric([1.0, 1.0])
    )


@pytest.mark.parametrize("with_x0", [False, True])
def test_remark1_singular_A_is_exact_after_s_steps_without_noise(with_x0):
    """The default s = nx - 1 = 1: from k = s on the box is the state itself (fixed time,
    Remark 3), with or without a prior (before: 'too many missing samples' without x0, and with
    x0 the open-loop prediction of x0, width 10 / 2^k)."""
    sys = _remark1_system(noise=False)
    x0 = Box([-5.0, -5.0], [5.0, 5.0]) if with_x0 else None
    est = ivobs.make_estimator("fixed-time", sys, x0=x0)
    assert est.s == 1 and est.design.L is not None
    assert abs(np.linalg.det(sys.A - est.design.L @ sys.C)) > 0.1  # A - LC invertible
    tr = ivobs.simulate(sys, [3.0, -2.0], T=12)
    for vectorize in (False, True):
        res = est.run(None, tr.y, vectorize=vectorize)
        assert_contains(res, tr.x)
        # exact up to the rounding margins of the bounds (ROUNDING and the certified gain)
        assert np.max(res.width[1:]) < 1e-8
        assert np.all(res.width[1:] <= 1e-9 * (1.0 + np.abs(tr.x[1:])))
    est.reset()
    for k in range(4):
        box = est.step(None, tr.y[k])
        if k >= 1:
            np.testing.assert_allclose(box.lo, tr.x[k], atol=1e-9)
            np.testing.assert_allclose(box.hi, tr.x[k], atol=1e-9)


def test_remark1_singular_A_with_noise_constant_widths_and_containment():
    """With bounded noise: every box of k >= s has the width of eq. (11) for the injected
    window: x1_k = y_k - 0.02 d2_k and x2_k = 0.5 y_k - 0.01 d2_k - 0.005 d1_(k-1) + 0.01 d2_(k-1)
    (0.04 and 0.05 wide),
    whatever the state (no open-loop growth), and contains the truth under vertex disturbances
    (loop and vectorised paths, with and without a prior)."""
    sys = _remark1_system(noise=True)
    for x0 in (None, Box([-50.0, -50.0], [50.0, 50.0])):
        est = ivobs.make_estimator("fixed-time", sys, x0=x0)
        assert est.s == 1 and est.design.L is not None
        for seed in range(4):
            tr = adversarial_run(sys, Box([-50.0, -50.0], [50.0, 50.0]), 300, seed=seed)
            _, loop = _check(sys, tr, x0=x0)
            w = loop.width[1:]
            # up to the rounding margins (relative to the data, ~1e-8 here)
            np.testing.assert_allclose(w, np.broadcast_to([0.04, 0.05], w.shape), atol=1e-6)
