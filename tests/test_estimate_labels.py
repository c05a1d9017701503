"""Names, units and sample times flow from the model into every Estimate (API, pandas, xarray,
CSV, plots), and a sampled system's record times are checked against its period."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem, NonlinearSystem, make_estimator
from ivobs.model.statespace import SignalNames


def _sampled(dt: float | bool = 0.01) -> LinearSystem:
    sys = LinearSystem(
        [[1.0, 0.01], [0.0, 0.99]],
        [[0.0], [0.01]],
        [[1.0, 0.0]],
        E=[[0.0, 0.0], [0.01, 0.0]],
        F=[[0.0, 1.0]],
        d=Box([-1.0, -0.01], [1.0, 0.01]),
        dt=dt,
    )
    sys.names = SignalNames(states=("angle", "rate"), units=("rad", "rad/s"))
    return sys


def _record(T: int = 30) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((T, 1)), np.zeros((T, 1))


def test_names_units_and_times_of_a_sampled_system():
    sys = _sampled()
    u, y = _record()
    est = make_estimator("strip", sys, x0=Box([-0.1, -1.0], [0.1, 1.0])).run(u, y)
    assert est.names == ("angle", "rate") and est.units == ("rad", "rad/s")
    assert est.state_labels == ["angle (rad)", "rate (rad/s)"]
    np.testing.assert_allclose(est.t, np.arange(30) * 0.01)
    fig = est.plot()
    assert [ax.get_ylabel() for ax in fig.axes] == ["angle (rad)", "rate (rad/s)"]
    assert fig.axes[-1].get_xlabel() == "t"


def test_labels_reach_pandas_xarray_and_csv(tmp_path):
    pytest.importorskip("pandas")
    pytest.importorskip("xarray")
    sys = _sampled()
    u, y = _record()
    est = make_estimator("interval-split", sys, x0=Box([-0.1, -1.0], [0.1, 1.0])).run(u, y)
    frame = est.to_pandas()
    assert list(frame["state"].cat.categories) == ["angle", "rate"]
    assert frame.attrs["units"] == {"angle": "rad", "rate": "rad/s"}
    np.testing.assert_allclose(frame["t"].unique(), np.arange(30) * 0.01)
    ds = est.to_xarray()
    assert list(ds["state"].values) == ["angle", "rate"]
    est.to_csv(tmp_path / "e.csv")
    back = ivobs.Estimate.from_csv(tmp_path / "e.csv")
    assert back.names == est.names and back.units == est.units
    np.testing.assert_allclose(back.t, est.t)
    assert "angle (rad)" in est._repr_html_()


def test_record_times_must_step_by_the_period():
    sys = _sampled()
    u, y = _record(10)
    est = make_estimator("strip", sys, x0=Box([-0.1, -1.0], [0.1, 1.0]))
    shifted = est.run(u, y, t=100.0 + np.arange(10) * 0.01)
    np.testing.assert_allclose(shifted.t, 100.0 + np.arange(10) * 0.01)
    gap = np.r_[np.arange(4), np.arange(5, 11)] * 0.01  # a dropped row between 0.03 and 0.05
    with pytest.raises(IvobsError, match=r"t\[3\] = 0.03 and t\[4\] = 0.05 .* dropped sample"):
        est.run(u, y, t=gap)
    with pytest.raises(IvobsError, match="10 finite, strictly increasing"):
        est.run(u, y, t=np.arange(9) * 0.01)


def test_unnamed_and_unit_period_systems_keep_step_counts():
    sys = _sampled(dt=True)
    sys.names = SignalNames()
    u, y = _record(5)
    est = make_estimator("strip", sys, x0=Box([-0.1, -1.0], [0.1, 1.0])).run(u, y)
    assert est.names is None and est.t is None
    assert est.state_labels == ["x1", "x2"]
    labelled = make_estimator("strip", sys, x0=Box([-0.1, -1.0], [0.1, 1.0])).run(
        u, y, t=[0.0, 0.5, 2.0, 2.1, 3.0]
    )  # dt=True: any increasing times label the steps
    np.testing.assert_allclose(labelled.t, [0.0, 0.5, 2.0, 2.1, 3.0])


def test_nonlinear_estimates_carry_the_state_names():
    sys = NonlinearSystem(
        f=["pos + 0.1*speed", "0.9*speed + 0.1*sin(pos) + w"],
        h=["pos + v"],
        states=["pos", "speed"],
        d={"w": (-0.01, 0.01), "v": (-0.05, 0.05)},
        dt=0.1,
    )
    u, y = np.zeros((8, 0)), np.zeros((8, 1))
    est = make_estimator("nl-interval", sys, x0=Box([-1.0, -1.0], [1.0, 1.0])).run(u, y)
    assert est.names == ("pos", "speed")
    np.testing.assert_allclose(est.t, np.arange(8) * 0.1)


def test_an_estimate_refuses_labels_of_the_wrong_length():
    with pytest.raises(IvobsError, match="names: expected 2 entries"):
        ivobs.Estimate(np.zeros((3, 2)), np.ones((3, 2)), names=("a",))
