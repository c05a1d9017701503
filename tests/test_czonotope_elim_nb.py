"""The compiled propagation and overshoots of the elimination (``_elim_nb``, numba) and the
loss kernel (``_loss_nb``) give the NumPy code's numbers bit for bit: on random arrays of both
memory layouts (whose row sums NumPy orders differently) and on the tank30 boxes they steer.
Skipped without numba."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import pytest

import ivobs
from ivobs.sets.czonotope import _elim_kernels, elimination, hull
from ivobs.sets.czonotope._tolerances import ZERO_TOL

pytest.importorskip("numba")

SHAPES = [(2, 9), (3, 1000), (81, 552), (200, 20), (1, 300), (40, 130), (7, 9000), (2, 20000)]


@pytest.fixture
def kernels(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """The kernels on every size (``KERNEL_MIN = 0``), looked up afresh."""
    monkeypatch.setattr(_elim_kernels, "_KERNELS", False)
    monkeypatch.setattr(_elim_kernels, "KERNEL_MIN", 0)
    assert _elim_kernels.kernels() is not None
    yield


def _both(
    f: Callable[[np.ndarray, np.ndarray], Any],
    A: np.ndarray,
    b: np.ndarray,
    monkeypatch: pytest.MonkeyPatch,
) -> tuple[Any, Any]:
    """``f(A, b)`` with the kernels (asserting they are used) and with NumPy's code."""
    assert _elim_kernels.select(A, b) is not None
    compiled = f(A, b)
    monkeypatch.setattr(_elim_kernels, "_KERNELS", None)
    assert _elim_kernels.select(A, b) is None
    ref = f(A, b)
    monkeypatch.setattr(_elim_kernels, "_KERNELS", False)
    return compiled, ref


def _same(x: Any, y: Any) -> bool:
    """Bit for bit (``-0.0`` is not ``0.0``), ``None`` alike; NaNs at the same places (their
    sign and payload bits are not kept by LLVM, which may swap the operands of ``+``)."""
    if x is None or y is None:
        return x is None and y is None
    if isinstance(x, tuple):
        return len(x) == len(y) and all(_same(u, v) for u, v in zip(x, y, strict=True))
    if x.shape != y.shape or not np.array_equal(np.isnan(x), np.isnan(y)):
        return False
    bits = [np.ascontiguousarray(np.where(np.isnan(z), 0.0, z)).view(np.uint64) for z in (x, y)]
    return np.array_equal(*bits)


def _random(K: int, m: int, seed: int, order: str) -> tuple[np.ndarray, np.ndarray]:
    """A normalised-looking ``A ξ = b``: two leading entries per row, the others of very
    different sizes (the order of the row
    sums shows), exact zeros and signed zeros, entries at the zero tolerance, a consistent
    ``b`` from a point of the box (feasible, bounds that tighten over the sweeps)."""
    rng = np.random.default_rng(seed)
    A = rng.uniform(-1.0, 1.0, (K, m)) * 10.0 ** rng.integers(-12, -4, (K, m))
    for i in range(K):  # two leading factors per row: their bounds tighten sweep by sweep
        A[i, rng.choice(m, 2, replace=False)] = rng.choice([-1.0, 1.0], 2) * [1.0, 0.3]
    A[rng.random((K, m)) < 0.2] = 0.0
    A[rng.random((K, m)) < 0.05] = -0.0
    near = rng.random((K, m)) < 0.05  # at the tolerance: kept or dropped by one ulp
    rmax = np.maximum(1.0, np.abs(A).max(axis=1, keepdims=True))
    tol = np.broadcast_to(ZERO_TOL * rmax, (K, m))
    A[near] = np.where(rng.random(near.sum()) < 0.5, tol[near], np.nextafter(tol[near], 1.0))
    A[:, rng.integers(0, m)] = 0.0  # a factor in no constraint
    b = A @ rng.uniform(-0.5, 0.5, m)
    if K > 2:  # a row of signed zeros, ``0 ξ = -0``
        A[1], b[1] = np.where(rng.random(m) < 0.5, 0.0, -0.0), -0.0
    return np.asarray(A, order=order), b


@pytest.mark.parametrize(("K", "m"), SHAPES)
@pytest.mark.parametrize("order", ["C", "F"])
def test_kernels_equal_numpy_bit_for_bit(
    K: int, m: int, order: str, kernels: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    A, b = _random(K, m, K * m, order)
    if order == "C" and m > 8192:  # NumPy may sum such rows in buffered chunks: its own code
        assert _elim_kernels.select(A, b) is None
        return
    for f in (elimination._propagate, elimination._overshoot):
        compiled, ref = _both(f, A, b, monkeypatch)
        assert _same(compiled, ref), f.__name__
    lo, hi = elimination._propagate(A, b)
    assert np.all(lo >= -1.0) and np.all(hi <= 1.0) and np.all(lo <= hi)
    assert np.any(hi - lo < 2.0)  # propagation tightened some bound: the sweeps ran
    R = elimination._overshoot(A, b)
    assert np.isinf(R).any() and np.isfinite(R).any()


@pytest.mark.parametrize("order", ["C", "F"])
def test_kernels_equal_numpy_on_pinned_factors(
    order: str, kernels: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Factors pinned by one-entry rows (a fixed point after one sweep, bounds of ``±0``)."""
    rng = np.random.default_rng(7)
    K, m = 30, 60
    A = np.zeros((K, m))
    A[np.arange(K), np.arange(K)] = 1.0
    A[K // 2 :] += rng.normal(size=(K - K // 2, m))
    b = np.zeros(K)
    b[: K // 2] = rng.choice([0.0, -0.0, 0.25, -1.0], K // 2)
    b[K // 2 :] = A[K // 2 :] @ np.where(np.arange(m) < K // 2, b[np.arange(m) % K], 0.0)
    A = np.asarray(A, order=order)
    for f in (elimination._propagate, elimination._overshoot):
        compiled, ref = _both(f, A, b, monkeypatch)
        assert _same(compiled, ref), f.__name__
    lo, hi = elimination._propagate(A, b)
    assert np.all(hi[: K // 2] - lo[: K // 2] <= 1e-8)  # pinned to b up to the padding


@pytest.mark.parametrize("order", ["C", "F"])
def test_kernels_equal_numpy_on_an_empty_set(
    order: str, kernels: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``ξ_0 + ξ_1 = 3`` cannot hold in the box: both give ``None``."""
    rng = np.random.default_rng(3)
    A = np.asarray(rng.normal(size=(6, 40)), order=order)
    A[0] = 0.0
    A[0, :2] = 1.0
    b = A @ rng.uniform(-0.5, 0.5, 40)
    b[0] = 3.0
    compiled, ref = _both(elimination._propagate, A, b, monkeypatch)
    assert compiled is None and ref is None
    compiled, ref = _both(elimination._overshoot, A, b, monkeypatch)
    assert _same(compiled, ref)


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # NumPy's overflows, wanted here
@pytest.mark.parametrize("order", ["C", "F"])
def test_kernels_equal_numpy_with_infinities(
    order: str, kernels: None, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Right-hand sides near the largest double: quotients overflow to ``±inf``, paddings to
    ``inf`` and ``inf - inf`` gives NaNs, which both propagate the same way."""
    A, b = _random(12, 50, 5, order)
    b[:3] = [1e308, -1e308, np.inf]
    A[:3, :5] = 1e-13  # tiny pivots: b / a overflows
    for f in (elimination._propagate, elimination._overshoot):
        compiled, ref = _both(f, A, b, monkeypatch)
        assert _same(compiled, ref), f.__name__
    R = elimination._overshoot(A, b)
    assert np.isnan(R).any() or np.isinf(R).any()


@pytest.mark.parametrize(
    ("K", "c", "m"),
    [(1, 1, 0), (1, 1, 1), (2, 3, 8), (5, 2, 136), (130, 3, 64), (17, 5, 777), (3, 2, 8192)],
)
def test_loss_kernel_equals_numpy_bit_for_bit(
    K: int, c: int, m: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``‖R_k - T_kc P_c‖₁`` with the rows of a candidate summed side by side (numba) equals
    NumPy's pairwise row sums bit for bit: no split, one split, leaves of 64 and of 128 terms,
    terms of very different sizes, an infinite entry."""
    rng = np.random.default_rng(K + c + m)
    R = rng.normal(size=(K, m)) * 10.0 ** rng.integers(-8, 8, (K, m))
    T, P = rng.normal(size=(K, c)), rng.normal(size=(c, m))
    if m > 2:
        R[-1, 1] = np.inf
    monkeypatch.setattr(hull, "_KERNEL", False)
    monkeypatch.setattr(hull, "_KERNEL_MIN", 0)
    assert hull._kernel() is not None
    compiled = hull._shifted_l1(R, np.asfortranarray(T), P)
    monkeypatch.setattr(hull, "_KERNEL", None)
    ref = hull._shifted_l1(R, T, P)
    assert _same(compiled, ref)
    assert compiled.shape == (K, c) and (m <= 2 or np.isinf(compiled[-1]).all())


def test_tank30_boxes_equal_with_and_without_the_kernels(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The first 12 tank30 steps (81 x 552 eliminations, Fortran-ordered) give the same boxes
    bit for bit through the kernels (which are used; the loss kernel too) as through NumPy's
    code."""
    monkeypatch.setattr(_elim_kernels, "_KERNELS", False)
    monkeypatch.setattr(hull, "_KERNEL", False)
    assert hull._kernel() is not None
    nb = _elim_kernels.kernels()
    assert nb is not None
    calls = {"propagate": 0, "overshoot": 0}

    def counted(name: str) -> Callable[..., Any]:
        f = getattr(nb, name)

        def g(*args: Any) -> Any:
            calls[name] += 1
            return f(*args)

        return g

    wrapped = _elim_kernels.Kernels(counted("propagate"), counted("overshoot"))
    monkeypatch.setattr(_elim_kernels, "_KERNELS", wrapped)
    sc = ivobs.scenarios.get("cora-tank30")
    u, y = sc.recorded.u[:12], sc.recorded.y[:12]

    def run() -> tuple[np.ndarray, np.ndarray]:
        res = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0).run(u, y)
        return res.lower, res.upper

    compiled = run()
    assert calls["propagate"] >= 100 and calls["overshoot"] >= 100
    monkeypatch.setattr(_elim_kernels, "_KERNELS", None)  # NumPy's code (IVOBS_NUMBA=0)
    monkeypatch.setattr(hull, "_KERNEL", None)
    ref = run()
    assert _same(compiled, ref)
    assert np.all(np.isfinite(ref[1] - ref[0])) and np.all(ref[1] >= ref[0])
