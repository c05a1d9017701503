"""Parity-space design [Wang2020]: stacked matrices (eq. 6), optimal T (Theorem 1, eq. 13),
general solution (Lemma 2), output injection (Remark 1)."""

import numpy as np
import pytest

import ivobs
from ivobs import DesignError, IvobsError
from ivobs.design.certify import forward_window, window_bound
from ivobs.design.injection import injection_candidates, invertible_injection, is_invertible
from ivobs.design.parity import general_T, optimal_T, pinv_perp, stack_window, width_optimal_T
from ivobs.linalg import is_observable
from ivobs.testing import random_system


def _stack(sys, s):
    """``(Mx, Mu, Md)`` of eq. (6) for a time-invariant system, window ``s``."""
    return stack_window([sys.matrices_at(0)] * (s + 1))


@pytest.fixture(scope="module")
def paper():
    sc = ivobs.scenarios.get("dinh2019")
    sys = sc.system
    Mx, Mu, Md = _stack(sys, 2)
    return sc.reference, Mx, Mu, Md, optimal_T(Mx, Md)


def test_paper_stacked_matrices_to_4_decimals(paper):
    ref, Mx, Mu, Md, _ = paper
    assert Mu.shape == (3, 6)  # the paper prints a 5-entry first row: it is 6 zeros
    for name, val in (("Mx", Mx), ("Mu", Mu), ("Md", Md)):
        np.testing.assert_array_equal(np.round(val, 4), ref[name], err_msg=name)


def test_paper_theorem1_quantities_to_4_decimals(paper):
    ref, _, _, _, opt = paper
    np.testing.assert_array_equal(np.round(opt.Mx_pinv, 4), ref["Mx_pinv"])
    np.testing.assert_array_equal(np.round(opt.Mx_perp, 4), ref["Mx_perp"])
    assert opt.rank == 1
    np.testing.assert_array_equal(np.round(opt.S1.ravel(), 4), [ref["S1"]])
    # singular vectors are defined up to a common sign
    sign = np.sign(opt.U1[0, 0] * ref["U1"][0])
    np.testing.assert_array_equal(np.round(sign * opt.U1.ravel(), 4), ref["U1"])
    np.testing.assert_array_equal(np.round(sign * opt.V1.ravel(), 4) + 0.0, ref["V1"])
    np.testing.assert_array_equal(np.round(opt.T, 4), ref["T"])


def _simulate_window(sys, s, k, rng):
    """A random trajectory; returns x_k, stacked y, u, d of the window ending at k."""
    T = k + 1
    u = rng.normal(size=(T, sys.nu))
    d = rng.uniform(sys.d.lo, sys.d.hi, size=(T, sys.nd))
    tr = ivobs.simulate(sys, rng.normal(size=sys.nx), u, d)
    lags = [k - i for i in range(s + 1)]
    return tr.x[k], tr.y[lags].ravel(), u[lags].ravel(), d[lags].ravel()


@pytest.mark.parametrize("seed", range(4))
def test_stack_identity_with_feedthrough(seed):
    """y_k = Mx x_k + Mu u_k + Md d_k holds exactly (eq. 6), with D u in the output."""
    rng = np.random.default_rng(seed)
    sys = random_system(seed, nx=3, ny=2, nu=2, feedthrough=True, symmetric_bounds=False)
    s = 3
    Mx, Mu, Md = _stack(sys, s)
    np.testing.assert_array_equal(Mu[:2, :2], sys.D)  # D u_k in the first block row
    np.testing.assert_array_equal(Mu[:2, 2:], 0.0)
    x, ys, us, ds = _simulate_window(sys, s, 10, rng)
    np.testing.assert_allclose(ys, Mx @ x + Mu @ us + Md @ ds, atol=1e-10)


def test_stack_identity_time_varying():
    """Remark 4: the window of a time-varying system, from A(k), C(k), ... per step."""
    rng = np.random.default_rng(5)

    def A(k):
        return np.array([[0.9, 0.3 * np.sin(k)], [-0.2, 0.7 + 0.2 * np.cos(0.3 * k)]])

    def C(k):
        return np.array([[1.0, 0.2 * k % 1.0]])

    def D(k):
        return np.array([[0.5 + 0.1 * k]])

    sys = ivobs.LinearSystem(
        A, [[0.0], [1.0]], C, D=D, E=[[0.1], [0.2]], F=[[0.05]], d=ivobs.Box([-1.0], [0.5])
    )
    s, k = 3, 9
    mats = [sys.matrices_at(k - i) for i in range(s + 1)]
    Mx, Mu, Md = stack_window(mats)
    x, ys, us, ds = _simulate_window(sys, s, k, rng)
    np.testing.assert_allclose(ys, Mx @ x + Mu @ us + Md @ ds, atol=1e-10)


def test_optimal_T_beats_every_general_solution():
    """Theorem 1: ‖T Md‖_F <= ‖(Mx† + S Mx⊥) Md‖_F for any S, and T Mx = I."""
    rng = np.random.default_rng(0)
    for seed in range(5):
        sys = random_system(seed, nx=3, ny=2, nu=1)
        Mx, _, Md = _stack(sys, 3)
        opt = optimal_T(Mx, Md)
        np.testing.assert_allclose(opt.T @ Mx, np.eye(3), atol=1e-10)
        best = np.linalg.norm(opt.T @ Md)
        # the closed form agrees with least squares min_X ‖Mx† Md + X Mx⊥ Md‖ (rank-aware)
        P = opt.Mx_perp @ Md
        X = np.linalg.lstsq(P.T, -(opt.Mx_pinv @ Md).T, rcond=1e-9)[0].T
        assert best == pytest.approx(np.linalg.norm((opt.Mx_pinv + X @ opt.Mx_perp) @ Md))
        # a naive pseudo-inverse of Mx⊥ Md inverts rounding-level singular values when ‖Md‖
        # is large (seeds 1-3: ‖X‖ ~ 1e13) and then breaks T Mx = I; where it does not, it
        # agrees with the rank-robust T
        X = -opt.Mx_pinv @ Md @ np.linalg.pinv(P)
        T_naive = opt.Mx_pinv + X @ opt.Mx_perp
        if np.abs(T_naive @ Mx - np.eye(3)).max() < 1e-8:
            assert best == pytest.approx(np.linalg.norm(T_naive @ Md))
        else:
            assert seed in (1, 2, 3)
        for _ in range(20):
            S = rng.normal(size=(3, Mx.shape[0])) * rng.choice([1e-3, 1.0, 10.0])
            T = general_T(Mx, S)
            np.testing.assert_allclose(T @ Mx, np.eye(3), atol=1e-9)
            assert best <= np.linalg.norm(T @ Md) + 1e-12


def test_rank_decision_ignores_rounding_level_singular_values():
    """Md inside the range of Mx: Mx⊥ Md is zero up to rounding, so r = 0 and T = Mx†
    (a rounding-level singular value, inverted, would blow T up)."""
    rng = np.random.default_rng(1)
    Mx = rng.normal(size=(6, 2))
    Md = Mx @ rng.normal(size=(2, 5)) * 1e3
    _, _, N, _ = pinv_perp(Mx)
    assert 0 < np.linalg.svd(N @ Md, compute_uv=False)[0] < 1e-9  # rounding, not zero
    opt = optimal_T(Mx, Md)
    assert opt.rank == 0
    np.testing.assert_allclose(opt.T, np.linalg.pinv(Mx), atol=1e-12)
    # square Mx (s = nx - 1, one output): Mx⊥ = 0, T = Mx⁻¹
    sq = rng.normal(size=(3, 3))
    opt = optimal_T(sq, rng.normal(size=(3, 4)))
    assert opt.rank == 0
    np.testing.assert_allclose(opt.T, np.linalg.inv(sq), atol=1e-10)


def test_weighted_and_width_criteria():
    sys = random_system(3, nx=3, ny=2, nu=1, nd=4)
    Mx, _, Md = _stack(sys, 3)
    W = np.tile(sys.d.radius, 4)
    Tf = optimal_T(Mx, Md).T
    Tw = optimal_T(Mx, Md, W).T
    Tl1 = width_optimal_T(Mx, Md, W)
    for T in (Tw, Tl1):
        np.testing.assert_allclose(T @ Mx, np.eye(3), atol=1e-10)
    assert np.linalg.norm(Tw @ Md * W) <= np.linalg.norm(Tf @ Md * W) + 1e-12
    widths = [np.abs(T @ Md * W).sum(axis=1) for T in (Tf, Tw, Tl1)]
    assert np.all(widths[2] <= widths[0] + 1e-9) and np.all(widths[2] <= widths[1] + 1e-9)


def test_general_T_shape_and_rank_errors():
    Mx = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    with pytest.raises(IvobsError, match=r"S: expected shape \(2, 3\)"):
        general_T(Mx, np.zeros((2, 2)))
    np.testing.assert_allclose(general_T(Mx, np.zeros((2, 3))), np.linalg.pinv(Mx))
    with pytest.raises(DesignError, match="rank 1 < nx = 2"):
        optimal_T(np.array([[1.0, 1.0], [2.0, 2.0]]), np.eye(2))


def test_output_injection_makes_A_invertible_and_keeps_observability():
    for seed in range(6):
        sys = random_system(seed, nx=3 + seed % 2, ny=1 + seed % 2, invertible=False)
        assert not is_invertible(sys.A)
        cands = injection_candidates(sys.A, sys.C)
        assert len(cands) >= 2
        for L in cands:
            Ap = sys.A - L @ sys.C
            assert is_invertible(Ap) and is_observable(Ap, sys.C)
        # the last candidate is the pole placement at 0.5 ... 0.9
        np.testing.assert_allclose(
            np.sort(np.linalg.eigvals(sys.A - cands[-1] @ sys.C).real),
            np.linspace(0.5, 0.9, sys.nx),
            atol=1e-6,
        )
        L = invertible_injection(sys.A, sys.C)
        assert any(np.array_equal(L, c) for c in cands)
        assert np.linalg.cond(sys.A - L @ sys.C) <= min(
            np.linalg.cond(sys.A - c @ sys.C) * (1 + np.linalg.norm(c @ sys.C, 2)) for c in cands
        )
    with pytest.raises(DesignError, match="C = 0"):
        invertible_injection(np.zeros((2, 2)), np.zeros((1, 2)))


def test_injection_is_small_and_well_conditioned():
    """A singular A (eigenvalues 0, -0.94, -0.99, ‖A‖ = 13.7). Placing the
    poles at 0.5 ... 0.9 needs |L| = 156 and gives cond(A - LC) = 2e6; the minimal-norm gain
    that only lifts the null direction of A needs |L| < 1 and gives cond(A - LC) < 20."""
    base = random_system(44, nx=3, ny=1, nu=1, invertible=False, rho=0.99)
    A, C = base.A, base.C
    placed = injection_candidates(A, C)[-1]
    assert np.abs(placed).max() > 100 and np.linalg.cond(A - placed @ C) > 1e6
    L = invertible_injection(A, C)
    assert np.abs(L).max() < 1.0
    assert np.linalg.cond(A - L @ C) < 20.0
    assert is_observable(A - L @ C, C)


def test_singular_A_in_window_is_a_design_error():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    with pytest.raises(DesignError, match="not invertible"):
        z = np.zeros((2, 0))
        stack_window([(A, z, np.array([[1.0, 0.0]]), z[:1], z, z[:1])] * 2)


# -- certification of a window gain on the forward form -------------------------------------
def _window_data(sys, s, k, rng, centre):
    """(w, ξ, x_k) of the window ending at k of a random trajectory, in the layouts of
    forward_window: w = [z_k; …; z_{k-s}], z = [u; y; c]; ξ = [x_{k-s}; v lag-major; δ]."""
    T = k + 1
    u = rng.normal(size=(T, sys.nu))
    d = rng.uniform(sys.d.lo, sys.d.hi, size=(T, sys.nd))
    tr = ivobs.simulate(sys, rng.normal(size=sys.nx), u, d)
    c = sys.d.center if centre else np.zeros(sys.nd)
    lags = [k - i for i in range(s + 1)]
    parts = [u[lags], tr.y[lags]] + ([np.broadcast_to(c, (s + 1, sys.nd))] if centre else [])
    w = np.hstack(parts).ravel()
    v = np.hstack([u[lags]] + ([np.broadcast_to(c, (s + 1, sys.nd))] if centre else []))
    xi = np.concatenate([tr.x[k - s], v.ravel(), (d[lags] - c).ravel()])
    return w, xi, tr.x[k]


@pytest.mark.parametrize("centre", [False, True])
def test_forward_window_reproduces_the_window(centre):
    sys = random_system(3, nx=3, ny=2, nu=1, feedthrough=True, symmetric_bounds=False)
    s, k = 3, 9
    fw = forward_window([sys.matrices_at(k - i) for i in range(s + 1)], centre=centre)
    w, xi, xk = _window_data(sys, s, k, np.random.default_rng(1), centre)
    np.testing.assert_allclose(np.asarray(fw.Z @ xi, dtype=float), w, atol=1e-12)
    np.testing.assert_allclose(np.asarray(fw.X @ xi, dtype=float), xk, atol=1e-12)
    assert np.all(fw.Za >= np.abs(fw.Z)) and np.all(fw.Xa >= np.abs(fw.X))


def _exact_residual(G, mats, nx, s):
    """|x_k - G w| coefficients in exact rational arithmetic (no centre, no missing)."""
    from fractions import Fraction

    def q(M):
        return np.vectorize(Fraction, otypes=[object])(np.asarray(M, dtype=float))

    A, B, C, D, E, F = (q(M) for M in mats[0])
    nu, ny, nd = B.shape[1], C.shape[0], E.shape[1]
    nz, nxi, d0 = nu + ny, nx + (s + 1) * (nu + nd), nx + (s + 1) * nu
    X = np.full((nx, nxi), Fraction(0), dtype=object)
    for i in range(nx):
        X[i, i] = Fraction(1)
    Z = np.full(((s + 1) * nz, nxi), Fraction(0), dtype=object)
    for i in range(s, -1, -1):
        cu, cd = nx + i * nu, d0 + i * nd
        Y = C.dot(X)
        Y[:, cu : cu + nu] += D
        Y[:, cd : cd + nd] += F
        Z[i * nz + nu : (i + 1) * nz] = Y
        for j in range(nu):
            Z[i * nz + j, cu + j] = Fraction(1)
        if i:
            X = A.dot(X)
            X[:, cu : cu + nu] += B
            X[:, cd : cd + nd] += E
    return np.abs((X - q(G).dot(Z)).astype(float))


def test_window_bound_is_a_bound_in_exact_arithmetic():
    """A singular A (eigenvalues 0, -0.94, -0.99) with the large gain of the 0.5 ... 0.9 pole
    placement: the computed window gain misses x_k - G w = -T Md 𝛅 by rounding; the certified
    bound contains the exact (rational) residual entry by entry, with and without refinement,
    and the refinement shrinks the x and v blocks to the rounding of G itself."""
    base = random_system(44, nx=3, ny=1, nu=1, invertible=False, rho=0.99)
    sys = ivobs.LinearSystem(base.A, base.B, base.C, E=base.E, F=base.F, d=base.d)
    L = injection_candidates(sys.A, sys.C)[-1]
    est = ivobs.make_estimator("fixed-time", sys, L=L)
    d = est.design
    s, nu, ny = d.s, sys.nu, sys.ny
    nz = nu + ny
    Mv = np.zeros(((s + 1) * ny, (s + 1) * nz))  # [Mu | My] interleaved per lag as w
    for i in range(s + 1):
        Mv[:, i * nz : i * nz + nu] = d.Mu[:, i * nu : (i + 1) * nu]
        Mv[:, i * nz + nu : (i + 1) * nz] = d.My[:, i * ny : (i + 1) * ny]
    Sel = np.zeros(((s + 1) * ny, (s + 1) * nz))
    for i in range(s + 1):
        Sel[i * ny : (i + 1) * ny, i * nz + nu : (i + 1) * nz] = np.eye(ny)
    G = d.T @ (Sel - Mv)
    mats = [sys.matrices_at(0)] * (s + 1)
    fw = forward_window(mats, centre=False)
    nxi = fw.Z.shape[1]
    for refine in (False, True):
        wb = window_bound(G, 3, fw, refine=refine)
        exact = _exact_residual(wb.G, mats, 3, s)
        bound = np.hstack([wb.Rx, wb.Rv, wb.Rd])
        assert bound.shape == (3, nxi)
        assert np.all(exact <= bound)
        if not refine:
            assert exact[:, :3].max() > 1e-12  # the unrefined gain is visibly off
        else:
            assert exact[:, :3].max() < 1e-13
    assert np.isfinite(wb.kappa) and wb.kappa > 1.0


def test_window_bound_detects_a_wrong_gain():
    sc = ivobs.scenarios.get("dinh2019")
    sys = sc.system
    est = ivobs.make_estimator("fixed-time", sys, s=2)
    kern = est._gains.complete(2)
    fw = forward_window([sys.matrices_at(0)] * 3, centre=False)
    good = window_bound(kern.GQ, 2, fw, refine=False)
    assert good.Rx.sum(axis=1).max() < 1e-14 and good.Rv.sum(axis=1).max() < 1e-14
    # |R_δ| is |T Md| of eq. (11) to rounding
    np.testing.assert_allclose(good.Rd[:2], np.abs(est.design.T @ est.design.Md), atol=1e-14)
    bad = window_bound(kern.GQ + 1e-6, 2, fw, refine=False)
    assert bad.Rx.sum(axis=1).min() > 1e-7
    fixed = window_bound(kern.GQ + 1e-6, 2, fw, refine=True)
    assert fixed.Rx.sum(axis=1).max() < 1e-14
