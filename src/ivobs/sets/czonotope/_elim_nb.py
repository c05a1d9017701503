"""The elimination loop's constraint propagation and overshoots compiled with numba (optional,
``ivobs[fast]``).

:func:`~.elimination._propagate` and :func:`~.elimination._overshoot` build a handful of
``A``-sized temporaries per sweep; on tank30 (81 constraints x 552 factors, ~21 eliminations
per step) they cost ~1.3 ms and ~0.65 ms per elimination, mostly memory traffic; these
kernels 0.2 and 0.08 ms (BENCHMARKS.md, "Constrained-zonotope elimination kernels"). They
compute the same numbers, **bit for bit**:

* each element is the same IEEE operations in the same order (``@njit`` without ``fastmath``:
  no FMA contraction, no reassociation); ``np.maximum``/``np.minimum`` are reproduced with
  their NaN propagation and their choice of the second operand on ties (``max(0.0, -0.0)`` is
  ``-0.0``), see :func:`_max` and :func:`_min`; a NaN (only from overflowing inputs, such as
  ``|b| ~ 1e308``) is a NaN at the same place, but its sign bit may differ (LLVM may swap the
  operands of ``+``, and x86 keeps the first NaN's), which no comparison sees;
* the column reductions (``max``/``min`` over the constraints) are order-free: no ``-0.0``
  can meet ``+0.0`` there (a propagated bound is ``q ∓ pad`` with ``pad >= 1e-10``; the
  overshoot only uses ``ρ`` through ``-1 - ρ`` and ``ρ - 1``) and NaN propagates either way;
* the row sums follow NumPy's order, which depends on the memory layout: a C-contiguous row
  is reduced pairwise (:func:`._loss_nb._pairwise_sum`, after NumPy's identity ``0.0``); a
  Fortran-ordered ``A`` (the elimination's own layout: ``A[:, cols]`` is F-ordered) is reduced
  one column at a time, ``((0 + a_0) + a_1) + …`` for every row at once. The caller uses the
  kernels only for these two layouts (``pairwise`` says which).

Bit for bit matters: the bounds rescale the factors and the overshoots choose the factor to
eliminate, which steers every later box. tests/test_czonotope_elim_nb.py compares the kernels
with the NumPy code on random arrays of both layouts (with zeros, entries at the tolerances
and overflows) and the tank30 boxes with and without the kernels (the first 12 steps; also
equal to tests/data/czonotope_reference_bounds.npz over 20 steps on the machine that recorded
it).
"""

from __future__ import annotations

import numpy as np

# numba's on-disk cache does not notice a change in another module: after editing
# _loss_nb._pairwise_sum (or its _plan), touch this file (or clear __pycache__) so that these
# recompile
from ._loss_nb import _pairwise_sum, jit
from ._tolerances import ZERO_TOL

__all__ = ["overshoot", "propagate"]


@jit
def _max(a: float, b: float) -> float:  # pragma: no cover - compiled
    """``np.maximum(a, b)``: NaN if either is NaN, else ``b`` unless ``a > b``."""
    return a if (a > b or a != a) else b


@jit
def _min(a: float, b: float) -> float:  # pragma: no cover - compiled
    """``np.minimum(a, b)``: NaN if either is NaN, else ``b`` unless ``a < b``."""
    return a if (a < b or a != a) else b


@jit
def _row_sums(T: np.ndarray, out: np.ndarray, pairwise: bool) -> None:  # pragma: no cover
    """``out[i] = T[i].sum()`` in NumPy's order for ``T``'s layout (see the module notes)."""
    K, m = T.shape
    if pairwise:
        for i in range(K):
            out[i] = 0.0 + _pairwise_sum(T[i], m)
        return
    for i in range(K):
        out[i] = 0.0
    for j in range(m):
        for i in range(K):
            out[i] = out[i] + T[i, j]


@jit
def _nonzero(A: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """``_propagate``'s mask ``|a_ij| > ZERO_TOL max(1, max_l |a_il|)`` (NumPy's
    ``np.maximum``: a NaN row maximum makes the whole row zero)."""
    K, m = A.shape
    rmax = np.full(K, -np.inf)
    for j in range(m):
        for i in range(K):
            rmax[i] = _max(rmax[i], abs(A[i, j]))
    nz = np.empty((K, m), dtype=np.bool_)
    for i in range(K):
        rmax[i] = ZERO_TOL * _max(1.0, rmax[i])
    for j in range(m):
        for i in range(K):
            nz[i, j] = abs(A[i, j]) > rmax[i]
    return nz


@jit
def _sweep(
    A: np.ndarray,
    b: np.ndarray,
    nz: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    T: np.ndarray,
    pairwise: bool,
) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """One sweep of ``_propagate``: the intersections ``new_lo``, ``new_hi`` over the rows of
    ``(b_i - Σ_{l≠j} a_il [ξ_l]) / a_ij`` widened by ``pad`` (``T`` a scratch array of
    ``A``'s layout, for the row sums)."""
    K, m = A.shape
    s_lo, s_hi = np.empty(K), np.empty(K)
    for j in range(m):
        for i in range(K):
            T[i, j] = _min(A[i, j] * lo[j], A[i, j] * hi[j])
    _row_sums(T, s_lo, pairwise)
    for j in range(m):
        for i in range(K):
            T[i, j] = _max(A[i, j] * lo[j], A[i, j] * hi[j])
    _row_sums(T, s_hi, pairwise)
    new_lo, new_hi = np.full(m, -np.inf), np.full(m, np.inf)
    for j in range(m):
        acc_lo, acc_hi = -np.inf, np.inf
        for i in range(K):
            if not nz[i, j]:  # no bound from this row (NumPy: ∓inf, neutral in max/min)
                continue
            a_lo, a_hi = A[i, j] * lo[j], A[i, j] * hi[j]
            rest_lo = s_lo[i] - _min(a_lo, a_hi)
            rest_hi = s_hi[i] - _max(a_lo, a_hi)
            q1 = (b[i] - rest_hi) / A[i, j]
            q2 = (b[i] - rest_lo) / A[i, j]
            pad = 1e-10 * ((1.0 + abs(q1)) + abs(q2))
            acc_lo = _max(acc_lo, _min(q1, q2) - pad)
            acc_hi = _min(acc_hi, _max(q1, q2) + pad)
        new_lo[j], new_hi[j] = acc_lo, acc_hi
    return new_lo, new_hi


@jit
def propagate(
    A: np.ndarray, b: np.ndarray, sweeps: int, pairwise: bool
) -> tuple[bool, np.ndarray, np.ndarray]:  # pragma: no cover - compiled
    """``_propagate(A, b, sweeps)`` as ``(feasible, lo, hi)`` (``A`` float64, C-contiguous
    with ``pairwise`` or Fortran-ordered without; ``b`` float64)."""
    m = A.shape[1]
    lo, hi = -np.ones(m), np.ones(m)
    nz = _nonzero(A)
    T = np.empty_like(A)  # A's layout: the row sums read it as NumPy reads its temporaries
    for _ in range(sweeps):
        new_lo, new_hi = _sweep(A, b, nz, lo, hi, T, pairwise)
        lo_next, hi_next = np.empty(m), np.empty(m)
        for j in range(m):
            lo_next[j] = _max(lo[j], new_lo[j])
            hi_next[j] = _min(hi[j], new_hi[j])
        for j in range(m):
            if lo_next[j] > hi_next[j] + 1e-9:
                return False, lo, hi
        same = True
        for j in range(m):
            hi_next[j] = _max(hi_next[j], lo_next[j])
            same = same and lo_next[j] == lo[j] and hi_next[j] == hi[j]
        if same:
            break  # a fixed point (NumPy's code returns the previous arrays, == these)
        lo, hi = lo_next, hi_next
    return True, lo, hi


@jit
def overshoot(A: np.ndarray, b: np.ndarray, pairwise: bool) -> np.ndarray:  # pragma: no cover
    """``_overshoot(A, b)``: ``R_j = max(0, -1 - ρ_lo_j, ρ_hi_j - 1)`` (same layouts as
    :func:`propagate`)."""
    K, m = A.shape
    T = np.empty_like(A)
    amax = -np.inf
    for j in range(m):
        for i in range(K):
            T[i, j] = abs(A[i, j])
            amax = _max(amax, T[i, j])
    # ZERO_TOL * max(1.0, float(absA.max())): Python's max keeps 1.0 unless the other is larger
    tol = ZERO_TOL * (amax if amax > 1.0 else 1.0)
    rows = np.empty(K)
    _row_sums(T, rows, pairwise)
    R = np.empty(m)
    for j in range(m):
        r_lo, r_hi = -np.inf, np.inf
        for i in range(K):
            if not T[i, j] > tol:
                continue
            spread = (rows[i] - T[i, j]) / abs(A[i, j])
            mid = b[i] / A[i, j]
            r_lo = _max(r_lo, mid - spread)
            r_hi = _min(r_hi, mid + spread)
        R[j] = _max(0.0, _max(-1.0 - r_lo, r_hi - 1.0))
    return R
