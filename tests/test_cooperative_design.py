"""Gains for cooperative interval observers (ivobs.design.cooperative): [Tang2019, LMI (41)] /
[Efimov2013, LMIs (7)-(8)], the LP for |A - LC| Schur, the width refinement and the checks."""

import numpy as np
import pytest

import ivobs
from ivobs import Box, DesignError, scenarios
from ivobs.design.cooperative import (
    NONNEG_TOL,
    abs_schur_gain,
    check_abs_schur,
    check_nonnegative_schur,
    missing_radius,
    nonnegative_gain,
    refine_width,
    steady_width,
)
from ivobs.design.cooperative_lp import output_weights
from ivobs.linalg import spectral_radius


def mats(name):
    sc = scenarios.get(name)
    A, _, C, _, E, F = sc.system.matrices_at(0)
    return sc, A, C, E, F, sc.system.d.hi - sc.system.d.lo


def rho(M):
    return np.max(np.abs(np.linalg.eigvals(M)))


def test_lmi41_is_feasible_on_the_servo_motor():
    sc, A, C, *_ = mats("servo-motor")
    L = nonnegative_gain(A, C)
    D = A - L @ C
    assert D.min() >= -1e-9
    # column 3 of C is zero, so A[3, 3] = 0.9995 stays on the diagonal: ρ >= 0.9995
    assert 0.9995 - 1e-9 <= rho(D) < 1.0
    # the paper's L2 (also from LMI (41)) passes the same check
    check_nonnegative_schur(A, C, sc.reference["L2"], "interval")


@pytest.mark.parametrize(
    "name, entry", [("tang-example2", r"entry \(2, 1\)"), ("efimov-planar", r"entry \(1, 2\)")]
)
def test_no_nonnegative_gain_exists_for_the_papers_counterexamples(name, entry):
    _, A, C, *_ = mats(name)
    with pytest.raises(DesignError, match=entry + r".*for every L.*LMI \(41\)"):
        nonnegative_gain(A, C)


def test_lmi41_infeasible_without_a_structural_reason():
    # A − LC >= 0 is possible (column 1 of C is zero but A[:, 0] >= 0), Schur is not: A[1,1] = 1.2
    A = np.array([[1.2, 0.3], [0.4, 0.5]])
    C = np.array([[0.0, 1.0]])
    # the linear program proves it: its best margin is negative
    with pytest.raises(DesignError, match=r"optimal margin s = -[0-9.e-]+ < 0, which proves it"):
        nonnegative_gain(A, C)


def test_check_messages_name_the_entry_and_the_spectral_radius():
    A = np.array([[0.5, -0.2], [0.1, 0.3]])
    C = np.array([[1.0, 0.0]])
    with pytest.raises(DesignError, match=r"not nonnegative: entry \(1, 2\) = -0.2"):
        check_nonnegative_schur(A, C, np.zeros((2, 1)), "interval")
    with pytest.raises(DesignError, match=r"not Schur: spectral radius 1.1"):
        check_nonnegative_schur(np.array([[1.1]]), np.array([[0.0]]), np.zeros((1, 1)), "x")
    # |A − LC| = [[0.5, 0.2], [0.1, 0.3]]: Schur; |[[0.9, -0.9], [0.9, 0.9]]|: radius 1.8
    check_abs_schur(A, C, np.zeros((2, 1)), "interval-split")
    msg = r"\|A − LC\| = D⁺ \+ D⁻ is not Schur: spectral radius 1.8"
    with pytest.raises(DesignError, match=msg):
        check_abs_schur(np.array([[0.9, -0.9], [0.9, 0.9]]), C, np.zeros((2, 1)), "split")


def test_margin_lp_finds_the_optimum_of_the_planar_example():
    """[Efimov2013, Section IV.A]: |A − LC| = [[|0.3 − l1|, 0.7], [|0.6 − l2|, 0.5]] has
    ρ >= 0.5 for every L (its entry (2, 2) is fixed); L = (0.3, 0.6) attains it (the paper's
    gain)."""
    _, A, C, *_ = mats("efimov-planar")
    L, r = abs_schur_gain(A, C)
    assert r == pytest.approx(0.5, abs=1e-7)
    assert rho(np.abs(A - L @ C)) == pytest.approx(r, abs=1e-12)
    assert np.sort(np.abs(np.linalg.eigvals(np.abs(A - np.array([[0.3], [0.6]]) @ C)))) == (
        pytest.approx([0.0, 0.5])
    )


def test_margin_lp_reports_failure_as_a_radius():
    # tang-example2: entry (1, 1) of |A − LC| is A[1, 1] = 1 for every L
    _, A, C, *_ = mats("tang-example2")
    _, r = abs_schur_gain(A, C)
    assert r >= 1.0 - 1e-12


def test_steady_width_is_the_limit_of_the_bounds_recursion():
    _, A, C, E, F, delta = mats("efimov-planar")
    L = np.array([[0.3], [0.6]])
    D, G = A - L @ C, E - L @ F
    w = np.array([4.0, 4.0])
    for _ in range(200):
        w = np.abs(D) @ w + np.abs(G) @ delta
    np.testing.assert_allclose(steady_width(D, G, delta), w, rtol=1e-12)
    # |G| Δ = (1 + 0.3·0.2, 1 + 0.6·0.2); w2 = 1.12 / 0.5, w1 = 0.7 w2 + 1.06
    np.testing.assert_allclose(w, [0.7 * 2.24 + 1.06, 2.24], rtol=1e-12)
    assert np.all(np.isinf(steady_width(np.array([[1.0]]), np.ones((1, 1)), np.ones(1))))


@pytest.mark.parametrize("seed", range(6))
def test_refinement_never_widens_and_keeps_the_structure(seed):
    rng = np.random.default_rng(seed)
    n, p, m = 3, 2, 4
    A = rng.uniform(0, 1, (n, n))
    A *= 0.95 / rho(A)
    C = rng.normal(size=(p, n))
    E, F = rng.normal(size=(n, m)) * 0.3, rng.normal(size=(p, m)) * 0.1
    delta = rng.uniform(0.2, 1.0, m)
    L0 = np.zeros((n, p))  # A >= 0 and Schur: a valid start for both observers
    w0 = steady_width(A, E, delta)
    for nonneg in (True, False):
        L = refine_width(A, C, E, F, delta, L0, nonnegative=nonneg)
        D = A - L @ C
        w = steady_width(D, E - L @ F, delta)
        assert np.all(w <= w0 * (1 + 1e-9))
        assert rho(np.abs(D)) < 1.0
        if nonneg:
            assert D.min() >= -1e-9
    # on the servo motor the refinement improves LMI (41)'s gain in every state
    _, A, C, E, F, delta = mats("servo-motor")
    L_lmi = nonnegative_gain(A, C)
    L = refine_width(A, C, E, F, delta, L_lmi, nonnegative=True)
    w_lmi = steady_width(A - L_lmi @ C, E - L_lmi @ F, delta)
    w_ref = steady_width(A - L @ C, E - L @ F, delta)
    assert np.all(w_ref <= w_lmi * (1 + 1e-9)) and w_ref.sum() < 0.999 * w_lmi.sum()


# -- redundant outputs: the smallest gain among the optimal ones ----------------------------------
A_R, C_R = np.array([[0.9]]), np.array([[1.0], [1.0]])  # two sensors of one state (redundant)


def test_margin_lp_returns_the_smallest_gain_with_redundant_outputs():
    """ρ(|A − LC|) = |0.9 − l1 − l2| is 0 on a whole line of gains: HiGHS used to return the
    vertex (−999999.1, 10⁶) of the |L| <= 1e6 box; the second stage picks (0.45, 0.45)."""
    L, r = abs_schur_gain(A_R, C_R)
    assert r < 1e-9
    np.testing.assert_allclose(L, [[0.45, 0.45]], atol=1e-9)
    np.testing.assert_allclose(missing_radius(A_R, C_R, L), [0.45, 0.45], atol=1e-9)


@pytest.mark.parametrize("nonnegative", [True, False])
def test_width_refinement_returns_the_smallest_gain_with_noise_free_outputs(nonnegative):
    """F = 0: the width (I − |D|)⁻¹|E|Δ does not depend on the part of L with LC = 0."""
    E, F, delta = np.array([[0.1]]), np.zeros((2, 1)), np.array([2.0])
    L = refine_width(A_R, C_R, E, F, delta, np.array([[0.3, 0.3]]), nonnegative=nonnegative)
    np.testing.assert_allclose(L, [[0.45, 0.45]], atol=1e-9)
    np.testing.assert_allclose(steady_width(A_R - L @ C_R, E, delta), [0.2], rtol=1e-9)


def test_output_weights_make_the_gain_scale_invariant():
    """Sensor 2 reads 1000 x: the gain's column 2 shrinks by 1000, L C is the same."""
    C = np.array([[1.0], [1000.0]])
    np.testing.assert_allclose(output_weights(C), [1.0, 1000.0])
    L, _ = abs_schur_gain(A_R, C)
    np.testing.assert_allclose(L, [[0.45, 0.45e-3]], atol=1e-9)


def test_refinement_keeps_single_output_gaps_bounded():
    """Sensor 1 sees the disturbance (F = 1e-3): G = E − LF vanishes only for l1 = 100, and
    then l2 = 0.9 − 100 and a gap of either sensor multiplies the width by ~100 per step. The
    start gain rides out both gaps, so the refinement stops before that gain."""
    E, F, delta = np.array([[0.1]]), np.array([[1e-3], [0.0]]), np.array([2.0])
    L0 = np.array([[0.45, 0.45]])
    for nonneg in (True, False):
        L = refine_width(A_R, C_R, E, F, delta, L0, nonnegative=nonneg)
        assert np.all(missing_radius(A_R, C_R, L) < 1.0)
        w0 = steady_width(A_R - L0 @ C_R, E - L0 @ F, delta)
        assert np.all(steady_width(A_R - L @ C_R, E - L @ F, delta) <= w0 * (1 + 1e-9))


@pytest.mark.parametrize(
    "name, L_expected",
    [
        ("servo-motor", [[1.0, 0.1], [0.0, 0.8495], [0.0, -0.0357]]),
        ("efimov-planar", [[0.3], [0.6]]),
        ("henon", [[0.0], [0.3]]),
    ],
)
def test_second_stage_keeps_the_papers_optimal_gains(name, L_expected):
    """Where the LP optimum is a single gain the second stage does not move it (1e-12 slack)."""
    sc = scenarios.get(name)
    A, _, C, _, E, F = sc.system.matrices_at(0)
    d = sc.system.d
    delta = d.hi - d.lo if isinstance(d, Box) else np.ones(E.shape[1])  # Hénon: callable bounds
    L, _ = abs_schur_gain(A, C)
    L = refine_width(A, C, E, F, delta, L, nonnegative=False)
    np.testing.assert_allclose(L, L_expected, atol=1e-10)


def test_missing_radius_without_a_sensor():
    """Servo motor: without sensor 1 the first state (an integrator) is unobserved."""
    _, A, C, *_ = mats("servo-motor")
    L = np.array([[1.0, 0.1], [0.0, 0.8495], [0.0, -0.0357]])
    r = missing_radius(A, C, L)
    assert r[0] == pytest.approx(1.0, abs=1e-12)
    assert r[1] == pytest.approx(rho(np.abs(A - L * [1.0, 0.0] @ C)), rel=1e-12) and r[1] > 1


def test_lmi_gain_is_repaired_when_the_sdp_leaves_round_off_negatives():
    """kkl-random8: the SDP meets P A − Y C >= 0 only to its tolerance and L = P⁻¹ Y leaves
    A − LC at −4e-9; the nearest nonnegative gain (LP) keeps A − LC >= 0 and Schur."""
    sc = ivobs.scenarios.get("kkl-random8")
    A, C = sc.system.A, sc.system.C
    L = nonnegative_gain(A, C)
    D = A - L @ C
    assert D.min() >= -NONNEG_TOL * max(1.0, np.abs(A).max())
    assert spectral_radius(D) < 1.0
    tr = sc.simulate("vertex", seed=3)
    res = ivobs.make_estimator("interval", sc.system, x0=sc.x0).run(tr.u, tr.y)
    assert res.contains(tr.x).all()
