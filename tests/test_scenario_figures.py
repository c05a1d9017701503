"""The scenarios' figures (``ivobs figures --scenario``): one panel per state, the true state and
each capable method's bounds exactly as the estimators return them; the Hénon map's two models
on one record (Remark 1 against the nonlinear model)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

import ivobs
from ivobs import figures
from ivobs.cli import main as cli_main
from ivobs.estimators import methods
from ivobs.report.figures import henon as hn
from ivobs.report.figures.scenario_figures import (
    SCENARIO_FIGURES,
    capable_methods,
    draw_scenario,
    scenario_runs,
)
from ivobs.scenarios.efimov2013 import henon_remark1_system

NL = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope", "nl-horizon"]
UNCERTAIN = ["reachability", "zonotope", "interval", "interval-transformed", "interval-split",
             "strip", "constrained-zonotope"]  # fmt: skip
SHORT = 25  # steps: enough for every method's transient, short for the test


def _lines_match(ax, runs, x, i, shift=0.0):
    """The axis holds, per method, its upper then lower bound of state i, then the truth."""
    lines = ax.get_lines()
    assert len(lines) == 2 * len(runs) + 1
    for m, res in enumerate(runs.values()):
        np.testing.assert_array_equal(lines[2 * m].get_ydata(), res.upper[:, i] - shift)
        np.testing.assert_array_equal(lines[2 * m + 1].get_ydata(), res.lower[:, i] - shift)
    np.testing.assert_array_equal(lines[-1].get_ydata(), x[:, i] - shift)


def test_capable_methods():
    assert capable_methods(ivobs.scenarios.get("cstr").system) == NL
    assert capable_methods(ivobs.scenarios.get("servo-uncertain").system) == UNCERTAIN
    exact = capable_methods(ivobs.scenarios.get("servo-motor").system)
    assert exact == [m for m in methods() if m != "intersect"]


@pytest.mark.parametrize("name", list(SCENARIO_FIGURES))
def test_scenario_figure_draws_every_state_and_method(name, tmp_path):
    sc, traj, runs = scenario_runs(name, horizon=min(SHORT, SCENARIO_FIGURES[name]))
    fig = draw_scenario(sc, traj, runs)
    nx = sc.system.nx
    assert list(runs) == (UNCERTAIN if name == "servo-uncertain" else NL)
    # the runs are the estimators' own output on the scenario's record
    m = next(iter(runs))
    fresh = ivobs.make_estimator(m, sc.system, x0=sc.x0).run(traj.u, traj.y)
    np.testing.assert_array_equal(fresh.lower, runs[m].lower)
    np.testing.assert_array_equal(fresh.upper, runs[m].upper)
    assert np.array_equal(traj.x, sc.simulate("paper", 0).x)
    axes = [ax for ax in fig.axes if ax.get_visible()]
    assert len(axes) == nx  # one panel per state (chain10-nl: a 5 x 2 grid)
    for i, ax in enumerate(axes):
        _lines_match(ax, runs, traj.x, i)
    # one legend for the figure: every method and the truth
    (legend,) = fig.legends
    assert [t.get_text() for t in legend.get_texts()] == [*runs, "true state"]
    fig.savefig(tmp_path / "f.png", dpi=50)
    plt.close(fig)
    data = (tmp_path / "f.png").read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 8_000


def test_generate_writes_the_selected_scenario_figures(tmp_path):
    paths = figures.generate(tmp_path, scenarios="CORA-tank6-nl,henon")
    assert [p.name for p in paths] == ["scenario_cora_tank6_nl.png", "henon_remark1_vs_nl.png"]
    for p in paths:
        data = p.read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000


def test_figure_selection_and_cli_list(tmp_path, capsys):
    every = figures.figure_specs()
    assert len(every) == 13 + len(SCENARIO_FIGURES) + 1
    assert [s.stem for s in figures.figure_specs(scenarios=["chain10-nl"])] == [
        "scenario_chain10_nl"
    ]
    both = figures.figure_specs("wang2020", scenarios="servo-uncertain")
    assert [s.stem for s in both] == ["wang2020_fig1", "wang2020_fig2", "scenario_servo_uncertain"]
    assert cli_main(["figures", "--list", "--scenario", "pendulum-nl,HENON"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out == ["scenario_pendulum_nl.png  (scenario pendulum-nl)",
                   "henon_remark1_vs_nl.png  (scenario henon)"]  # fmt: skip
    assert cli_main(["figures", "--out", str(tmp_path), "--scenario", "cstr,tank"]) == 2
    err = capsys.readouterr().err
    assert "--scenario" in err and "'tank'" in err and "unicycle-range" in err
    assert not list(tmp_path.iterdir())  # nothing drawn before the check
    assert cli_main(["figures", "--scenario", "cstr"]) == 2
    assert "--out" in capsys.readouterr().err


def test_henon_models_share_the_numbers_and_the_record():
    pair = hn.henon_pair("henon-nl", 40)
    nl = pair.nonlinear
    assert nl.param_names == ["a"] and nl.signal_names == ["w1", "v1"]
    np.testing.assert_allclose(nl.w_box.lo, [1.39, -0.005, -0.02])
    np.testing.assert_allclose(nl.w_box.hi, [1.41, 0.005, 0.02])
    sc = ivobs.scenarios.get("henon-nl", horizon=40)
    assert pair.x0 == sc.x0
    np.testing.assert_array_equal(pair.traj.y, sc.simulate("paper", 0).y)
    # the record is a trajectory of the Remark-1 model: b = x1+ - x2 within the bounds from y
    x, y = pair.traj.x, pair.traj.y
    for k in range(39):
        box = pair.remark1.d_at(k, y[k])
        b = x[k + 1, 0] - x[k, 1]
        assert box.lo[0] <= b <= box.hi[0]
    # the default Remark-1 system is the henon scenario's
    ref = ivobs.scenarios.get("henon").system
    for yk in (-1.2, 0.05, 0.9):
        assert henon_remark1_system().d_at(3, [yk]) == ref.d_at(3, [yk])


def test_henon_nonlinear_model_is_tighter_than_remark1():
    """On the same record the nonlinear methods beat every Remark-1 method on x2, even the LP
    hull of the Remark-1 model (exact), which is the tightest that model allows."""
    pair = hn.henon_pair("henon-nl", 120)
    widths = {m: hn.henon_run(pair, m).mean_width(12) for m in
              ("interval (3)", "exact", *hn.NL_METHODS)}  # fmt: skip
    for m in hn.NL_METHODS:
        assert widths[m][1] < 0.85 * widths["exact"][1], (m, widths[m], widths["exact"])
        assert widths[m][0] <= widths["exact"][0] + 1e-3
        assert np.all(widths[m] < 0.4 * widths["interval (3)"])
    # x1 is measured: no method beats the strip of width 2 |v| = 0.04 by much on average
    assert all(w[0] > 0.02 for w in widths.values())


def test_henon_compare_figure_plots_the_runs():
    fig = hn.henon_compare_fig("henon-nl", horizon=30)
    pair = hn.henon_pair("henon-nl", 30)
    runs = {m: hn.henon_run(pair, m) for m in ("interval (3)", *hn.NL_METHODS)}
    left = [ax for ax in fig.axes if ax.get_subplotspec().colspan.start == 0]
    right = [ax for ax in fig.axes if ax.get_subplotspec().colspan.start == 1]
    for i in range(2):
        _lines_match(left[i], runs, pair.traj.x, i)
        _lines_match(right[i], runs, pair.traj.x, i, shift=pair.traj.x[:, i])
    (legend,) = fig.legends
    assert legend.get_texts()[0].get_text() == "Remark 1: interval observer (3)"
    plt.close(fig)
    with pytest.raises(ivobs.IvobsError, match="setting: expected one of henon-nl, henon"):
        hn.henon_pair("henon-remark1")
