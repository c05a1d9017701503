"""ConstrainedZonotope: exact operations, LP interval hull, emptiness, reduction (Scott 2016)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

import ivobs
from ivobs.sets import ConstrainedZonotope, eliminate_constraints, reduce_generators


def vertices(z: ConstrainedZonotope) -> np.ndarray:
    """Vertices of a small constrained zonotope by enumeration (no LP): a vertex of
    ``{ξ ∈ [-1, 1]^m : A ξ = b}`` has ``m - nc`` coordinates at ``±1`` (A of full row rank)."""
    m, nc = z.num_generators, z.num_constraints
    pts = []
    for fixed in itertools.combinations(range(m), m - nc):
        free = [j for j in range(m) if j not in fixed]
        for signs in itertools.product([-1.0, 1.0], repeat=m - nc):
            xi = np.zeros(m)
            xi[list(fixed)] = signs
            rhs = z.b - z.A[:, list(fixed)] @ np.array(signs)
            sol = np.linalg.solve(z.A[:, free], rhs) if nc else np.zeros(0)
            if np.all(np.abs(sol) <= 1 + 1e-12):
                xi[free] = sol
                pts.append(z.c + z.G @ xi)
    return np.array(pts)


def random_cz(rng: np.random.Generator, n: int = 2, m: int = 6, nc: int = 2) -> ConstrainedZonotope:
    G = rng.normal(size=(n, m))
    A = rng.normal(size=(nc, m))
    b = A @ rng.uniform(-0.8, 0.8, m)  # a feasible ξ exists: nonempty
    return ConstrainedZonotope(rng.normal(size=n), G, A, b)


def with_box(r) -> ConstrainedZonotope:
    """``<c, G, A, b> ⊕ box(e)`` of an elimination as one constrained zonotope."""
    G = np.hstack([r.G, np.diag(r.e)])
    return ConstrainedZonotope(r.c, G, np.hstack([r.A, np.zeros((r.A.shape[0], r.e.size))]), r.b)


def test_hull_of_a_known_set() -> None:
    # {[0,0] + G ξ : -2 ξ1 + ξ2 - ξ3 = 2}: ξ3 = -2 ξ1 + ξ2 - 2 forces ξ1 <= 0.5(ξ2 - 1)
    z = ConstrainedZonotope([0, 0], [[1, 0, 1], [1, 2, -1]], [[-2, 1, -1]], [2])
    box = z.interval_hull()
    np.testing.assert_allclose(box.lo, [-2.0, -2.0], atol=1e-9)
    np.testing.assert_allclose(box.hi, [0.0, 3.0], atol=1e-9)
    assert not z.is_empty()


@pytest.mark.parametrize("seed", range(6))
def test_hull_equals_vertex_enumeration_and_is_never_inside_it(seed: int) -> None:
    z = random_cz(np.random.default_rng(seed), n=3, m=6, nc=2)
    v = vertices(z)
    box = z.interval_hull()
    assert np.all(box.lo <= v.min(axis=0) + 1e-12)  # certified bounds: never cut the set
    assert np.all(box.hi >= v.max(axis=0) - 1e-12)
    np.testing.assert_allclose(box.lo, v.min(axis=0), atol=1e-7)
    np.testing.assert_allclose(box.hi, v.max(axis=0), atol=1e-7)


def test_linear_map_minkowski_sum_and_translation() -> None:
    rng = np.random.default_rng(3)
    z1, z2 = random_cz(rng), random_cz(rng)
    M = rng.normal(size=(2, 2))
    v1, v2 = vertices(z1), vertices(z2)
    s = z1 + z2
    assert s.num_generators >= 12 and s.num_constraints == 4  # (and the rounding's box)
    for p in v1[:3]:
        for q in v2[:3]:
            assert s.contains(p + q)
    mz = M @ z1
    assert all(mz.contains(M @ p) for p in v1)
    box = (z1 + np.array([1.0, -2.0])).interval_hull()
    np.testing.assert_allclose(box.lo, v1.min(axis=0) + np.array([1.0, -2.0]), atol=1e-7)
    # sum with a box and a zonotope
    zb = z1 + ivobs.Box([-1.0, 0.0], [1.0, 0.0])
    np.testing.assert_allclose(
        zb.interval_hull().hi, v1.max(axis=0) + np.array([1.0, 0.0]), atol=1e-7
    )
    zz = z1 + ivobs.Zonotope([0.0, 0.0], [[1.0], [1.0]])
    np.testing.assert_allclose(zz.interval_hull().hi, v1.max(axis=0) + 1, atol=1e-7)


def test_a_box_or_zonotope_on_the_left_of_a_sum_gives_a_constrained_zonotope() -> None:
    z = random_cz(np.random.default_rng(5))
    for left in (ivobs.Box([-1.0, 0.0], [1.0, 0.5]), ivobs.Zonotope([0.5, 0.0], [[1.0], [2.0]])):
        s, r = left + z, z + left
        assert isinstance(s, ConstrainedZonotope) and s.num_constraints == z.num_constraints
        np.testing.assert_array_equal(s.c, r.c)
        np.testing.assert_allclose(s.interval_hull().lo, r.interval_hull().lo, atol=1e-12)
        np.testing.assert_allclose(s.interval_hull().hi, r.interval_hull().hi, atol=1e-12)
    np.testing.assert_array_equal((np.array([1.0, 2.0]) + z).c, z.c + np.array([1.0, 2.0]))


def test_intersection_with_box_strip_and_hyperplane() -> None:
    sq = ConstrainedZonotope.from_box(ivobs.Box([-1.0, -1.0], [1.0, 1.0]))
    # the strip |x1 + x2 - 1.5| <= 0.1 cuts the corner of the square
    st = sq.intersect_strip([1.0, 1.0], 1.5, 0.1)
    np.testing.assert_allclose(st.interval_hull().lo, [0.4, 0.4], atol=1e-8)
    np.testing.assert_allclose(st.interval_hull().hi, [1.0, 1.0], atol=1e-8)
    hp = sq.intersect_hyperplane([1.0, -1.0], 1.0)  # x1 - x2 = 1
    np.testing.assert_allclose(hp.interval_hull().lo, [0.0, -1.0], atol=1e-8)
    np.testing.assert_allclose(hp.interval_hull().hi, [1.0, 0.0], atol=1e-8)
    other = ivobs.Box([0.5, -3.0], [3.0, 0.2])
    both = sq.intersect(other)
    np.testing.assert_allclose(both.interval_hull().lo, [0.5, -1.0], atol=1e-8)
    np.testing.assert_allclose(both.interval_hull().hi, [1.0, 0.2], atol=1e-8)
    # generalised intersection {z : R z ∈ Y}: x1 + x2 in [1.9, 3] leaves the corner (1, 1)
    corner = sq.intersect(ivobs.Box([1.9], [3.0]), R=[[1.0, 1.0]])
    np.testing.assert_allclose(corner.interval_hull().lo, [0.9, 0.9], atol=1e-8)


def test_emptiness_is_detected_and_reported() -> None:
    sq = ConstrainedZonotope.from_box(ivobs.Box([0.0, 0.0], [1.0, 1.0]))
    far = sq.intersect(ivobs.Box([2.0, 0.0], [3.0, 1.0]))
    assert far.is_empty()
    with pytest.raises(ivobs.InconsistentDataError):
        far.interval_hull()
    with pytest.raises(ivobs.InconsistentDataError):
        far.reduce(max_constraints=0)
    touching = sq.intersect(ivobs.Box([1.0, 0.0], [3.0, 1.0]))  # a segment: not empty
    assert not touching.is_empty()
    np.testing.assert_allclose(touching.interval_hull().lo, [1.0, 0.0], atol=1e-7)


def test_contains() -> None:
    z = ConstrainedZonotope([0, 0], [[1, 0, 1], [1, 2, -1]], [[-2, 1, -1]], [2])
    assert z.contains([-1.0, 0.0])
    assert not z.contains([0.0, -2.0])  # in the zonotope, cut by the constraint
    assert ivobs.Zonotope([0, 0], [[1, 0, 1], [1, 2, -1]]).contains([0.0, -2.0])


@pytest.mark.parametrize("seed", range(8))
def test_reduction_contains_the_original(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    z = random_cz(rng, n=3, m=14, nc=5)
    box = z.interval_hull()
    red = z.reduce(max_generators=9, max_constraints=2)
    assert red.num_constraints <= 2 and red.num_generators <= 9
    rbox = red.interval_hull()
    assert np.all(rbox.lo <= box.lo + 1e-9) and np.all(rbox.hi >= box.hi - 1e-9)
    for p in z.sample(15, rng):
        assert red.contains(p, tol=1e-7)
    # each stage alone is sound, and the generator stage keeps the constraints
    c, G, A, b = reduce_generators(z.c, z.G, z.A, z.b, 8)
    assert G.shape[1] <= 8 and A.shape[0] == 5
    assert all(ConstrainedZonotope(c, G, A, b).contains(p, tol=1e-7) for p in z.sample(5, rng))
    out = eliminate_constraints(z.c, z.G, z.A, z.b, 0)
    assert out is not None and out.A.shape[0] == 0
    assert all(with_box(out).contains(p, tol=1e-7) for p in z.sample(5, rng))


def test_redundant_constraint_is_eliminated_exactly() -> None:
    # x = ξ1 + ξ2 with ξ3 = 0.1 ξ1: the bound |ξ3| <= 1 is redundant, elimination is exact
    z = ConstrainedZonotope([0.0], [[1.0, 1.0, 0.0]], [[0.1, 0.0, -1.0]], [0.0])
    red = z.reduce(max_constraints=0)
    assert red.num_constraints == 0
    np.testing.assert_allclose(red.interval_hull().lo, [-2.0], atol=1e-12)
    np.testing.assert_allclose(red.interval_hull().hi, [2.0], atol=1e-12)


def test_rescale_keeps_the_set() -> None:
    z = random_cz(np.random.default_rng(7), n=2, m=5, nc=2)
    r = z.rescale()
    np.testing.assert_allclose(r.interval_hull().lo, z.interval_hull().lo, atol=1e-8)
    np.testing.assert_allclose(r.interval_hull().hi, z.interval_hull().hi, atol=1e-8)


def test_to_zonotope_encloses() -> None:
    z = random_cz(np.random.default_rng(9), n=2, m=6, nc=2)
    zz = z.to_zonotope()
    assert isinstance(zz, ivobs.Zonotope)
    assert all(zz.contains(p) for p in vertices(z))


def test_bad_input_names_the_argument() -> None:
    with pytest.raises(ivobs.IvobsError, match="generators"):
        ConstrainedZonotope([0, 0], [[1, 2, 3]])
    with pytest.raises(ivobs.IvobsError, match="A and b"):
        ConstrainedZonotope([0], [[1.0]], A=[[1.0]])
    with pytest.raises(ivobs.IvobsError, match="one column per generator"):
        ConstrainedZonotope([0], [[1.0, 2.0]], A=[[1.0]], b=[0.0])
    with pytest.raises(ivobs.IvobsError, match="sigma"):
        ConstrainedZonotope([0], [[1.0]]).intersect_strip([1.0], 0.0, -1.0)
    with pytest.raises(ivobs.IvobsError, match="max_constraints"):
        ConstrainedZonotope([0], [[1.0]]).reduce(max_constraints=-1)


@pytest.mark.parametrize("seed", range(4))
def test_certificates_follow_the_reduction(seed: int) -> None:
    """The certificates of the hull bounds are transformed with the set: their objectives stay
    the rows of ±G, and the bounds they certify stay valid (below the LP optimum) after every
    elimination."""
    from ivobs.sets import hull_certificates

    z = random_cz(np.random.default_rng(200 + seed), n=3, m=14, nc=6)
    lo, hi, cert = hull_certificates(z.c, z.G, z.A, z.b)
    out = eliminate_constraints(z.c, z.G, z.A, z.b, 2, cert)
    assert out is not None
    c, G, A, b, _ = out
    np.testing.assert_allclose(cert.D, np.vstack([G, -G]), atol=1e-9)
    bound = cert.mu @ b - np.abs(cert.D - cert.mu @ A).sum(axis=1)
    red = ConstrainedZonotope(c, G, A, b).interval_hull()
    assert np.all(c + bound[:3] <= red.lo + 1e-9) and np.all(c - bound[3:] >= red.hi - 1e-9)
    assert np.all(red.lo <= lo + 1e-9) and np.all(red.hi >= hi - 1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_hull_with_extra_objectives_matches_linprog_and_certifies_them(seed: int) -> None:
    """The hull solved on one warm-started HiGHS model (with the extra objectives the filter
    adds for its prediction) equals ``linprog``'s optimum to LP tolerance, every certified
    bound is below the optimum of its program, and the extra objectives' certificates survive
    an elimination (the bound after it stays below the reduced set's optimum)."""
    from scipy.optimize import linprog

    from ivobs.sets import hull_certificates

    rng = np.random.default_rng(300 + seed)
    z = random_cz(rng, n=3, m=16, nc=6)
    P = rng.normal(size=(2, z.G.shape[1]))
    lo, _, cert = hull_certificates(z.c, z.G, z.A, z.b, P)
    D = np.vstack([z.G, -z.G, P, -P])
    assert cert.D.shape == D.shape and cert.mu.shape == (10, 6)
    opt = np.array([linprog(g, A_eq=z.A, b_eq=z.b, bounds=(-1, 1), method="highs").fun for g in D])
    bound = cert.mu @ z.b - np.abs(cert.D - cert.mu @ z.A).sum(axis=1)
    assert np.all(bound <= opt + 1e-12 * (1 + np.abs(opt)))
    np.testing.assert_allclose(bound, opt, atol=1e-7)
    np.testing.assert_allclose(lo, z.c + opt[:3], atol=1e-7)
    out = eliminate_constraints(z.c, z.G, z.A, z.b, 3, cert)
    assert out is not None
    A, b = out.A, out.b
    after = cert.mu @ b - np.abs(cert.D - cert.mu @ A).sum(axis=1)
    Pc = cert.D[6:8]  # the extra objectives, mapped to the reduced factors
    opt2 = np.array([linprog(g, A_eq=A, b_eq=b, bounds=(-1, 1), method="highs").fun for g in Pc])
    assert np.all(after[6:8] <= opt2 + 1e-9)


@pytest.mark.parametrize("seed", range(2))
def test_prediction_bounds_combined_from_the_box_are_sound_and_near_their_optimum(
    monkeypatch, seed: int
) -> None:
    """On a set too large for one block program, the bounds of ``P = M G + Q`` are first
    certified by combining the box's multipliers: every one is below the optimum of its
    program and none is further from it than ``COMBINED_GAP`` of ``P``'s width. Rows of ``M``
    with one entry (``Q`` in factors of no constraint) combine exactly and are not solved for;
    rows that mix the coordinates combine loosely (10-50 % of the width here) and are."""
    from scipy.optimize import linprog

    from ivobs.sets.czonotope import hull

    rng = np.random.default_rng(400 + seed)
    n, m, nc, half = 6, 180, 110, 3
    z = random_cz(rng, n=n, m=m, nc=nc)
    G = np.hstack([z.G, np.zeros((n, 8))])  # 8 new factors, in P only (the E R of a filter)
    A = np.hstack([z.A, np.zeros((nc, 8))])
    M = np.diag(rng.uniform(-2.0, 2.0, n))
    M[half:] = rng.normal(size=(n - half, n))
    P = M @ G + np.hstack([np.zeros((n, m)), 0.05 * rng.normal(size=(n, 8))])
    assert 2 * n * (m + 8) > hull.BLOCK_SIZE  # the regime where each bound is a solve
    solved = []
    real = hull._certified_mins

    def counting(Gs, A_, b_, radius, chains, warm=False, points=False):
        solved.append(Gs.shape[0])
        return real(Gs, A_, b_, radius, chains, warm, points)

    monkeypatch.setattr(hull, "_certified_mins", counting)
    lo, _, cert = hull.hull_certificates(z.c, G, A, z.b, P, M)
    assert solved == [2 * n, 2 * (n - half)]  # the box, then the mixing rows of ±P
    D = np.vstack([G, -G, P, -P])
    opt = np.array([linprog(g, A_eq=A, b_eq=z.b, bounds=(-1, 1), method="highs").fun for g in D])
    bound = cert.mu @ z.b - np.abs(cert.D - cert.mu @ A).sum(axis=1)
    assert np.all(bound <= opt + 1e-9 * (1 + np.abs(opt)))
    width = -(opt[2 * n : 3 * n] + opt[3 * n :])
    gap = opt[2 * n :] - bound[2 * n :]
    assert np.all(gap <= hull.COMBINED_GAP * np.tile(width, 2) + 1e-7)
    np.testing.assert_allclose(lo, z.c + opt[:n], atol=1e-7)


@pytest.mark.parametrize("seed", range(3))
def test_reduced_costs_follow_each_elimination(seed: int) -> None:
    """The certificates' reduced costs ``D − μ A``, updated by a rank-one term per elimination
    (not recomputed), equal the recomputed ones after a chain of eliminations, rescalings and
    row scalings of the constraints."""
    from ivobs.sets import Certificates

    rng = np.random.default_rng(700 + seed)
    K, nc, m = 5, 6, 12
    A = rng.normal(size=(nc, m))
    cert = Certificates(rng.normal(size=(K, m)), rng.normal(size=(K, nc)), np.ones(K))
    cert.reduced_costs(A)  # cached from here on
    for _ in range(3):
        j = int(rng.integers(A.shape[1]))
        p = int(np.argmax(np.abs(A[:, j])))
        cert.eliminate(A, j, p)
        A = A - np.outer(A[:, j], A[p] / A[p, j])
        A = np.delete(np.delete(A, p, axis=0), j, axis=1)
        rad = rng.uniform(0.5, 1.0, size=A.shape[1])
        A = A * rad
        cert.scale_factors(rad)
        s = rng.uniform(0.5, 2.0, size=A.shape[0])
        A = A / s[:, None]
        cert.scale_rows(s)
        np.testing.assert_allclose(cert.reduced_costs(A), cert.D - cert.mu @ A, atol=1e-9)


def test_a_set_the_solver_calls_infeasible_is_relaxed_row_by_row(monkeypatch) -> None:
    """When HiGHS calls a nonempty set infeasible (thin sets near its tolerances do), the hull
    is that of the set with each constraint relaxed by a tiny slack factor: a superset within
    about the slack of the exact hull, and the caller keeps that set (``soften``). Widening
    the factors' box instead (the last resort) can multiply the widths."""
    from ivobs.sets.czonotope import hull, hull_certificates, soften

    rng = np.random.default_rng(7)
    z = random_cz(rng, n=2, m=6, nc=2)
    exact_lo, exact_hi = vertices(z).min(axis=0), vertices(z).max(axis=0)
    real = hull._certified_mins
    calls = []

    def refuses_the_set_as_given(Gs, A, b, radius, chains):
        calls.append(A.shape)
        if A.shape == z.A.shape:  # the solver's false "infeasible" on the set itself
            nan = np.full(Gs.shape[0], np.nan)
            return nan, np.zeros((Gs.shape[0], A.shape[0])), False, np.full(Gs.shape, np.nan)
        return real(Gs, A, b, radius, chains)

    monkeypatch.setattr(hull, "_certified_mins", refuses_the_set_as_given)
    monkeypatch.setattr(hull, "radius_certificate", lambda A, b: (2.0, 0.5))
    lo, hi, cert = hull_certificates(z.c, z.G, z.A, z.b)
    assert calls == [(2, 6), (2, 8)]  # the set, then its relaxation by the first tolerance
    assert cert.softened and cert.radius == 1.0 and cert.slack is not None
    assert np.all(lo <= exact_lo) and np.all(hi >= exact_hi)
    scale = 1.0 + np.abs(z.b).max() + np.abs(z.A).sum(axis=1).max()
    np.testing.assert_allclose(lo, exact_lo, atol=1e-6 * scale)
    np.testing.assert_allclose(hi, exact_hi, atol=1e-6 * scale)
    G, A, e = soften(z.G, z.A, cert.radius, cert.slack)
    assert G.shape == (2, 8) and A.shape == (2, 8) and not e.any()  # no rounding at radius 1
    kept = ConstrainedZonotope(z.c, G, A, z.b)
    monkeypatch.setattr(hull, "_certified_mins", real)
    assert np.all(vertices(kept).min(axis=0) <= exact_lo)
    assert np.all(vertices(kept).max(axis=0) >= exact_hi)


def test_a_set_pinned_to_a_point_keeps_its_width_when_the_solver_balks() -> None:
    """Dinh's random 8-state plant pins the state down to widths of 1e-10 within a step; at
    some steps HiGHS then calls the thin filtered set infeasible. Widening the factors' box to
    the solver's inaccurate smallest radius (2.1 where it is at most 1) made the box 5 units
    wide at such steps (a mean 9x that of the exact filter over the record); the rows'
    relaxation keeps every step within 1e-6."""
    sc = ivobs.scenarios.get("kkl-random8", horizon=30)
    traj = sc.simulate("vertex", seed=0)
    est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0)
    res = est.run(traj.u, traj.y)
    width = res.upper - res.lower
    x = np.asarray(traj.x)
    assert np.all(res.lower <= x) and np.all(x <= res.upper)
    assert width[0].max() > 1.0  # the prior's step
    assert width[1:].max() < 1e-6
