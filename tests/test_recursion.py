"""The vectorised linear recursion agrees with the loop (to rounding), with batches."""

import numpy as np
import pytest

from ivobs.estimators._recursion import affine_recursion


def _loop(M, v, x0):
    x = [np.asarray(x0, float)]
    for k in range(v.shape[0]):
        x.append(M @ x[-1] + v[k])
    return np.array(x)


@pytest.mark.parametrize("T", [1, 5, 33, 1000, 4097])
def test_doubling_scan_matches_loop(T):
    rng = np.random.default_rng(T)
    M = rng.normal(size=(3, 3))
    M *= 0.95 / np.max(np.abs(np.linalg.eigvals(M)))
    v = rng.normal(size=(T, 3))
    x0 = rng.normal(size=3)
    X = affine_recursion(M, v, x0)
    np.testing.assert_allclose(X, _loop(M, v, x0), rtol=1e-10, atol=1e-12)


def test_batches_and_unstable_matrices():
    rng = np.random.default_rng(0)
    M = np.array([[1.1, 0.2], [0.0, 0.9]])  # unstable: loop path
    v = rng.normal(size=(4, 50, 2))
    X = affine_recursion(M, v, np.zeros(2))
    for b in range(4):
        np.testing.assert_allclose(X[b], _loop(M, v[b], np.zeros(2)), rtol=1e-12)
    Ms = 0.5 * M
    Xs = affine_recursion(Ms, v[:2], np.ones((2, 2)))
    np.testing.assert_allclose(Xs[1], _loop(Ms, v[1], np.ones(2)), rtol=1e-10, atol=1e-12)
