"""Adversarial tests of soundness and of the error-handling promises
(docs/dev/soundness-review.md).

Part 1 pins the review's findings as regression tests, one or more per finding. Part 2 is a
compact adversarial containment test over every registered method (worst-case disturbances built
from the model, vertex priors, missing samples, batches, ``step()`` with ``state()``/``restore()``,
and the orderings ``exact ⊆ every method`` and ``intersect ⊆ every member``).
"""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem
from ivobs.testing import adversarial_run, random_system


def _excess(res: ivobs.Estimate, x: np.ndarray) -> float:
    """Largest distance by which the true state leaves the box (<= 0: contained)."""
    vf = res.valid_from
    ex = np.maximum(res.lower - x, x - res.upper)[..., vf:, :]
    return float(np.max(ex)) if ex.size else -np.inf


def _quiet_run(est, u, y, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return est.run(u, y, **kw)


# =============================================================================================
# Part 1: the soundness review's findings
# =============================================================================================


def test_fixed_time_vectorised_run_without_inputs():
    """nu = 0: every batch, and every single record of >= 2000 steps, takes the vectorised
    path, which crashes with a raw NumPy ValueError."""
    sys = LinearSystem(
        [[0.5, 1.0], [0.0, 0.4]],
        C=[[1.0, 0.0]],
        E=0.1 * np.eye(2),
        F=[[0.0, 0.0]],
        d=Box.symmetric([1.0, 1.0]),
    )
    est = ivobs.make_estimator("fixed-time", sys)
    res = est.run(None, np.zeros((2000, 1)))  # long record: vectorised by default
    assert np.isfinite(res.lower[1:]).all()


def test_fixed_time_s0_predicts_a_missing_sample_with_the_previous_input():
    sys = LinearSystem([[-0.999]], [[1.0]], [[-2.0]], E=[[0.5]], F=[[0.0]], d=Box([0.6], [0.6]))
    T = 8
    u = np.linspace(-1.0, 1.0, T)[:, None]
    tr = ivobs.simulate(sys, [0.3], u=u, d=np.full((T, 1), 0.6))
    y = tr.y.copy()
    y[3] = np.nan
    est = ivobs.make_estimator("fixed-time", sys)  # nx = 1: s = 0
    assert est.run(tr.u, y, vectorize=True).contains(tr.x).all()  # the vectorised path is right
    res = est.run(tr.u, y)  # the loop (and step()) is not: x[3] = -0.712, box [-0.427, -0.427]
    assert res.contains(tr.x).all()


def test_fixed_time_nearly_singular_A():
    A = np.array(
        [
            [0.12609559714027987, 0.32010332880987175, -1.0651677453570858],
            [-0.05129062982893862, -0.1007573188128995, -0.7896390780376499],
            [-0.10299442591650111, -0.25134455581851856, 0.4499763881251059],
        ]
    )
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
    sys = LinearSystem(A, None, C, E=E, F=F, d=Box(-r, r))  # eigenvalues 1e-7, 0.83, -0.35
    est = ivobs.make_estimator("fixed-time", sys)
    rng = np.random.default_rng(16)
    x0 = rng.uniform(-10, 10, 3)
    d = np.where(rng.random((25, 2)) < 0.5, -r, r)
    tr = ivobs.simulate(sys, x0, None, d)
    res = est.run(None, tr.y)
    assert res.contains(tr.x)[res.valid_from :].all()  # x[7] leaves the box by 2.9


def test_fixed_time_output_injection_rounding():
    base = random_system(44, nx=3, ny=1, nu=1, invertible=False, rho=0.99)
    A, B, C, _, E, F = base.matrices_at(0)
    sys = LinearSystem(A, B, C, E=E, F=F, d=Box.symmetric(np.full(E.shape[1], 1e-6)))
    est = ivobs.make_estimator("fixed-time", sys)
    assert est.design.L is not None
    rng = np.random.default_rng(44)
    rng.choice([2, 3])
    d = np.where(rng.random((200, E.shape[1])) < 0.5, -1e-6, 1e-6)
    x0 = rng.uniform(-5, 5, 3)
    tr = ivobs.simulate(sys, x0, rng.normal(size=(200, 1)), d)
    res = est.run(tr.u, tr.y)
    assert res.contains(tr.x)[res.valid_from :].all()


def test_exact_safe_bound_rounding_compounds():
    sys = LinearSystem(
        [[1.02]],
        C=[[-2.0]],
        E=[[0.5654947821624227, -0.4344598025301682]],
        F=[[-0.02959681857860406, -0.06036165972136037]],
        d=Box.symmetric([329.84765770643713, 672.0568907545257]),
    )
    x0 = Box([-388149.2789262264], [-388149.2789262264])
    r = np.array([329.84765770643713, 672.0568907545257])
    signs = np.array([[1, -1]] * 8 + [[-1, 1], [1, -1], [-1, -1], [1, 1]])
    tr = ivobs.simulate(sys, x0.lo, None, signs * r)  # worst case for max x[8] (open loop)
    res = _quiet_run(ivobs.make_estimator("exact", sys, x0=x0), None, tr.y)
    assert _excess(res, tr.x) <= 0.0
    # every other method contains this trajectory
    for m in ("reachability", "interval-split", "kkl", "fixed-time"):
        other = _quiet_run(ivobs.make_estimator(m, sys, x0=x0), None, tr.y)
        assert other.contains(tr.x)[other.valid_from :].all()


def test_exact_does_not_flag_valid_data_as_inconsistent():
    c = 0.528973903776374
    x0 = Box([8214304519.280842], [8214304526.113711])
    sys = LinearSystem([[0.5]], C=[[c]], E=[[1.0]], F=[[0.0]], d=Box(-1.0, 1.0))
    y = np.array([[c * x0.lo[0]]])  # the true x[0] = x0.lo, measured without noise
    res = ivobs.make_estimator("exact", sys, x0=x0, on_inconsistent="raise").run(None, y)
    assert not res.inconsistent.any()


def test_intersect_margin_covers_each_members_rounding():
    lo1, hi1 = -199999999.80468366, 0.7128333002200049
    sys = LinearSystem(
        [[0.5, 0.2], [0.0, 0.6]],
        C=np.eye(2),
        E=0.1 * np.eye(2),
        F=0.01 * np.eye(2),
        d=Box.symmetric([1.0, 1.0]),
    )
    x0 = Box([lo1, -1.0], [hi1, 1.0])
    d = np.zeros((5, 2))
    d[0] = [-1.0, 0.0]
    tr = ivobs.simulate(sys, [hi1, 0.0], None, d)
    reach = ivobs.make_estimator("reachability", sys, x0=x0).run(None, tr.y)
    assert reach.contains(tr.x).all()  # the member alone is fine (its own margin is 0.02)
    est = ivobs.make_estimator("intersect", sys, x0=x0, methods=["reachability"])
    assert est.run(None, tr.y).contains(tr.x).all()


_FEEDTHROUGH_FAILS = [
    "reachability",
    "zonotope",
    "interval",
    "interval-split",
    "interval-transformed",
    "kkl",
    "exact",
    "strip",
    "constrained-zonotope",
    "intersect",
]


@pytest.mark.parametrize("method", _FEEDTHROUGH_FAILS)
def test_large_feedthrough_rounding(method):
    sys = LinearSystem(
        [[0.5]], [[0.0]], [[1.0]], D=[[1e8]], E=[[1e-3]], F=[[0.0]], d=Box(-1.0, 1.0)
    )
    T = 20
    tr = ivobs.simulate(sys, [1.0], u=np.ones((T, 1)), d=np.ones((T, 1)))
    res = _quiet_run(ivobs.make_estimator(method, sys, x0=Box(-1.0, 1.0)), tr.u, tr.y)
    assert res.contains(tr.x)[res.valid_from :].all()


def test_large_feedthrough_fixed_time_is_sound():
    """The control case of the large feedthrough: fixed-time's rounding term covers the large data
    terms."""
    sys = LinearSystem(
        [[0.5]], [[0.0]], [[1.0]], D=[[1e8]], E=[[1e-3]], F=[[0.0]], d=Box(-1.0, 1.0)
    )
    tr = ivobs.simulate(sys, [1.0], u=np.ones((20, 1)), d=np.ones((20, 1)))
    assert ivobs.make_estimator("fixed-time", sys).run(tr.u, tr.y).contains(tr.x).all()


def test_interval_split_degenerate_width_gain_with_missing_component():
    sys = LinearSystem(
        [[0.9]], [[1.0]], [[1.0], [1.0]], E=[[0.1]], F=[[0.2], [-0.1]], d=Box([0.5], [0.5])
    )
    T = 10
    tr = ivobs.simulate(sys, [0.7], u=np.sin(np.arange(T))[:, None], d=np.full((T, 1), 0.5))
    y = tr.y.copy()
    y[2:5, 1] = np.nan
    est = ivobs.make_estimator("interval-split", sys, x0=Box([-1.0], [1.0]))
    assert np.abs(est.design.L).max() < 1e3  # a sane gain (interval finds L = [0.45, 0.45])
    res = _quiet_run(est, tr.u, y)
    assert res.contains(tr.x).all() and not res.inconsistent.any()


@pytest.mark.parametrize("method", ["interval", "interval-split"])
def test_interval_gain_with_redundant_noise_free_sensors(method):
    sys = LinearSystem(
        [[0.9]], [[1.0]], [[1.0], [1.0]], E=[[0.1]], F=[[0.0], [0.0]], d=Box([-1.0], [1.0])
    )
    T = 12
    d = np.where(np.random.default_rng(0).random((T, 1)) < 0.5, -1.0, 1.0)
    tr = ivobs.simulate(sys, [0.7], np.sin(np.arange(T))[:, None], d)
    y = tr.y.copy()
    y[2:5, 1] = np.nan
    res = ivobs.make_estimator(method, sys, x0=Box([-1.0], [1.0])).run(tr.u, y)
    assert res.contains(tr.x).all()
    assert np.max(res.width) < 10.0


def test_kkl_continuous_time_long_record():
    sys = LinearSystem(
        [[-1.92, 1.36], [1.22, -2.46]],
        None,
        [[-0.53, 0.57]],
        E=0.1 * np.eye(2),
        F=np.zeros((1, 2)),
        d=Box.symmetric([1.0, 1.0]),
        dt=0,
    )
    est = ivobs.make_estimator("kkl", sys, x0=Box(-np.ones(2), np.ones(2)))
    t = np.arange(200) * 1.0
    tr = ivobs.simulate(sys, [0.3, -0.2], d=np.zeros((200, 2)), t=t)
    assert est.run(None, tr.y, t=t).contains(tr.x).all()


@pytest.mark.parametrize("method", ["interval", "interval-split", "interval-transformed", "kkl"])
def test_batch_with_time_varying_bounds(method):
    T = 30
    r = np.linspace(0.5, 1.0, T)[:, None]
    sys = LinearSystem(
        [[0.5, 0.2], [-0.1, 0.6]],
        [[1.0], [0.0]],
        [[1.0, 0.0]],
        E=[[0.3], [0.1]],
        F=[[0.1]],
        d=Box(-r, r),
    )
    x0 = Box([-1.0, -1.0], [1.0, 1.0])
    trs = [
        ivobs.simulate(
            sys,
            [0.5, -0.5],
            np.sin(np.arange(T) + b)[:, None],
            np.where(np.arange(T)[:, None] % (b + 2) == 0, r, -r),
        )
        for b in range(3)
    ]
    u = np.array([tr.u for tr in trs])
    y = np.array([tr.y for tr in trs])
    res = ivobs.make_estimator(method, sys, x0=x0).run(u, y)
    assert res.contains(np.array([tr.x for tr in trs])).all()


def _pinned_far_from_the_origin() -> tuple[LinearSystem, Box, ivobs.Trajectory]:
    """Two outputs that pin a 2-state unstable plant at |x| ~ 1e5, bang-bang disturbance."""
    sys = LinearSystem(
        [[1.57, 1.41], [-0.59, -0.34]],
        None,
        [[-0.53, 0.57], [-0.06, 0.75]],
        E=[[-0.92], [0.78]],
        F=[[-0.02], [0.14]],
        d=Box([-1.0], [1.0]),
    )
    x0 = Box(np.full(2, 1e5 - 1.0), np.full(2, 1e5 + 1.0))
    signs = "--++++++-+--+-++----+--+-+----"
    d = np.array([[1.0 if c == "+" else -1.0] for c in signs])
    return sys, x0, ivobs.simulate(sys, x0.hi, None, d)


def test_strip_rounding_when_the_measurements_pin_the_state():
    sys, x0, tr = _pinned_far_from_the_origin()
    res = _quiet_run(ivobs.make_estimator("strip", sys, x0=x0), None, tr.y)
    assert res.contains(tr.x).all()


def test_constrained_zonotope_does_not_flag_valid_data():
    sys, x0, tr = _pinned_far_from_the_origin()
    res = _quiet_run(ivobs.make_estimator("constrained-zonotope", sys, x0=x0), None, tr.y)
    assert res.contains(tr.x).all()
    assert not res.inconsistent.any()


# -- error handling ---------------------------------------------------------------------------


def _small():
    sys = random_system(3, nx=2, ny=1, nu=1)
    x0 = Box([-1.0, -1.0], [1.0, 1.0])
    return sys, x0, adversarial_run(sys, x0, 20, seed=0)


@pytest.mark.parametrize("method", ["fixed-time", "interval-transformed", "kkl", "intersect"])
def test_empty_record_vectorised(method):
    sys, x0, tr = _small()
    est = ivobs.make_estimator(method, sys, x0=x0)
    try:
        res = est.run(tr.u[:0], tr.y[:0], vectorize=True)
    except IvobsError:
        return
    assert res.lower.shape == (0, 2)


def test_complex_measurements_are_rejected():
    sys, x0, tr = _small()
    est = ivobs.make_estimator("reachability", sys, x0=x0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(IvobsError, match="y"):
            est.run(tr.u, tr.y + 1j)


def test_step_bad_time_is_an_ivobs_error():
    sys, x0, tr = _small()
    est = ivobs.make_estimator("reachability", sys, x0=x0)
    with pytest.raises(IvobsError, match="t"):
        est.step(tr.u[0], tr.y[0], t="a")


def test_restore_of_a_tampered_state_is_an_ivobs_error():
    sys, x0, _tr = _small()
    est = ivobs.make_estimator("reachability", sys, x0=x0)
    st = json.loads(json.dumps(est.state()))
    st["state"]["xh"]["shape"] = [3]  # 2 values, claimed shape (3,)
    with pytest.raises(IvobsError, match="state"):
        est.restore(st)


def test_intersect_restore_missing_entry_is_an_ivobs_error():
    sys, x0, _tr = _small()
    est = ivobs.make_estimator("intersect", sys, x0=x0)
    st = json.loads(json.dumps(est.state()))
    del st["state"]["k"]
    with pytest.raises(IvobsError, match="state"):
        est.restore(st)


def test_kkl_non_numeric_option_is_an_ivobs_error():
    sys, x0, _ = _small()
    with pytest.raises(IvobsError, match="max_cond"):
        ivobs.make_estimator("kkl", sys, x0=x0, max_cond="x")


# =============================================================================================
# Part 2: compact adversarial containment
# =============================================================================================


def _open_loop_extremes(sys, x0, u, targets, rng):
    """For each ``(k, i, sense)``: the vertex prior and vertex disturbances that maximise
    ``sense * x[k][i]`` over *all* admissible trajectories (the sign pattern of the rows of
    ``A^(k-1-j) E`` and ``A^k``). Exact hull edges: any sound box must reach that far."""
    A, _B, _C, _D, E, _F = sys.matrices_at(0)
    T = u.shape[0]
    box = sys.d
    out_x0, out_d = [], []
    for k, i, sense in targets:
        d = np.where(rng.random((T, sys.nd)) < 0.5, box.lo, box.hi)
        w = np.zeros(sys.nx)
        w[i] = sense
        for j in range(k - 1, -1, -1):
            g = w @ E
            d[j] = np.where(g > 0, box.hi, np.where(g < 0, box.lo, d[j]))
            w = w @ A
        out_x0.append(np.where(w > 0, x0.hi, x0.lo))
        out_d.append(d)
    return out_x0, out_d


def _records(sys, x0, T, seed, n_random=3, n_extreme=3):
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(T, sys.nu))
    xs, ys = [], []
    for j in range(n_random):
        tr = adversarial_run(sys, x0, T, seed=seed * 100 + j)
        tr = ivobs.simulate(sys, tr.x[0], u, tr.d)
        xs.append(tr.x)
        ys.append(tr.y)
    targets = [
        (int(rng.integers(1, T)), int(rng.integers(sys.nx)), float(rng.choice([-1, 1])))
        for _ in range(n_extreme)
    ]
    for x0v, d in zip(*_open_loop_extremes(sys, x0, u, targets, rng)):
        tr = ivobs.simulate(sys, x0v, u, d)
        xs.append(tr.x)
        ys.append(tr.y)
    U = np.broadcast_to(u, (len(xs), T, sys.nu))
    return U, np.array(xs), np.array(ys)


_FAST = [
    "fixed-time",
    "reachability",
    "zonotope",
    "interval",
    "interval-transformed",
    "interval-split",
    "kkl",
    "strip",
    "intersect",
]
_CASES = [  # (seed, nx, ny, options of random_system)
    (0, 2, 1, {}),
    (1, 3, 2, {"symmetric_bounds": False}),
    (2, 3, 1, {"invertible": False}),
    (3, 2, 2, {"feedthrough": True, "symmetric_bounds": False}),
    (4, 3, 3, {"rho": 1.0}),
]


@pytest.mark.parametrize("seed, nx, ny, opts", _CASES)
def test_adversarial_containment_all_methods(seed, nx, ny, opts):
    """Worst-case (open-loop extreme) and random vertex trajectories from vertex priors, with and
    without missing samples, loop and vectorised batch paths; plus the orderings
    exact ⊆ every method and intersect ⊆ each member, on the same data."""
    sys = random_system(seed, nx=nx, ny=ny, nu=1, **opts)
    rng = np.random.default_rng(seed)
    x0 = Box(rng.uniform(-2, -0.5, nx), rng.uniform(0.5, 2, nx))
    T = 25
    U, X, Y = _records(sys, x0, T, seed)
    Ym = Y.copy()
    Ym[rng.random(Y.shape) < 0.1] = np.nan
    Ym[:, 10:16] = np.nan  # a gap
    ex = ivobs.make_estimator("exact", sys, x0=x0)
    exact = [_quiet_run(ex, U[b], Yb, vectorize=False) for b, Yb in ((0, Y[0]), (3, Y[3]))]
    for res, b in zip(exact, (0, 3)):
        assert _excess(res, X[b]) <= 0.0, "exact"
    checked = 0
    for m in _FAST:
        try:
            est = ivobs.make_estimator(m, sys, x0=x0)
        except ivobs.DesignError:
            continue
        for Yin in (Y, Ym):
            for vec in (False, True):
                res = _quiet_run(est, U, Yin, vectorize=vec)
                assert _excess(res, X) <= 0.0, (m, vec)
                assert np.isfinite(res.lower[:, res.valid_from :]).all(), m
        full = _quiet_run(est, U, Y, vectorize=False)
        for res, b in zip(exact, (0, 3)):  # exact is the tightest box from the same data
            vf = full.valid_from
            tol = 1e-7 * (1.0 + np.abs(res.upper[vf:]) + np.abs(res.lower[vf:]))
            assert np.all(full.lower[b, vf:] <= res.lower[vf:] + tol), m
            assert np.all(full.upper[b, vf:] >= res.upper[vf:] - tol), m
        if m == "intersect":
            for member in est.members:
                mres = _quiet_run(member, U, Y, vectorize=False)
                vf = mres.valid_from
                assert np.all(full.lower[:, vf:] >= mres.lower[:, vf:] - 1e-12)
                assert np.all(full.upper[:, vf:] <= mres.upper[:, vf:] + 1e-12)
        checked += 1
    assert checked >= 5


@pytest.mark.parametrize(
    "method",
    [
        "fixed-time",
        "reachability",
        "zonotope",
        "interval-split",
        "kkl",
        "strip",
        "constrained-zonotope",
        "exact",
        "intersect",
    ],
)
def test_step_with_state_restore_matches_run_under_missing_samples(method):
    """Online use through a JSON state round trip, missing samples, and a worst-case record."""
    sys = random_system(7, nx=2, ny=2, nu=1, symmetric_bounds=False)
    x0 = Box([-1.0, -1.5], [1.5, 1.0])
    T = 16
    U, X, Y = _records(sys, x0, T, 7, n_random=0, n_extreme=1)
    y = Y[0].copy()
    y[3] = np.nan
    y[8:11, 1] = np.nan
    est = ivobs.make_estimator(method, sys, x0=x0)
    ref = _quiet_run(est, U[0], y, vectorize=False)
    assert _excess(ref, X[0]) <= 0.0
    est.reset()
    lo, hi = [], []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for k in range(T):
            if k == 6:
                saved = json.loads(json.dumps(est.state()))
                est = ivobs.make_estimator(method, sys, x0=x0)
                est.restore(saved)
            box = est.step(U[0, k], y[k])
            lo.append(box.lo)
            hi.append(box.hi)
    # exact: the restored LP is solved from a cold start and can end on another optimal basis
    # of a degenerate program; two safe bounds then differ by up to the dual feasibility
    # tolerance (1e-10) times the sum of the variables' widths (about 50 here): 5e-9
    tol = 1e-8 if method == "exact" else 1e-9
    np.testing.assert_allclose(np.array(lo), ref.lower, rtol=1e-9, atol=tol)
    np.testing.assert_allclose(np.array(hi), ref.upper, rtol=1e-9, atol=tol)


def test_time_varying_and_measurement_dependent_bounds():
    """Time-varying matrices (stacked) and bounds computed from y, vertex disturbances."""
    rng = np.random.default_rng(11)
    T = 20
    A0 = np.array([[0.6, 0.3], [-0.2, 0.5]])
    A = np.stack([A0 * (1 + 0.2 * np.sin(0.4 * k)) for k in range(T + 1)])
    C = np.array([[1.0, 0.5]])

    def bounds(k, y):  # |d - 0.3 sin(y)| <= 0.2 (a nonlinearity bounded from the measurement)
        c = 0.0 if y is None or np.isnan(y).any() else 0.3 * np.sin(y[0])
        r = 0.5 if y is None or np.isnan(y).any() else 0.2
        return Box([c - r, -0.05], [c + r, 0.05])

    sys = LinearSystem(A, None, C, E=[[0.5, 0.0], [0.2, 0.0]], F=[[0.0, 1.0]], d=bounds)
    x0 = Box([-1.0, -1.0], [1.0, 1.0])
    x = np.empty((T, 2))
    y = np.empty((T, 1))
    xk = np.array([1.0, -1.0])
    for k in range(T):
        v = 0.05 * (1 if rng.random() < 0.5 else -1)
        y[k] = C @ xk + v
        b = bounds(k, y[k])
        d = np.array([b.hi[0] if rng.random() < 0.5 else b.lo[0], v])
        x[k] = xk
        xk = A[k] @ xk + np.array([[0.5, 0.0], [0.2, 0.0]]) @ d
    for m in ("fixed-time", "kkl", "exact", "strip", "constrained-zonotope", "intersect"):
        est = ivobs.make_estimator(m, sys, x0=x0)
        res = _quiet_run(est, None, y)
        assert _excess(res, x) <= 0.0, m
