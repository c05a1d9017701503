"""nl-zonotope's fast path (issue 16): the same numbers as before, bit for bit.

* The float forms of the small kernels (strip propagation on lists, NumPy's pairwise sum,
  the section hull's quantiles and bounds for a few rows, the basis test of the reduction for
  ``n <= 4``, the power-of-two scaling test) against their array forms.
* The filter's bounds on Hénon (2,000 steps) and on ``pendulum-nl`` (300 steps) against those
  of the code before issue 16 (commit 8486d05, stored in ``tests/data/nl_zonotope_ref.npz``;
  produced on the project's machine: a different BLAS may sum the products differently).
Containment is checked by the soundness tests (tests/test_nl_sound_random.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import ivobs
from ivobs.estimators import _strip_hull as sh
from ivobs.sets.czonotope import reduction as red

REF = Path(__file__).parent / "data" / "nl_zonotope_ref.npz"


def _spread(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Values over many magnitudes (the order of a sum then matters)."""
    return rng.standard_normal(shape) * 10.0 ** rng.integers(-8, 8, shape)


@pytest.mark.parametrize("n", [*range(0, 20), 31, 64, 127, 128, 129, 200, 513])
def test_pairwise_sum_is_numpys(n: int) -> None:
    rng = np.random.default_rng(n)
    for _ in range(40):
        a = _spread(rng, (n,))
        assert sh.pairwise_sum(a.tolist()) == float(np.add.reduce(a))


def test_propagate_lists_is_propagate_strip() -> None:
    rng = np.random.default_rng(1)
    misses = 0
    for trial in range(3000):
        n = int(rng.integers(1, 12))
        h = rng.standard_normal(n) * (rng.random(n) < 0.7)  # some zero coefficients
        lo = rng.standard_normal(n)
        hi = lo + rng.random(n) * 10.0 ** rng.integers(-3, 2)
        t = float(h @ (lo + (hi - lo) * rng.random(n)) + rng.standard_normal() * 0.5)
        sigma = float(rng.random() * 10.0 ** rng.integers(-6, 0))
        ref = sh.propagate_strip(h, t, np.stack([lo, hi]), sigma)
        got = sh.propagate_lists(h.tolist(), t, lo.tolist(), hi.tolist(), sigma)
        if ref is None:
            misses += 1
            assert got is None, trial
        else:
            assert got is not None, trial
            assert got[0] == ref[0].tolist() and got[1] == ref[1].tolist(), trial
    assert 50 < misses < 2950  # both outcomes are exercised


def test_section_hull_float_rows_are_the_array_rows() -> None:
    """Rows are independent in the section hull: the first rows of a tall ``H`` (array form)
    are the same numbers as those rows alone (the float form, ``n <= 4``)."""
    rng = np.random.default_rng(2)
    for trial in range(800):
        m = int(rng.integers(1, 40))
        H = _spread(rng, (8, m)) * (rng.random((8, m)) < 0.8)
        s = rng.standard_normal(m) * (rng.random(m) < 0.8)
        z = rng.standard_normal(8)
        e = float(rng.standard_normal() * (np.abs(s).sum() + 0.1))
        sigma = float(rng.random()) * (trial % 3)  # 0 included
        full = sh.section_hull(z, H, s, e, sigma)
        for n in (1, 2, 3, 4):
            part = sh.section_hull(z[:n], H[:n], s, e, sigma)
            assert np.array_equal(part[0], full[0][:n]), (trial, n)
            assert np.array_equal(part[1], full[1][:n]), (trial, n)


def test_box_in_basis_floats_are_the_array_form(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(3)
    cases = []
    for _ in range(600):
        n = int(rng.integers(1, 5))
        P = rng.standard_normal((n, n)) + np.eye(n) * rng.random() * 3
        rho = rng.random(n) * 10.0 ** rng.integers(-12, 0)
        cases.append((P, rho, red._box_in_basis(P, rho)))
    monkeypatch.setattr(red, "_FEW", 0)  # the array form for every size
    rejected = 0
    for P, rho, fast in cases:
        ref = red._box_in_basis(P, rho)
        if ref is None:
            rejected += 1
            assert fast is None
        else:
            assert fast is not None
            assert np.array_equal(fast[0], ref[0]) and fast[1] == ref[1]
    assert rejected < len(cases)


def _ref_pow2_scaling(L: np.ndarray) -> np.ndarray | None:
    """The scaling test before issue 16 (L * d formed and checked entry by entry)."""
    mx = np.abs(L).max(axis=1)
    e = np.zeros(mx.shape[0])
    nz = mx > 0
    with np.errstate(over="ignore", invalid="ignore"):
        e[nz] = -np.frexp(mx[nz])[1] + 1
        d = np.ldexp(1.0, e.astype(int))
        S = L * d[:, None]
    aS = np.abs(S)
    ok = np.all(np.isfinite(S)) and np.all((aS >= red._TINY) | ((aS == 0) & (L == 0)))
    return d if ok else None


@pytest.mark.parametrize(
    "special",
    [None, 0.0, 5e-324, 1e-310, 1e-300, 1e300, 1.7e308, math.inf, -math.inf, math.nan],
)
def test_pow2_scaling_is_the_entrywise_test(special: float | None) -> None:
    rng = np.random.default_rng(4)
    for _ in range(200):
        L = _spread(rng, (3, 6)) * (rng.random((3, 6)) < 0.8)
        if special is not None:
            L[rng.integers(0, 3), rng.integers(0, 6)] = special
        if rng.random() < 0.2:
            L[1] = 0.0  # a zero row
        ref, got = _ref_pow2_scaling(L), red._pow2_scaling(L)
        assert (ref is None) == (got is None)
        if ref is not None:
            assert np.array_equal(ref, got)


def _henon() -> tuple[ivobs.NonlinearSystem, np.ndarray]:
    sys_ = ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=["x1 + v1"],
        states=["x1", "x2"],
        params={"a": (1.39, 1.41), "b": 0.3},
        d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )
    # the measurements of benchmarks/bench_nonlinear_sets.py:henon_record(2000)
    rng = np.random.default_rng(0)
    x = np.array([0.3, 0.1])
    y = np.empty((2000, 1))
    for k in range(2000):
        a = rng.choice([1.39, 1.41])
        y[k, 0] = x[0] + rng.choice([-0.02, 0.02])
        x = np.array([1 - a * x[0] ** 2 + x[1] + rng.choice([-0.005, 0.005]), 0.3 * x[0]])
    return sys_, y


def _same(lo: np.ndarray, hi: np.ndarray, rlo: np.ndarray, rhi: np.ndarray) -> None:
    """Bit for bit on the machine that recorded them (checked when merged); to 1e-9 of the
    scale elsewhere, where another BLAS may round the products (fused or not) differently."""
    scale = 1.0 + np.abs(rlo) + np.abs(rhi)
    assert np.max(np.abs(lo - rlo) / scale) <= 1e-9
    assert np.max(np.abs(hi - rhi) / scale) <= 1e-9


def test_henon_bounds_are_those_before_issue_16() -> None:
    ref = np.load(REF)
    sys_, y = _henon()
    est = ivobs.make_estimator("nl-zonotope", sys_, x0=ivobs.Box([0.2, 0.0], [0.4, 0.2]))
    res = est.run(np.zeros((2000, 0)), y)
    _same(res.lower, res.upper, ref["henon_lo"], ref["henon_hi"])
    w = res.upper - res.lower
    assert np.all(w[200:] < 0.5)  # a bounded filter, not a trivially equal divergence


def test_pendulum_bounds_are_those_before_issue_16() -> None:
    ref = np.load(REF)
    sc = ivobs.scenarios.get("pendulum-nl", horizon=300)
    tr = sc.simulate("vertex", seed=0)
    res = ivobs.make_estimator("nl-zonotope", sc.system, x0=sc.x0).run(tr.u, tr.y)
    _same(res.lower, res.upper, ref["pendulum_lo"], ref["pendulum_hi"])
    assert np.all(res.lower <= tr.x) and np.all(tr.x <= res.upper)
    assert np.all(np.isfinite(res.upper - res.lower))
