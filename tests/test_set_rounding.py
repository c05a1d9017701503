"""The proven rounding model of the set operations (ivobs.sets.rounding): every bound is checked
against the exact result in rational arithmetic, at magnitudes from 1e-300 to 1e300."""

from fractions import Fraction as Fr

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ivobs import Box, DesignError, Zonotope
from ivobs.sets.rounding import DecayBound, mid_rad, product_error, upper

seeds = st.integers(0, 2**32 - 1)


def _scaled(rng, shape, lo=-12, hi=12):
    return rng.standard_normal(shape) * 10.0 ** rng.integers(lo, hi, size=shape)


def _exact_matvec(M, x):
    return [
        sum((Fr(M[i, k]) * Fr(x[k]) for k in range(M.shape[1])), Fr(0)) for i in range(M.shape[0])
    ]


@settings(max_examples=60, deadline=None)
@given(seeds)
def test_product_error_bounds_a_matvec_exactly(seed):
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(1, 9)), int(rng.integers(1, 6))
    M, x = _scaled(rng, (m, n)), _scaled(rng, n, -300, 290)  # products within the float range
    y, e = M @ x, product_error(np.abs(M) @ np.abs(x), n)
    for i, ex in enumerate(_exact_matvec(M, x)):
        assert np.isfinite(e[i]) and abs(Fr(y[i]) - ex) <= Fr(e[i])


def test_upper_bounds_a_long_sum_of_nonnegative_terms():
    rng = np.random.default_rng(1)
    v = rng.uniform(0, 1, 5000) * 10.0 ** rng.integers(-5, 5, 5000)
    s = float(upper(v.sum(), v.size))
    assert Fr(s) >= sum(Fr(t) for t in v.tolist())
    assert s < v.sum() * (1 + 1e-11)  # and it stays a rounding-level enlargement


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_mid_rad_contains_the_interval(seed):
    rng = np.random.default_rng(seed)
    lo = _scaled(rng, 6, -300, 307)
    hi = np.where(rng.uniform(size=6) < 0.2, lo, lo + np.abs(_scaled(rng, 6, -300, 307)))
    c, r = mid_rad(lo, hi)
    for a, b, cc, rr in zip(lo, hi, c, r):
        assert Fr(cc) - Fr(rr) <= Fr(a) and Fr(cc) + Fr(rr) >= Fr(b)


@settings(max_examples=30, deadline=None)
@given(seeds)
def test_box_and_zonotope_verbs_contain_the_exact_images(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5))
    M = _scaled(rng, (n, n), -3, 3)
    lo = _scaled(rng, n, -8, 10)
    hi = lo + np.abs(_scaled(rng, n, -8, 10))
    box = Box(lo, hi)
    image = M @ box
    z = M @ box.to_zonotope()
    zh = z.interval_hull()
    for v in box.vertices():  # the image of a box is the hull of its vertices' images
        ex = _exact_matvec(M, v)
        for i in range(n):
            assert Fr(image.lo[i]) <= ex[i] <= Fr(image.hi[i])
            assert Fr(zh.lo[i]) <= ex[i] <= Fr(zh.hi[i])
    s = box + box
    for i in range(n):
        assert Fr(s.lo[i]) <= 2 * Fr(lo[i]) and Fr(s.hi[i]) >= 2 * Fr(hi[i])


def test_zonotope_reduction_rounds_the_box_up():
    rng = np.random.default_rng(3)
    G = rng.uniform(0.1, 1.0, (2, 40)) * 10.0 ** rng.integers(-3, 3, (2, 40))
    red = Zonotope(np.zeros(2), G).reduce(2)
    for i in range(2):
        assert Fr(red.G[i, i]) >= sum(Fr(abs(g)) for g in G[i].tolist())


@settings(max_examples=20, deadline=None)
@given(seeds)
def test_decay_bound_holds_for_the_exact_powers(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4))
    M = rng.standard_normal((n, n))
    M *= rng.uniform(0.2, 0.95) / max(np.max(np.abs(np.linalg.eigvals(M))), 1e-3)
    db = DecayBound.of(M)
    P = [[Fr(int(i == j)) for j in range(n)] for i in range(n)]
    MF = [[Fr(v) for v in row] for row in M.tolist()]
    for i in range(40):
        assert max(sum(abs(v) for v in row) for row in P) <= Fr(db.c) * Fr(db.lam) ** i
        P = [[sum(MF[a][k] * P[k][b] for k in range(n)) for b in range(n)] for a in range(n)]
    q = 0.0
    r = rng.uniform(0, 1, 50)
    qs = db.accumulate(r)
    for k in range(50):
        q = db.next(q, r[k])
        assert qs[k] >= q * (1 - 1e-15) and q >= 0  # the filter and the loop agree, both upper


def test_decay_bound_refuses_an_unstable_matrix():
    with pytest.raises(DesignError, match="not Schur"):
        DecayBound.of(np.array([[1.01]]), max_power=2000)
