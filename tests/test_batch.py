"""Batches of streams and the shared recursion kernel.

The vectorised path of every recursive method is one pass of
:mod:`ivobs.estimators._recursion`; here it is checked against the step-by-step loop (the
reference, ``vectorize=False``) on batches of adversarial (vertex-disturbance) streams, for
soundness and agreement to ~1e-9.
"""

import tracemalloc
import warnings

import numpy as np
import pytest
from scipy.sparse import csr_matrix

import ivobs
from ivobs.estimators._recursion import LinearFilter, SplitFilter, matrix_product, scratch
from ivobs.testing import adversarial_run, random_system

FAST = ("reachability", "interval", "interval-split", "interval-transformed", "fixed-time", "kkl")


def _reference(M, W, g, v, x0):
    """The filter's definition, step by step, for one stream: the states and ``x[T]``."""
    T = v[0].shape[0]
    X = np.empty((T, M.shape[0]))
    x = np.array(x0, dtype=float)
    for k in range(T):
        X[k] = x
        x = M @ x + sum(Ws @ a[k] for Ws, a in zip(W, v)) + (0.0 if g is None else g)
    return X, x


def _random_filter(rng, n, stable=0.95):
    M = rng.normal(size=(n, n))
    M *= stable / np.max(np.abs(np.linalg.eigvals(M)))
    return M, [rng.normal(size=(n, 2)), rng.normal(size=(n, 1))], rng.normal(size=n)


@pytest.mark.parametrize(
    "n, T, B",
    [(3, 1000, 40), (3, 37, 3), (2, 20_003, None), (6, 1001, None), (30, 60, 2), (3, 1, 2)],
)
def test_linear_filter_matches_its_definition(n, T, B):
    # blocks (small n) with tails, batches (block-start loop) and one long record (block starts
    # by the same method, recursively), the loop form for n = 30
    rng = np.random.default_rng(n * T)
    M, W, g = _random_filter(rng, n)
    shape = (T,) if B is None else (B, T)
    v = [rng.normal(size=(*shape, 2)), rng.normal(size=(*shape, 1))]
    x0 = rng.normal(size=n)
    filt = LinearFilter(M, W, g)
    assert filt.blocks == (n <= 24)
    got, xT = filt.run(v, x0=x0, final=True)
    for b in (0,) if B is None else (0, B - 1):
        vb = v if B is None else [a[b] for a in v]
        want, x_end = _reference(M, W, g, vb, x0)
        gb = got if B is None else got[b]
        np.testing.assert_allclose(gb, want, rtol=1e-9, atol=1e-9 * (1 + np.abs(want).max()))
        np.testing.assert_allclose(xT if B is None else xT[b], x_end, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("T", [1, 5, 33, 1000, 4097])
def test_block_scan_matches_the_loop(T):
    rng = np.random.default_rng(T)
    M = rng.normal(size=(3, 3))
    M *= 0.95 / np.max(np.abs(np.linalg.eigvals(M)))
    v = rng.normal(size=(T, 3))
    x0 = rng.normal(size=3)
    X, xT = LinearFilter(M, [np.eye(3)]).run([v], x0=x0, final=True)
    want, x_end = _reference(M, [np.eye(3)], None, [v], x0)
    np.testing.assert_allclose(np.vstack([X, xT]), np.vstack([want, x_end]), rtol=1e-10,
                               atol=1e-12)  # fmt: skip


def test_batches_and_unstable_matrices():
    rng = np.random.default_rng(0)
    M = np.array([[1.1, 0.2], [0.0, 0.9]])  # unstable
    v = rng.normal(size=(4, 50, 2))
    X = LinearFilter(M, [np.eye(2)]).run([v])[0]
    for b in range(4):
        np.testing.assert_allclose(X[b], _reference(M, [np.eye(2)], None, [v[b]], np.zeros(2))[0],
                                   rtol=1e-12)  # fmt: skip
    Ms = 0.5 * M
    Xs = LinearFilter(Ms, [np.eye(2)]).run([v[:2]], x0=np.ones((2, 2)))[0]
    want = _reference(Ms, [np.eye(2)], None, [v[1]], np.ones(2))[0]
    np.testing.assert_allclose(Xs[1], want, rtol=1e-10, atol=1e-12)


def test_sparse_filter_matches_the_dense_loop():
    rng = np.random.default_rng(3)
    n, T = 40, 300
    M = (
        np.diag(np.full(n, 0.5))
        + np.diag(np.full(n - 1, 0.2), 1)
        + np.diag(np.full(n - 1, 0.2), -1)
    )
    W = [rng.normal(size=(n, 2))]
    g = rng.normal(size=n)
    v = [rng.normal(size=(T, 2))]
    dense = LinearFilter(M, W, g)
    sparse = LinearFilter(csr_matrix(M), W, g)
    assert sparse.sparse and not sparse.blocks
    want = dense.run(v, x0=np.ones(n))[0]
    np.testing.assert_allclose(sparse.run(v, x0=np.ones(n))[0], want, rtol=1e-12, atol=1e-12)
    vb = [np.stack([v[0], 2 * v[0]])]  # a batch, sparse: one product per step for all streams
    Xb = sparse.run(vb, x0=np.ones(n))[0]
    np.testing.assert_allclose(Xb[0], want, rtol=1e-12, atol=1e-12)


def test_split_filter_shared_plus_data_is_the_whole_response():
    rng = np.random.default_rng(5)
    M, W, g = _random_filter(rng, 3)
    y = rng.normal(size=(4, 200, 2))
    u = np.broadcast_to(rng.normal(size=(200, 1)), (4, 200, 1))  # one input for the batch
    x0 = rng.normal(size=3)
    split = SplitFilter(M, W, g)
    (data,), shared = split.run([y, u], x0=x0)
    assert shared is not None and shared[0].shape == (200, 3)
    whole = LinearFilter(M, W, g).run([y, np.ascontiguousarray(u)], x0=x0)[0]
    np.testing.assert_allclose(data + shared[0], whole, rtol=1e-10, atol=1e-12)
    single, none = split.run([y[1], u[1]], x0=x0)  # one record: nothing to share
    assert none is None
    np.testing.assert_allclose(single[0], whole[1], rtol=1e-10, atol=1e-12)


def test_helpers():
    X = np.arange(24.0 * 4096).reshape(-1, 3)
    Mt = np.array([[1.0, 2.0], [0.5, 0.0], [-1.0, 3.0]])
    np.testing.assert_allclose(matrix_product(X, Mt), X @ Mt)  # narrow: kron(I_8, Mt) path
    np.testing.assert_allclose(matrix_product(X[:5], csr_matrix(Mt)), X[:5] @ Mt)
    a = scratch(test_helpers, "t", (3, 4))
    assert scratch(test_helpers, "t", (3, 4)) is a  # reused between calls
    assert scratch(test_helpers, "t", (3, 5)) is not a


def _streams(sc, B, T, seed=0):
    """``B`` streams from random vertices of the prior box with vertex disturbances and the
    scenario's input (one ``u`` for the batch)."""
    rng = np.random.default_rng(seed)
    sys, box = sc.system, sc.x0
    trs = []
    for _ in range(B):
        x_true0 = np.where(rng.integers(0, 2, sys.nx).astype(bool), box.hi, box.lo)
        d = ivobs.vertex_disturbance(sys.d, T, seed=rng)
        trs.append(ivobs.simulate(sys, x_true0, sc.u[:T], d))
    return sc.u[:T], np.stack([t.y for t in trs]), np.stack([t.x for t in trs])


@pytest.mark.parametrize("method", FAST)
def test_batch_equals_the_loop_per_stream_and_contains_the_state(method):
    sc = ivobs.scenarios.get("servo-motor", horizon=301)
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    U, Y, X = _streams(sc, 5, 301)
    res = est.run(U, Y)  # a batch: the vectorised path, one pass for all streams
    assert res.lower.shape == (5, 301, 3) and not res.inconsistent.any()
    vf = res.valid_from
    assert res.contains(X)[:, vf:].all()
    for b in (0, 4):
        ref = est.run(U, Y[b], vectorize=False)
        scale = 1.0 + np.abs(ref.upper[vf:])
        assert np.max(np.abs(res.upper[b, vf:] - ref.upper[vf:]) / scale) < 1e-9
        assert np.max(np.abs(res.lower[b, vf:] - ref.lower[vf:]) / scale) < 1e-9


@pytest.mark.parametrize("method", ("reachability", "interval-split", "fixed-time", "kkl"))
def test_per_stream_inputs_feedthrough_and_asymmetric_bounds(method):
    sys = random_system(11, nx=3, ny=2, nu=2, feedthrough=True, symmetric_bounds=False)
    x0 = ivobs.Box(-np.ones(3), np.ones(3))
    try:
        est = ivobs.make_estimator(method, sys, x0=x0)
    except ivobs.DesignError:  # pragma: no cover - the seed is chosen so that all designs exist
        pytest.skip("no design for this random system")
    trs = [adversarial_run(sys, x0, 150, seed=s) for s in range(3)]
    U = np.stack([t.u for t in trs])
    Y = np.stack([t.y for t in trs])
    res = est.run(U, Y)
    vf = res.valid_from
    assert res.contains(np.stack([t.x for t in trs]))[:, vf:].all()
    for b in range(3):
        ref = est.run(U[b], Y[b], vectorize=False)
        scale = 1.0 + np.abs(ref.upper[vf:])
        assert np.max(np.abs(res.upper[b, vf:] - ref.upper[vf:]) / scale) < 1e-9


@pytest.mark.parametrize("method", FAST)
def test_an_inconsistent_stream_is_reported_and_the_others_are_unchanged(method):
    sc = ivobs.scenarios.get("servo-motor", horizon=120)
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, on_inconsistent="ignore")
    U, Y, X = _streams(sc, 3, 120, seed=7)
    clean = est.run(U, Y)
    Y = Y.copy()
    Y[1, 60, 0] += 5.0  # a sensor fault in stream 1
    res = est.run(U, Y)
    assert res.inconsistent[1, 60] and not res.inconsistent[[0, 2]].any()
    np.testing.assert_allclose(res.upper[[0, 2]], clean.upper[[0, 2]], rtol=1e-12)  # unchanged
    ref = est.run(U, Y[1], vectorize=False)  # the faulty stream as the loop treats it
    np.testing.assert_allclose(res.upper[1], ref.upper, rtol=1e-9, atol=1e-12)
    assert ref.inconsistent[60]
    vf = res.valid_from
    assert res.contains(X)[:, vf:].all()  # the fault was not used


def test_batches_larger_than_one_chunk_and_identical_streams():
    # 700 streams x 1000 steps: more than one chunk of the base class; identical streams must
    # give identical boxes (no stream-dependent rounding)
    sc = ivobs.scenarios.get("servo-motor", horizon=1000)
    tr = sc.simulate("vertex", seed=3)
    Y = np.broadcast_to(tr.y, (700, 1000, 2))
    for method in ("interval", "kkl"):
        res = ivobs.make_estimator(method, sc.system, x0=sc.x0).run(tr.u, Y)
        assert res.lower.shape == (700, 1000, 3)
        assert (res.upper == res.upper[0]).all() and (res.lower == res.lower[0]).all()
        assert res.contains(np.broadcast_to(tr.x, (700, 1000, 3))).all()


@pytest.fixture(scope="module")
def long_servo():
    sc = ivobs.scenarios.get("servo-motor", horizon=16_000)
    return sc, sc.simulate("sinusoidal")


@pytest.mark.parametrize("method", ("reachability", "interval", "kkl", "fixed-time"))
def test_memory_of_a_long_record_is_linear_in_its_length(method, long_servo):
    # peak of run() over T steps, in floats per (step x state); docs/scale.md gives the numbers
    # for 10^6 steps (benchmarks/bench_batch.py --memory)
    sc, tr = long_servo
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    peaks = []
    for T in (8_000, 16_000):
        est.run(tr.u[:T], tr.y[:T])  # warm caches (designs, filters)
        tracemalloc.start()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            est.run(tr.u[:T], tr.y[:T])
        peaks.append(tracemalloc.get_traced_memory()[1] / (8 * T * sc.system.nx))
        tracemalloc.stop()
    assert peaks[1] < 12.0  # floats per step and state: O(T nx) with a small constant
    assert peaks[1] < 1.15 * peaks[0] + 0.5  # and no term that grows faster than T


@pytest.mark.parametrize("method", ("interval", "interval-split", "interval-transformed", "kkl"))
def test_batch_with_time_varying_bounds(method):
    T = 40
    r = np.linspace(0.5, 1.0, T)[:, None]
    sys = ivobs.LinearSystem(
        [[0.5, 0.2], [-0.1, 0.6]],
        [[1.0], [0.0]],
        [[1.0, 0.0]],
        E=[[0.3], [0.1]],
        F=[[0.1]],
        d=ivobs.Box(-r, r),
    )
    x0 = ivobs.Box([-1.0, -1.0], [1.0, 1.0])
    trs = [
        ivobs.simulate(
            sys,
            [1.0, -1.0],
            np.sin(np.arange(T) + b)[:, None],
            np.where(np.arange(T)[:, None] % (b + 2) == 0, r, -r),
        )
        for b in range(3)
    ]
    U, Y = np.stack([t.u for t in trs]), np.stack([t.y for t in trs])
    est = ivobs.make_estimator(method, sys, x0=x0)
    res = est.run(U, Y)  # the (T, ·) bound terms are shared by the streams
    assert res.contains(np.stack([t.x for t in trs])).all()
    for b in range(3):
        ref = est.run(U[b], Y[b], vectorize=False)
        np.testing.assert_allclose(res.upper[b], ref.upper, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("method", FAST)
def test_empty_records_and_systems_without_inputs(method):
    sys = ivobs.LinearSystem(
        [[0.5, 0.2], [0.0, 0.4]],
        C=[[1.0, 0.0], [0.0, 1.0]],
        E=0.1 * np.eye(2),
        F=np.zeros((2, 2)),
        d=ivobs.Box.symmetric([1.0, 1.0]),
    )
    x0 = ivobs.Box([-1.0, -1.0], [1.0, 1.0])
    est = ivobs.make_estimator(method, sys, x0=x0)
    assert est.run(None, np.zeros((0, 2)), vectorize=True).lower.shape == (0, 2)
    tr = ivobs.simulate(sys, [0.5, -0.5], None, ivobs.vertex_disturbance(sys.d, 300, seed=1))
    vec = est.run(None, tr.y, vectorize=True)  # nu = 0
    ref = est.run(None, tr.y, vectorize=False)
    vf = vec.valid_from
    assert vec.contains(tr.x)[vf:].all()
    np.testing.assert_allclose(vec.upper[vf:], ref.upper[vf:], rtol=1e-9, atol=1e-12)
    batch = est.run(None, np.stack([tr.y, tr.y]))
    np.testing.assert_allclose(batch.upper[1, vf:], ref.upper[vf:], rtol=1e-9, atol=1e-12)


def test_a_batch_of_empty_records():
    """``(B, 0, ny)``: an empty estimate of shape ``(B, 0, nx)`` (no division by the length)."""
    sys_ = random_system(5, nx=3, ny=1, nu=1)
    est = ivobs.make_estimator("reachability", sys_, x0=ivobs.Box([-1] * 3, [1] * 3))
    res = est.run(np.zeros((0, 1)), np.zeros((4, 0, 1)))
    assert res.lower.shape == (4, 0, 3) and res.upper.shape == (4, 0, 3)
