"""The typed online state: every method saves its state mid-run (JSON, versioned) and a fresh
estimator restored from it continues identically; states of another format version are refused
by name; a step never modifies the state it starts from."""

from __future__ import annotations

import dataclasses
import json
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError
from ivobs.estimators.state import STATE_FORMAT, STATE_VERSION, OnlineState

SERVO = ivobs.scenarios.get("servo-motor", horizon=24)  # every method designs here
SYS, X0 = SERVO.system, SERVO.x0
T, CUT = 24, 9


def _record() -> tuple[np.ndarray, np.ndarray]:
    tr = SERVO.simulate("vertex", seed=3)
    y = tr.y.copy()
    y[4] = np.nan  # a missing sample before the cut
    y[CUT + 2, 1] = np.nan  # and a missing component after it
    return tr.u, y


def _steps(est: ivobs.Estimator, u: np.ndarray, y: np.ndarray, ks: range) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return np.array([np.r_[b.lo, b.hi] for b in (est.step(u[k], y[k]) for k in ks)])


@pytest.mark.parametrize("method", ivobs.methods())
def test_restored_state_continues_identically(method: str) -> None:
    u, y = _record()
    whole = ivobs.make_estimator(method, SYS, x0=X0)
    ref = _steps(whole, u, y, range(T))
    first = ivobs.make_estimator(method, SYS, x0=X0)
    _steps(first, u, y, range(CUT))
    saved = json.loads(json.dumps(first.state()))  # strict JSON
    assert saved["format"] == STATE_FORMAT and saved["version"] == STATE_VERSION
    assert saved["method"] == method and saved["state"]["k"] == CUT
    second = ivobs.make_estimator(method, SYS, x0=X0)
    second.restore(saved)
    assert second.k == CUT
    rest = _steps(second, u, y, range(CUT, T))
    if method == "exact":  # a cold LP may end on another optimal basis: safe bounds within 1e-8
        np.testing.assert_allclose(rest, ref[CUT:], rtol=1e-9, atol=1e-8)
    else:
        np.testing.assert_array_equal(rest, ref[CUT:])


@pytest.mark.parametrize("method", ivobs.methods())
def test_a_step_returns_a_new_state_and_leaves_its_own_alone(method: str) -> None:
    u, y = _record()
    est = ivobs.make_estimator(method, SYS, x0=X0)
    state = est.initial_state()
    assert isinstance(state, OnlineState) and dataclasses.is_dataclass(state)
    for k in range(6):
        before = json.dumps(est.save_state(state))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            new, _box = est.advance(state, u[k], y[k])
        assert new is not state and new.k == state.k + 1
        assert json.dumps(est.save_state(state)) == before  # nothing changed in place
        with pytest.raises(dataclasses.FrozenInstanceError):
            new.k = 0  # type: ignore[misc]
        state = new


def test_predict_does_not_change_the_continuation() -> None:
    u, y = _record()
    for method in ("interval-split", "strip", "kkl"):
        ref = _steps(ivobs.make_estimator(method, SYS, x0=X0), u, y, range(T))
        est = ivobs.make_estimator(method, SYS, x0=X0)
        out = []
        for k in range(T):
            est.predict(u[k])
            out.append(_steps(est, u, y, range(k, k + 1))[0])
        np.testing.assert_array_equal(np.array(out), ref)


def test_a_state_of_another_format_version_is_refused_by_its_version() -> None:
    est = ivobs.make_estimator("interval-split", SYS, x0=X0)
    saved = est.state()
    old = {k: v for k, v in saved.items() if k not in ("format", "version")}  # before typed states
    with pytest.raises(IvobsError, match=r"state format version 1; this ivobs reads version 2"):
        ivobs.make_estimator("interval-split", SYS, x0=X0).restore(old)
    newer = {**saved, "version": 3}
    with pytest.raises(IvobsError, match=r"version 3"):
        ivobs.make_estimator("interval-split", SYS, x0=X0).restore(newer)
    members = ivobs.make_estimator("intersect", SYS, x0=X0)
    with pytest.raises(IvobsError, match=r"version 1"):
        members.restore({k: v for k, v in members.state().items() if k != "version"})
