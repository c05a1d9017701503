"""The papers' examples: they build, simulate inside their bounds, carry the printed numbers."""

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError, scenarios

PAPERS = [
    "dinh2019",
    "servo-motor",
    "tang-example2",
    "efimov-planar",
    "henon",
    "kkl-random8",
    "pendulum",
    "kkl-ltv-dt",
]
CORA = ["cora-2dim", "cora-vehicle6", "cora-pedestrian4", "cora-slip4", "cora-tank30"]


def test_all_names_present():
    assert set(PAPERS + CORA) <= set(scenarios.names())
    with pytest.raises(IvobsError, match="unknown scenario 'nope'; known: dinh2019"):
        scenarios.get("nope")
    with pytest.raises(IvobsError, match="bad options"):
        scenarios.get("servo-motor", bogus=1)


@pytest.mark.parametrize("name", PAPERS + CORA)
@pytest.mark.parametrize("kind", ["paper", "vertex"])
def test_scenarios_simulate_within_their_bounds(name, kind):
    sc = scenarios.get(name)
    tr = sc.simulate(kind, seed=1)  # simulate() raises if d leaves the bounds
    assert tr.x.shape == (sc.horizon, sc.system.nx) and np.all(np.isfinite(tr.x))
    assert tr.y.shape == (sc.horizon, sc.system.ny)
    assert sc.x0.contains(sc.x_true0) and sc.source and sc.description


def test_paper_002_example_1_numbers():
    sc = scenarios.get("servo-motor")
    np.testing.assert_array_equal(
        sc.system.A, [[1, 0.1, 0], [0, 0.8495, 0.4977], [0, -0.0357, 0.9995]]
    )
    assert sc.system.d == ivobs.Box(
        -np.array([0.0225, 0.0225, 0.0404, 0.0564, 0.0564]),
        np.array([0.0225, 0.0225, 0.0404, 0.0564, 0.0564]),
    )
    assert sc.x0 == ivobs.Box.symmetric(0.2 * np.ones(3))
    assert sc.reference["L1"].shape == (3, 2) and sc.reference["L2"][1, 0] == -2.5012
    np.testing.assert_array_equal(sc.u, 2.0)


def test_paper_001_signals():
    sc = scenarios.get("dinh2019")
    d = sc.d
    np.testing.assert_allclose(d[5], [np.sin(5), np.sin(25.0)])
    np.testing.assert_array_equal(sc.system.E, [[1 / 9, 0], [1 / 9, 0]])
    np.testing.assert_array_equal(sc.system.F, [[0, 1 / 9]])


def test_henon_bounds_are_sound_for_every_measurement():
    sc = scenarios.get("henon")
    a_lo, a_hi = sc.reference["a"]
    V, delta = sc.reference["V"], sc.reference["delta"]
    rng = np.random.default_rng(0)
    x1 = np.concatenate([rng.uniform(-2, 2, 3000), rng.uniform(-0.1, 0.1, 3000), [0.0]])
    for x in x1:
        for a in (a_lo, a_hi, rng.uniform(a_lo, a_hi)):
            for v in (-V, V, rng.uniform(-V, V), -x if abs(x) <= V else 0.0):
                box = sc.system.d_at(0, np.array([x + v]))
                assert box.lo[1] == -V and box.hi[1] == V
                for dist in (-delta, delta):
                    b = 1 - a * x**2 + dist
                    assert box.lo[0] - 1e-12 <= b <= box.hi[0] + 1e-12
    # the paper's printed upper bound 1 - a(|y| - V)^2 + δ misses b when |y| < V:
    x, v, dist = 0.0, 0.05, delta
    y = x + v
    assert 1 - a_lo * 0**2 + dist > 1 - a_lo * (abs(y) - V) ** 2 + delta
    with pytest.raises(IvobsError, match="missing at step"):
        sc.system.d_at(0, np.array([np.nan]))


def test_henon_bounds_hold_the_exact_real_bounds():
    """No tolerance: the box holds the bounds computed in exact rational arithmetic from the
    same doubles (the measurement and the parameters), so rounding cannot make it miss."""
    from fractions import Fraction as Q

    sc = scenarios.get("henon")
    a_lo, a_hi = (Q(a) for a in sc.reference["a"])
    V, delta = Q(sc.reference["V"]), Q(sc.reference["delta"])
    rng = np.random.default_rng(1)
    ys = np.concatenate([rng.uniform(-2, 2, 400), rng.uniform(-0.2, 0.2, 400), [0.0, 0.1, -0.1]])
    for y in ys:
        box = sc.system.d_at(0, np.array([y]))
        sq_lo = max(Q(0), abs(Q(y)) - V) ** 2
        sq_hi = (abs(Q(y)) + V) ** 2
        assert Q(box.lo[0]) <= 1 - a_hi * sq_hi - delta
        assert Q(box.hi[0]) >= 1 - a_lo * sq_lo + delta
        # and outward by a few ulps only
        exact = (1 - a_lo * sq_lo + delta) - (1 - a_hi * sq_hi - delta)
        assert Q(box.hi[0] - box.lo[0]) <= exact + Q(1e-14) * (1 + abs(Q(box.lo[0])))


def test_henon_adversarial_runs_stay_bounded_and_use_vertices():
    sc = scenarios.get("henon", horizon=3000)
    tr = sc.simulate("vertex", seed=5)
    assert np.max(np.abs(tr.x)) < 2.0
    V = sc.reference["V"]
    assert set(np.round(np.abs(tr.d[:, 1]), 12)) == {V}


def test_tang_example2_and_efimov_notes_explain_choices():
    assert "F = 1" in scenarios.get("tang-example2").notes
    assert "not nonnegative" in scenarios.get("efimov-planar").notes


def test_continuous_and_time_varying_scenarios():
    p = scenarios.get("pendulum")
    assert p.system.is_continuous and p.system.is_time_varying and p.t.size == p.horizon
    k = scenarios.get("kkl-ltv-dt")
    np.testing.assert_allclose(
        k.system.A_at(1), [[1.2, -1 + 0.5 * np.cos(1)], [0, 0.5 + 0.2 * np.sin(1)]]
    )
    r8 = scenarios.get("kkl-random8")
    assert r8.system.is_observable() and (r8.system.nx, r8.system.ny) == (8, 6)
    r8c = scenarios.get("kkl-random8", continuous=True)
    assert r8c.system.is_continuous and r8c.system.is_stable()


def test_cora_records():
    veh = scenarios.get("cora-vehicle6")
    rec = veh.simulate("recorded")
    assert rec.x.shape == (350, 6) and veh.system.dt == 0.01
    # y[k] measures x[k] (CORA's convention): the residual lies in V = 0.1 * unit box
    res = rec.y - rec.x @ veh.system.C.T
    assert np.max(np.abs(res)) <= 0.1 + 1e-12
    two = scenarios.get("cora-2dim").simulate("recorded")
    assert np.isnan(two.x).all() and two.y.shape == (20, 1)


def test_cora_tank30_matches_its_description():
    sc = scenarios.get("cora-tank30")
    A, C = sc.system.A, sc.system.C
    assert A.shape == (30, 30) and C.shape == (21, 30) and sc.u.shape == (235, 15)
    assert np.allclose(np.triu(A, 1), 0) and np.allclose(np.tril(A, -2), 0)  # lower bidiagonal
    assert abs(np.linalg.eigvals(A)).max() == pytest.approx(0.997, abs=5e-4)
    unmeasured = np.flatnonzero(~np.abs(C).any(axis=0))
    assert unmeasured.tolist() == [0, 2, 5, 8, 11, 14, 17, 23, 29]
    assert sc.x0 == ivobs.Box.symmetric(4 * np.ones(30))
