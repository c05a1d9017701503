"""Large sparse systems (issue 9: "large systems"): the heat-1d scenario, interval observers with
sparse ``A`` (one stacked sparse product per step), and dense design steps that refuse large
``nx`` with a DesignError pointing to what scales."""

import json

import numpy as np
import pytest
import scipy.sparse as sp

import ivobs
from ivobs import DesignError, IvobsError
from ivobs.design._lmi import MAX_LMI_STATES
from ivobs.io import dumps_system, equal_systems, loads_system
from ivobs.scenarios import heat_gain
from ivobs.testing import adversarial_run, assert_contains

SPARSE = ("interval", "interval-split")


def sparse_run(sc, T, seed=0, x_true0=None):
    """Vertex-disturbance trajectory computed with sparse products (dense simulation of a large
    system would dominate the test time)."""
    s = sc.system
    rng = np.random.default_rng(seed)
    box = s.d
    d = np.where(rng.integers(0, 2, (T, s.nd)).astype(bool), box.hi, box.lo)
    A, C = s.sparse("A"), s.sparse("C")
    B, E, F = s.B_at(0), s.E_at(0), s.F_at(0)
    x = np.empty((T, s.nx))
    xk = sc.x_true0.copy() if x_true0 is None else x_true0
    for k in range(T):
        x[k] = xk
        xk = A @ xk + B @ sc.u[k] + E @ d[k]
    return x, (C @ x.T).T + d @ F.T


@pytest.fixture(scope="module")
def heat300():
    sc = ivobs.scenarios.get("heat-1d", nx=300, sensors=4, horizon=600)
    x, y = sparse_run(sc, 600, seed=1, x_true0=sc.x0.hi.copy())  # from a vertex of the prior
    return sc, x, y


# -- the scenario ----------------------------------------------------------------------------
def test_heat_scenario_is_sparse_nonnegative_and_stable():
    sc = ivobs.scenarios.get("heat-1d")
    s = sc.system
    assert (s.nx, s.ny, s.nu, s.nd) == (50, 3, 1, 6) and s.is_sparse
    A = s.sparse("A")
    assert A.nnz == 3 * 50 - 2 and A.min() >= 0
    assert abs(A).sum(axis=1).max() <= 1 - 0.01 + 1e-12  # row sums <= 1 - cooling: Schur
    assert sc.x0.contains(sc.x_true0)
    assert list(sc.reference["sensors"]) == [12, 25, 37]
    L = sc.reference["L"]
    D = (A - sp.csr_matrix(L) @ s.sparse("C")).toarray()
    assert D.min() >= 0 and np.max(np.abs(np.linalg.eigvals(D))) < 0.99
    tr = sc.simulate("vertex", seed=0)
    res = ivobs.make_estimator("interval", s, x0=sc.x0, L=L).run(tr.u, tr.y)
    assert_contains(res, tr.x)
    np.testing.assert_allclose(heat_gain(s), L)


def test_heat_scenario_options_are_checked():
    assert ivobs.scenarios.get("heat-1d", nx=2000, horizon=3).system.nx == 2000
    with pytest.raises(IvobsError, match="nx: expected an integer >= 3"):
        ivobs.scenarios.get("heat-1d", nx=2)
    with pytest.raises(IvobsError, match="sensors: expected 1..10"):
        ivobs.scenarios.get("heat-1d", nx=10, sensors=11)
    with pytest.raises(IvobsError, match="2 alpha \\+ cooling <= 1"):
        ivobs.scenarios.get("heat-1d", alpha=0.5, cooling=0.1)


def test_heat_system_file_keeps_sparse_matrices():
    sc = ivobs.scenarios.get("heat-1d", nx=20)
    text = dumps_system(sc)
    assert "[system.A]" in text and "shape = [20, 20]" in text
    back = loads_system(text)
    assert back.system.is_sparse and equal_systems(back.system, sc.system)
    assert (back.system.sparse("A") != sc.system.sparse("A")).nnz == 0


@pytest.mark.parametrize(
    "table, message",
    [
        ("shape = [2, 2]\nrows = [0, 2]\ncols = [0, 1]\nvalues = [1.0, 2.0]", "outside 0..1"),
        ("shape = [2, 2]\nrows = [0, 0]\ncols = [1, 1]\nvalues = [1.0, 2.0]", "given twice"),
        ("shape = [2, 2]\nrows = [0]\ncols = [0, 1]\nvalues = [1.0, 2.0]", "different lengths"),
        ("shape = [2]\nrows = [0]\ncols = [0]\nvalues = [1.0]", "expected \\[rows, cols\\]"),
        ("shape = [2, 2]\nrows = [0]\ncols = [0]", "missing values"),
        ("shape = [2, 2]\nrows = [0]\ncols = [0]\nvalues = [1.0]\nformat = 1", "unknown key"),
    ],
)
def test_bad_sparse_tables_are_rejected_with_the_key(table, message):
    text = f"[system]\nC = [[1.0, 0.0]]\n\n[system.A]\n{table}\n"
    with pytest.raises(IvobsError, match=message):
        loads_system(text)


# -- interval observers with sparse A ---------------------------------------------------------
@pytest.mark.parametrize("method", SPARSE)
def test_sparse_observers_contain_the_state_and_paths_agree(method, heat300):
    sc, x, y = heat300
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, L=sc.reference["L"])
    assert est.operators.sparse and sp.issparse(est.design.D) and est.design.spectral_radius < 1
    vec = est.run(sc.u, y, vectorize=True)
    loop = est.run(sc.u, y, vectorize=False)
    assert_contains(vec, x)
    assert_contains(loop, x)
    scale = 1.0 + np.abs(loop.upper)
    assert np.max(np.abs(vec.upper - loop.upper) / scale) < 1e-9
    assert np.max(np.abs(vec.lower - loop.lower) / scale) < 1e-9
    est.reset()
    for k in range(40):  # the online loop is the same code as run(vectorize=False)
        box = est.step(sc.u[k], y[k])
        np.testing.assert_array_equal(box.hi, loop.upper[k])
    width = (vec.upper - vec.lower)[-1]
    np.testing.assert_allclose(width.mean(), est.design.steady_width.mean(), rtol=0.05)


def test_sparse_observer_equals_the_dense_one():
    sc = ivobs.scenarios.get("heat-1d", nx=40, horizon=300)
    tr = sc.simulate("vertex", seed=2)
    L = sc.reference["L"]
    s = sc.system
    dense_sys = ivobs.LinearSystem(s.A, s.B, s.C, E=s.E, F=s.F, d=s.d)
    for method in SPARSE:
        a = ivobs.make_estimator(method, s, x0=sc.x0, L=L).run(tr.u, tr.y, vectorize=False)
        # (a sparse system has no finite-memory bound: compare the observers themselves)
        b = ivobs.make_estimator(method, dense_sys, x0=sc.x0, L=L, finite_memory=False)
        b = b.run(tr.u, tr.y)
        np.testing.assert_allclose(a.upper, b.upper, rtol=1e-8, atol=1e-12)
        np.testing.assert_allclose(a.lower, b.lower, rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("method", SPARSE)
def test_sparse_missing_samples_and_faults(method, heat300):
    sc, x, y = heat300
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, L=sc.reference["L"])
    rng = np.random.default_rng(4)
    ym = y.copy()
    ym[rng.random(ym.shape[0]) < 0.1] = np.nan  # 10% of the samples missing
    ym[200:220] = np.nan  # and a gap of 20 steps
    ym[300, 1] = np.nan  # one component missing
    res = est.run(sc.u, ym)
    assert np.isfinite(res.upper).all() and np.isfinite(res.lower).all()
    assert_contains(res, x)
    yf = y.copy()
    yf[400, 2] += 10.0  # a sensor fault
    with pytest.warns(UserWarning, match="inconsistent"):
        res = est.run(sc.u, yf)
    assert res.inconsistent[400] and res.inconsistent.sum() == 1
    assert_contains(res, x)


def test_sparse_batch_of_streams(heat300):
    sc, _, y = heat300
    est = ivobs.make_estimator("interval", sc.system, x0=sc.x0, L=sc.reference["L"])
    Y = np.stack([y[:100], y[:100]])
    res = est.run(sc.u[:100], Y)
    single = est.run(sc.u[:100], y[:100], vectorize=False)
    np.testing.assert_allclose(res.upper[1], single.upper, rtol=1e-9, atol=1e-12)


def test_sparse_gain_checks():
    sc = ivobs.scenarios.get("heat-1d", nx=300)
    L = sc.reference["L"].copy()
    bad = L.copy()
    s0 = sc.reference["sensors"][0]
    bad[s0 + 1, 0] = 1.0  # more than A[s0 + 1, s0] = alpha: A - LC negative there
    with pytest.raises(DesignError, match=f"entry \\({s0 + 2}, {s0 + 1}\\)"):
        ivobs.make_estimator("interval", sc.system, x0=sc.x0, L=bad)
    est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, L=bad)  # any sign: fine
    assert est.design.spectral_radius < 1
    with pytest.raises(DesignError, match="not Schur: spectral radius"):
        ivobs.make_estimator("interval-split", sc.system, x0=sc.x0, L=-40 * L)


# -- dense design steps refuse large nx ---------------------------------------------------------
@pytest.mark.parametrize(
    "method, options, step",
    [
        ("interval", {"gain": "lmi"}, "LMI \\(41\\)"),
        ("interval-split", {"gain": "margin"}, "linear programs"),
        ("interval-split", {"gain": "lmi"}, "LMIs \\(7\\)-\\(8\\)"),
        ("interval-transformed", {"transform": "search"}, "similarity transform"),
        ("reachability", {}, "interval hull"),
        ("reachability", {"L": "heat"}, "interval hull"),
        ("kkl", {}, "Sylvester"),
        ("fixed-time", {}, "stacked matrices"),
        ("zonotope", {}, "generator matrix"),
        ("zonotope", {"L": "heat"}, "generator matrix"),
        ("strip", {}, "generator matrix"),
        ("constrained-zonotope", {}, "constrained zonotope"),
        ("exact", {}, "2 nx linear programs"),
    ],
)
def test_dense_design_steps_refuse_large_systems(method, options, step):
    sc = ivobs.scenarios.get("heat-1d", nx=MAX_LMI_STATES + 1)
    if options.get("L") == "heat":
        options = {**options, "L": sc.reference["L"]}
    with pytest.raises(DesignError, match=step) as err:
        ivobs.make_estimator(method, sc.system, x0=sc.x0, **options)
    msg = str(err.value)
    assert f"nx = {MAX_LMI_STATES + 1} > {MAX_LMI_STATES}" in msg and "L=" in msg
    assert "'interval'" in msg or "interval-split" in msg


@pytest.mark.parametrize(
    ("method", "options", "gain"),
    [
        ("interval", {}, "width"),
        ("interval-split", {}, "width"),
        ("interval-transformed", {}, "identity"),
        ("interval-transformed", {"L": "heat"}, "given"),
    ],
)
def test_interval_family_designs_scale_past_the_dense_limit(method, options, gain):
    """The width LP (sparse, O(nx²) variables) designs the interval family above the dense
    limit (it used to refuse); heat-1d's gain in interval-transformed keeps S = I. The truth
    stays inside with disturbances on the vertices of their bounds."""
    sc = ivobs.scenarios.get("heat-1d", nx=MAX_LMI_STATES + 1, horizon=200)
    if options.get("L") == "heat":
        options = {**options, "L": sc.reference["L"]}
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, **options)
    assert est.design.gain == gain and est.design.spectral_radius < 1.0
    tr = sc.simulate("vertex")
    assert est.run(tr.u, tr.y).contains(tr.x).all()


def _random_sparse_system(seed):
    """A random stable sparse system (banded ``A``, point sensors, ``d`` in both equations) and
    a gain for each sparse method: ``A − LC >= 0`` for ``interval``, entries of both signs with
    ``|A − LC|`` Schur for ``interval-split``."""
    rng = np.random.default_rng(seed)
    n, ny = 30 + 7 * seed, 2 + seed % 2
    diag = rng.uniform(0.2, 0.5, n)
    off = rng.uniform(-0.15 * (seed % 2), 0.15, (2, n - 1))  # odd seeds: both signs
    A = sp.diags([off[0], diag, off[1]], [-1, 0, 1], format="csr")
    sensors = rng.choice(n, ny, replace=False)
    C = np.zeros((ny, n))
    C[np.arange(ny), sensors] = rng.uniform(0.5, 2.0, ny)
    nd = 3
    E = 0.1 * rng.normal(size=(n, nd))
    F = np.zeros((ny, nd))
    F[:, -1] = 0.05
    r = rng.uniform(0.2, 1.0, nd)
    c = 0.3 * rng.normal(size=nd) if seed % 2 else np.zeros(nd)
    sys = ivobs.LinearSystem(A, rng.normal(size=(n, 1)), C, E=E, F=F, d=ivobs.Box(c - r, c + r))
    gains: dict[str, np.ndarray] = {}
    L = np.zeros((n, ny))
    L[sensors, np.arange(ny)] = 0.5 * diag[sensors] / C[np.arange(ny), sensors]
    gains["interval-split"] = L.copy()
    if seed % 2 == 0:
        assert np.all(A.toarray() - L @ C >= 0.0)
        gains["interval"] = L
    return sys, gains


@pytest.mark.parametrize("seed", range(4))
def test_sparse_random_systems_vectorised_equals_loop(seed):
    """The sparse fast path (one stacked sparse product per step, all input terms precomputed)
    against the step-by-step loop on random sparse systems with vertex disturbances; streams of
    a batch against single records."""
    sys, gains = _random_sparse_system(seed)
    x0 = ivobs.Box(-np.ones(sys.nx), 2 * np.ones(sys.nx))
    trs = [adversarial_run(sys, x0, 150, seed=100 * seed + b, hold=1 + b) for b in range(2)]
    for method, L in gains.items():
        est = ivobs.make_estimator(method, sys, x0=x0, L=L)
        assert est.operators.sparse
        for tr in trs:
            loop = est.run(tr.u, tr.y, vectorize=False)
            vec = est.run(tr.u, tr.y, vectorize=True)
            assert_contains(loop, tr.x)
            assert_contains(vec, tr.x)
            scale = 1.0 + np.abs(loop.upper) + np.abs(loop.lower)
            assert np.max(np.abs(vec.upper - loop.upper) / scale) < 1e-9
            assert np.max(np.abs(vec.lower - loop.lower) / scale) < 1e-9
        batch = est.run(np.stack([t.u for t in trs]), np.stack([t.y for t in trs]))
        for b, tr in enumerate(trs):
            single = est.run(tr.u, tr.y, vectorize=True)  # a batch sums in another order
            np.testing.assert_allclose(batch.upper[b], single.upper, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(batch.lower[b], single.lower, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("method", SPARSE)
def test_sparse_state_restores_to_identical_continuations(method, heat300):
    sc, _x, y = heat300
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, L=sc.reference["L"])
    ref = est.run(sc.u[:80], y[:80], vectorize=False)
    est.reset()
    for k in range(40):
        est.step(sc.u[k], y[k])
    saved = json.loads(json.dumps(est.state()))
    assert set(saved["state"]) >= {"lo", "hi", "k"}
    other = ivobs.make_estimator(method, sc.system, x0=sc.x0, L=sc.reference["L"])
    other.restore(saved)
    for k in range(40, 80):
        box = other.step(sc.u[k], y[k])
        np.testing.assert_array_equal(box.lo, ref.lower[k])
        np.testing.assert_array_equal(box.hi, ref.upper[k])
