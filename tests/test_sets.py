"""Box and Zonotope: the same verbs, exact hulls ([Efimov2013, Lemma 1]), sound reduction."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ivobs
from ivobs import Box, InconsistentDataError, IvobsError, Zonotope, image_bounds
from ivobs.sets import neg, pos

seeds = st.integers(0, 2**31 - 1)


def test_box_basic_properties():
    b = Box([-1.0, 0.0], [1.0, 4.0])
    np.testing.assert_array_equal(b.center, [0.0, 2.0])
    np.testing.assert_array_equal(b.radius, [1.0, 2.0])
    np.testing.assert_array_equal(b.width, [2.0, 4.0])
    assert b.dim == 2 and not b.is_time_varying
    assert b.contains([0.5, 4.0]) and not b.contains([0.5, 4.1])
    assert b.contains([1.05, 0.0], tol=0.1)
    assert Box.from_center([1, 1], [0.5, 0.25]) == Box([0.5, 0.75], [1.5, 1.25])
    assert Box.symmetric([2.0]) == Box([-2.0], [2.0])


@pytest.mark.parametrize(
    "lo, hi, message",
    [
        ([0.0, 2.0], [1.0, 1.0], "lower bound above upper bound at index (1,)"),
        ([0.0], [1.0, 2.0], "same shape"),
        ([np.nan], [1.0], "NaN"),
        ([[[0.0]]], [[[1.0]]], "(n,) or (T, n)"),
        (["a"], [1.0], "expected numbers"),
    ],
)
def test_box_rejects_bad_bounds(lo, hi, message):
    with pytest.raises(IvobsError, match=message.replace("(", r"\(").replace(")", r"\)")):
        Box(lo, hi)


def test_box_intersection_and_empty_intersection_is_a_fault():
    a, b = Box([0, 0], [2, 2]), Box([1, -1], [3, 1])
    assert a.intersect(b) == Box([1, 0], [2, 1])
    with pytest.raises(InconsistentDataError, match="component 0"):
        a.intersect(Box([3, 0], [4, 1]))
    assert not a.intersects(Box([3, 0], [4, 1]))


def test_time_varying_box():
    lo = np.zeros((3, 2))
    hi = np.arange(1, 7, dtype=float).reshape(3, 2)
    b = Box(lo, hi)
    assert b.is_time_varying
    assert b.at(2) == Box([0, 0], [5, 6])
    with pytest.raises(IvobsError, match="step 3 is outside the 3 steps"):
        b.at(3)


def test_pos_neg_split():
    M = np.array([[1.0, -2.0], [0.0, 3.0]])
    np.testing.assert_array_equal(pos(M) - neg(M), M)
    assert (pos(M) >= 0).all() and (neg(M) >= 0).all()


@settings(max_examples=40, deadline=None)
@given(seeds)
def test_image_bounds_is_the_exact_hull(seed):
    """Lemma 1: M⁺lo − M⁻hi ≤ Mx ≤ M⁺hi − M⁻lo, attained at vertices of the box."""
    rng = np.random.default_rng(seed)
    n, m = rng.integers(1, 5, size=2)
    M = rng.normal(size=(m, n))
    lo = rng.normal(size=n)
    hi = lo + rng.uniform(0, 2, size=n)
    b_lo, b_hi = image_bounds(M, lo, hi)
    V = Box(lo, hi).vertices() @ M.T
    np.testing.assert_allclose(b_lo, V.min(axis=0), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(b_hi, V.max(axis=0), rtol=1e-12, atol=1e-12)
    P = Box(lo, hi).sample(50, rng) @ M.T
    assert np.all(P >= b_lo - 1e-12) and np.all(P <= b_hi + 1e-12)
    assert M @ Box(lo, hi) == Box(b_lo, b_hi)
    assert np.all(b_lo <= V.min(axis=0)) and np.all(b_hi >= V.max(axis=0))  # outward


def test_image_bounds_with_infinite_bounds_and_batches():
    M = np.array([[1.0, 0.0], [0.0, -2.0]])
    lo, hi = image_bounds(M, [-np.inf, 1.0], [0.0, 2.0])
    assert lo[0] == -np.inf and -4.0 - 1e-14 < lo[1] <= -4.0  # outward by its rounding bound
    assert 0.0 <= hi[0] < 1e-14 and -2.0 <= hi[1] < -2.0 + 1e-14
    L = np.zeros((5, 7, 2))
    H = np.ones((5, 7, 2))
    lo, hi = image_bounds(M, L, H)
    assert lo.shape == (5, 7, 2)
    assert np.all((hi[..., 1] >= 0.0) & (hi[..., 1] < 1e-14))


def test_zonotope_operations():
    z = Zonotope([1.0, 0.0], [[1.0, 0.5], [0.0, 1.0]])
    hull = z.interval_hull()  # the exact hull [-0.5, 2.5] x [-1, 1], rounded outward
    assert np.all(hull.lo <= [-0.5, -1.0]) and np.all(hull.hi >= [2.5, 1.0])
    np.testing.assert_allclose(hull.lo, [-0.5, -1.0], rtol=0, atol=1e-14)
    np.testing.assert_allclose(hull.hi, [2.5, 1.0], rtol=0, atol=1e-14)
    w = np.array([[2.0, 0.0], [1.0, 1.0]]) @ z
    np.testing.assert_array_equal(w.c, [2.0, 1.0])
    np.testing.assert_array_equal(w.G[:, :2], [[2.0, 1.0], [1.0, 1.5]])
    assert w.num_generators == 4 and np.all(w.G[:, 2:] < 1e-14)  # + the box of its rounding
    s = z + Box([0, 0], [1, 1])
    assert s.num_generators == 6  # 2 + the box's 2 + the centre's rounding box
    np.testing.assert_array_equal(s.c, [1.5, 0.5])
    assert z.contains([2.5, 1.0]) and not z.contains([2.5, -1.0])
    t = Box([0, 0], [1, 1]) + z  # the box's generators first
    np.testing.assert_allclose(t.G[:, :4], np.hstack([np.diag([0.5, 0.5]), z.G]), atol=1e-15)
    np.testing.assert_array_equal(t.c, s.c)
    with pytest.raises(IvobsError, match="expected shape"):
        Zonotope([0.0, 0.0], np.ones((3, 2)))


@settings(max_examples=25, deadline=None)
@given(seeds)
def test_hull_contains_samples_and_is_tight(seed):
    rng = np.random.default_rng(seed)
    n, m = int(rng.integers(1, 4)), int(rng.integers(1, 8))
    z = Zonotope(rng.normal(size=n), rng.normal(size=(n, m)))
    hull = z.interval_hull()
    pts = z.sample(200, rng)
    assert hull.contains(pts).all()
    # tight: each face of the hull is touched by a vertex (b = sign of the generator row)
    for i in range(n):
        top = z.c + z.G @ np.sign(z.G[i])
        assert np.isclose(top[i], hull.hi[i])


@settings(max_examples=25, deadline=None)
@given(seeds)
def test_reduction_contains_the_original(seed):
    """[Tang2019, Remark 2]: <0, H> ⊆ <0, ↓_{q,W} H>; checked on vertices of the original (LP)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 4))
    m = int(rng.integers(n + 1, 12))
    q = int(rng.integers(n, m + 1))
    z = Zonotope(rng.normal(size=n), rng.normal(size=(n, m)))
    W = np.diag(rng.uniform(0.5, 2.0, n))
    r = z.reduce(q, weight=W)
    assert r.num_generators <= q
    for p in z.sample(15, rng, vertices=True):
        assert r.contains(p, tol=1e-7)
    assert np.all(r.interval_hull().hi >= z.interval_hull().hi - 1e-12)


def test_reduction_keeps_largest_generators_and_boxes_the_rest():
    G = np.array([[3.0, 0.1, 0.0, 1.0], [0.0, 0.1, 2.0, -1.0]])
    r = Zonotope([0, 0], G).reduce(3)  # keep q - n = 1 generator, box the other three
    np.testing.assert_array_equal(r.G[:, 0], [3.0, 0.0])
    np.testing.assert_allclose(r.G[:, 1:], np.diag([1.1, 3.1]))
    with pytest.raises(IvobsError, match="must be >= n = 2"):
        Zonotope([0, 0], G).reduce(1)


def test_public_names():
    for name in [
        "Box",
        "Zonotope",
        "LinearSystem",
        "Estimate",
        "make_estimator",
        "simulate",
        "IvobsError",
        "DesignError",
        "scenarios",
        "methods",
    ]:
        assert hasattr(ivobs, name)
    assert issubclass(ivobs.DesignError, ivobs.IvobsError)
    assert issubclass(ivobs.IvobsError, ValueError)
