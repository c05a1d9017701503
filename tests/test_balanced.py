"""The balanced coordinates of ivobs.estimators._balanced: exact products by powers of two, a
fallback where they would not be exact, and the box of x from that of the balanced state
rounded outward."""

from __future__ import annotations

import numpy as np

import ivobs
from ivobs.estimators._balanced import balanced, balancing, unbalanced
from ivobs.testing import conformance_plants


def _mats(sys):
    return tuple(np.asarray(m, dtype=float) for m in sys.matrices_at(0))


def test_the_scaled_plant_is_balanced_exactly_and_maps_back():
    sys, x0 = conformance_plants(0)["scaled"]
    mats = _mats(sys)
    (A, B, C, D, E, F), b0, s = balanced(mats, x0)
    np.testing.assert_array_equal(F, mats[5])
    assert s is not None and np.all(np.frexp(s)[0] == 0.5)  # powers of two
    # the states' magnitudes (1e6, 1, 1e-3) are evened out to within a factor of 16
    assert np.ptp(np.log2(s)) > 25 and np.ptp(np.log2(b0.hi - b0.lo)) < 4
    # the same model: S Ã S⁻¹ = A etc., exactly
    np.testing.assert_array_equal(A * s[:, None] / s[None, :], mats[0])
    np.testing.assert_array_equal(B * s[:, None], mats[1])
    np.testing.assert_array_equal(C / s[None, :], mats[2])
    np.testing.assert_array_equal(E * s[:, None], mats[4])
    np.testing.assert_array_equal(D, mats[3])
    np.testing.assert_array_equal(b0.lo * s, x0.lo)
    # back to x: exact where s >= 1, one ulp outward where s < 1 (a product may underflow)
    lo, hi = unbalanced(b0.lo, b0.hi, s)
    big = s >= 1.0
    np.testing.assert_array_equal(lo[big], x0.lo[big])
    assert np.all(lo[~big] < x0.lo[~big]) and np.all(hi[~big] > x0.hi[~big])
    assert np.all(lo[~big] == np.nextafter(x0.lo[~big], -np.inf))


def test_a_balanced_model_and_an_inexact_scaling_keep_the_coordinates():
    sys = ivobs.LinearSystem(
        [[0.5, 0.1], [0.0, 0.8]],
        [[1.0], [0.0]],
        [[1.0, 0.0]],
        d=ivobs.Box([-0.1], [0.1]),
        E=[[1.0], [1.0]],
    )
    x0 = ivobs.Box([-1.0, -1.0], [1.0, 1.0])
    _, b0, s = balanced(_mats(sys), x0)
    assert s is None and b0 is x0
    # a scaling that would push an entry below the normal range: not exact, not used
    A = np.array([[0.5, 1e-300], [1e300, 0.5]])
    tiny = (A, np.zeros((2, 1)), np.array([[1.0, 1.0]]), np.zeros((1, 1)), np.eye(2),
            np.zeros((1, 2)))  # fmt: skip
    assert np.any(balancing(A, tiny[2], tiny[4], tiny[5]) != 1.0)
    assert balanced(tiny, ivobs.Box([-1.0, -1.0], [1.0, 1.0]))[2] is not None
    # ... but the prior's 1e-300 would leave the normal range: the coordinates are kept
    _, b1, s1 = balanced(tiny, ivobs.Box([-1.0, 1e-300], [1.0, 1.0]))
    assert s1 is None and b1.lo[1] == 1e-300
