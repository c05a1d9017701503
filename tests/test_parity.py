"""Parity-space design of paper 001: stacked matrices (eq. 6), optimal T (Theorem 1, eq. 13),
general solution (Lemma 2), output injection (Remark 1)."""

import numpy as np
import pytest

import ivobs
from ivobs import DesignError, IvobsError
from ivobs.design.parity import (
    general_T,
    invertible_injection,
    is_invertible,
    optimal_T,
    pinv_perp,
    stack_matrices,
    stack_window,
    width_optimal_T,
)
from ivobs.linalg import is_observable
from ivobs.testing import random_system


@pytest.fixture(scope="module")
def paper():
    sc = ivobs.scenarios.get("dinh2019")
    sys = sc.system
    Mx, Mu, Md = stack_matrices(sys.A, sys.B, sys.C, sys.D, sys.E, sys.F, s=2)
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
    Mx, Mu, Md = stack_matrices(sys.A, sys.B, sys.C, sys.D, sys.E, sys.F, s=s)
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
        Mx, _, Md = stack_matrices(sys.A, sys.B, sys.C, sys.D, sys.E, sys.F, s=3)
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
    Mx, _, Md = stack_matrices(sys.A, sys.B, sys.C, sys.D, sys.E, sys.F, s=3)
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
        L = invertible_injection(sys.A, sys.C)
        Ap = sys.A - L @ sys.C
        assert is_invertible(Ap) and is_observable(Ap, sys.C)
        np.testing.assert_allclose(
            np.sort(np.linalg.eigvals(Ap).real), np.linspace(0.5, 0.9, sys.nx), atol=1e-6
        )
    with pytest.raises(DesignError, match="C = 0"):
        invertible_injection(np.zeros((2, 2)), np.zeros((1, 2)))


def test_singular_A_in_window_is_a_design_error():
    A = np.array([[0.0, 1.0], [0.0, 0.0]])
    with pytest.raises(DesignError, match="not invertible"):
        stack_matrices(A, None, [[1.0, 0.0]], s=1)
