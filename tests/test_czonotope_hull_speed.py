"""The constrained-zonotope speed work of 2026-11-27 against what it replaced.

* The filters' boxes equal (on the recording machine; the same widths elsewhere) those of the
  implementation before it (commit 8486d05, stored in
  ``tests/data/czonotope_reference_bounds.npz``) on the servo (2,000 steps, vertex
  disturbances), Hénon with ``nl-constrained-zonotope`` (1,000 steps) and the first 20 steps of
  CORA's tank30 record: the LP multipliers steer the elimination, so any change in them (even
  an equally optimal one on a degenerate program) would show here.
* The rewritten kernels against the code they replaced, bit for bit (memory layout included:
  it decides how BLAS rounds the products that follow).
* The block program (:func:`ivobs.sets.czonotope._highs.block_duals`, not the default) gives
  the chain's bounds to LP tolerance, sound ones, and a filter using it contains the state of a
  simulator written here under vertex disturbances.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

import ivobs
from ivobs.sets.czonotope import _highs, elimination, hull
from ivobs.sets.czonotope._tolerances import ROW_TOL
from test_czonotope_fast import _random_set, _vertex_case
from test_nl_zonotope_fast import _henon

REFERENCE = Path(__file__).parent / "data" / "czonotope_reference_bounds.npz"


def _run(case: str) -> tuple[np.ndarray, np.ndarray]:
    if case == "servo":
        sc = ivobs.scenarios.get("servo-motor", horizon=2000)
        tr = sc.simulate("vertex", seed=0)
        est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0)
        res = est.run(tr.u, tr.y)
        assert np.all(res.contains(tr.x))
    elif case == "henon":
        x0 = ivobs.Box([0.2, 0.0], [0.4, 0.2])
        henon, y = _henon()  # the first 1,000 of its 2,000 steps
        est = ivobs.make_estimator("nl-constrained-zonotope", henon, x0=x0)
        res = est.run(np.zeros((1000, 0)), y[:1000])
    else:
        sc = ivobs.scenarios.get("cora-tank30")
        tr = sc.recorded
        est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0)
        res = est.run(tr.u[:20], tr.y[:20])
    return res.lower, res.upper


@pytest.mark.parametrize("case", ["servo", "henon", "tank"])
def test_boxes_equal_the_previous_implementation(case: str) -> None:
    ref = np.load(REFERENCE)
    lo, hi = _run(case)
    rlo, rhi = ref[f"{case}_lo"], ref[f"{case}_hi"]
    assert lo.shape == rlo.shape
    # Bit for bit on the machine that recorded them (checked when merged); elsewhere another
    # BLAS may round a product differently, the LP then returns another of several equally
    # optimal multipliers and the elimination another factor: the boxes may differ step by step
    # by a few per cent while the widths stay the same on the whole, which is what is asserted.
    w, rw = hi - lo, rhi - rlo
    assert abs(w.mean() / rw.mean() - 1.0) <= 2e-3
    assert np.max(w / rw) <= 1.05


def _drop_zero_idx_reference(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, ...]:
    """``_drop_zero_idx`` as it was written before."""
    scale = 1.0 + (np.abs(A).max() if A.size else 0.0)
    rows = np.any(np.abs(A) > ROW_TOL * scale, axis=1)
    zb, za = b[~rows], np.abs(A[~rows]).sum(axis=1)
    consistent = bool(np.all(np.abs(zb) <= za + 1e-8 * (1.0 + np.abs(zb))))
    A, b = A[rows], b[rows]
    cols = np.any(G != 0, axis=0) | np.any(A != 0, axis=0)
    return c, G[:, cols], A[:, cols], b, rows, cols, consistent


def test_drop_zero_idx_equals_reference_layout_included() -> None:
    rng = np.random.default_rng(5)
    kinds = set()
    for trial in range(40):
        c, G, A, b = _random_set(rng, 3, int(rng.integers(3, 30)), int(rng.integers(1, 8)))
        if trial % 4 == 1:
            A[0] = 1e-12 * rng.normal(size=A.shape[1])  # a row of rounding noise
            b[0] = 0.5 if trial % 8 == 1 else 0.0  # ... inconsistent, or not
        if trial % 4 == 2:
            G[:, 0] = 0.0
            A[:, 0] = 0.0  # a zero generator
        if trial % 2:
            G, A = np.asfortranarray(G), np.asfortranarray(A)
        ref = _drop_zero_idx_reference(c, G, A, b)
        got = elimination._drop_zero_idx(c, G, A, b)
        kinds.add((bool(np.all(ref[4])), bool(np.all(ref[5])), ref[6]))
        for r, g in zip(ref, got, strict=True):
            if isinstance(r, np.ndarray):
                assert np.array_equal(r, g) and r.dtype == g.dtype
                assert r.flags.c_contiguous == g.flags.c_contiguous
                assert r.flags.f_contiguous == g.flags.f_contiguous
            else:
                assert r == g
    assert len(kinds) >= 4  # rows dropped or not, columns dropped or not, empty or not


@pytest.mark.parametrize("order", ["C", "F"])
def test_loss_bound_uses_the_same_row_sums(order: str) -> None:
    """The screening bound of ``elimination_loss`` sums ``|A|`` once per constraint instead of
    once per factor: the same candidates, so the same losses, bit for bit."""
    rng = np.random.default_rng(1 if order == "C" else 2)
    for _ in range(10):
        c, G, A, b = _random_set(rng, 3, 70, 6)
        out = hull.hull_certificates(c, G, A, b)
        assert out is not None
        cert = out[2]
        A = np.asarray(A, order=order)
        piv = np.argmax(np.abs(A), axis=0)
        got = cert.elimination_loss(A, b, piv)
        assert np.array_equal(got, _loss_reference(cert, A, b, piv))
        assert np.count_nonzero(np.isfinite(got)) == hull.LOSS_CANDIDATES


def _loss_reference(
    cert: hull.Certificates, A: np.ndarray, b: np.ndarray, piv: np.ndarray
) -> np.ndarray:
    """``Certificates.elimination_loss`` as it was written before (every candidate)."""
    m = A.shape[1]
    Rc = cert.D - cert.mu @ A
    apj = A[piv, np.arange(m)]
    t = Rc / np.where(apj != 0, apj, 1.0)
    upper = cert.weight @ np.abs(t) * (np.abs(A[piv]).sum(axis=1) + np.abs(b[piv]))
    idx = np.arange(m)
    idx = idx[np.argsort(upper[idx], kind="stable")[: hull.LOSS_CANDIDATES]]
    out = np.full(m, np.inf)
    tj = t[:, idx]
    new = hull._shifted_l1(Rc, tj, A[piv[idx]])
    loss = new - tj * b[piv[idx]][None, :] - np.abs(Rc).sum(axis=1, keepdims=True)
    out[idx] = cert.weight @ loss
    return out


@pytest.mark.parametrize("seed", range(5))
def test_block_program_gives_the_chain_bounds(seed: int) -> None:
    rng = np.random.default_rng(40 + seed)
    n, m, nc = 3, 10 + 6 * seed, 1 + seed
    _, G, A, b = _random_set(rng, n, m, nc)
    Gs = np.vstack([G, -G])
    chain = _highs.chain_duals(Gs, A, b, 1.0, [list(range(2 * n))])
    block = _highs.block_duals(Gs, A, b, 1.0)
    assert isinstance(chain, np.ndarray) and isinstance(block, np.ndarray)
    assert block.shape == chain.shape == (2 * n, nc)
    v_chain = hull._dual_bounds(Gs, A, b, chain, 1.0)
    v_block = hull._dual_bounds(Gs, A, b, block, 1.0)
    scale = 1.0 + np.abs(Gs).sum(axis=1)
    assert np.all(np.abs(v_block - v_chain) <= 1e-9 * scale)
    for row, v in zip(Gs, v_block, strict=True):  # sound: below the optimum
        opt = linprog(row, A_eq=A, b_eq=b, bounds=(-1, 1), method="highs").fun
        assert v <= opt + 1e-12 * (1.0 + np.abs(row).sum())


def test_block_program_reports_an_infeasible_set() -> None:
    G = np.eye(3)
    A = np.array([[1.0, 1.0, -0.1]])  # needs |b| <= 2.1
    Gs = np.vstack([G, -G])
    assert isinstance(_highs.block_duals(Gs, A, np.array([2.0]), 1.0), np.ndarray)
    assert _highs.block_duals(Gs, A, np.array([2.5]), 1.0) == "infeasible"


@pytest.mark.parametrize("seed", range(2))
def test_filter_with_the_block_program_contains_the_state(
    monkeypatch: pytest.MonkeyPatch, seed: int
) -> None:
    monkeypatch.setattr(_highs, "BLOCK_MAX", 10**6)
    used = {"block": 0}
    real = _highs.block_duals

    def counted(*args: object) -> object:
        used["block"] += 1
        return real(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(_highs, "block_duals", counted)
    rng = np.random.default_rng(300 + seed)
    n, T = 3, 60
    sys_, xs, ys = _vertex_case(rng, 1 + seed, 0.95, n, T)
    est = ivobs.make_estimator("constrained-zonotope", sys_, x0=ivobs.Box(-np.ones(n), np.ones(n)))
    widths = []
    for k in range(T):
        box = est.step(np.zeros(1), ys[k])
        assert np.all(box.lo <= xs[k]) and np.all(xs[k] <= box.hi), k
        widths.append(box.hi - box.lo)
    assert used["block"] >= T  # the block program was used at every step
    assert np.max(widths[-1]) < 2.0  # informative
