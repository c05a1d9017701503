"""The constrained-zonotope filter [Scott2016]: exact without reduction, sound and close
to exact with it, bounded size, faults, online use."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem, scenarios
from ivobs.testing import adversarial_run, assert_contains, random_system

CASES = [
    # (seed, nx, ny, invertible, symmetric bounds, feedthrough)
    (0, 2, 1, True, True, False),
    (1, 3, 1, False, False, True),
    (2, 3, 2, True, False, True),
    (3, 4, 2, False, True, False),
]


@cache
def case(i: int, T: int):
    seed, nx, ny, inv, sym, ft = CASES[i]
    sys = random_system(
        seed, nx=nx, ny=ny, nu=1, invertible=inv, symmetric_bounds=sym, feedthrough=ft
    )
    x0 = Box(-np.ones(nx), np.ones(nx))
    return sys, x0, adversarial_run(sys, x0, T, seed=seed + 20)


@cache
def exact(i: int, T: int) -> ivobs.Estimate:
    sys, x0, tr = case(i, T)
    return ivobs.make_estimator("exact", sys, x0=x0, progress=False).run(tr.u, tr.y)


needs_exact = pytest.mark.skipif("exact" not in ivobs.methods(), reason="no exact reference")


@needs_exact
@pytest.mark.parametrize("i", range(len(CASES)))
def test_without_reduction_it_is_the_exact_hull(i: int) -> None:
    sys, x0, tr = case(i, 15)
    cz = ivobs.make_estimator("constrained-zonotope", sys, x0=x0, reduce=False).run(tr.u, tr.y)
    ex = exact(i, 15)
    scale = 1.0 + np.abs(ex.upper)
    np.testing.assert_allclose(cz.lower, ex.lower, atol=1e-6 * scale.max())
    np.testing.assert_allclose(cz.upper, ex.upper, atol=1e-6 * scale.max())
    assert_contains(cz, tr.x)


@needs_exact
@pytest.mark.parametrize("i", range(len(CASES)))
def test_with_reduction_it_is_sound_and_close_to_exact(i: int) -> None:
    sys, x0, tr = case(i, 40)
    cz = ivobs.make_estimator("constrained-zonotope", sys, x0=x0).run(tr.u, tr.y)
    ex = exact(i, 40)
    assert_contains(cz, tr.x)
    tol = 1e-6 * (1.0 + np.abs(ex.upper))
    assert np.all(cz.lower <= ex.lower + tol) and np.all(cz.upper >= ex.upper - tol)
    ratio = cz.tightness_ratio(ex, burn_in=5)
    assert np.all(ratio < 1.05), ratio  # measured <= 1.006 on these systems


@needs_exact
def test_certificate_guided_elimination_beats_the_hausdorff_heuristic() -> None:
    """Same limits, same reduction of generators; only the choice of the eliminated factor
    differs (3 states, 2 outputs, vertex disturbances, 40 steps)."""
    sys = random_system(12, nx=3, ny=2, nu=1, symmetric_bounds=True, feedthrough=True)
    x0 = Box(-np.ones(3), np.ones(3))
    tr = adversarial_run(sys, x0, 40, seed=12)
    ex = ivobs.make_estimator("exact", sys, x0=x0, progress=False).run(tr.u, tr.y)
    ratio = {}
    for how in ("certificates", "hausdorff"):
        est = ivobs.make_estimator("constrained-zonotope", sys, x0=x0, elimination=how)
        res = est.run(tr.u, tr.y)
        assert_contains(res, tr.x)
        ratio[how] = float(np.mean(res.tightness_ratio(ex, burn_in=10)))
    assert ratio["certificates"] < 1.1 < 1.2 < ratio["hausdorff"]  # measured 1.06 and 1.30


@pytest.mark.parametrize("i", range(len(CASES)))
def test_contains_the_true_state_at_every_step_with_vertex_disturbances(i: int) -> None:
    sys, x0, tr = case(i, 60)
    res = ivobs.make_estimator("constrained-zonotope", sys, x0=x0).run(tr.u, tr.y)
    assert_contains(res, tr.x)
    assert not res.inconsistent.any()


def test_servo_motor_tighter_than_strip() -> None:
    sc = scenarios.get("servo-motor", horizon=60)
    tr = sc.simulate("vertex", seed=4)
    cz = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0).run(tr.u, tr.y)
    st = ivobs.make_estimator("strip", sc.system, x0=sc.x0).run(tr.u, tr.y)
    assert_contains(cz, tr.x)
    assert np.all(cz.mean_width(10) <= st.mean_width(10) * (1 + 1e-9))
    # the measured states (θ, n) are known to within the noise: |v| <= 0.0564
    assert np.all(cz.mean_width(10)[:2] <= 2 * 0.0564 + 1e-9)


def test_size_stays_bounded_by_the_limits() -> None:
    sys, x0, tr = case(3, 60)
    est = ivobs.make_estimator(
        "constrained-zonotope", sys, x0=x0, max_constraints=5, max_generators=30
    )
    st = est.initial_state()
    for k in range(60):
        st, _ = est.advance(st, tr.u[k], tr.y[k])
        assert st.A.shape[0] <= 5 and st.G.shape[1] <= 30
        assert st.A.shape[1] == st.G.shape[1]
    assert est.design.max_constraints == 5 and est.design.max_generators == 30


def test_step_reproduces_run_and_state_round_trips() -> None:
    sys, x0, tr = case(2, 30)
    est = ivobs.make_estimator("constrained-zonotope", sys, x0=x0)
    res = est.run(tr.u, tr.y)
    est.reset()
    for k in range(15):
        box = est.step(tr.u[k], tr.y[k])
        assert np.array_equal(box.lo, res.lower[k]) and np.array_equal(box.hi, res.upper[k])
    other = ivobs.make_estimator("constrained-zonotope", sys, x0=x0)
    other.restore(est.state())
    for k in range(15, 30):
        box = other.step(tr.u[k], tr.y[k])
        np.testing.assert_allclose(box.lo, res.lower[k], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(box.hi, res.upper[k], rtol=1e-9, atol=1e-12)


def test_fault_detection_empty_set() -> None:
    """A sensor fault (a bias no admissible disturbance explains) empties the set: reported at
    the step it appears, the measurement is dropped and the true state stays in the box."""
    sys, x0, tr = case(1, 40)
    y = tr.y.copy()
    y[30:33, 0] += 25.0
    est = ivobs.make_estimator("constrained-zonotope", sys, x0=x0, on_inconsistent="ignore")
    res = est.run(tr.u, y)
    assert list(np.flatnonzero(res.inconsistent)) == [30, 31, 32]
    assert_contains(res, tr.x)
    with pytest.raises(ivobs.InconsistentDataError) as err:
        ivobs.make_estimator("constrained-zonotope", sys, x0=x0, on_inconsistent="raise").run(
            tr.u, y
        )
    assert err.value.step == 30


def test_time_varying_and_callable_bounds() -> None:
    """The Hénon scenario bounds d from y_k [Efimov2013, Remark 1]; kkl-ltv-dt has A_k."""
    for name in ("henon", "kkl-ltv-dt"):
        sc = scenarios.get(name, horizon=30)
        tr = sc.simulate("paper")
        res = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0).run(tr.u, tr.y)
        assert_contains(res, tr.x)


def test_bad_options() -> None:
    sys, x0, _ = case(0, 10)
    with pytest.raises(ivobs.IvobsError, match="max_constraints"):
        ivobs.make_estimator("constrained-zonotope", sys, x0=x0, max_constraints=-1)
    with pytest.raises(ivobs.IvobsError, match="max_generators"):
        ivobs.make_estimator("constrained-zonotope", sys, x0=x0, max_generators=0)
    with pytest.raises(ivobs.IvobsError, match="reduce"):
        ivobs.make_estimator("constrained-zonotope", sys, x0=x0, reduce="yes")
    with pytest.raises(ivobs.IvobsError, match="elimination"):
        ivobs.make_estimator("constrained-zonotope", sys, x0=x0, elimination="volume")
    with pytest.raises(ivobs.IvobsError, match="x0"):
        ivobs.make_estimator("constrained-zonotope", sys)


def test_correlated_disturbance_is_used_exactly() -> None:
    """x+ = x/2 + d, y = x + d with the same d: y - x = d, so x+ = y - x/2 and the state is
    determined after a few steps (treating d as two independent signals leaves widths up to 2)."""
    sys = ivobs.LinearSystem([[0.5]], None, [[1.0]], E=[[1.0]], F=[[1.0]], d=Box([-1.0], [1.0]))
    x0 = Box([-1.0], [1.0])
    tr = adversarial_run(sys, x0, 40, seed=1)
    res = ivobs.make_estimator("constrained-zonotope", sys, x0=x0).run(tr.u, tr.y)
    assert_contains(res, tr.x)
    assert np.all(res.width[1:] < 1e-7)  # only the rounding margins are left
    split = ivobs.LinearSystem.from_process_measurement(
        [[0.5]], None, [[1.0]], [[1.0]], [[1.0]], [1.0], [1.0]
    )
    tr2 = ivobs.simulate(split, tr.x[0], None, np.hstack([tr.d, tr.d]))
    ind = ivobs.make_estimator("constrained-zonotope", split, x0=x0).run(tr2.u, tr2.y)
    assert np.all(ind.width[1:] > 0.1) and np.mean(ind.width[1:]) > 1.0  # 0.125, 1.375


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.filterwarnings("ignore:invalid value encountered:RuntimeWarning")
@pytest.mark.parametrize("method", ["strip", "constrained-zonotope", "intersect"])
def test_overflow_of_an_unstable_plant_is_a_clear_error(method):
    """An unstable plant through a long outage: the set really exceeds the largest float; the
    error says so (step, cause), instead of a raw SciPy 'array must not contain infs'."""
    sys = LinearSystem([[1.8, 0.3], [0.0, 1.5]], None, [[1.0, 0.0]], E=0.1 * np.eye(2),
                       F=np.zeros((1, 2)), d=Box.symmetric([1.0, 1.0]))  # fmt: skip
    est = ivobs.make_estimator(method, sys, x0=Box([-1.0, -1.0], [1.0, 1.0]))
    overflow = r"overflowed \(exceed 1\.8e308\) at step 12\d\d: the system is unstable"
    with pytest.raises(IvobsError, match=overflow):
        est.run(None, np.full((1300, 1), np.nan))
