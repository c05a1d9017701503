"""The papers' figures (``ivobs.figures``, ``ivobs figures``): files written, checks that can fail,
and the numbers behind [Tang2019, Fig. 5] (Theorem 8)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

import ivobs
from ivobs import figures
from ivobs.cli import main as cli_main
from ivobs.report.figures.common import check_contains
from ivobs.report.figures.tang2019 import in_planar_zonotope

PNG = b"\x89PNG\r\n\x1a\n"


def _assert_png(path, min_bytes=15_000):
    data = path.read_bytes()
    assert data[:8] == PNG
    assert len(data) > min_bytes, f"{path.name}: only {len(data)} bytes"


def test_generate_wang2020_writes_both_figures(tmp_path):
    paths = figures.generate(tmp_path / "out", papers=["Wang2020"])
    assert [p.name for p in paths] == ["wang2020_fig1.png", "wang2020_fig2.png"]
    for p in paths:
        _assert_png(p)


def test_cli_writes_figures_and_rejects_unknown_papers(tmp_path, capsys):
    assert cli_main(["figures", "--out", str(tmp_path), "--paper", "wang2020"]) == 0
    assert "2 figure(s)" in capsys.readouterr().out
    _assert_png(tmp_path / "wang2020_fig2.png")
    assert cli_main(["figures", "--out", str(tmp_path), "--paper", "Wang2020,Smith2007"]) == 2
    assert "Smith2007" in capsys.readouterr().err
    assert cli_main(["figures", "--out", str(tmp_path), "--paper", ","]) == 2


def test_every_paper_has_its_figures():
    stems = [s.stem for s in figures.figure_specs(figures.PAPERS)]
    assert [s.stem for s in figures.figure_specs()][:13] == stems  # then the scenarios'
    assert stems == [
        "wang2020_fig1",
        "wang2020_fig2",
        "tang2019_fig1",
        "tang2019_fig2",
        "tang2019_fig3",
        "tang2019_fig4",
        "tang2019_fig5",
        "efimov2013_fig1",
        "efimov2013_fig2",
        "dinh2024_fig1_ct",
        "dinh2024_fig1_dt",
        "dinh2024_fig4",
        "dinh2024_fig5",
    ]
    assert [s.stem for s in figures.figure_specs("EFIMOV2013")] == stems[7:9]


@pytest.mark.parametrize(
    "make",
    [
        lambda: figures.tang2019_fig2(horizon=30),
        lambda: figures.tang2019_fig4(horizon=15),
        lambda: figures.efimov2013_fig2(horizon=40),
        lambda: figures.dinh2024_fig4(t_final=2.0, dt=0.05),
        lambda: figures.dinh2024_fig5(horizon=12),
    ],
    ids=["tang2019-fig2", "tang2019-fig4", "efimov2013-fig2", "dinh2024-fig4", "dinh2024-fig5"],
)
def test_short_figures_render(tmp_path, make):
    fig = make()
    path = tmp_path / "f.png"
    fig.savefig(path, dpi=60)
    plt.close(fig)
    _assert_png(path, 8_000)


def test_tang2019_fig1_draws_the_theta_bands_on_their_own_scale():
    """θ grows to about 37 rad while its bands are 0.17-0.31 rad wide: on θ's axis they collapse
    onto one line. Fig. 1 adds the bounds minus the true θ, on an axis of the order of the
    widths, and a magnified inset of the paper's view."""
    fig = figures.tang2019_fig1()
    sc = ivobs.scenarios.get("servo-motor", horizon=100)
    traj = sc.simulate("paper")
    theta = traj.x[:, 0]
    (err,) = [ax for ax in fig.axes if ax.get_ylabel().startswith("bounds minus θ")]
    lo, hi = err.get_ylim()
    assert -0.35 < lo < -0.2 and 0.2 < hi < 0.35, (lo, hi)  # the widths' scale, not θ's
    assert theta.max() > 35  # (what the paper's axis has to span)
    # the plotted quantity: every method's bounds minus θ, upper >= 0 >= lower
    runs = {
        "Algorithm 1, $L_1$": ("reachability", sc.reference["L1"]),
        "zonotope (34), $L_1$": ("zonotope", sc.reference["L1"]),
        "Algorithm 1, $L_2$": ("reachability", sc.reference["L2"]),
        "interval observer (36), $L_2$": ("interval", sc.reference["L2"]),
    }
    lines = err.get_lines()
    for label, (method, L) in runs.items():
        paper = {"finite_memory": False} if method == "interval" else {}  # the paper's (36)
        res = ivobs.make_estimator(method, sc.system, x0=sc.x0, L=L, **paper).run(traj.u, traj.y)
        i = next(j for j, ln in enumerate(lines) if ln.get_label() == label)
        up, down = lines[i].get_ydata(), lines[i + 1].get_ydata()
        np.testing.assert_allclose(up, res.upper[:, 0] - theta, rtol=0, atol=1e-12)
        np.testing.assert_allclose(down, res.lower[:, 0] - theta, rtol=0, atol=1e-12)
        assert up.min() >= 0 >= down.max()
        width = float(np.mean(up[10:] - down[10:]))
        assert 0.15 < width < 0.35 and (hi - lo) < 4 * width, (label, width)
    # the paper's view stays, with a magnified window where the four bands separate
    (paper,) = [ax for ax in fig.axes if ax.get_ylabel() == "θ (rad)" and ax is not err]
    assert paper.get_ylim()[1] > 35
    (inset,) = paper.child_axes
    assert 1.0 < np.ptp(inset.get_ylim()) < 3.0 and np.ptp(inset.get_xlim()) < 5
    plt.close(fig)


def test_containment_check_raises_on_a_missed_state():
    sc = ivobs.scenarios.get("dinh2019", horizon=20)
    traj = sc.simulate("paper")
    res = ivobs.make_estimator("fixed-time", sc.system, s=2).run(traj.u, traj.y)
    check_contains("ok", res, traj.x)  # the real truth passes
    x = traj.x.copy()
    x[7, 1] = res.upper[7, 1] + 1e-6
    with pytest.raises(figures.FigureCheckError, match=r"first at \(7,\)"):
        check_contains("shifted", res, x)


def test_error_sets_of_tang2019_fig5():
    """Theorem 8 on Example 2 at k = 40: Box(Ω_k) ⊆ Box(P̃), samples in Ω_k, S of eq. (48)."""
    s = figures.error_sets(k=40, runs=200, seed=1)
    # S from the paper's R, e1, e2 by (48) reproduces its printed S
    ref = ivobs.scenarios.get("tang-example2").reference
    np.testing.assert_allclose(s.S, ref["S"], atol=5e-4)
    # Algorithm 1's box is the interval hull of the zonotope Ω_k (symmetric: d, x0 centred)
    hull = s.omega.interval_hull()
    np.testing.assert_allclose(s.box_reach.hi, hull.hi, atol=1e-9)
    np.testing.assert_allclose(s.box_reach.hi, [0.7421, 0.5461], atol=1e-4)
    np.testing.assert_allclose(s.box_transformed.hi, [2.3155, 1.4333], atol=1e-4)
    # Theorem 8 / (80): much wider, and P̃'s hull is the transformed box (79)
    assert np.all(s.box_transformed.hi > 2.5 * s.box_reach.hi)
    pts = s.parallelotope()
    np.testing.assert_allclose(pts.max(axis=0), s.box_transformed.hi, atol=1e-9)
    # the samples are inside Ω_k (and fill a good part of it)
    assert in_planar_zonotope(s.omega, s.samples).all()
    assert np.all(np.abs(s.samples).max(axis=0) > 0.4 * s.box_reach.hi)
    assert s.samples.shape == (200, 2)


def test_zonotope_polygon():
    # generators (1, 0), (0, 1), (1, 1): a hexagon
    Z = ivobs.Zonotope([1.0, -1.0], np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0]]))
    P = figures.zonotope_polygon(Z)
    assert P.shape == (6, 2)
    x, y = P[:, 0], P[:, 1]
    area = 0.5 * (x @ np.roll(y, -1) - y @ np.roll(x, -1))
    assert area == pytest.approx(12.0)  # 4 Σ_{i<j} |det(g_i, g_j)| = 4 * (1 + 1 + 1)
    box = Z.interval_hull()
    np.testing.assert_allclose(P.min(axis=0), box.lo)
    np.testing.assert_allclose(P.max(axis=0), box.hi)
    # random zonotope: every sample inside, every vertex on the boundary (a support point)
    rng = np.random.default_rng(3)
    Z = ivobs.Zonotope(rng.normal(size=2), rng.normal(size=(2, 7)))
    assert in_planar_zonotope(Z, Z.sample(500, rng)).all()
    P = figures.zonotope_polygon(Z)
    assert in_planar_zonotope(Z, P).all()
    assert not in_planar_zonotope(Z, Z.center + 1.01 * (P - Z.center)).any()
    with pytest.raises(ivobs.IvobsError, match="planar"):
        figures.zonotope_polygon(ivobs.Zonotope(np.zeros(3), np.eye(3)))


def test_unknown_paper_names_the_argument_and_the_keys(tmp_path, capsys):
    with pytest.raises(ivobs.IvobsError, match=r"^papers: expected some of Wang2020, Tang2019, "):
        figures.generate(tmp_path, papers=["Tang2019", "Tang2018"])
    assert not list(tmp_path.iterdir())  # nothing drawn before the check
    assert cli_main(["figures", "--out", str(tmp_path), "--paper", "dinh2024,Dinh"]) == 2
    err = capsys.readouterr().err
    assert "--paper" in err and "Efimov2013" in err and "'Dinh'" in err
