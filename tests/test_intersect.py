"""The intersection of several guaranteed estimators (and of the measurement strip): never wider
than a member, sound, nested state, vectorised path, faults. Members that are not registered
(yet) are skipped."""

import json
import warnings
from dataclasses import dataclass, replace
from functools import cache
from typing import ClassVar

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem, image_bounds, scenarios
from ivobs.estimators import Estimator
from ivobs.estimators.intersect import DEFAULT_METHODS
from ivobs.estimators.state import OnlineState, Step
from ivobs.testing import adversarial_run, assert_contains, exact_misses, exact_run, random_system
from ivobs.testing.conformance import conformance_plants, vertex_disturbance

RTOL = 1e-12  # "contained in a member": up to the rounding margin of a crossing


@dataclass(frozen=True)
class BoxState(OnlineState):
    """The predicted box of ``x[k]``."""

    lo: np.ndarray
    hi: np.ndarray
    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"),)


class OpenLoop(Estimator):
    """x[k+1] ∈ A[x[k]] + B u[k] + E[d[k]]: ignores the measurements (a wide member)."""

    name = "open-loop-test"
    data_used = "prediction"  # uses no measurement: no strips of its own

    def __init__(self, sys, x0=None, *, start=0, on_inconsistent="warn"):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)
        self.valid_from = start

    def _initial_state(self):
        return BoxState(lo=self.x0.lo.copy(), hi=self.x0.hi.copy())

    def _step(self, state, u_k, y_k, t_k):
        lo, hi = state.lo, state.hi
        A, B, _, _, E, _ = self.sys.matrices_at(state.k)
        d = self.sys.d_at(state.k, y_k)
        a_lo, a_hi = image_bounds(A, lo, hi)
        e_lo, e_hi = image_bounds(E, d.lo, d.hi)
        nxt = replace(state, lo=a_lo + B @ u_k + e_lo, hi=a_hi + B @ u_k + e_hi)
        return Step(nxt, lo.copy(), hi.copy())


def need(*names):
    missing = [n for n in names if n not in ivobs.methods()]
    if missing:
        pytest.skip(f"method(s) not registered yet: {missing}")


def intersect(sys, x0, **options):
    return ivobs.make_estimator("intersect", sys, x0=x0, **options)


def assert_within(res, member, k0=None):
    """``res`` ⊆ ``member`` at every step where the member is valid."""
    k0 = member.valid_from if k0 is None else k0
    tol = RTOL * (1 + np.abs(member.upper[..., k0:, :]))
    assert np.all(res.lower[..., k0:, :] >= member.lower[..., k0:, :] - tol)
    assert np.all(res.upper[..., k0:, :] <= member.upper[..., k0:, :] + tol)


# -- never wider than a member, sound ------------------------------------------------------
@cache
def _servo_default():
    sc = scenarios.get("servo-motor", horizon=60)
    est = intersect(sc.system, sc.x0)
    return sc, est, sc.simulate("vertex", seed=3)


def servo_default():
    if not set(DEFAULT_METHODS) & set(ivobs.methods()):
        pytest.skip("none of the default members is registered yet")
    return _servo_default()


def test_default_members_are_intersected_soundly():
    _, est, tr = servo_default()
    assert est.design.methods == tuple(m.name for m in est.members) and est.members
    assert est.valid_from == min(m.valid_from for m in est.members)
    res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    widths = []
    for m in est.members:
        r = m.run(tr.u, tr.y)
        assert_contains(r, tr.x)
        assert_within(res, r)
        widths.append(r.mean_width(10))
    # never wider than the best member, component by component
    assert np.all(res.mean_width(10) <= np.min(widths, axis=0) + 1e-12)


def test_exact_members_and_windows():
    sys = random_system(3, nx=3, ny=1, nu=1, symmetric_bounds=False)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 25, seed=1)
    est = intersect(sys, x0, methods=["exact", ("exact", {"window": 3, "progress": False})])
    res = est.run(tr.u, tr.y)
    full = ivobs.make_estimator("exact", sys, x0=x0).run(tr.u, tr.y)
    win = ivobs.make_estimator("exact", sys, x0=x0, window=3).run(tr.u, tr.y)
    assert_contains(res, tr.x)
    assert_within(res, full)
    assert_within(res, win)
    # exact is the tightest: the intersection is the exact hull (to rounding)
    np.testing.assert_allclose(res.lower, full.lower, atol=1e-9)
    np.testing.assert_allclose(res.upper, full.upper, atol=1e-9)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_systems_with_vertex_disturbances(seed):
    need("fixed-time")
    sys = random_system(seed, nx=3, ny=2, nu=1, feedthrough=seed == 1,
                        invertible=seed != 2, symmetric_bounds=seed != 0)  # fmt: skip
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 60, seed=seed)
    members = [OpenLoop(sys, x0), "fixed-time", ("exact", {"window": 2})]
    est = intersect(sys, x0, methods=members)
    res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    for m in est.members:
        assert_within(res, m.run(tr.u, tr.y))


def test_valid_from_is_the_earliest_member_and_late_members_are_ignored():
    sys = random_system(4, nx=2, ny=1, nu=1)
    x0 = Box(-np.ones(2), np.ones(2))
    tr = adversarial_run(sys, x0, 12, seed=0)
    late, early = OpenLoop(sys, x0, start=5), OpenLoop(sys, Box(-2 * np.ones(2), 2 * np.ones(2)))
    est = intersect(sys, x0, methods=[late, early], strips=False)
    assert est.valid_from == 0
    res = est.run(tr.u, tr.y)
    r_early, r_late = early.run(tr.u, tr.y), late.run(tr.u, tr.y)
    np.testing.assert_array_equal(res.lower[:5], r_early.lower[:5])  # NaN rows of `late` ignored
    assert_within(res, r_late)
    assert np.all(res.width[5:] <= r_late.width[5:])


# -- the measurement strip -----------------------------------------------------------------
def strip_system():
    """x in R^3; y1 = -2 x1 + noise, y2 = x2 + x3 (not a pinning row), y3 = 0.5 x3 + D u."""
    A = np.array([[0.9, 0.2, 0.0], [0.0, 0.8, 0.1], [0.1, 0.0, 0.7]])
    C = np.array([[-2.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.5]])
    F = np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.05]])
    D = np.array([[0.0], [0.0], [0.3]])
    E = 0.1 * np.eye(3)
    d = Box([-1.0, -1.0, -0.5], [1.0, 1.0, 1.5])
    return LinearSystem(A, np.ones((3, 1)), C, D=D, E=E, F=F, d=d), Box(-np.ones(3), np.ones(3))


def test_strip_gives_the_measurement_box():
    sys, x0 = strip_system()
    tr = adversarial_run(sys, x0, 30, seed=2)
    wide = OpenLoop(sys, Box(-100 * np.ones(3), 100 * np.ones(3)))
    est = intersect(sys, x0, methods=[wide])
    assert est.design.strip_rows == (0, 1, 2)
    res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    # x1 = (y1 - 0.1 d1) / -2,  x3 = (y3 - 0.3 u - 0.05 d3) / 0.5
    x1 = np.sort(np.stack([(tr.y[:, 0] - 0.1) / -2, (tr.y[:, 0] + 0.1) / -2]), axis=0)
    x3 = np.stack([(tr.y[:, 2] - 0.3 * tr.u[:, 0] - 0.075) / 0.5,
                   (tr.y[:, 2] - 0.3 * tr.u[:, 0] + 0.025) / 0.5])  # fmt: skip
    np.testing.assert_allclose(res.lower[:, 0], x1[0], atol=1e-9)
    np.testing.assert_allclose(res.upper[:, 0], x1[1], atol=1e-9)
    np.testing.assert_allclose(res.lower[:, 2], x3[0], atol=1e-9)
    np.testing.assert_allclose(res.upper[:, 2], x3[1], atol=1e-9)
    off = intersect(sys, x0, methods=[wide], strips=False).run(tr.u, tr.y)
    assert np.all(off.width[:, 0] > 10)  # without the strips: the wide member alone
    # x2 is pinned by y2 = x2 + x3 once x3 is: its width is that of the two sensors' strips
    assert np.all(res.width[:, 1] < 1.0) and np.all(off.width[:, 1] > 10)


def test_strip_with_identity_C_and_missing_components():
    A = np.array([[0.5, 0.3], [-0.2, 0.6]])
    sys = LinearSystem(A, None, np.eye(2), E=np.eye(2) * 0.1, F=np.eye(2) * 0.2,
                       d=Box.symmetric([1.0, 1.0]))  # fmt: skip
    x0 = Box([-5.0, -5.0], [5.0, 5.0])
    tr = adversarial_run(sys, x0, 20, seed=1)
    y = tr.y.copy()
    y[3, 1] = np.nan
    res = intersect(sys, x0, methods=[OpenLoop(sys, x0)]).run(tr.u, y)
    assert_contains(res, tr.x)
    np.testing.assert_allclose(res.lower[4:], y[4:] - 0.2, atol=1e-9)
    np.testing.assert_allclose(res.upper[4:], y[4:] + 0.2, atol=1e-9)
    assert res.width[3, 1] > 0.4 + 1e-6  # the missing component is predicted
    np.testing.assert_allclose(res.lower[3, 0], y[3, 0] - 0.2, atol=1e-9)


# -- vectorised path, batches, online, persistence -------------------------------------------
def test_vectorised_run_and_batches_match_the_loop():
    need("reachability")
    sc = scenarios.get("servo-motor", horizon=50)
    est = intersect(sc.system, sc.x0, methods=["reachability", OpenLoop(sc.system, sc.x0)])
    trs = [sc.simulate("vertex", seed=s) for s in range(3)]
    loop = [est.run(tr.u, tr.y, vectorize=False) for tr in trs]
    vec = est.run(trs[0].u, trs[0].y, vectorize=True)
    np.testing.assert_allclose(vec.lower, loop[0].lower, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(vec.upper, loop[0].upper, rtol=1e-9, atol=1e-12)
    batch = est.run(np.stack([t.u for t in trs]), np.stack([t.y for t in trs]))
    assert batch.lower.shape == (3, 50, 3)
    for b in range(3):
        np.testing.assert_allclose(batch.lower[b], loop[b].lower, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(batch.upper[b], loop[b].upper, rtol=1e-9, atol=1e-12)
    est.reset()
    for k in range(50):
        box = est.step(trs[0].u[k], trs[0].y[k])
        assert np.array_equal(box.lo, loop[0].lower[k]) and np.array_equal(box.hi, loop[0].upper[k])


def test_vectorised_path_adds_nothing_to_the_members_on_a_badly_scaled_plant():
    """The 'scaled' conformance plant (states of magnitude 1e6, 1 and 1e-3), vertex disturbances,
    exact states. On either path the box is the members' boxes of that path intersected and met
    with the strips, bit for bit: intersect's own part is exact and the same on both paths, so
    where the paths differ, a member's paths do. Both hold the state; with members whose
    vectorised path is their loop's within rounding, the widths are the loop's."""
    need("reachability")
    sys, x0 = conformance_plants()["scaled"]
    rng, T = np.random.default_rng(0), 100
    x_true0 = np.where(rng.integers(0, 2, sys.nx).astype(bool), x0.hi, x0.lo)
    u = rng.uniform(-1.0, 1.0, size=(T, sys.nu))
    y, x = exact_run(sys, x_true0, u, vertex_disturbance(sys.d_at(0), T, rng))
    est = intersect(sys, x0)
    vf = est.valid_from
    for vectorize in (False, True):
        res = est.run(u, y, vectorize=vectorize)
        assert exact_misses(res.lower, res.upper, x).size == 0 and not res.inconsistent.any()
        members = [m.run(u, y, vectorize=vectorize) for m in est.members]
        lo = np.fmax.reduce([m.lower for m in members])
        hi = np.fmin.reduce([m.upper for m in members])
        est._strips.meet(lo[vf:], hi[vf:], u[vf:], y[vf:], np.arange(vf, T))
        np.testing.assert_array_equal(res.lower[vf:], lo[vf:])
        np.testing.assert_array_equal(res.upper[vf:], hi[vf:])


def test_state_and_restore_nest_the_members():
    sys = random_system(5, nx=3, ny=2, nu=1)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 16, seed=4)

    def build():
        return intersect(sys, x0, methods=[("exact", {"window": 4}), OpenLoop(sys, x0)])

    ref = build().run(tr.u, tr.y)
    est = build()
    for k in range(8):
        est.step(tr.u[k], tr.y[k])
    saved = json.loads(json.dumps(est.state()))
    assert [s["method"] for s in saved["state"]["members"]] == ["exact", "open-loop-test"]
    other = build()
    other.restore(saved)
    assert other.k == 8
    rest = np.array([other.step(tr.u[k], tr.y[k]).hi for k in range(8, 16)])
    np.testing.assert_allclose(rest, ref.upper[8:], atol=1e-8)
    with pytest.raises(IvobsError, match="other members"):
        intersect(sys, x0, methods=[OpenLoop(sys, x0)]).restore(saved)


# -- faults --------------------------------------------------------------------------------
def test_empty_intersection_is_flagged_and_returns_the_members_hull():
    sys, x0 = strip_system()
    tr = adversarial_run(sys, x0, 20, seed=5)
    y = tr.y.copy()
    y[12, 0] += 40.0  # a fault on the sensor that pins x1
    member = OpenLoop(sys, x0)
    est = intersect(sys, x0, methods=[member])
    with pytest.warns(UserWarning, match=r"step\(s\) \[12\]"):
        res = est.run(tr.u, y)
    assert res.inconsistent.tolist() == [k == 12 for k in range(20)]
    assert np.all(res.lower <= res.upper)
    alone = member.run(tr.u, y)
    np.testing.assert_array_equal(res.lower[12], alone.lower[12])
    np.testing.assert_array_equal(res.upper[12], alone.upper[12])
    assert_contains(res, tr.x)
    with pytest.raises(ivobs.InconsistentDataError):
        intersect(sys, x0, methods=[member], on_inconsistent="raise").run(tr.u, y)


def test_a_members_report_is_passed_on():
    sys = random_system(7, nx=3, ny=2, nu=1)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 16, seed=3)
    y = tr.y.copy()
    y[9, 1] += 50.0
    est = intersect(sys, x0, methods=["exact"], strips=False)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = est.run(tr.u, y)
    assert res.inconsistent[9] and res.inconsistent.sum() == 1
    assert any("intersect" in str(w.message) for w in caught)
    assert_contains(res, tr.x)


# -- construction --------------------------------------------------------------------------
def test_bad_member_specifications():
    sys = random_system(0, nx=2, ny=1, nu=1)
    x0 = Box(-np.ones(2), np.ones(2))
    with pytest.raises(IvobsError, match="unknown method"):
        intersect(sys, x0, methods=["no-such-method"])
    with pytest.raises(IvobsError, match="methods"):
        intersect(sys, x0, methods="exact")
    with pytest.raises(IvobsError, match="at least one"):
        intersect(sys, x0, methods=[])
    with pytest.raises(IvobsError, match=r"methods\[0\]"):
        intersect(sys, x0, methods=[("exact", 3)])
    other = random_system(0, nx=3, ny=1, nu=1)
    with pytest.raises(IvobsError, match="same plant"):
        intersect(sys, x0, methods=[OpenLoop(other, Box(-np.ones(3), np.ones(3)))])
    with pytest.raises(IvobsError, match="strips"):
        intersect(sys, x0, methods=["exact"], strips="yes")
    with pytest.raises(IvobsError, match="does not accept"):
        intersect(sys, x0, methods=[("exact", {"gain": 1})])


def test_default_members_skip_what_cannot_be_designed():
    sc, est, _ = servo_default()
    candidates = [m for m in DEFAULT_METHODS if m in ivobs.methods()]
    assert len(est.members) + len(est.design.skipped) == len(candidates)
    # without a prior box, members that need one are skipped, with the reason
    if any(not ivobs.estimators.get(m).needs_x0 for m in candidates):
        no_x0 = intersect(sc.system, None)
        assert no_x0.members and all(not m.needs_x0 for m in no_x0.members)
        for name in candidates:
            if ivobs.estimators.get(name).needs_x0:
                assert any(s.startswith(f"{name}: ") and "x0" in s for s in no_x0.design.skipped)
    # a continuous-time system: only members that support it
    ct = LinearSystem([[-1.0, 0.5], [0.0, -2.0]], None, [[1.0, 0.0]], E=[[0.1], [0.1]],
                      F=[[0.0]], d=Box.symmetric([1.0]), dt=0)  # fmt: skip
    if any(ivobs.estimators.get(m).supports_continuous for m in candidates):
        est_ct = intersect(ct, Box(-np.ones(2), np.ones(2)))
        assert all(m.supports_continuous for m in est_ct.members)
        assert any("discrete-time" in s for s in est_ct.design.skipped)
    else:
        with pytest.raises(ivobs.DesignError, match="methods="):
            intersect(ct, Box(-np.ones(2), np.ones(2)))


def test_vectorised_path_keeps_the_members_inconsistency_flags():
    """A faulty stream in a complete batch: the fixed-time member flags it in its own
    vectorised run; intersect reports the same steps as its loop (it used to drop them)."""
    sys_ = random_system(1, nx=2, ny=2, nu=2, feedthrough=True)
    x0 = Box([-1, -1], [1, 1])
    est = ivobs.make_estimator("intersect", sys_, x0=x0, on_inconsistent="ignore")
    tr = adversarial_run(sys_, x0, 30, seed=2)
    Y = tr.y.copy()
    Y[10:, 0] += 0.05  # a small sensor offset from step 10
    rb = est.run(np.stack([tr.u] * 4), np.stack([tr.y] * 3 + [Y]))
    rl = est.run(tr.u, Y, vectorize=False)
    assert rl.inconsistent.any()
    np.testing.assert_array_equal(rb.inconsistent[3], rl.inconsistent)
    assert not rb.inconsistent[:3].any()


def test_time_varying_system_uses_the_strip_in_every_path():
    """The pendulum (continuous time, time-varying C): the measurement strip depends on the
    time, so the vectorised path defers to the loop instead of leaving the strip out."""
    sc = scenarios.get("pendulum", t_final=3.0)
    est = ivobs.make_estimator("intersect", sc.system, x0=sc.x0)
    Y = np.stack([sc.simulate("vertex", seed=s).y for s in (0, 1)])
    rb = est.run(sc.u, Y, t=sc.t)
    rl = est.run(sc.u, Y[0], t=sc.t, vectorize=False)
    np.testing.assert_allclose(rb.lower[0], rl.lower, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(rb.upper[0], rl.upper, rtol=1e-9, atol=1e-12)


def test_predict_between_steps_leaves_the_members_warm_starts_alone():
    """``predict()`` is a look-ahead: with an ``exact`` member (a warm-started LP kept for the
    online state), stepping with predictions in between gives run()'s numbers exactly."""
    sys = random_system(6, nx=3, ny=2, nu=1)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 20, seed=2)
    ref = intersect(sys, x0, methods=[("exact", {"window": 4}), "interval-split"]).run(tr.u, tr.y)
    est = intersect(sys, x0, methods=[("exact", {"window": 4}), "interval-split"])
    his = []
    for k in range(20):
        est.predict(tr.u[k])
        his.append(est.step(tr.u[k], tr.y[k]).hi)
    np.testing.assert_array_equal(np.array(his)[est.valid_from :], ref.upper[est.valid_from :])


# -- soundness at every scale, missing samples -----------------------------------------------
@pytest.mark.parametrize(
    ("scale", "gain", "noise"),
    [(1.0, 1.0, 0.0), (1e6, 1e3, 0.0), (1e10, 1e3, 1e-2)],
    ids=["unit", "1e6-gain1e3", "1e10-thin"],
)
def test_exact_trajectories_are_contained_at_every_scale(scale, gain, noise):
    """Exact records (tests/exactsim.py) with members whose rounding is proven, the
    measurement strip of an output that pins a state, a JSON round trip at every step: no
    miss, no flag, never wider than a member."""
    from exactsim import simulate_linear
    from test_strip_soundness import exact_system

    sys, x0, x_true0, rng = exact_system(int(np.log10(scale)) + 50, scale, gain, 0.95, noise)
    C = sys.C.copy()
    C[1] = [0.0, 2.0, 0.0]  # y2 pins x2
    sys = LinearSystem(sys.A, sys.B, C, sys.D, E=sys.E, F=sys.F, d=sys.d)
    rec = simulate_linear(sys, x_true0, 100, rng.normal(size=(100, 1)) * scale, seed=3)
    est = intersect(sys, x0, methods=["strip", "ellipsoid"])
    assert est.design.strip_rows == (0, 1)  # every output's strip (y2's pins x2)
    res = est.run(rec.U, rec.Y)
    assert rec.misses(res.lower, res.upper).size == 0 and not res.inconsistent.any()
    for m in est.members:
        assert_within(res, m.run(rec.U, rec.Y))
    est.reset()
    for k in range(rec.Y.shape[0]):
        box = est.step(rec.U[k], rec.Y[k])
        assert np.array_equal(box.lo, res.lower[k]) and np.array_equal(box.hi, res.upper[k])
        est.restore(json.loads(json.dumps(est.state())))


def test_a_sample_rounded_past_its_bound_is_not_a_contradiction():
    """``y = x + v`` with ``x = -0.1`` and ``v`` at its bound ``-0.005``: a float64 record holds
    ``fl(-0.1 + -0.005) = -0.10500000000000001``, outside the exact set by rounding. The
    measurement strip includes that rounding: it meets the members' boxes (no flag) and holds
    ``x``."""
    y = -0.1 + -0.005
    sys = LinearSystem([[0.5]], None, [[1.0]], E=[[0.0, 0.0]], F=[[0.0, 1.0]],
                       d=Box([-0.01, -0.005], [0.01, 0.005]))  # fmt: skip
    est = intersect(sys, Box([-0.1], [-0.1]), methods=["strip"], on_inconsistent="raise")
    box = est.step(None, [y])
    assert box.lo[0] <= -0.1 <= box.hi[0] and not est.last_inconsistent


@pytest.mark.parametrize(("seed", "T"), [(0, 600), pytest.param(1, 3000, marks=pytest.mark.slow)])
def test_missing_samples_leave_the_widths_bounded(seed, T):
    """10 % of the output components missing at random on a random stable plant: every box
    holds the state, widths within 20x of those with every sample."""
    rng = np.random.default_rng(seed)
    sys = random_system(seed + 80, nx=3, ny=2, nu=1, rho=0.85)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, T, seed=seed)
    gaps = tr.y.copy()
    gaps[rng.random(gaps.shape) < 0.1] = np.nan
    est = intersect(sys, x0, methods=["strip", "ellipsoid"])
    full, missing = est.run(tr.u, tr.y), est.run(tr.u, gaps)
    assert_contains(full, tr.x)
    assert_contains(missing, tr.x)
    ratio = missing.width[50:].mean() / full.width[50:].mean()
    assert 1.0 <= ratio < 20.0
