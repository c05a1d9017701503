"""``ivobs.sets.expm``: every enclosure ``E ± R`` contains the exact exponential (and integral),
checked against exact rational results and 50-digit mpmath ones, and is tight."""

from fractions import Fraction

import mpmath
import numpy as np
import pytest

from ivobs import IvobsError
from ivobs.sets.expm import expm, expm_integral, interval_product, scaled


def _contains_exact(E, R, exact):
    """Every entry: |exact - E| <= R, compared in exact rational arithmetic."""
    for (i, j), e in np.ndenumerate(E):
        assert abs(exact[i][j] - Fraction(e)) <= Fraction(R[i, j]), (i, j, e, R[i, j])


def _contains_mp(E, R, exact):
    """Every entry: |exact - E| <= R with a 50-digit reference (its own error < 1e-45)."""
    with mpmath.workdps(60):
        for (i, j), e in np.ndenumerate(E):
            gap = abs(exact[i, j] - mpmath.mpf(e)) - mpmath.mpf(R[i, j])
            assert gap <= mpmath.mpf("1e-45"), (i, j, e, R[i, j], gap)


def _tight(M):
    """The radius expected relative to ``max |e^M|``: rounding, grown by the squarings
    (about ``2^s`` with ``s = log2 ‖M‖``) and by cancellation in non-normal matrices."""
    return 1e-13 * max(1.0, float(np.abs(M).sum(axis=1).max())) ** 2


def _frac_matmul(X, Y):
    return [[sum(X[i][k] * Y[k][j] for k in range(len(Y))) for j in range(len(Y[0]))]
            for i in range(len(X))]  # fmt: skip


def _mp_expm(A, t=1):
    with mpmath.workdps(50):
        return mpmath.expm(mpmath.matrix(A.tolist()) * mpmath.mpf(t))


def test_nilpotent_matrices_against_the_exact_finite_series():
    rng = np.random.default_rng(1)
    for n in (2, 3, 5):
        for scale in (0.5, 3.0, 40.0):
            N = np.triu(np.round(rng.normal(size=(n, n)) * 8) / 8 * scale, 1)
            E, R = expm(N)
            Nf = [[Fraction(v) for v in row] for row in N]
            term = [[Fraction(int(i == j)) for j in range(n)] for i in range(n)]
            exact = [row[:] for row in term]
            for k in range(1, n):
                term = [[v / k for v in row] for row in _frac_matmul(term, Nf)]
                exact = [[a + b for a, b in zip(r1, r2)] for r1, r2 in zip(exact, term)]
            _contains_exact(E, R, exact)
            assert np.all(R <= 1e-12 * (1.0 + np.abs(E)) * max(1.0, scale) ** n)


def test_integral_of_a_nilpotent_exponential_against_exact_rationals():
    A = np.array([[0.0, 1.0, 0.5], [0.0, 0.0, -2.0], [0.0, 0.0, 0.0]])
    B = np.array([[1.0], [0.25], [-3.0]])
    for t in (0.01, 0.5, 2.0):
        (Ad, RA), (Bd, RB) = expm_integral(A, B, t)
        tf = Fraction(t)
        Af = [[Fraction(v) for v in row] for row in A]
        # ∫_0^t e^{As} ds = Σ A^k t^(k+1) / (k+1)!
        power = [[Fraction(int(i == j)) for j in range(3)] for i in range(3)]
        integral = [[Fraction(0)] * 3 for _ in range(3)]
        expo = [[Fraction(0)] * 3 for _ in range(3)]
        fact = 1
        for k in range(3):
            fact *= k + 1
            for i in range(3):
                for j in range(3):
                    integral[i][j] += power[i][j] * tf ** (k + 1) / fact
                    expo[i][j] += power[i][j] * tf**k * (k + 1) / fact
            power = _frac_matmul(power, Af)
        _contains_exact(Ad, RA, expo)
        _contains_exact(Bd, RB, _frac_matmul(integral, [[Fraction(v[0])] for v in B]))
        assert np.max(RB) < 4e-14 * np.max(np.abs(Bd)) and np.max(RA) < 4e-14 * np.max(np.abs(Ad))


def test_diagonalisable_matrices_with_known_exponentials():
    # A = S diag(lam) S^-1 with a unimodular integer S: e^A = S diag(e^lam) S^-1
    S = np.array([[1.0, 2.0, 0.0], [0.0, 1.0, 1.0], [1.0, 3.0, 2.0]])
    Si = np.round(np.linalg.inv(S))
    assert np.array_equal(S @ Si, np.eye(3))
    for lam in ([-1.0, -2.0, -0.5], [0.5, -3.0, -6.0], [-20.0, -0.125, 1.5]):
        A = S @ np.diag(lam) @ Si  # integer-valued products of dyadic numbers: exact
        for t in (0.01, 1.0):
            E, R = expm(*scaled(A, t))
            with mpmath.workdps(50):
                D = mpmath.diag([mpmath.exp(mpmath.mpf(v) * mpmath.mpf(t)) for v in lam])
                exact = mpmath.matrix(S.tolist()) * D * mpmath.matrix(Si.tolist())
            _contains_mp(E, R, exact)
            assert np.max(R) <= _tight(A * t) * np.max(np.abs(E))


@pytest.mark.parametrize("n, scale", [(2, 0.1), (4, 1.0), (6, 4.0), (8, 2.0), (3, 25.0)])
def test_random_matrices_against_mpmath(n, scale):
    rng = np.random.default_rng(n)
    for _ in range(3):
        A = rng.normal(size=(n, n)) * scale / np.sqrt(n)
        E, R = expm(A)
        exact = _mp_expm(A)
        _contains_mp(E, R, exact)
        assert np.max(R) <= _tight(A) * np.max(np.abs(E))


def test_interval_of_times_contains_every_time_in_it():
    A = np.array([[-1.92, 1.36], [1.22, -2.46]])
    t = (0.1 - 1e-9, 0.1 + 1e-9)
    E, R = expm(*scaled(A, t))
    for tt in (t[0], 0.1, t[1]):
        _contains_mp(E, R, _mp_expm(A, mpmath.mpf(tt)))
    assert np.max(R) < 1e-8  # the spread of the times, |A| e^{|A| t} 1e-9, and no more


def test_interval_matrix_input_contains_every_matrix_of_it():
    rng = np.random.default_rng(5)
    M = rng.normal(size=(3, 3))
    Rm = np.full((3, 3), 1e-6)
    E, R = expm(M, Rm)
    for _ in range(4):
        X = M + Rm * rng.choice([-1.0, 1.0], size=(3, 3))
        _contains_mp(E, R, _mp_expm(X))


def test_interval_product_contains_products_of_members():
    rng = np.random.default_rng(2)
    A, B = rng.normal(size=(4, 4)) * 1e8, rng.normal(size=(4, 4)) * 1e-8
    RA, RB = np.abs(A) * 1e-10, np.abs(B) * 1e-10
    C, RC = interval_product(A, RA, B, RB)
    for _ in range(3):
        X = A + RA * rng.choice([-1.0, 1.0], size=A.shape)
        Y = B + RB * rng.choice([-1.0, 1.0], size=B.shape)
        exact = _frac_matmul([[Fraction(v) for v in r] for r in X],
                             [[Fraction(v) for v in r] for r in Y])  # fmt: skip
        _contains_exact(C, RC, exact)


def test_bad_input_is_refused_with_the_argument_named():
    with pytest.raises(IvobsError, match="M: expected a square matrix"):
        expm(np.ones((2, 3)))
    with pytest.raises(IvobsError, match="M: expected finite"):
        expm(np.array([[np.nan]]))
    with pytest.raises(IvobsError, match="t: expected a finite time"):
        scaled(np.eye(2), (1.0, 0.0))
    with pytest.raises(IvobsError, match="A, B: expected"):
        expm_integral(np.eye(2), np.ones((3, 1)), 1.0)
    E, _ = expm(np.zeros((0, 0)))
    assert E.shape == (0, 0)
