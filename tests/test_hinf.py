"""H∞ observer gain of [Tang2019, Theorem 1, problem (20), LMI (16)]."""

import numpy as np
import pytest

import ivobs
from ivobs import DesignError, IvobsError
from ivobs.design.hinf import check_gain, designed_gain, hinf_gain


def hinf_norm(M, G, n=2001):
    """max over the unit circle of ‖(zI - M)⁻¹ G‖₂ (frequency sweep)."""
    I = np.eye(M.shape[0])
    return max(
        np.linalg.norm(np.linalg.solve(np.exp(1j * w) * I - M, G), 2)
        for w in np.linspace(0.0, np.pi, n)
    )


def _mats(name):
    s = ivobs.scenarios.get(name).system
    return s.A, s.C, s.E, s.F


def test_tang_example2_reproduces_the_papers_gain_and_eigenvalues():
    sc = ivobs.scenarios.get("tang-example2")
    A, C, E, F = _mats("tang-example2")
    L, gamma, P = hinf_gain(A, C, E, F)
    np.testing.assert_allclose(L, sc.reference["L"], atol=1e-3)  # (-0.8479, 1.6739)
    eig = np.sort(np.abs(np.linalg.eigvals(A - L @ C)))
    np.testing.assert_allclose(eig, np.sort(sc.reference["eig"]), atol=1e-3)  # {0.3258, 0.0003}
    assert np.linalg.eigvalsh(P).min() > 1.0  # (16) implies P ≻ I
    # Theorem 1: ‖G_ed‖∞ < γ, and γ is the optimum (problem (20)): the bound is attained
    norm = hinf_norm(A - L @ C, E - L @ F)
    assert norm < gamma + 1e-6
    assert norm > gamma - 1e-3
    assert gamma == pytest.approx(3.4368, abs=1e-3)


def test_servo_gain_is_optimal_and_at_least_as_good_as_the_papers_L1():
    sc = ivobs.scenarios.get("servo-motor")
    A, C, E, F = _mats("servo-motor")
    L, gamma, _ = hinf_gain(A, C, E, F, method="lmi")
    assert gamma == pytest.approx(3.2415, abs=1e-3)
    assert hinf_norm(A - L @ C, E - L @ F) < gamma + 1e-6
    L1 = sc.reference["L1"]
    # the optimum is degenerate in the first column, so compare norms, not gains
    assert hinf_norm(A - L1 @ C, E - L1 @ F) >= gamma - 1e-6
    np.testing.assert_allclose(L[1:, 1], L1[1:, 1], atol=5e-3)
    assert np.abs(np.linalg.eigvals(A - L @ C)).max() < 0.33


def test_design_is_deterministic():
    A, C, E, F = _mats("servo-motor")
    L1, g1, _ = hinf_gain(A, C, E, F)
    L2, g2, _ = hinf_gain(A, C, E, F)
    np.testing.assert_array_equal(L1, L2)
    assert g1 == g2


def test_no_disturbance_still_gives_a_stabilising_gain():
    A = np.array([[1.1, 0.3], [0.0, 0.7]])
    C = np.array([[1.0, 0.0]])
    L, gamma, P = hinf_gain(A, C, np.zeros((2, 0)), np.zeros((1, 0)))
    assert gamma == 0.0 and P.shape == (2, 2)
    assert np.abs(np.linalg.eigvals(A - L @ C)).max() < 1.0


def test_undetectable_pair_is_a_design_error():
    A = np.diag([2.0, 0.5])  # the unstable mode is not seen by y = x2
    C = np.array([[0.0, 1.0]])
    with pytest.raises(DesignError, match="problem \\(20\\)"):
        hinf_gain(A, C, np.eye(2), np.zeros((1, 2)))


def test_bad_shapes_and_sizes():
    A, C, E, F = _mats("tang-example2")
    with pytest.raises(IvobsError, match="C: expected shape"):
        hinf_gain(A, np.ones((1, 3)), E, F)
    with pytest.raises(IvobsError, match="F: expected shape"):
        hinf_gain(A, C, E, np.ones((1, 2)))
    with pytest.raises(DesignError, match="does not scale"):
        hinf_gain(0.5 * np.eye(201), np.eye(201)[:1], np.eye(201), np.zeros((1, 201)), method="lmi")
    with pytest.raises(IvobsError, match="method: expected 'riccati' or 'lmi'"):
        hinf_gain(A, C, E, F, method="sdp")


def test_user_gain_is_checked():
    sc = ivobs.scenarios.get("servo-motor")
    s = sc.system
    d = designed_gain(s, sc.reference["L1"], "test")
    assert d.gamma is None and d.P is None
    assert d.rho == pytest.approx(0.31168, abs=1e-4)
    with pytest.raises(DesignError, match=r"spectral radius 1 >= 1") as info:
        designed_gain(s, np.zeros((3, 2)), "test")  # A itself has eigenvalue 1
    assert "A - LC is not Schur" in str(info.value)
    with pytest.raises(IvobsError, match=r"L: expected shape \(3, 2\)"):
        designed_gain(s, np.zeros((2, 3)), "test")
    assert check_gain(s.A, s.C, sc.reference["L2"], "x") == pytest.approx(0.99977, abs=1e-4)


def test_an_lmi_without_solution_says_what_to_do():
    """An infeasible LMI: the DesignError names the problem, the solvers' statuses and the ways
    out (an explicit gain, another method)."""
    import cvxpy as cp

    from ivobs.design._lmi import solve

    P = cp.Variable((2, 2), symmetric=True)
    problem = cp.Problem(cp.Minimize(0), [P >> np.eye(2), P << -np.eye(2)])
    with pytest.raises(DesignError, match=r"toy LMI: the LMI has no .*infeasible.*L=\.\.\."):
        solve(problem, "toy LMI")
