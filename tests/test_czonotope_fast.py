"""The fast paths of the constrained-zonotope filter against reference computations.

The hull LPs (HiGHS chains, and the fallback) are checked against ``scipy.optimize.linprog``
on random sets; the elimination's rewritten kernels
(propagation, loss, factor choice) against straightforward implementations written here (the
code they replaced), bit for bit; and the filter's boxes against a simulator written here under
vertex (adversarial) disturbances.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

import ivobs
from ivobs.sets.czonotope import _highs, elimination, hull
from ivobs.sets.czonotope._tolerances import PIVOT_TOL, ZERO_TOL


def _random_set(
    rng: np.random.Generator, n: int, m: int, nc: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    G = rng.normal(size=(n, m))
    A = rng.normal(size=(nc, m))
    A[rng.random(A.shape) < 0.3] = 0.0
    xi = rng.uniform(-1.0, 1.0, m)
    edge = rng.random(m) < 0.5
    xi[edge] = np.where(xi[edge] >= 0, 1.0, -1.0)  # a point on the boundary
    return rng.normal(size=n), G, A, A @ xi


def _linprog_hull(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Optimal ``min/max x_i`` by linprog, and the minimisers' points (feasible: inside)."""
    lo, hi, pts = [], [], []
    for i in range(G.shape[0]):
        for sign, out in ((1.0, lo), (-1.0, hi)):
            res = linprog(sign * G[i], A_eq=A, b_eq=b, bounds=(-1, 1), method="highs")
            assert res.status == 0
            out.append(c[i] + G[i] @ res.x)
            pts.append(c + G @ res.x)
    return np.array(lo), np.array(hi), np.array(pts)


@pytest.mark.parametrize("seed", range(6))
def test_hull_equals_linprog_and_is_sound(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n, m, nc = 3 + seed % 3, 12 + 5 * seed, 1 + seed
    c, G, A, b = _random_set(rng, n, m, nc)
    P = rng.normal(size=(2, m))  # extra objectives, as the filter's prediction rows
    out = hull.hull_certificates(c, G, A, b, P)
    assert out is not None
    lo, hi, cert = out
    ref_lo, ref_hi, pts = _linprog_hull(c, G, A, b)
    scale = 1.0 + np.abs(G).sum(axis=1)
    # tight: the optimum to LP tolerance
    assert np.all(np.abs(lo - ref_lo) <= 1e-9 * scale)
    assert np.all(np.abs(hi - ref_hi) <= 1e-9 * scale)
    # sound: every optimal point (a point of the set) lies in the certified box
    assert np.all(pts >= lo - 1e-12 * scale) and np.all(pts <= hi + 1e-12 * scale)
    # the certificates of the extra rows bound P ξ from below, at the optimum
    vals = hull._dual_bounds(cert.D, A, b, cert.mu, 1.0)
    for row, v in zip(np.vstack([P, -P]), vals[2 * n :], strict=True):
        opt = linprog(row, A_eq=A, b_eq=b, bounds=(-1, 1), method="highs").fun
        assert v <= opt + 1e-12 * (1 + np.abs(row).sum())
        assert v >= opt - 1e-9 * (1 + np.abs(row).sum())


def test_a_failing_program_sends_all_to_the_fallback(monkeypatch: pytest.MonkeyPatch) -> None:
    """HiGHS failing on one program of the chain: every program is solved by the fallback
    (their multipliers, not a mix, are what the elimination's choices were tuned on), and the
    bounds are the same to LP tolerance."""
    rng = np.random.default_rng(7)
    c, G, A, b = _random_set(rng, 3, 20, 4)
    ref = hull.hull_certificates(c, G, A, b)
    assert ref is not None
    calls = {"fallback": 0}
    real_min = hull._certified_min

    def failed(*args: object, **kw: object) -> str:
        return "failed"

    def counted(*args: object, **kw: object) -> object:
        calls["fallback"] += 1
        return real_min(*args, **kw)  # type: ignore[arg-type]

    real_first = _highs.linprog_duals

    def counted_first(Gs: np.ndarray, *args: object) -> object:  # linprog's first attempt
        out = real_first(Gs, *args)  # type: ignore[arg-type]
        calls["fallback"] += int(np.all(np.isfinite(out), axis=1).sum())
        return out

    monkeypatch.setattr(_highs, "chain_duals", failed)
    monkeypatch.setattr(hull, "_certified_min", counted)
    monkeypatch.setattr(_highs, "linprog_duals", counted_first)
    out = hull.hull_certificates(c, G, A, b)
    assert out is not None
    assert calls["fallback"] == 2 * G.shape[0]
    scale = 1.0 + np.abs(G).sum(axis=1)
    assert np.all(np.abs(out[0] - ref[0]) <= 1e-9 * scale)
    assert np.all(np.abs(out[1] - ref[1]) <= 1e-9 * scale)


def test_infeasible_set_is_not_given_a_box() -> None:
    # x1 = 2 with |ξ| <= 1 and x1 = ξ1 + ξ2 - 0.1 ξ3: needs 2 <= 2.1, feasible; 2.5: empty
    G = np.eye(3)
    A = np.array([[1.0, 1.0, -0.1]])
    assert hull.hull_certificates(np.zeros(3), G, A, np.array([2.0])) is not None
    assert hull.hull_certificates(np.zeros(3), G, A, np.array([2.5])) is None


def _propagate_reference(
    A: np.ndarray, b: np.ndarray, sweeps: int = 3
) -> tuple[np.ndarray, np.ndarray] | None:
    """The propagation as it was written before (all sweeps, fresh arrays)."""
    m = A.shape[1]
    lo, hi = -np.ones(m), np.ones(m)
    absA = np.abs(A)
    nz = absA > ZERO_TOL * np.maximum(1.0, absA.max(axis=1, keepdims=True))
    safe = np.where(nz, A, 1.0)
    for _ in range(sweeps):
        t_lo = np.minimum(A * lo, A * hi)
        t_hi = np.maximum(A * lo, A * hi)
        rest_lo = t_lo.sum(axis=1, keepdims=True) - t_lo
        rest_hi = t_hi.sum(axis=1, keepdims=True) - t_hi
        q1 = (b[:, None] - rest_hi) / safe
        q2 = (b[:, None] - rest_lo) / safe
        pad = 1e-10 * (1.0 + np.abs(q1) + np.abs(q2))
        new_lo = np.where(nz, np.minimum(q1, q2) - pad, -np.inf).max(axis=0, initial=-np.inf)
        new_hi = np.where(nz, np.maximum(q1, q2) + pad, np.inf).min(axis=0, initial=np.inf)
        lo = np.maximum(lo, new_lo)
        hi = np.minimum(hi, new_hi)
        if np.any(lo > hi + 1e-9):
            return None
        hi = np.maximum(hi, lo)
    return lo, hi


def test_propagation_equals_reference_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    empty = 0
    for trial in range(60):
        nc, m = int(rng.integers(1, 12)), int(rng.integers(2, 60))
        _, _, A, b = _random_set(rng, 1, m, nc)
        if trial % 3 == 0:
            b = b + 3.0 * rng.normal(size=nc)  # often empty
        A, b, _ = elimination._normalise_rows_s(A, b)
        ref, got = _propagate_reference(A, b), elimination._propagate(A, b)
        assert (ref is None) == (got is None)
        empty += ref is None
        if ref is not None and got is not None:
            assert np.array_equal(ref[0], got[0]) and np.array_equal(ref[1], got[1])
    assert 0 < empty < 60  # both outcomes exercised


@pytest.mark.parametrize("chunk", [1, 7, 1 << 16])
def test_loss_kernel_equals_direct_formula(monkeypatch: pytest.MonkeyPatch, chunk: int) -> None:
    monkeypatch.setattr(hull, "_CHUNK", chunk)
    rng = np.random.default_rng(chunk)
    R, T, P = rng.normal(size=(9, 13)), rng.normal(size=(9, 5)), rng.normal(size=(5, 13))
    direct = np.abs(R[:, None, :] - T[:, :, None] * P[None, :, :]).sum(axis=2)
    assert np.array_equal(hull._shifted_l1(R, T, P), direct)


def _choose_reference(
    G: np.ndarray, A: np.ndarray, b: np.ndarray, cert: hull.Certificates
) -> tuple[int, int] | None:
    """The factor choice as it was written before (Hausdorff estimate always computed)."""
    m = A.shape[1]
    R, err = elimination._elimination_scores(G, A, b)
    piv = np.argmax(np.abs(A), axis=0)
    cand = np.isfinite(R) & (np.abs(A[piv, np.arange(m)]) >= PIVOT_TOL)
    if not np.any(cand):
        return None
    shape = np.where(cand & np.isfinite(err), err, np.inf)
    if not np.any(np.isfinite(shape)):
        with np.errstate(invalid="ignore"):
            shape = np.where(cand, R * np.linalg.norm(G, axis=0), np.inf)
    loss = cert.elimination_loss(A, b, piv, cand)
    best = loss.min()
    ties = loss <= best + 1e-9 * (1.0 + abs(best))
    key = np.where(ties, shape, np.inf)
    if not np.any(np.isfinite(key)):
        key = loss
    j = int(np.argmin(key))
    return j, int(piv[j])


def test_factor_choice_equals_reference() -> None:
    rng = np.random.default_rng(11)
    unique = 0
    for _ in range(40):
        n, nc = int(rng.integers(2, 5)), int(rng.integers(2, 6))
        m = nc + int(rng.integers(2, 20))
        c, G, A, b = _random_set(rng, n, m, nc)
        out = hull.hull_certificates(c, G, A, b)
        assert out is not None
        cert = out[2]
        A, b, s = elimination._normalise_rows_s(A, b)
        cert.scale_rows(s)
        got = elimination._choose_factor(G, A, b, cert)
        assert got == _choose_reference(G, A, b, cert)
        piv = np.argmax(np.abs(A), axis=0)
        loss = cert.elimination_loss(A, b, piv)
        unique += int(np.count_nonzero(loss <= loss.min() + 1e-9 * (1 + abs(loss.min()))) == 1)
    assert unique > 0  # the shortcut (a unique least loss) was taken


def _simulate(
    A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, x0: np.ndarray, d: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``x+ = A x + E d``, ``y = C x + F d`` (no input), step by step."""
    xs, ys, x = [], [], x0
    for dk in d:
        xs.append(x)
        ys.append(C @ x + F @ dk)
        x = A @ x + E @ dk
    return np.array(xs), np.array(ys)


def _vertex_case(
    rng: np.random.Generator, ny: int, rho: float, n: int = 3, T: int = 60
) -> tuple[ivobs.LinearSystem, np.ndarray, np.ndarray]:
    """A random system of spectral radius ``rho`` with ``d`` in the unit box, its states and
    outputs over ``T`` steps with ``d`` on the box's vertices and ``x[0]`` partly on the prior
    box's boundary (``[-1, 1]^n``)."""
    A = rng.normal(size=(n, n))
    A *= rho / max(abs(np.linalg.eigvals(A)))
    C = rng.normal(size=(ny, n))
    E = np.hstack([0.1 * np.eye(n), np.zeros((n, ny))])
    F = np.hstack([np.zeros((ny, n)), 0.05 * np.eye(ny)])
    d = np.where(rng.integers(0, 2, (T, n + ny)) > 0, 1.0, -1.0)  # vertices of the box
    x0 = rng.uniform(-1.0, 1.0, n)
    x0[rng.random(n) < 0.5] = 1.0  # on the prior box's boundary
    xs, ys = _simulate(A, C, E, F, x0, d)
    sys_ = ivobs.LinearSystem(
        A, np.zeros((n, 1)), C, E=E, F=F, d=ivobs.Box(-np.ones(n + ny), np.ones(n + ny))
    )
    return sys_, xs, ys


@pytest.mark.parametrize("seed", range(3))
def test_filter_contains_the_state_under_vertex_disturbances(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    n, T = 3, 60
    # up to marginally stable
    sys_, xs, ys = _vertex_case(rng, 1 + seed % 2, 0.9 + 0.1 * seed, n, T)
    est = ivobs.make_estimator("constrained-zonotope", sys_, x0=ivobs.Box(-np.ones(n), np.ones(n)))
    widths = []
    for k in range(T):
        box = est.step(np.zeros(1), ys[k])
        assert np.all(box.lo <= xs[k]) and np.all(xs[k] <= box.hi), k
        widths.append(box.hi - box.lo)
    assert np.all(np.isfinite(widths)) and np.max(widths[-1]) < 2.0  # bounded, informative
