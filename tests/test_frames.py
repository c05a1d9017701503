"""Estimates and records as pandas/xarray tables, logs from DataFrames, notebook output."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError
from ivobs.io import log_from_frame, read_log, write_log

pd = pytest.importorskip("pandas")


@pytest.fixture(scope="module")
def servo():
    sc = ivobs.scenarios.get("servo-motor")
    full = sc.simulate("vertex", seed=3)
    tr = ivobs.Trajectory(x=full.x[:40], y=full.y[:40], u=full.u[:40], d=full.d[:40], t=full.t[:40])
    est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0).run(tr.u, tr.y)
    return sc, tr, est


def test_tidy_frame_has_one_row_per_step_and_state(servo):
    _sc, tr, est = servo
    df = est.to_pandas(truth=tr, names=["theta", "omega", "current"])
    assert list(df.columns) == [
        "k", "state", "lower", "upper", "width", "truth", "contained", "missing", "inconsistent"
    ]  # fmt: skip
    assert len(df) == 40 * 3 and list(df["state"].cat.categories) == ["theta", "omega", "current"]
    row = df[(df.k == 17) & (df.state == "omega")].iloc[0]
    assert row.lower == est.lower[17, 1] and row.upper == est.upper[17, 1]
    assert row.truth == tr.x[17, 1] and row.width == pytest.approx(est.width[17, 1])
    assert df["contained"].all()
    assert df.attrs == {"method": "interval-split", "valid_from": 0}
    # pivot back to the arrays
    wide = df.pivot(index="k", columns="state", values="upper")[["theta", "omega", "current"]]
    np.testing.assert_array_equal(wide.to_numpy(), est.upper)


def test_frame_flags_a_miss_and_keeps_time_and_batches(servo):
    _sc, tr, est = servo
    x = tr.x.copy()
    x[5, 2] = est.upper[5, 2] + 1.0  # a true state outside the box must show up
    df = est.to_pandas(truth=x)
    assert df.loc[~df.contained, ["k", "state"]].values.tolist() == [[5, "x3"]]
    timed = ivobs.Estimate(est.lower, est.upper, method="m", t=0.1 * np.arange(40))
    assert timed.to_pandas()["t"].iloc[3 * 7] == pytest.approx(0.7)
    batch = ivobs.Estimate(np.stack([est.lower, est.lower - 1]), np.stack([est.upper] * 2))
    bdf = batch.to_pandas()
    assert len(bdf) == 2 * 40 * 3 and bdf["stream"].tolist()[120] == 1
    assert bdf["lower"].iloc[120] == est.lower[0, 0] - 1
    with pytest.raises(IvobsError, match="names: expected 3 state names"):
        est.to_pandas(names=["a"])
    with pytest.raises(IvobsError, match="truth: expected the true states"):
        est.to_pandas(truth=tr.x[:5])


def test_xarray_dataset(servo):
    pytest.importorskip("xarray")
    _sc, tr, est = servo
    ds = est.to_xarray(truth=tr)
    assert ds["lower"].dims == ("k", "state") and ds.sizes == {"k": 40, "state": 3}
    np.testing.assert_array_equal(ds["upper"].sel(state="x2").values, est.upper[:, 1])
    assert ds.attrs["method"] == "interval-split" and ds["missing"].dims == ("k",)
    assert bool((ds.lower <= ds.truth).all()) and bool((ds.truth <= ds.upper).all())


def test_trajectory_repr_and_frame(servo):
    _sc, tr, _ = servo
    assert repr(tr) == "Trajectory(T=40, nx=3, ny=2, nu=1, nd=5)"
    df = tr.to_pandas()
    assert df.index.name == "k" and list(df.columns[:4]) == ["t", "x1", "x2", "x3"]
    np.testing.assert_array_equal(df["y2"].to_numpy(), tr.y[:, 1])


def test_log_from_frame_matches_the_csv_reader(servo, tmp_path):
    sc, tr, _ = servo
    y = tr.y.copy()
    y[4, 1] = np.nan  # a missing sample
    write_log(tmp_path / "log.csv", tr.u, y)
    from_file = read_log(tmp_path / "log.csv", sc.system)
    frame = pd.read_csv(tmp_path / "log.csv")
    from_frame = log_from_frame(frame, sc.system)
    np.testing.assert_array_equal(from_frame.y, from_file.y)
    np.testing.assert_array_equal(from_frame.u, from_file.u)
    np.testing.assert_array_equal(from_frame.steps, from_file.steps)
    indexed = log_from_frame(frame.set_index("k"), sc.system)  # a step index is kept
    np.testing.assert_array_equal(indexed.steps, np.arange(40))
    with pytest.raises(IvobsError, match="the log needs 2 y-columns"):
        log_from_frame(frame.drop(columns=["y2"]), sc.system)
    with pytest.raises(IvobsError, match="expected numbers"):
        log_from_frame(frame.assign(y1="high"), sc.system)
    with pytest.raises(IvobsError, match="expected a pandas DataFrame"):
        log_from_frame(tr.y, sc.system)


def test_notebook_html(servo):
    _, _, est = servo
    page = est._repr_html_()
    assert "interval-split" in page and "<table>" in page and "data:image/png;base64," in page
    mean = est.mean_width()
    assert f"{mean[0]:.4g}" in page


# -- python-control -------------------------------------------------------------------------
def _plant():
    control = pytest.importorskip("control")
    return control.ss(
        [[0.9, 0.1], [0.0, 0.8]], [[0.0, 1.0], [1.0, 0.0]], [[1.0, 0.0]], [[0.0, 0.0]],
        dt=0.1, inputs=["torque", "gust"], states=["pos", "vel"], outputs=["meas"],
    )  # fmt: skip


def test_statespace_inputs_split_into_u_and_d_with_names():
    ss = _plant()
    sys = ivobs.LinearSystem.from_statespace(ss, disturbances=["gust"], d=ivobs.Box([-0.1], [0.1]))
    assert (sys.nu, sys.nd, sys.dt) == (1, 1, 0.1)
    np.testing.assert_array_equal(sys.B, [[0.0], [1.0]])
    np.testing.assert_array_equal(sys.E, [[1.0], [0.0]])
    assert sys.names.states == ("pos", "vel") and sys.names.inputs == ("torque",)
    assert sys.names.disturbances == ("gust",) and sys.names.outputs == ("meas",)
    same = ivobs.LinearSystem.from_statespace(ss, disturbances=[1], d=ivobs.Box([-0.1], [0.1]))
    assert ivobs.equal_systems(sys, same)
    with pytest.raises(IvobsError, match="no input named 'wind'"):
        ivobs.LinearSystem.from_statespace(ss, disturbances=["wind"], d=ivobs.Box([0], [1]))
    with pytest.raises(IvobsError, match="d: expected a Box of 1 components"):
        ivobs.LinearSystem.from_statespace(ss, disturbances=["gust"])


def test_statespace_where_a_system_is_expected():
    ss = _plant()
    with pytest.raises(IvobsError, match="A: got a control.StateSpace; use .*from_statespace"):
        ivobs.LinearSystem(ss)
    est = ivobs.make_estimator("exact", ss, x0=ivobs.Box([-1, -1], [1, 1]), progress=False)
    assert est.sys.nu == 2 and est.sys.names.states == ("pos", "vel")


def test_plot_takes_a_trajectory_and_read_log_a_system_file(servo, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    sc, tr, est = servo
    fig = est.plot(truth=tr)  # a Trajectory as the truth, as to_pandas takes it
    assert len(fig.axes) == 3
    ivobs.save_system(tmp_path / "s.toml", sc)
    write_log(tmp_path / "log.csv", tr.u, tr.y)
    spec = ivobs.load_system(tmp_path / "s.toml")
    np.testing.assert_array_equal(read_log(tmp_path / "log.csv", spec).y, tr.y)
    with pytest.raises(IvobsError, match="system: expected an ivobs system"):
        read_log(tmp_path / "log.csv", "servo")


def test_notebook_html_of_systems_and_sets():
    sc = ivobs.scenarios.get("servo-motor")
    page = sc.system._repr_html_()
    assert "3 / 1 / 2 / 5" in page and "[-0.0225, -0.0225, -0.0404" in page
    box = sc.x0._repr_html_()
    assert "<th style='text-align:left'>width</th><td>[0.4, 0.4, 0.4]</td>" in box
    nl = ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "0.3*x1"], h=["x1 + v1"], states=["x1", "x2"],
        params={"a": (1.39, 1.41)}, d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )  # fmt: skip
    page = nl._repr_html_()
    assert "x1⁺ =" in page and "a, w1, v1" in page and "&lt;" not in page
