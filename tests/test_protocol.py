"""The estimator protocol, exercised with a minimal method defined here (an open-loop interval
predictor by Lemma 1, not registered): run/step agreement, state and restore, batches, errors."""

import json
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem, image_bounds, make_estimator
from ivobs.estimators import Estimator
from ivobs.estimators.state import OnlineState, Step
from ivobs.testing import adversarial_run, random_system


@dataclass(frozen=True)
class BoxState(OnlineState):
    """The predicted box of ``x[k]``."""

    lo: np.ndarray
    hi: np.ndarray
    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"),)


class OpenLoop(Estimator):
    """x[k+1] ∈ A[x[k]] + B u[k] + E[d[k]] (uses no measurement)."""

    name = "open-loop-test"

    def __init__(self, sys, x0=None, *, on_inconsistent="warn"):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)

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


class Late(OpenLoop):
    name = "late-test"

    def __init__(self, sys, x0=None, *, start=3, on_inconsistent="warn"):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)
        self.valid_from = start


def _setup(T=60, seed=0):
    sys = random_system(seed, nx=3, ny=2, nu=1)
    x0 = Box(-np.ones(3), np.ones(3))
    return sys, x0, adversarial_run(sys, x0, T, seed=seed)


def test_run_is_sound_and_step_reproduces_it_bit_for_bit():
    sys, x0, tr = _setup()
    est = OpenLoop(sys, x0)
    res = est.run(tr.u, tr.y)
    assert res.contains(tr.x).all() and res.method == "open-loop-test"
    est.reset()
    for k in range(tr.T):
        box = est.step(tr.u[k], tr.y[k])
        np.testing.assert_array_equal(box.lo, res.lower[k])
        np.testing.assert_array_equal(box.hi, res.upper[k])
    assert est.k == tr.T


def test_valid_from_rows_are_nan_and_step_returns_unknown_box():
    sys, x0, tr = _setup(T=10)
    est = Late(sys, x0, start=4)
    res = est.run(tr.u, tr.y)
    assert res.valid_from == 4
    assert np.isnan(res.lower[:4]).all() and np.isfinite(res.lower[4:]).all()
    assert res.contains(tr.x).all()
    est.reset()
    assert est.step(tr.u[0], tr.y[0]).is_unknown


def test_state_restore_continues_identically_through_json():
    sys, x0, tr = _setup(T=40)
    est = OpenLoop(sys, x0)
    est.reset()
    for k in range(15):
        est.step(tr.u[k], tr.y[k])
    saved = json.loads(json.dumps(est.state()))
    rest = [est.step(tr.u[k], tr.y[k]) for k in range(15, 40)]
    other = OpenLoop(sys, x0)
    other.restore(saved)
    for k, box in zip(range(15, 40), rest):
        b2 = other.step(tr.u[k], tr.y[k])
        np.testing.assert_array_equal(b2.lo, box.lo)
    with pytest.raises(IvobsError, match="same method"):
        Late(sys, x0).restore(saved)
    with pytest.raises(IvobsError, match="expected the dict"):
        other.restore({"bogus": 1})


def test_batch_runs_equal_single_runs():
    sys, x0, tr = _setup(T=25)
    tr2 = adversarial_run(sys, x0, 25, seed=9)
    U = np.stack([tr.u, tr2.u])
    Y = np.stack([tr.y, tr2.y])
    res = OpenLoop(sys, x0).run(U, Y)
    assert res.lower.shape == (2, 25, 3) and res.is_batch
    np.testing.assert_array_equal(res.lower[1], OpenLoop(sys, x0).run(tr2.u, tr2.y).lower)
    assert res.contains(np.stack([tr.x, tr2.x])).all()


def test_input_validation_messages():
    sys, x0, tr = _setup(T=5)
    est = OpenLoop(sys, x0)
    with pytest.raises(IvobsError, match=r"y: expected shape \(T, 2\)"):
        est.run(tr.u, tr.y[:, :1])
    with pytest.raises(IvobsError, match=r"u and y: expected the same number .*u: 4, y: 5"):
        est.run(tr.u[:4], tr.y)
    with pytest.raises(IvobsError, match="u: NaN at index"):
        est.run(np.full_like(tr.u, np.nan), tr.y)
    with pytest.raises(IvobsError, match="y_k: expected 2 measurement value"):
        est.step(tr.u[0], [1.0])
    with pytest.raises(IvobsError, match="x0: expected an ivobs.Box"):
        OpenLoop(sys, [0, 0, 0])
    with pytest.raises(IvobsError, match="needs a prior box"):
        OpenLoop(sys, None)
    with pytest.raises(IvobsError, match="constant Box of dimension 3"):
        OpenLoop(sys, Box([0, 0], [1, 1]))
    with pytest.raises(IvobsError, match="on_inconsistent"):
        OpenLoop(sys, x0, on_inconsistent="explode")
    ct = LinearSystem(-np.eye(3), C=np.eye(3)[:1], dt=0)
    with pytest.raises(IvobsError, match="discrete-time systems"):
        OpenLoop(ct, x0)
    tv = LinearSystem(lambda k: 0.5 * np.eye(3), C=np.eye(3)[:1])
    with pytest.raises(IvobsError, match="time-invariant"):
        OpenLoop(tv, x0)
    # flags are booleans: a string such as "no" is truthy and would mean the opposite
    with pytest.raises(IvobsError, match="vectorize: expected True or False, got 'no'"):
        est.run(tr.u, tr.y, vectorize="no")
    with pytest.raises(IvobsError, match="progress: expected True, False or None"):
        est.run(tr.u, tr.y, progress="yes")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"check_consistency": "no"}, "check_consistency: expected True or False, got 'no'"),
        ({"weighted": 1}, "weighted: expected True or False, got 1"),
        ({"s": 10**6}, "s: expected a window of at most 1000 past samples"),
    ],
)
def test_fixed_time_option_errors(options, message):
    sc = ivobs.scenarios.get("servo-motor", horizon=10)
    with pytest.raises(IvobsError, match=message):
        make_estimator("fixed-time", sc.system, x0=sc.x0, **options)


def test_inconsistency_reporting_policy():
    class Flagging(OpenLoop):
        name = "flagging-test"

        def _step(self, state, u_k, y_k, t_k):
            res = super()._step(state, u_k, y_k, t_k)
            return res._replace(inconsistent=state.k == 2)

    sys, x0, tr = _setup(T=6)
    with pytest.warns(UserWarning, match=r"step\(s\) \[2\] is inconsistent"):
        res = Flagging(sys, x0).run(tr.u, tr.y)
    assert res.inconsistent.tolist() == [False, False, True, False, False, False]
    with pytest.raises(ivobs.InconsistentDataError) as info:
        Flagging(sys, x0, on_inconsistent="raise").run(tr.u, tr.y)
    assert info.value.step == 2


def test_registry_errors_name_the_known_methods_and_options():
    sys, x0, _ = _setup(T=2)
    with pytest.raises(IvobsError, match="unknown method 'no-such-method'; known methods"):
        make_estimator("no-such-method", sys, x0)
    assert isinstance(ivobs.methods(), list)
    for name in ivobs.methods():
        cls = ivobs.estimators.get(name)
        with pytest.raises(IvobsError, match="does not accept 'bogus_option'"):
            make_estimator(name, sys, x0, bogus_option=1)
        assert cls.name == name and cls.summary and cls.reference
