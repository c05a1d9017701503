"""Bad input to the public API: each error is an IvobsError naming the argument that is wrong,
what was expected and what came (not a NumPy traceback, a NaN box or the wrong culprit)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

import ivobs
from ivobs import Box, DesignError, IvobsError, LinearSystem


def _servo() -> tuple[ivobs.scenarios.Scenario, ivobs.Trajectory]:
    sc = ivobs.scenarios.get("servo-motor")
    return sc, sc.simulate()


# -- 1. run(u, y) with records of different lengths ----------------------------------------
def test_run_with_records_of_different_lengths_names_both():
    sc, tr = _servo()
    est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0)
    with pytest.raises(
        IvobsError,
        match=r"u and y: expected the same number of samples.*"
        r"got u: 50, y: 40",
    ):
        est.run(tr.u[:50], tr.y[:40])
    with pytest.raises(IvobsError, match=r"u and y: .* got u: 40, y: 50"):
        est.run(tr.u[:40], tr.y[:50])
    assert est.run(tr.u[:40], tr.y[:40]).lower.shape == (40, 3)


# -- 2. from_process_measurement: w and v ---------------------------------------------------
_A, _B, _C = np.eye(3) * 0.5, np.zeros((3, 1)), np.eye(2, 3)


def _pm(w: object, v: object) -> LinearSystem:
    return LinearSystem.from_process_measurement(_A, _B, _C, E=np.eye(3), F=np.eye(2), w=w, v=v)


@pytest.mark.parametrize(
    ("w", "v", "pattern"),
    [
        ([0.1, 0.1], [0.1, 0.1], r"^w: expected a vector of 3 .*columns? of E.* got shape \(2,\)"),
        (0.1, [0.1, 0.1], r"^w: expected a vector of 3 .* got a scalar"),
        ([0.1] * 3, [0.1] * 3, r"^v: expected a vector of 2 .*column of F.* got shape \(3,\)"),
        ([np.nan, 0.1, 0.1], [0.1, 0.1], r"^w: expected finite numbers"),
        ([0.1] * 3, [0.1, np.nan], r"^v: expected finite numbers"),
        ([0.1] * 3, [0.1, np.inf], r"^v: expected finite numbers"),
        ([0.1, -0.1, 0.1], [0.1, 0.1], r"^w: expected nonnegative bounds"),
        (
            Box.symmetric([0.1, 0.1]),
            [0.1, 0.1],
            r"^w: expected a Box of dimension 3 .*got "
            r"dimension 2",
        ),
    ],
)
def test_process_measurement_bounds_name_w_or_v(w, v, pattern):
    with pytest.raises(IvobsError, match=pattern):
        _pm(w, v)


def test_process_measurement_accepts_vectors_and_boxes():
    sys = _pm([0.1, 0.2, 0.3], Box([-0.1, -0.2], [0.1, 0.2]))
    assert sys.nd == 5
    np.testing.assert_array_equal(sys.d.hi, [0.1, 0.2, 0.3, 0.1, 0.2])
    np.testing.assert_array_equal(
        _pm(np.array([[0.1, 0.2, 0.3]]), [0.1, 0.1]).d.lo[:3], [-0.1, -0.2, -0.3]
    )


# -- 3. the shape the user passed; nx >= 1 ----------------------------------------------------
def test_a_reports_the_shape_passed_and_needs_a_state():
    with pytest.raises(IvobsError, match=r"^A: expected a square matrix .* got shape \(3,\)$"):
        LinearSystem(A=np.ones(3), C=[[1.0]])
    with pytest.raises(
        IvobsError,
        match=r"^A: expected a square matrix with at least one row, "
        r"got shape \(0, 0\)$",
    ):
        LinearSystem(A=np.zeros((0, 0)), C=np.zeros((1, 0)))
    # other matrices: the shape passed, and how a 1-D array was read
    with pytest.raises(
        IvobsError,
        match=r"^C: expected shape \(any, 2\), got \(3,\) \(read as "
        r"a row \(1, 3\)\)$",
    ):
        LinearSystem(np.eye(2), C=np.ones(3))


# -- 4. an unobservable pair is a design impossibility for every method ------------------------
def _unobservable() -> LinearSystem:
    return LinearSystem(
        [[0.5, 0], [0, 0.7]],
        None,
        [[1.0, 0.0]],
        E=np.eye(2),
        F=np.zeros((1, 2)),
        d=Box.symmetric([1, 1]),
    )


@pytest.mark.parametrize(
    ("method", "opts"),
    [("fixed-time", {}), ("kkl", {}), ("interval-transformed", {"transform": "search"})],
)
def test_unobservable_pair_is_a_design_error(method, opts):
    with pytest.raises(DesignError, match="not observable"):
        ivobs.make_estimator(method, _unobservable(), x0=Box([-1, -1], [1, 1]), **opts)


def test_detectable_pair_gets_an_interval_transformed_design_with_s_identity():
    """Eq. (48) needs (A − LC, e1) observable; the default design then falls back to S = I,
    since L = (0.5, 0) makes A − LC = diag(0, 0.7) nonnegative and Schur (the unobservable
    mode 0.7 stays: the steady-state width of x2 is 2 / (1 − 0.7))."""
    est = ivobs.make_estimator("interval-transformed", _unobservable(), x0=Box([-1, -1], [1, 1]))
    assert est.design.gain == "identity"
    assert est.design.spectral_radius == pytest.approx(0.7)
    assert est.design.steady_width[1] == pytest.approx(2.0 / 0.3)


# -- 5. restore of a corrupted state ------------------------------------------------------------
def _stepped(method: str, steps: int = 4) -> ivobs.Estimator:
    sc, tr = _servo()
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    for k in range(steps):
        est.step(tr.u[k], tr.y[k])
    return est


def _with(saved: dict, key: str, value: object) -> dict:
    out = json.loads(json.dumps(saved))
    out["state"][key] = value
    return out


def _arr(a: object) -> dict:
    a = np.asarray(a, dtype=float)
    return {"array": a.tolist(), "shape": list(a.shape)}


def test_restore_rejects_a_state_that_is_not_a_dict():
    est = _stepped("interval-split")
    with pytest.raises(IvobsError, match=r"^state: expected entry 'state' .*got str"):
        est.restore({**est.state(), "state": "junk"})


@pytest.mark.parametrize(
    ("key", "value", "pattern"),
    [
        (
            "lo",
            _arr([0.0, 0.0]),
            r"state: entry 'lo': expected an array of shape \(3,\), got "
            r"\(2,\)",
        ),
        ("lo", _arr([np.nan, 0.0, 0.0]), r"state: entry 'lo': expected finite numbers, got nan"),
        ("lo", _arr([5.0, 5.0, 5.0]), r"state: entries 'lo' and 'hi': expected lower <= upper"),
        ("hi", 3.0, r"state: entry 'hi': expected a saved array, got float"),
        ("k", -2, r"state: entry 'k': expected the step count \(an integer >= 0\), got -2"),
        ("k", "3", r"state: entry 'k': expected the step count"),
    ],
)
def test_restore_names_the_corrupted_entry(key, value, pattern):
    est = _stepped("interval-split")
    other = ivobs.make_estimator("interval-split", est.sys, x0=est.x0)
    with pytest.raises(IvobsError, match=pattern):
        other.restore(_with(est.state(), key, value))


@pytest.mark.parametrize(
    "method", ["zonotope", "reachability", "fixed-time", "kkl", "strip", "constrained-zonotope"]
)
def test_restore_checks_arrays_of_every_method(method):
    est = _stepped(method)
    saved = json.loads(json.dumps(est.state()))
    arrays = [k for k, v in saved["state"].items() if isinstance(v, dict)]
    other = ivobs.make_estimator(method, est.sys, x0=est.x0)
    other.restore(saved)  # the genuine state restores
    for key in arrays:
        a = np.array(saved["state"][key]["array"], dtype=float).reshape(
            saved["state"][key]["shape"]
        )
        with pytest.raises(IvobsError, match=rf"state: entry '{key}': expected an array of shape"):
            other.restore(_with(saved, key, _arr(a[..., None])))  # one axis too many
        if a.size:
            bad = a.copy()
            bad.flat[0] = np.nan
            with pytest.raises(IvobsError, match=rf"state: entry '{key}': expected finite"):
                other.restore(_with(saved, key, _arr(bad)))
    with pytest.raises(IvobsError, match="state: entry 'k'"):
        other.restore(_with(saved, "k", None))


def test_restore_of_a_scalar_entry_checks_its_type():
    est = _stepped("fixed-time")
    with pytest.raises(IvobsError, match=r"state: entry 'has_box': expected True or False"):
        est.restore(_with(est.state(), "has_box", "yes"))
    est = _stepped("reachability")
    with pytest.raises(IvobsError, match=r"state: entry 'mode': expected an integer"):
        est.restore(_with(est.state(), "mode", "junk"))


# -- 6. kkl on a stack of matrices shorter than the record ---------------------------------------
def test_kkl_reports_a_stack_shorter_than_the_record():
    A = np.stack([np.array([[0.9, 0.1], [0.0, 0.8]])] * 2)
    sys = LinearSystem(
        A, None, [[1.0, 0.0]], E=0.1 * np.eye(2), F=np.zeros((1, 2)), d=Box.symmetric([1.0, 1.0])
    )
    y = np.zeros((5, 1))
    for method in ("kkl", "exact"):
        with pytest.raises(IvobsError, match=r"^A: step 2 is beyond the 2 stacked matrices"):
            ivobs.make_estimator(method, sys, x0=Box([-1, -1], [1, 1])).run(None, y)
    # too short for T[k] to become left-invertible: the design says so (not the model's index)
    with pytest.raises(DesignError, match=r"never becomes valid in the horizon given"):
        ivobs.make_estimator(
            "kkl", LinearSystem(A[:1], None, [[1.0, 0.0]]), x0=Box([-1, -1], [1, 1])
        )


# -- 7. bounds that overflow the float range -------------------------------------------------------
@pytest.mark.parametrize("method", ["reachability", "fixed-time", "zonotope"])
def test_overflowing_bounds_are_explained_not_called_a_bug(method):
    sys = LinearSystem(
        [[1.8, 0.3], [0.0, 1.5]],
        None,
        [[1.0, 0.0]],
        E=0.1 * np.eye(2),
        F=np.zeros((1, 2)),
        d=Box.symmetric([1.0, 1.0]),
    )
    y = np.full((1300, 1), np.nan)
    est = ivobs.make_estimator(method, sys, x0=Box([-1, -1], [1, 1]))
    pattern = r"the bounds overflowed \(exceed 1\.8e308\) at step \d+: the system is unstable"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        with pytest.raises(IvobsError, match=pattern) as run_err:
            est.run(None, y)
        assert "a bug" not in str(run_err.value)
        est.reset()
        with pytest.raises(IvobsError, match=pattern):
            for _ in range(1300):
                est.step(None, None)


# -- 8. seeds -----------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [-1, "a", 1.5, True])
def test_bad_seed_names_seed(seed):
    sc = ivobs.scenarios.get("servo-motor")
    with pytest.raises(IvobsError, match=r"^seed: expected None, an integer >= 0"):
        ivobs.vertex_disturbance(sc.system.d, 5, seed=seed)
    with pytest.raises(IvobsError, match=r"^seed: "):
        ivobs.uniform_disturbance(sc.system.d, 5, seed=seed)
    with pytest.raises(IvobsError, match=r"^seed: "):
        sc.simulate("uniform", seed)
    with pytest.raises(IvobsError, match=r"^seed: "):  # its own disturbance generator
        ivobs.scenarios.get("henon").simulate("uniform", seed)


def test_good_seeds_are_accepted():
    d = ivobs.scenarios.get("servo-motor").system.d
    a = ivobs.vertex_disturbance(d, 6, seed=np.int64(3))
    np.testing.assert_array_equal(a, ivobs.vertex_disturbance(d, 6, seed=3))
    np.testing.assert_array_equal(a, ivobs.vertex_disturbance(d, 6, seed=np.random.default_rng(3)))
    assert ivobs.uniform_disturbance(d, 6, seed=None).shape == (6, d.dim)
