"""Designs that scale: the width-optimal LP of ``interval`` / ``interval-split``
(:mod:`ivobs.design.width_lp`), ``interval-transformed`` beyond the eq. (48) search (``S = I`` or
Schur coordinates, :mod:`ivobs.design.schur_transform`), and the fixed-time window on 30-state
plants. Containment is checked at every step against a simulator written here, with
disturbances on the vertices of their bounds."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import Box, DesignError, LinearSystem
from ivobs.design import width_lp
from ivobs.estimators.fixed_time.design import rank_advice
from ivobs.linalg import observability_index
from ivobs.testing import random_system


def plant(n, seed, kind, rho=1.02, ny=None):
    """The generator of ``benchmarks/bench_design_scale.py``: ``gaussian`` (dense normal ``A``,
    ``C``) or ``positive`` (sparse nonnegative ``A`` with a positive diagonal, point sensors),
    ``A`` scaled to spectral radius ``rho``; process noise ``0.1·I``, sensor noise ``0.05·I``."""
    rng = np.random.default_rng(seed)
    ny = ny or max(2, n // 10)
    if kind == "gaussian":
        A = rng.normal(size=(n, n))
        C = rng.normal(size=(ny, n))
    else:
        A = rng.uniform(0, 1, (n, n)) * (rng.random((n, n)) < min(1.0, 4.0 / n))
        A += np.diag(rng.uniform(0.2, 1.0, n))
        C = np.zeros((ny, n))
        C[np.arange(ny), rng.choice(n, ny, replace=False)] = 1.0
    A *= rho / np.max(np.abs(np.linalg.eigvals(A)))
    E = np.hstack([0.1 * np.eye(n), np.zeros((n, ny))])
    F = np.hstack([np.zeros((ny, n)), 0.05 * np.eye(ny)])
    d = Box(-np.ones(n + ny), np.ones(n + ny))
    return LinearSystem(A, rng.normal(size=(n, 1)), C, E=E, F=F, d=d)


def vertex_run(sys, x0, T, seed):
    """Simulate here (not ivobs.simulate): a vertex of ``x0``, disturbances on vertices."""
    rng = np.random.default_rng(seed)
    A, B, C, D, E, F = sys.matrices_at(0)
    lo, hi = sys.d.lo, sys.d.hi
    x = np.where(rng.random(sys.nx) < 0.5, x0.lo, x0.hi)
    u = rng.normal(size=(T, sys.nu))
    X, Y = np.empty((T, sys.nx)), np.empty((T, sys.ny))
    for k in range(T):
        d = np.where(rng.random(sys.nd) < 0.5, lo, hi)
        X[k], Y[k] = x, C @ x + D @ u[k] + F @ d
        x = A @ x + B @ u[k] + E @ d
    return u, Y, X


def assert_contained(est, sys, x0, T=300, seed=0):
    u, y, x = vertex_run(sys, x0, T, seed)
    res = est.run(u, y)
    ok = (res.lower <= x) & (x <= res.upper)
    assert ok[res.valid_from :].all(), np.argwhere(~ok)[:3]
    assert np.all(np.isfinite(res.width[res.valid_from :]))
    return res


@pytest.mark.parametrize(("n", "seed"), [(10, 0), (20, 1), (50, 2)])
@pytest.mark.parametrize("method", ["interval", "interval-split", "interval-transformed"])
def test_positive_plants_design_and_contain_the_truth(method, n, seed):
    sys = plant(n, seed, "positive")
    x0 = Box.symmetric(np.ones(n))
    # the observer's own boxes (they settle at the design's width; the finite-memory bound
    # would cut some of them below it)
    est = ivobs.make_estimator(method, sys, x0=x0, finite_memory=False)
    assert est.design.spectral_radius < 1.0
    if method != "interval-transformed":
        assert est.design.gain == "width"
        D = sys.A_at(0) - est.design.L @ sys.C_at(0)
        if method == "interval":
            assert D.min() >= -1e-9
    else:
        assert est.design.gain == "identity"  # A − LC >= 0 is possible: S = I
    res = assert_contained(est, sys, x0)
    # the bounds settle at the design's steady-state width (constant bounds)
    np.testing.assert_allclose(res.width[-1], est.design.steady_width, rtol=1e-3, atol=1e-9)


@pytest.mark.parametrize(("n", "seed"), [(10, 3), (30, 4), (50, 5)])
def test_gaussian_plants_transformed_in_schur_coordinates(n, seed):
    """No gain makes |A − LC| Schur (so none makes A − LC >= 0): interval and interval-split
    say so, proved; interval-transformed designs in Schur/modal coordinates and is sound."""
    sys = plant(n, seed, "gaussian")
    x0 = Box.symmetric(np.ones(n))
    with pytest.raises(DesignError, match=r"no gain L makes A − LC nonnegative.*proved"):
        ivobs.make_estimator("interval", sys, x0=x0)
    with pytest.raises(DesignError, match=r"no gain L makes \|A − LC\| Schur.*proved"):
        ivobs.make_estimator("interval-split", sys, x0=x0)
    est = ivobs.make_estimator("interval-transformed", sys, x0=x0)
    d = est.design
    assert d.gain == "schur" and d.spectral_radius < 1.0
    lam = np.linalg.eigvals(sys.A_at(0) - d.L @ sys.C_at(0))
    # Schur or modal coordinates: ρ(|R|) = max |Re λ| + |Im λ| over the spectrum of A − LC
    assert d.spectral_radius == pytest.approx(np.max(np.abs(lam.real) + np.abs(lam.imag)), rel=1e-6)
    assert np.max(np.abs(lam)) < 1.0
    res = assert_contained(est, sys, x0, seed=n)
    assert np.all(res.width[-1] <= 1.01 * d.steady_width + 1e-9)


def test_the_width_lp_is_the_global_optimum_and_its_certificate_checks():
    """Against the old default (LMI (41) then local width LPs) on small positive plants: never
    wider in the LP's objective (sum of the balanced steady-state widths); the copositive
    certificate q satisfies |A − LC|ᵀ q < q numerically."""
    for seed in range(4):
        sys = plant(6, 10 + seed, "positive", rho=0.98)
        A, _, C, _, E, F = sys.matrices_at(0)
        delta = sys.d.hi - sys.d.lo
        res = width_lp.width_lp(A, C, E, F, delta, nonnegative=True)
        assert res.status == "optimal"
        D = np.abs(A - res.L @ C)
        # q is the certificate in balanced coordinates: the Perron bound holds there
        dv = ivobs.design.balance.state_scaling(A, C, E, F)
        Dt = D * dv[None, :] / dv[:, None]
        assert np.max((Dt.T @ res.q) / res.q) < 1.0
        x0 = Box.symmetric(np.ones(6))
        new = ivobs.make_estimator("interval", sys, x0=x0)
        old = ivobs.make_estimator("interval", sys, x0=x0, gain="lmi+width")
        assert np.sum(new.design.steady_width / dv) <= np.sum(old.design.steady_width / dv) * (
            1 + 1e-7
        )


def test_solver_failure_is_not_reported_as_no_gain(monkeypatch):
    sys = plant(10, 0, "positive")

    class Failed:
        status, x, message, fun = 4, None, "numerical difficulties", None

    import scipy.optimize

    real = scipy.optimize.linprog

    def fake(c, *a, **k):  # the per-row and kernel tests pass, the width LP fails
        return Failed() if np.size(c) > 3 * sys.nx else real(c, *a, **k)

    monkeypatch.setattr(scipy.optimize, "linprog", fake)
    with pytest.raises(DesignError, match="solver failure, not a proof that no gain exists"):
        ivobs.make_estimator("interval", sys, x0=Box.symmetric(np.ones(10)))


def test_a_gain_failing_its_check_is_refused(monkeypatch):
    sys = plant(10, 0, "positive")
    bad = width_lp.WidthLP("optimal", "", np.full((10, 2), 5.0), np.ones(10), 0.0)
    monkeypatch.setattr(width_lp, "width_lp", lambda *a, **k: bad)
    with pytest.raises(DesignError, match="A − LC is not nonnegative"):
        ivobs.make_estimator("interval", sys, x0=Box.symmetric(np.ones(10)))


def test_redundant_noise_free_sensors_share_the_correction():
    """Two identical noise-free sensors: the part of L on the left null space of [C, F_Δ] is
    removed, so the correction is shared equally."""
    L = np.array([[-999999.1, 1e6]])
    out = width_lp.null_space_free(L, np.array([[1.0], [1.0]]), np.zeros((2, 1)), np.ones(1))
    np.testing.assert_allclose(out, [[0.45, 0.45]], atol=1e-9)


def test_fixed_time_on_a_30_state_plant_is_finite_and_sound():
    """Default window ν + 1 = 3 (ν = 2, 15 outputs) instead of nx − 1 = 29: on main the boxes
    overflowed at step ~500 (the window gain could not be certified, and the model prediction
    diverged); now the width is constant from k = s on."""
    sys = random_system(1, nx=30, ny=15)
    x0 = Box.symmetric(np.ones(30))
    est = ivobs.make_estimator("fixed-time", sys, x0=x0)
    assert est.s == 3
    res = assert_contained(est, sys, x0, T=2000, seed=2)
    w = res.width[est.s :].sum(axis=1)
    assert w.max() < 1.001 * w.min() and w.max() < 1000.0


def test_fixed_time_says_why_a_long_window_is_refused():
    sys = random_system(1, nx=30, ny=2)
    assert observability_index(sys.A_at(0), sys.C_at(0)) == 15
    assert "smaller window, s = 14 .. 16" in rank_advice(sys, 29)
    assert "cannot be designed for this pair in floating point" in rank_advice(sys, 15)
    assert "Increase s to at least ν − 1 = 14" in rank_advice(sys, 10)


@pytest.mark.parametrize("name", ["cora-tank30", "cora-vehicle6", "cora-slip4"])
@pytest.mark.parametrize("method", ["interval", "interval-split"])
def test_cora_benchmarks_contain_the_recorded_truth(name, method):
    """The width-LP gains on CORA's benchmarks [Althoff2021]: the recorded true state inside
    at every step (the bounds are those of the global optimum of the positivity condition)."""
    sc = ivobs.scenarios.get(name)
    tr = sc.simulate("recorded")
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    res = est.run(tr.u, tr.y)
    assert res.contains(tr.x).all()
    if name == "cora-tank30":
        r = 0.5 * res.width.mean(axis=-1)
        # the same as the old default (LMI (41) + local LPs), reached now in < 1 s: the
        # positivity condition allows nothing tighter
        assert r[19] == pytest.approx(1.4098, abs=1e-4)
        assert r[234] == pytest.approx(0.7535, abs=1e-4)


def test_cora_tank30_transformed_uses_the_identity():
    sc = ivobs.scenarios.get("cora-tank30")
    tr = sc.simulate("recorded")
    est = ivobs.make_estimator("interval-transformed", sc.system, x0=sc.x0)
    assert est.design.gain == "identity" and np.array_equal(est.design.S, np.eye(30))
    res = est.run(tr.u, tr.y)
    assert res.contains(tr.x).all()
    assert 0.5 * res.width[234].mean() == pytest.approx(0.7535, abs=1e-4)
