"""The strip method's fused array form (issue 17): the section hull and the strip propagation
give the numbers of the one-bound-at-a-time reference kept below, never looser, and the filter
built on them still holds the true state of a simulator written here (vertex disturbances
entering both the state and the output, a bound on ``d`` that changes with ``k``)."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import Box
from ivobs.estimators import _strip_kernel
from ivobs.estimators._strip_hull import propagate_strip, section_hull
from ivobs.linalg import gamma

# -- the reference: the form before issue 17 (one bound, one NumPy call each) -------------------


def ref_section_hull(z, H, s, e, sigma=0.0, absH=None):
    n, m = H.shape
    if absH is None:
        absH = np.abs(H).sum(axis=1)
    a_s = np.abs(s)
    smax = float(a_s.max()) if m else 0.0
    if not smax > 0.0:
        r = absH + gamma(m + 2) * (np.abs(z) + absH)
        return z - r, z + r
    keep = a_s > 1e-14 * smax
    with np.errstate(over="ignore"):
        b = np.hstack([H[:, keep] / s[keep], np.zeros((n, 1))])
    b[~np.isfinite(b)] = 0.0
    w = np.append(a_s[keep], sigma)
    idx = np.argsort(b, axis=1)
    cw = np.cumsum(w[idx], axis=1)
    total = cw[:, -1]
    rows = np.arange(n)
    mu_hi = b[rows, idx[rows, np.argmax(cw >= 0.5 * (total - e)[:, None], axis=1)]]
    mu_lo = b[rows, idx[rows, np.argmax(cw >= 0.5 * (total + e)[:, None], axis=1)]]
    s1 = float(a_s.sum())
    g = gamma(m + 4)
    bounds = []
    for mu, sign in ((mu_hi, 1.0), (mu_lo, -1.0)):
        am = np.abs(mu)
        spread = np.abs(H - mu[:, None] * s).sum(axis=1)
        err = g * (np.abs(z) + am * (abs(e) + sigma + s1) + absH)
        bounds.append(sign * mu * e + am * sigma + spread + err)
    return z - bounds[1], z + bounds[0]


def ref_propagate(h, t, lo, hi, sigma=0.0):
    t_lo = np.minimum(h * lo, h * hi)
    t_hi = np.maximum(h * lo, h * hi)
    s_lo, s_hi = t_lo.sum(), t_hi.sum()
    delta = gamma(h.size + 3) * (abs(t) + sigma + np.maximum(np.abs(t_lo), np.abs(t_hi)).sum())
    if t + sigma < s_lo - delta or t - sigma > s_hi + delta:
        return None
    nz = h != 0
    a = (t - sigma) - (s_hi - t_hi[nz]) - delta
    b = (t + sigma) - (s_lo - t_lo[nz]) + delta
    q1, q2 = a / h[nz], b / h[nz]
    pad = gamma(2) * np.maximum(np.abs(q1), np.abs(q2))
    lo, hi = lo.copy(), hi.copy()
    lo[nz] = np.maximum(lo[nz], np.minimum(q1, q2) - pad)
    hi[nz] = np.minimum(hi[nz], np.maximum(q1, q2) + pad)
    if np.any(lo > hi):
        return None
    return lo, hi


def random_section(rng: np.random.Generator, n: int, m: int):
    """A zonotope <z, H> and a strip |sᵀξ - e| <= σ meeting it, with the awkward cases mixed
    in: exact zeros and tiny entries of s (dropped breakpoints), repeated breakpoints, σ = 0."""
    z = rng.normal(size=n) * 10.0 ** rng.integers(-2, 3)
    H = rng.normal(size=(n, m))
    H[rng.random((n, m)) < 0.3] = 0.0
    s = rng.normal(size=m)
    s[rng.random(m) < 0.2] = 0.0
    s[rng.random(m) < 0.1] *= 1e-16
    if m > 2:
        H[:, 1] = 2.0 * H[:, 0]  # the same breakpoint twice
        s[1] = 2.0 * s[0]
    sigma = 0.0 if rng.random() < 0.3 else float(rng.uniform(0, 0.5))
    e = float(np.abs(s).sum() + sigma) * rng.uniform(-0.99, 0.99)
    return z, H, s, e, sigma


@pytest.mark.parametrize("seed", range(6))
def test_section_hull_equals_the_reference(seed: int) -> None:
    rng = np.random.default_rng(seed)
    for n, m in [(1, 1), (2, 3), (3, 35), (5, 60), (30, 340)]:
        z, H, s, e, sigma = random_section(rng, n, m)
        lo, hi = section_hull(z, H, s, e, sigma, np.abs(H).sum(axis=1))
        rlo, rhi = ref_section_hull(z, H, s, e, sigma)
        scale = np.abs(z) + np.abs(H).sum(axis=1)
        assert np.all(lo >= rlo - 1e-12 * scale) and np.all(hi <= rhi + 1e-12 * scale)
        np.testing.assert_allclose(lo, rlo, rtol=0, atol=1e-12 * scale.max())
        np.testing.assert_allclose(hi, rhi, rtol=0, atol=1e-12 * scale.max())


def test_section_hull_holds_the_points_of_the_section_and_touches_them() -> None:
    """Points ξ of the cube meeting the strip (sampled, then the exact maximisers of an LP per
    coordinate): inside the bounds, and the bounds are reached to 1e-9."""
    from scipy.optimize import linprog

    rng = np.random.default_rng(7)
    for _ in range(8):
        z, H, s, e, sigma = random_section(rng, 3, 12)
        lo, hi = section_hull(z, H, s, e, sigma)
        xi = rng.uniform(-1, 1, size=(20000, 12))
        xi = xi[np.abs(xi @ s - e) <= sigma + 1e-3 * np.abs(s).sum()]
        ok = np.abs(xi @ s - e) <= sigma
        pts = z + xi[ok] @ H.T
        assert np.all(pts >= lo) and np.all(pts <= hi)
        A_ub, b_ub = np.vstack([s, -s]), [e + sigma, sigma - e]
        for j in range(3):
            for sign, bound in ((1.0, hi[j]), (-1.0, lo[j])):
                res = linprog(-sign * H[j], A_ub=A_ub, b_ub=b_ub, bounds=[(-1, 1)] * 12)
                assert res.status == 0
                reached = z[j] + H[j] @ res.x
                assert sign * (bound - reached) >= -1e-12
                assert abs(bound - reached) <= 1e-9 * (1 + abs(z[j]) + np.abs(H[j]).sum())


@pytest.mark.parametrize("seed", range(4))
def test_propagation_equals_the_reference(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    misses = 0
    for _ in range(60):
        n = int(rng.integers(1, 9))
        h = rng.normal(size=n)
        h[rng.random(n) < 0.3] = 0.0
        lo = rng.normal(size=n) - rng.uniform(0, 2, size=n)
        hi = lo + rng.uniform(0, 2, size=n)
        sigma = float(rng.uniform(0, 0.3))
        t = float(h @ rng.uniform(lo, hi)) + rng.normal() * (2.0 if rng.random() < 0.3 else 0.1)
        ref = ref_propagate(h, t, lo, hi, sigma)
        out = propagate_strip(h, t, np.stack([lo, hi]), sigma)
        out_nz = propagate_strip(h, t, np.stack([lo, hi]), sigma, np.flatnonzero(h))
        if ref is None:
            misses += 1
            assert out is None and out_nz is None
            continue
        assert out is not None and out_nz is not None
        np.testing.assert_array_equal(out, np.stack(ref))
        np.testing.assert_array_equal(out_nz, out)
    assert 0 < misses < 60  # both branches exercised


# -- the whole filter against a simulator written here ------------------------------------------


def simulate(A, B, C, D, E, F, x0, u, dlo, dhi, rng):
    """x+ = A x + B u + E d, y = C x + D u + F d, d at a vertex of [dlo[k], dhi[k]]."""
    T = u.shape[0]
    x = np.empty((T, A.shape[0]))
    y = np.empty((T, C.shape[0]))
    xk = x0
    for k in range(T):
        d = np.where(rng.random(dlo.shape[1]) < 0.5, dlo[k], dhi[k])
        x[k] = xk
        y[k] = C @ xk + D @ u[k] + F @ d
        xk = A @ xk + B @ u[k] + E @ d
    return x, y


@pytest.mark.parametrize("kernel", [True, False], ids=["kernel", "numpy"])
@pytest.mark.parametrize("reduction", ["parallelotope", "girard", "box"])
@pytest.mark.parametrize("seed", range(3))
def test_contains_a_simulated_state_with_correlated_vertex_disturbances(
    seed, reduction, kernel, monkeypatch
):
    """With the compiled step (estimators/_strip_kernel_nb.py, when numba is installed; the
    box reduction always takes the NumPy path) and with the NumPy path."""
    if kernel:
        pytest.importorskip("numba")
    monkeypatch.setattr(_strip_kernel, "ENABLED", kernel)
    rng = np.random.default_rng(seed)
    nx, ny, nu, nd, T = 4, 2, 1, 5, 150
    A = rng.normal(size=(nx, nx))
    A *= 0.95 / max(abs(np.linalg.eigvals(A)))
    B, C, D = rng.normal(size=(nx, nu)), rng.normal(size=(ny, nx)), rng.normal(size=(ny, nu))
    E = rng.normal(size=(nx, nd)) * 0.1
    F = rng.normal(size=(ny, nd)) * 0.05
    E[:, 4] = 0.0  # a noise component in the output only
    F[:, 0] = 0.0  # a disturbance in the state only
    width = 1.0 + 0.5 * np.sin(0.1 * np.arange(T))  # d's bound changes with k
    dlo, dhi = -np.outer(width, np.ones(nd)), np.outer(width, np.ones(nd))

    def dbox(k, y=None):
        return Box(dlo[int(k)], dhi[int(k)])

    sys = ivobs.LinearSystem(A, B, C, D, E=E, F=F, d=dbox)
    x0 = Box(-np.ones(nx), np.ones(nx))
    u = rng.normal(size=(T, nu))
    x, y = simulate(A, B, C, D, E, F, rng.choice([-1.0, 1.0], nx), u, dlo, dhi, rng)
    est = ivobs.make_estimator("strip", sys, x0=x0, order=3 * nx, reduction=reduction)
    assert (est._kernel is not None) == (kernel and reduction != "box")
    res = est.run(u, y)
    assert np.all(res.lower <= x) and np.all(x <= res.upper)
    assert not res.inconsistent.any()
    assert np.max(res.upper - res.lower) < 50.0  # bounded, not a vacuous box
    est.reset()  # the online recursion is the same one: the same numbers
    for k in range(T):
        box = est.step(u[k], y[k])
        assert np.array_equal(box.lo, res.lower[k]) and np.array_equal(box.hi, res.upper[k])
