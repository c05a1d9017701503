"""The ellipsoidal set-membership filter (``ellipsoid``; [Liu2016], [Schweppe1968]): sound under
vertex disturbances (this test's own simulator, and exact trajectories from tests/exactsim.py
with states from 1e-6 to 1e10), never tighter than the exact hull, bounded over long runs and
with missing samples, state round trips, and the pieces (box ellipsoid, covers of a rounded
shape and of a rounded centre, strip update) checked on their own."""

from __future__ import annotations

import json

import numpy as np
import pytest

import ivobs
from ivobs import Box, LinearSystem
from ivobs.estimators.ellipsoid import (
    _best_lambda,
    _cover,
    _cover_centre,
    _trace_after,
    box_ellipsoid,
)
from ivobs.testing import random_system


def _inside(c: np.ndarray, Q: np.ndarray, x: np.ndarray) -> bool:
    """``x ∈ E(c, Q)`` (Q positive definite here)."""
    d = x - c
    return float(d @ np.linalg.solve(Q, d)) <= 1.0 + 1e-12


def _random_system(rng: np.random.Generator, nx: int, ny: int, nd: int) -> LinearSystem:
    A = rng.standard_normal((nx, nx))
    A *= 0.95 / max(abs(np.linalg.eigvals(A)))
    B = rng.standard_normal((nx, 1))
    C = rng.standard_normal((ny, nx))
    E = rng.standard_normal((nx, nd)) * 0.1
    F = rng.standard_normal((ny, nd)) * 0.1  # d enters both: correlated noise
    lo = -rng.uniform(0.1, 1.0, nd)
    hi = rng.uniform(0.1, 1.0, nd)
    return LinearSystem(A, B, C, E=E, F=F, d=Box(lo, hi))


def _simulate(sys, x0, T, rng, y_offset=0.0):
    """The test's own simulator: disturbances on the vertices of their box."""
    x = np.array(x0, dtype=float)
    X, Y, U = [], [], rng.uniform(-1, 1, (T, sys.nu))
    lo, hi = sys.d.lo, sys.d.hi
    D = np.zeros((sys.ny, sys.nu)) if sys.D is None else sys.D
    for k in range(T):
        d = np.where(rng.random(sys.nd) < 0.5, lo, hi)
        X.append(x.copy())
        Y.append(sys.C @ x + D @ U[k] + sys.F @ d + y_offset)
        x = sys.A @ x + sys.B @ U[k] + sys.E @ d
    return np.array(X), np.array(Y), U


@pytest.mark.parametrize("seed", range(4))
def test_sound_and_bounded_under_vertex_disturbances(seed):
    rng = np.random.default_rng(seed)
    nx, ny, nd = int(rng.integers(2, 6)), int(rng.integers(1, 4)), int(rng.integers(1, 5))
    sys = _random_system(rng, nx, ny, nd)
    x0 = Box(-np.ones(nx), np.ones(nx))
    X, Y, U = _simulate(sys, rng.choice([-1.0, 1.0], nx), 1000, rng)
    res = ivobs.make_estimator("ellipsoid", sys, x0=x0).run(U, Y)
    assert res.contains(X).all()
    assert not res.inconsistent.any()
    w = res.width
    assert np.isfinite(w).all()
    # bounded (the widths depend on the data, so they fluctuate): no drift from the second
    # quarter of the run to the last
    assert w[750:].mean() <= 1.05 * w[250:500].mean()
    assert w[750:].max() <= 1.2 * w[250:500].max()


@pytest.mark.parametrize(
    ("scale", "gain", "rho", "noise"),
    [(1.0, 1.0, 0.9, 0.0), (1e6, 1e3, 0.95, 0.0), (1e10, 1.0, 1.02, 0.0), (1e-6, 1e3, 0.9, 0.0),
     (1e10, 1e3, 0.95, 1e-2)],
    ids=["unit", "1e6-gain1e3", "1e10-unstable", "1e-6", "1e10-thin"],
)  # fmt: skip
def test_exact_trajectories_are_contained_at_every_scale(scale, gain, rho, noise):
    """Exact records (rational arithmetic, disturbances on their bounds): no miss, no
    admissible sample flagged, with a JSON state round trip at every step."""
    from test_strip_soundness import exact_case

    sys, x0, rec = exact_case(int(np.log10(scale)) + 30, scale, gain, rho, 120, noise)
    est = ivobs.make_estimator("ellipsoid", sys, x0=x0)
    res = est.run(rec.U, rec.Y)
    assert rec.misses(res.lower, res.upper).size == 0
    assert not res.inconsistent.any()
    est.reset()
    for k in range(rec.Y.shape[0]):
        box = est.step(rec.U[k], rec.Y[k])
        assert np.array_equal(box.lo, res.lower[k]) and np.array_equal(box.hi, res.upper[k])
        est.restore(json.loads(json.dumps(est.state())))


@pytest.mark.parametrize(
    ("seed", "T"), [(0, 800), pytest.param(1, 3000, marks=pytest.mark.slow),
                    pytest.param(2, 3000, marks=pytest.mark.slow)]
)  # fmt: skip
def test_missing_samples_leave_the_widths_bounded(seed, T):
    """10 % of the output components missing at random over 3,000 steps (800 in the quick
    run) on a random stable plant: every box holds the state, widths within 20x of those with
    every sample (measured: within 1.1x)."""
    rng = np.random.default_rng(seed)
    sys = random_system(seed + 60, nx=3, ny=2, nu=1, rho=0.85)
    X, Y, U = _simulate(sys, np.zeros(3), T, rng)
    gaps = Y.copy()
    gaps[rng.random(Y.shape) < 0.1] = np.nan
    est = ivobs.make_estimator("ellipsoid", sys, x0=Box(-np.ones(3), np.ones(3)))
    full, missing = est.run(U, Y), est.run(U, gaps)
    assert full.contains(X).all() and missing.contains(X).all()
    ratio = missing.width[100:].mean() / full.width[100:].mean()
    assert 1.0 <= ratio < 20.0


def test_never_tighter_than_the_exact_hull_and_filter_form():
    rng = np.random.default_rng(11)
    sys = _random_system(rng, 3, 2, 3)
    x0 = Box(-np.ones(3), np.ones(3))
    _, Y, U = _simulate(sys, np.ones(3), 60, rng)
    ell = ivobs.make_estimator("ellipsoid", sys, x0=x0).run(U, Y)
    ex = ivobs.make_estimator("exact", sys, x0=x0, progress=False).run(U, Y)
    tol = 1e-7 * (1 + np.abs(ex.lower) + np.abs(ex.upper))
    assert (ell.lower <= ex.lower + tol).all() and (ex.upper <= ell.upper + tol).all()
    # (vertex disturbances entering both E and F: the exact hull nearly pins the state down,
    # while the ellipsoid bounds E d and F d as if independent) within a few times strip's
    strip = ivobs.make_estimator("strip", sys, x0=x0).run(U, Y)
    ratio = ell.width[10:].mean() / strip.width[10:].mean()
    assert 1.0 <= ratio < 6.0
    # filter form: y[0] already narrows the box of x[0] below the prior's
    assert (ell.width[0] < 2.0).any()


def test_missing_samples_and_an_inconsistent_measurement():
    rng = np.random.default_rng(5)
    sys = _random_system(rng, 3, 2, 2)
    x0 = Box(-np.ones(3), np.ones(3))
    X, Y, U = _simulate(sys, -np.ones(3), 400, rng)
    Y = Y.copy()
    Y[100:140, 0] = np.nan
    Y[200:210] = np.nan
    est = ivobs.make_estimator("ellipsoid", sys, x0=x0, on_inconsistent="ignore")
    res = est.run(U, Y)
    assert res.contains(X).all()
    assert res.width[205].sum() > res.width[195].sum()  # an outage widens the box
    Y[300, 1] += 1e3  # far outside the noise bound: reported, not used
    res2 = est.run(U, Y)
    assert res2.inconsistent[300] and res2.inconsistent.sum() == 1
    assert res2.contains(X).all()


def test_large_offsets_keep_it_sound():
    """y of size 1e6 carrying a state of size 1 (the rounding of t and h c widens the strip)."""
    rng = np.random.default_rng(2)
    A = np.array([[0.9, 0.2], [0.0, 0.7]])
    sys = LinearSystem(
        A,
        np.zeros((2, 1)),
        [[1.0, 0.0]],
        D=[[1e6]],
        E=[[0.05, 0.0], [0.0, 0.0]],
        F=[[0.0, 1e-3]],
        d=Box([-1.0, -1.0], [1.0, 1.0]),
    )
    T = 500
    U = np.ones((T, 1))
    x = np.array([1.0, -1.0])
    X, Y = [], []
    for _ in range(T):
        d = rng.choice([-1.0, 1.0], 2)
        X.append(x.copy())
        Y.append(sys.C @ x + sys.D @ U[0] + sys.F @ d)
        x = A @ x + sys.E @ d
    res = ivobs.make_estimator("ellipsoid", sys, x0=Box([-2, -2], [2, 2])).run(U, np.array(Y))
    assert res.contains(np.array(X)).all()


def test_noise_free_output_pins_a_state():
    sys = LinearSystem(
        [[0.5, 0.1], [0.0, 0.8]],
        [[0.0], [0.0]],
        [[1.0, 0.0]],
        E=[[0.0], [0.1]],
        F=[[0.0]],
        d=Box([-1.0], [1.0]),
    )
    rng = np.random.default_rng(3)
    X, Y, U = _simulate(sys, [0.3, -0.2], 300, rng)
    res = ivobs.make_estimator("ellipsoid", sys, x0=Box([-1, -1], [1, 1])).run(U, Y)
    assert res.contains(X).all()
    assert res.width[50:, 0].max() < 1e-5  # measured exactly: known to rounding


def test_step_equals_run_and_restore_continues_identically():
    sc = ivobs.scenarios.get("servo-motor", horizon=200)
    tr = sc.simulate("vertex", seed=1)
    est = ivobs.make_estimator("ellipsoid", sc.system, x0=sc.x0)
    res = est.run(tr.u, tr.y)
    assert res.contains(tr.x).all()
    est.reset()
    for k in range(100):
        b = est.step(tr.u[k], tr.y[k])
        assert b.lo.tobytes() == res.lower[k].tobytes()
    saved = json.loads(json.dumps(est.state()))
    other = ivobs.make_estimator("ellipsoid", sc.system, x0=sc.x0)
    other.restore(saved)
    for k in range(100, 200):
        assert other.step(tr.u[k], tr.y[k]).hi.tobytes() == res.upper[k].tobytes()


def test_box_ellipsoid_contains_the_box_vertices_with_minimal_trace():
    rng = np.random.default_rng(0)
    G = rng.standard_normal((3, 4))
    r = np.array([0.5, 1.0, 0.0, 2.0])
    Q = box_ellipsoid(G, r)
    for b in np.array(np.meshgrid(*[[-1.0, 1.0]] * 4)).reshape(4, -1).T:
        assert _inside(np.zeros(3), Q + 1e-12 * np.eye(3), G @ (r * b))
    norms = np.linalg.norm(G, axis=0)
    assert np.trace(Q) == pytest.approx(float(r @ norms) ** 2, rel=1e-9)


def test_best_lambda_minimises_the_trace_and_the_update_contains_the_intersection():
    rng = np.random.default_rng(4)
    for _ in range(50):
        n = 3
        R = rng.standard_normal((n, n))
        Q = R @ R.T + 0.1 * np.eye(n)
        c = rng.standard_normal(n)
        h = rng.standard_normal(n)
        sigma = rng.uniform(0.05, 1.0)
        g = float(h @ Q @ h)
        t = float(h @ c) + rng.uniform(-1, 1) * (np.sqrt(g) + sigma) * 0.9
        e = t - float(h @ c)
        Qh = Q @ h
        lam = _best_lambda(np.trace(Q), float(Qh @ Qh), g, e * e, sigma**2)
        grid = np.linspace(1e-4, 1 - 1e-4, 2000)
        best = _trace_after(grid, np.trace(Q), float(Qh @ Qh), g, e * e, sigma**2).min()
        assert _trace_after(lam, np.trace(Q), float(Qh @ Qh), g, e * e, sigma**2) <= best * (
            1 + 1e-6
        )
        s = (1 - lam) * sigma**2 + lam * g
        delta = lam * (1 - lam) * e * e / s
        c2 = c + (lam / s) * Qh * e
        Q2 = (1 - delta) / (1 - lam) * (Q - (lam / s) * np.outer(Qh, Qh))
        # sample the intersection: points of E(c, Q) inside the strip are inside E(c2, Q2)
        L = np.linalg.cholesky(Q)
        for _ in range(200):
            v = rng.standard_normal(n)
            p = c + L @ (v / np.linalg.norm(v) * rng.uniform() ** (1 / n))
            if abs(h @ p - t) <= sigma:
                assert _inside(c2, Q2 + 1e-12 * np.eye(n), p)


def test_the_covers_contain_the_exact_ellipsoids():
    """``_cover``: a matrix perturbed within ``M`` entrywise is dominated by the cover
    (smallest eigenvalue of the difference >= 0, in a wide margin of the float check);
    ``_cover_centre``: points of ``E(c, Q)`` moved by up to ``ε`` stay in the covered one."""
    rng = np.random.default_rng(9)
    for _ in range(50):
        n = int(rng.integers(1, 6))
        R = rng.standard_normal((n, n))
        Q = R @ R.T + 1e-3 * np.eye(n)
        M = np.abs(rng.standard_normal((n, n))) * 1e-6
        P = Q + rng.uniform(-1, 1, (n, n)) * M
        P = 0.5 * (P + P.T)
        assert np.linalg.eigvalsh(_cover(Q.copy(), M) - P).min() >= -1e-12
        eps = np.abs(rng.standard_normal(n)) * 0.1
        Qc = _cover_centre(Q.copy(), eps)
        L = np.linalg.cholesky(Q)
        for _ in range(50):
            v = rng.standard_normal(n)
            p = L @ (v / np.linalg.norm(v)) + rng.uniform(-1, 1, n) * eps
            assert _inside(np.zeros(n), Qc, p)


def test_bad_input_is_refused_with_the_argument_named():
    sys = _random_system(np.random.default_rng(0), 2, 1, 1)
    with pytest.raises(ivobs.IvobsError, match="x0"):
        ivobs.make_estimator("ellipsoid", sys)
    with pytest.raises(ivobs.IvobsError, match="does not accept|order"):
        ivobs.make_estimator("ellipsoid", sys, x0=Box([-1, -1], [1, 1]), order=3)
