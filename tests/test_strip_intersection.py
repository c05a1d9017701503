"""The set operations of the strip method (``ivobs.sets.strip``, ``ivobs.sets.reduction``): the
section hull is the exact hull of a zonotope and a strip and holds every point of it at every
magnitude (checked in exact rational arithmetic), the weighted quantiles are the least
breakpoints reaching their thresholds, the box contraction and [Alamo2005]'s update keep every
point of the intersection, and the reductions enclose the zonotope."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import ivobs
from ivobs.sets import ConstrainedZonotope
from ivobs.sets.reduction import MAX_BASIS_CONDITION, reduce_girard, reduce_parallelotope
from ivobs.sets.strip import contract_box, intersect_strip, section_hull, weighted_quantiles


def hull(z, H, s, e, sigma=0.0):
    """The section hull of ``<z, H> ∩ {|sᵀξ - e| <= σ}`` on every coordinate."""
    return section_hull(z, H, H.shape[1], z.shape[0], s, e, sigma, np.abs(H).sum(axis=1))


def random_section(rng: np.random.Generator, n: int, m: int, offset: float = 1.0):
    """A zonotope <z, H> and a strip |sᵀξ - e| <= σ meeting it, with the awkward cases mixed
    in: exact zeros and tiny entries of s (dropped breakpoints), a repeated breakpoint, σ = 0,
    weights concentrated on a few generators or flat."""
    z = rng.normal(size=n) * offset
    H = rng.normal(size=(n, m)) * (rng.lognormal(sigma=2.0, size=m) if rng.random() < 0.5 else 1)
    H[rng.random((n, m)) < 0.3] = 0.0
    s = rng.normal(size=m) * (rng.lognormal(sigma=2.0, size=m) if rng.random() < 0.5 else 1)
    s[rng.random(m) < 0.2] = 0.0
    s[rng.random(m) < 0.1] *= 1e-16
    if m > 2:
        H[:, 1] = 2.0 * H[:, 0]  # the same breakpoint twice
        s[1] = 2.0 * s[0]
    sigma = 0.0 if rng.random() < 0.3 else float(rng.uniform(0, 0.5)) * np.abs(s).sum()
    e = float(np.abs(s).sum() + sigma) * rng.uniform(-0.99, 0.99)
    return z, H, s, e, sigma


def dual_minimum(z, H, s, e, sigma):
    """``z_j ± min_μ f_j(±μ)`` by evaluating the dual at every breakpoint (the minimum of a
    convex piecewise-linear function is at one of them): the exact hull, by brute force."""
    lo, hi = np.empty(z.shape[0]), np.empty(z.shape[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        for j in range(z.shape[0]):
            mus = np.append(np.where(s != 0, H[j] / s, 0.0), 0.0)
            mus = mus[np.isfinite(mus)]
            spread = np.abs(H[j][None, :] - mus[:, None] * s[None, :]).sum(axis=1)
            hi[j] = z[j] + np.min(mus * e + np.abs(mus) * sigma + spread)
            lo[j] = z[j] - np.min(-mus * e + np.abs(mus) * sigma + spread)
    return lo, hi


# -- the section hull ----------------------------------------------------------------------
def test_section_hull_is_the_exact_hull_of_a_zonotope_and_a_hyperplane() -> None:
    rng = np.random.default_rng(4)
    for _ in range(5):
        z = rng.normal(size=3)
        H = rng.normal(size=(3, 6))
        s = rng.normal(size=6)
        e = 0.5 * float(np.abs(s).sum()) * rng.uniform(-1, 1)
        lo, hi = hull(z, H, s, e)
        box = ConstrainedZonotope(z, H, s[None, :], [e]).interval_hull()
        np.testing.assert_allclose(lo, box.lo, atol=1e-9)
        np.testing.assert_allclose(hi, box.hi, atol=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_section_hull_is_the_minimum_of_the_dual_at_every_size(seed: int) -> None:
    """Sizes from one generator to tank30's (30 x 340): whether the heaviest breakpoints
    decide the quantile, the bracket does, or the selection over all of them, the bound is the
    dual's minimum (within rounding) and never inside it."""
    rng = np.random.default_rng(seed)
    for n, m in [(1, 1), (2, 3), (3, 35), (5, 60), (30, 340)]:
        z, H, s, e, sigma = random_section(rng, n, m)
        lo, hi = hull(z, H, s, e, sigma)
        rlo, rhi = dual_minimum(z, H, s, e, sigma)
        scale = 1e-12 * (np.abs(z) + np.abs(H).sum(axis=1))
        assert np.all(hi >= rhi - scale) and np.all(lo <= rlo + scale)
        assert np.all(hi <= rhi + scale) and np.all(lo >= rlo - scale)


def test_section_hull_holds_the_points_of_the_section_and_touches_them() -> None:
    """Points ξ of the cube meeting the strip (sampled, then the maximisers of an LP per
    coordinate): inside the bounds, and the bounds are reached to 1e-9."""
    from scipy.optimize import linprog

    rng = np.random.default_rng(7)
    for _ in range(8):
        z, H, s, e, sigma = random_section(rng, 3, 12)
        lo, hi = hull(z, H, s, e, sigma)
        xi = rng.uniform(-1, 1, size=(20000, 12))
        pts = z + xi[np.abs(xi @ s - e) <= sigma] @ H.T
        assert np.all(pts >= lo) and np.all(pts <= hi)
        A_ub, b_ub = np.vstack([s, -s]), [e + sigma, sigma - e]
        for j in range(3):
            for sign, bound in ((1.0, hi[j]), (-1.0, lo[j])):
                res = linprog(-sign * H[j], A_ub=A_ub, b_ub=b_ub, bounds=[(-1, 1)] * 12)
                assert res.status == 0
                reached = z[j] + H[j] @ res.x
                assert sign * (bound - reached) >= -1e-12
                assert abs(bound - reached) <= 1e-9 * (1 + abs(z[j]) + np.abs(H[j]).sum())


def _exact_point(z, H, xi):
    """``z + H ξ`` in rationals."""
    return [
        Fraction(float(zj)) + sum(Fraction(float(h)) * Fraction(float(x)) for h, x in zip(row, xi))
        for zj, row in zip(z, H)
    ]


@pytest.mark.parametrize("offset", [1.0, 1e6, 1e10])
def test_section_hull_holds_every_vertex_of_the_section_exactly_at_every_magnitude(offset):
    """Vertices of the section (the LP's basic solutions: every ξ_l = ±1 but one, which meets
    the hyperplane ``sᵀξ = e``) computed and checked in exact rational arithmetic, centres up
    to 1e10: inside the returned bounds, with no margin."""
    rng = np.random.default_rng(int(np.log10(offset)))
    checked = 0
    for _ in range(20):
        n, m = 3, 8
        z, H, s, e, _ = random_section(rng, n, m, offset)
        s[s == 0.0] = 1.0
        s[np.abs(s) < 1e-8] = 1.0
        lo, hi = hull(z, H, s, e)
        sf = [Fraction(float(v)) for v in s]
        for _ in range(40):
            signs = [Fraction(int(v)) for v in rng.choice([-1, 1], m)]
            free = int(rng.integers(m))
            rest = sum(sf[l] * signs[l] for l in range(m) if l != free)
            x_free = (Fraction(e) - rest) / sf[free]
            if abs(x_free) > 1:
                continue
            xi = [*signs[:free], x_free, *signs[free + 1 :]]
            for j, v in enumerate(_exact_point(z, H, xi)):
                assert Fraction(float(lo[j])) <= v <= Fraction(float(hi[j])), (j, float(v))
            checked += 1
    assert checked > 100


def test_section_hull_with_breakpoints_beyond_the_float_range() -> None:
    """|H_jl / s_l| overflows: the hull stays finite where it can and contains the set."""
    rng = np.random.default_rng(5)
    H = np.array([[1e300, 1.0, -2.0], [0.5, 1.0, 1.0]])
    s = np.array([1e-10, 1.0, 0.5])
    z, e, sigma = np.array([0.0, 1.0]), 0.2, 0.1
    lo, hi = hull(z, H, s, e, sigma)
    assert not np.isnan(lo).any() and not np.isnan(hi).any()
    assert np.isfinite(lo[1]) and np.isfinite(hi[1])
    for _ in range(2000):
        xi = rng.uniform(-1, 1, 3)
        if abs(s @ xi - e) <= sigma:
            x = z + H @ xi
            assert np.all(lo <= x) and np.all(x <= hi)


# -- weighted quantiles --------------------------------------------------------------------
def _reference_quantile(b, w, t):
    """The least ``v`` with ``Σ_{b_l <= v} w_l >= t``, by sorting (integer weights: exact)."""
    values = np.unique(b)
    reach = np.array([w[b <= v].sum() for v in values])
    hit = np.flatnonzero(reach >= t)
    return float(values[hit[0]]) if hit.size else float(values[-1])


@pytest.mark.parametrize("seed", range(3))
def test_weighted_quantiles_are_the_least_breakpoints_reaching_the_thresholds(seed: int) -> None:
    """Integer weights (exact sums) with zeros and ties, thresholds from below 0 to above the
    total, both thresholds in one call."""
    rng = np.random.default_rng(seed)
    for _ in range(300):
        n = int(rng.integers(1, 80))
        b = rng.integers(-6, 7, n).astype(float) * (1.0 if rng.random() < 0.5 else 0.37)
        w = rng.integers(0, 5, n).astype(float)
        total = w.sum()
        t1, t2 = sorted(rng.uniform(-0.2, 1.2, 2) * max(total, 1.0))
        t1, t2 = (float(np.round(t1)), float(np.round(t2))) if rng.random() < 0.5 else (t1, t2)
        got = weighted_quantiles(b.copy(), w.copy(), n, t1, t2)
        assert got == (_reference_quantile(b, w, t1), _reference_quantile(b, w, t2))


# -- the contraction and the update ----------------------------------------------------------
@pytest.mark.parametrize("seed", range(3))
def test_contraction_keeps_every_point_of_box_and_strip(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    empty = 0
    for _ in range(60):
        n = int(rng.integers(1, 9))
        h = rng.normal(size=n)
        h[rng.random(n) < 0.3] = 0.0
        lo = rng.normal(size=n) - rng.uniform(0, 2, size=n)
        hi = lo + rng.uniform(0, 2, size=n)
        sigma = float(rng.uniform(0, 0.3))
        t = float(h @ rng.uniform(lo, hi)) + rng.normal() * (2.0 if rng.random() < 0.3 else 0.1)
        clo, chi = lo.copy(), hi.copy()
        ok = contract_box(h, t, sigma, clo, chi)
        pts = rng.uniform(lo, hi, size=(4000, n))
        inside = pts[np.abs(pts @ h - t) <= sigma]
        if not ok:
            empty += 1
            assert inside.shape[0] == 0
            continue
        assert np.all(clo >= lo) and np.all(chi <= hi)
        assert np.all(inside >= clo) and np.all(inside <= chi)
    assert 0 < empty < 60  # both outcomes exercised


def test_a_strip_touching_a_corner_of_the_box_keeps_it() -> None:
    """Integers: the corner (1, 2, -3) lies exactly on the strip's edge ``hᵀζ = t + σ``: never
    reported empty, and the corner stays in the contracted box."""
    h = np.array([2.0, -1.0, 4.0])
    corner = np.array([1.0, 2.0, -3.0])
    lo, hi = corner - np.array([3.0, 0.0, 1.0]), corner + np.array([0.0, 5.0, 0.0])
    sigma = 0.5
    t = float(h @ corner) - sigma  # the largest value of hᵀζ on the box is at the corner
    assert float(h @ corner) == max(h @ np.array(v) for v in np.array(np.meshgrid(
        *zip(lo, hi))).reshape(3, -1).T)  # fmt: skip
    clo, chi = lo.copy(), hi.copy()
    assert contract_box(h, t, sigma, clo, chi)
    assert np.all(clo <= corner) and np.all(corner <= chi)


@pytest.mark.parametrize("seed", range(3))
def test_alamo_update_contains_the_intersection(seed: int) -> None:
    """Points of ``<z, H> ⊕ box(acc)`` in the strip stay in the updated zonotope ⊕ box(acc')
    (an LP each) and in the updated box."""
    rng = np.random.default_rng(seed)
    nz, m, n_hull = 4, 9, 3
    z = rng.normal(size=nz)
    H = np.zeros((nz, m + 1))
    H[:, :m] = rng.normal(size=(nz, m))
    acc = rng.uniform(0, 1e-3, nz)
    rows = np.abs(H[:, :m]).sum(axis=1)
    lo, hi = z - rows - acc - 0.1, z + rows + acc + 0.1
    h = rng.normal(size=nz)
    sigma = 0.3
    xi = rng.uniform(-1, 1, size=(3000, m))
    a = rng.uniform(-1, 1, size=(3000, nz)) * acc
    pts = z + xi @ H[:, :m].T + a
    t = float(h @ pts[0])
    inside = pts[np.abs(pts @ h - t) <= sigma][:30]
    z1, H1, acc1, rows1 = z.copy(), H.copy(), acc.copy(), rows.copy()
    lo1, hi1 = lo.copy(), hi.copy()
    grown = intersect_strip(h, t, sigma, z1, H1, m, acc1, rows1, lo1, hi1, n_hull)
    assert grown == m + 1
    np.testing.assert_allclose(rows1, np.abs(H1).sum(axis=1), rtol=1e-14)
    Z = ivobs.Zonotope(z1, np.hstack([H1, np.diag(acc1)]))
    for p in inside:
        assert Z.contains(p, tol=1e-12)
        assert np.all(lo1 <= p) and np.all(p <= hi1)
    # a strip far away: certainly missed, nothing changed
    z2, H2 = z.copy(), H.copy()
    assert intersect_strip(h, t + 1e3, sigma, z2, H2, m, acc.copy(), rows, lo, hi, n_hull) == -1
    assert np.array_equal(z2, z) and np.array_equal(H2, H)


# -- reductions ----------------------------------------------------------------------------
def _contained(G, G2, rho, rng) -> bool:
    """Vertices of <0, G> in <0, G2> ⊕ box(rho) (one LP each)."""
    Z = ivobs.Zonotope(np.zeros(G.shape[0]), np.hstack([G2, np.diag(rho)]))
    pts = ivobs.Zonotope(np.zeros(G.shape[0]), G).sample(15, rng, vertices=True)
    return all(Z.contains(p, tol=1e-12) for p in pts)


def test_reductions_enclose_the_zonotope() -> None:
    rng = np.random.default_rng(5)
    for _ in range(3):
        n, m = int(rng.integers(2, 6)), int(rng.integers(8, 30))
        G = rng.normal(size=(n, m)) * rng.lognormal(size=m)
        for q in (n, n + 2, m - 1):
            G2, rho = reduce_parallelotope(G, q)
            assert G2.shape[1] <= q and _contained(G, G2, rho, rng)
            G3 = reduce_girard(G, q)
            assert G3.shape[1] <= q and _contained(G, G3, np.zeros(n), rng)


def test_an_ill_conditioned_basis_falls_back_to_girard() -> None:
    """Nearly parallel generators: any basis of two of them is nearly singular (condition
    ~1e7 > MAX_BASIS_CONDITION); the reduction is Girard's box."""
    G = np.array([[1.0, 2.0, 3.0, -1.0, 1.5], [1.0, 2.0 + 1e-7, 3.0 - 2e-7, -1.0, 1.5 + 1e-7]])
    G2, rho = reduce_parallelotope(G, 3)
    assert MAX_BASIS_CONDITION < 1e6
    np.testing.assert_array_equal(G2, reduce_girard(G, 3))
    assert not rho.any()
