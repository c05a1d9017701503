"""The hull's fallback when the HiGHS chain fails (issue 17, 2026-11-27 evening): SciPy's
HiGHS called directly (:func:`ivobs.sets.czonotope._highs.linprog_duals`) returns the same
multipliers, bit for bit, as ``scipy.optimize.linprog(method="highs")`` did, so the boxes that
the multipliers steer (through the elimination) stay the same."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from scipy.optimize import linprog

from ivobs.sets.czonotope import _highs, hull
from test_czonotope_fast import _random_set


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_linprog_duals_equal_linprog_bit_for_bit(seed: int) -> None:
    rng = np.random.default_rng(seed)
    _, G, A, b = _random_set(rng, 6, 40, 9)
    Gs = np.vstack([G, -G])
    for radius in (1.0, 1.5):
        mu = _highs.linprog_duals(Gs, A, b, radius)
        ref = np.array(
            [
                linprog(g, A_eq=A, b_eq=b, bounds=(-radius, radius), method="highs").eqlin.marginals
                for g in Gs
            ]
        )
        assert mu.shape == (12, 9)
        assert np.array_equal(mu, ref)
        assert np.any(mu != 0.0)  # a set pinned down by its constraints: multipliers in use


def test_fallback_bounds_equal_the_linprog_fallback(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the chain failing, the hull's bounds and multipliers are those of the one-by-one
    linprog fallback it replaces (forced here by hiding the direct path), bit for bit; and the
    bounds hold: no point of the set is below them."""
    rng = np.random.default_rng(7)
    _, G, A, b = _random_set(rng, 5, 30, 7)
    Gs = np.vstack([G, -G])
    monkeypatch.setattr(_highs, "chain_duals", lambda *args: "failed")
    vals, mu, ok = hull._certified_mins(Gs, A, b)
    monkeypatch.setattr(_highs, "linprog_duals", lambda *args: None)
    rvals, rmu, rok = hull._certified_mins(Gs, A, b)
    assert ok and rok
    assert np.array_equal(vals, rvals) and np.array_equal(mu, rmu)
    for i, g in enumerate(Gs):
        res = linprog(g, A_eq=A, b_eq=b, bounds=(-1, 1), method="highs")
        assert vals[i] <= res.fun
        assert vals[i] >= res.fun - 1e-7 * (1.0 + abs(res.fun))


@pytest.mark.parametrize(
    ("K", "c", "m"),
    [(3, 2, 1), (7, 5, 3), (12, 24, 50), (9, 4, 129), (5, 3, 257), (120, 24, 552), (4, 2, 1000)],
)
def test_compiled_loss_equals_numpy_bit_for_bit(
    K: int, c: int, m: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The compiled ``‖R_k - T_kc P_c‖₁`` (numba) equals NumPy's, bit for bit, on every row
    length class of NumPy's pairwise sum (below 8, up to 128, split once, twice)."""
    pytest.importorskip("numba")
    rng = np.random.default_rng(m)
    R, T, P = rng.normal(size=(K, m)), rng.normal(size=(K, c)), rng.normal(size=(c, m))
    R[0, : m // 2] *= 1e8  # terms of very different sizes: the order of the sum shows
    monkeypatch.setattr(hull, "_KERNEL", False)  # looked up afresh
    monkeypatch.setattr(hull, "_KERNEL_MIN", 0)  # the small cases too
    assert hull._kernel() is not None
    compiled = hull._shifted_l1(R, T, P)
    monkeypatch.setattr(hull, "_KERNEL", None)  # the NumPy path
    ref = hull._shifted_l1(R, T, P)
    assert hull._kernel() is None
    assert np.array_equal(compiled, ref)
    assert np.allclose(ref, np.abs(R[:, None, :] - T[:, :, None] * P[None, :, :]).sum(axis=2))


def test_small_sets_do_not_load_numba() -> None:
    """The servo's eliminations (12 objectives x 50 factors) stay in NumPy: a short run does
    not pay numba's import and the kernel's load (~0.5 s of CPU once per process)."""
    code = (
        "import sys, ivobs\n"
        "sc = ivobs.scenarios.get('servo-motor', horizon=30)\n"
        "tr = sc.simulate('vertex', seed=0)\n"
        "est = ivobs.make_estimator('constrained-zonotope', sc.system, x0=sc.x0)\n"
        "res = est.run(tr.u, tr.y)\n"
        "assert res.contains(tr.x).all()\n"
        "print('numba' in sys.modules)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
