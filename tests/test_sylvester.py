"""Sylvester (KKL) designs of [Dinh2024]: eq. (4), Proposition 1's conditions, default targets."""

import numpy as np
import pytest

import ivobs
from ivobs import DesignError, IvobsError, linalg
from ivobs.design.sylvester import (
    block_target,
    check_target,
    default_target,
    predicted_width,
    solve_transform,
)
from ivobs.testing import random_system


def _delta(sys):
    return sys.d.hi - sys.d.lo


def test_solve_transform_satisfies_eq4_and_matches_the_row_formula():
    sys = ivobs.scenarios.get("servo-motor").system
    A, C = sys.A, sys.C
    Az = np.diag([0.1, 0.3, 0.5])
    Bz = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    T = solve_transform(A, C, Az, Bz)
    np.testing.assert_allclose(T @ A, Az @ T + Bz @ C, atol=1e-12)
    # diagonal A_z: row i is b_i C (A - a_i I)^-1
    for i, a in enumerate(np.diag(Az)):
        np.testing.assert_allclose(T[i], Bz[i] @ C @ np.linalg.inv(A - a * np.eye(3)), atol=1e-12)


def test_solve_transform_rejects_a_shared_eigenvalue():
    A = np.diag([0.5, 0.2])
    C = np.array([[1.0, 1.0]])
    with pytest.raises(DesignError, match="share an eigenvalue|eig"):
        solve_transform(A, C, np.diag([0.5, 0.1]), np.ones((2, 1)))


def test_check_target_names_each_failed_condition():
    Bz = np.ones((2, 1))
    with pytest.raises(DesignError, match="nonnegative"):
        check_target(np.array([[0.1, -0.1], [0.0, 0.2]]), Bz, continuous=False)
    with pytest.raises(DesignError, match="spectral radius is 1.1"):
        check_target(np.diag([1.1, 0.2]), Bz, continuous=False)
    with pytest.raises(DesignError, match="Metzler"):
        check_target(np.array([[-1.0, -0.5], [0.0, -2.0]]), Bz, continuous=True)
    with pytest.raises(DesignError, match="Hurwitz"):
        check_target(np.diag([0.5, -2.0]), Bz, continuous=True)
    with pytest.raises(DesignError, match="not controllable"):
        check_target(np.diag([0.1, 0.1]), Bz, continuous=False)
    with pytest.raises(DesignError, match="shares an eigenvalue with A"):
        check_target(np.diag([0.1, 0.2]), Bz, continuous=False, A=np.diag([0.2, 3.0]))
    Az, B = check_target(np.diag([0.1, 0.2]), Bz, continuous=False, A=np.diag([0.5, 3.0]))
    assert Az.shape == (2, 2) and B.shape == (2, 1)


@pytest.mark.parametrize("continuous", [False, True])
def test_default_target_meets_proposition_1(continuous):
    name_kw = {"continuous": True} if continuous else {}
    sys = ivobs.scenarios.get("kkl-random8", **name_kw).system
    ch = default_target(sys.A, sys.C, sys.E, sys.F, _delta(sys), continuous=continuous)
    Az, Bz, T = ch.A_z, ch.B_z, ch.T
    assert np.count_nonzero(Az - np.diag(np.diag(Az))) == 0
    if continuous:
        assert linalg.is_metzler(Az) and linalg.is_hurwitz(Az)
    else:
        assert linalg.is_nonnegative(Az) and linalg.is_schur(Az)
    assert linalg.is_controllable(Az, Bz)
    np.testing.assert_allclose(T @ sys.A, Az @ T + Bz @ sys.C, atol=1e-9 * np.abs(T).max())
    assert np.linalg.cond(T) < 1e4
    np.testing.assert_allclose(np.linalg.norm(T, axis=1), 1.0)  # rows normalised
    # the refinement never makes the predicted width worse than the best candidate
    plain = default_target(
        sys.A, sys.C, sys.E, sys.F, _delta(sys), continuous=continuous, tune=False
    )
    assert ch.score <= plain.score * (1 + 1e-9)
    w = predicted_width(T, Az, Bz, sys.E, sys.F, _delta(sys), continuous)
    np.testing.assert_allclose(w.sum(), ch.score, rtol=1e-6)


def test_tuning_improves_the_random8_width_by_a_large_factor():
    sys = ivobs.scenarios.get("kkl-random8").system
    tuned = default_target(sys.A, sys.C, sys.E, sys.F, _delta(sys), continuous=False)
    plain = default_target(sys.A, sys.C, sys.E, sys.F, _delta(sys), continuous=False, tune=False)
    assert tuned.tuned and tuned.score < 0.5 * plain.score


def test_predicted_width_is_the_fixed_point_of_the_width_recursion():
    sys = random_system(3, nx=3, ny=2, nu=1)
    ch = default_target(sys.A, sys.C, sys.E, sys.F, _delta(sys), continuous=False, tune=False)
    G = ch.T @ sys.E - ch.B_z @ sys.F
    wz = np.zeros(3)
    for _ in range(2000):  # w+ = A_z w + |G| Δd (3.a), any start
        wz = ch.A_z @ wz + np.abs(G) @ _delta(sys)
    wx = np.abs(np.linalg.inv(ch.T)) @ wz
    np.testing.assert_allclose(
        predicted_width(ch.T, ch.A_z, ch.B_z, sys.E, sys.F, _delta(sys), False), wx, rtol=1e-10
    )


def test_without_disturbance_the_transient_is_scored():
    A = np.array([[1.0, 0.1], [-0.2, 0.9]])
    C = np.array([[1.0, 0.0]])
    ch = default_target(
        A, C, np.zeros((2, 0)), np.zeros((1, 0)), np.zeros(0), continuous=False, w0=np.ones(2)
    )
    assert np.isfinite(ch.score) and ch.score > 0 and linalg.is_schur(ch.A_z)


def test_default_target_refuses_an_unobservable_pair():
    with pytest.raises(DesignError, match="not observable"):
        default_target(
            np.diag([0.5, 0.2]),
            np.array([[1.0, 0.0]]),
            np.zeros((2, 0)),
            np.zeros((1, 0)),
            np.zeros(0),
            continuous=False,
        )


def test_remark_1_single_output_any_controllable_target_gives_an_invertible_T():
    rng = np.random.default_rng(0)
    for seed in range(10):
        sys = random_system(seed, nx=4, ny=1, nu=0)
        a = np.sort(rng.uniform(0, 0.95, 4))
        T = solve_transform(sys.A, sys.C, np.diag(a), rng.uniform(0.5, 2, (4, 1)))
        assert np.linalg.matrix_rank(T) == 4


def test_block_targets_of_examples_2_and_3():
    ex3 = ivobs.scenarios.get("kkl-ltv-dt")
    At, Bt, m = block_target(ex3.system.A_at(0), ex3.system.C_at(0), continuous=False)
    np.testing.assert_array_equal(At, ex3.reference["A_tilde"])
    np.testing.assert_array_equal(Bt, ex3.reference["B_tilde"])
    assert m == [2]
    pend = ivobs.scenarios.get("pendulum")
    At, Bt, m = block_target(pend.system.A_at(0.0), pend.system.C_at(0.0), continuous=True)
    np.testing.assert_array_equal(At, pend.reference["A_tilde"])
    np.testing.assert_array_equal(Bt, pend.reference["B_tilde"])


def test_block_target_sizes_follow_the_observability_indices():
    sys = ivobs.scenarios.get("kkl-random8").system
    At, Bt, m = block_target(sys.A, sys.C, continuous=False)
    assert m == sys.observability_indices() and sum(m) == 8
    assert At.shape == (8, 8) and Bt.shape == (8, 6)
    assert np.all(Bt.sum(axis=0) == m) and linalg.is_controllable(At, Bt)
    # a frozen pair that is not observable: one full block per output
    At, Bt, m = block_target(np.diag([0.5, 0.2]), np.array([[1.0, 0.0]]), continuous=False)
    assert m == [2]


def test_check_target_shapes():
    with pytest.raises(IvobsError, match="square"):
        check_target(np.ones((2, 3)), np.ones((2, 1)), continuous=False)
