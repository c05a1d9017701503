"""The elimination loss's ``‖R_k - T_kc P_c‖₁`` compiled with numba (optional, ``ivobs[fast]``).

:func:`~.hull._shifted_l1` builds ``|R - t p|`` in temporaries and sums each row with NumPy's
``sum``; on tank30 (120 objectives x 552 factors, 24 candidates, ~18 eliminations per step)
that is ~3 ms per elimination. This kernel computes the same numbers in one pass, **bit for
bit**: each term ``|r - t p|`` is the same two IEEE operations (``@njit`` without
``fastmath``: no FMA contraction, no reassociation), and each row is summed in NumPy's
pairwise order (``pairwise_sum`` of ``numpy/_core/src/umath/loops_utils.h.src``: below 8
terms left to right; up to 128 terms eight running sums combined as
``((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))`` and the remainder added in turn; above,
split at ``n/2`` rounded down to a multiple of 8), which is what NumPy uses to reduce a
contiguous row. Bit for bit matters: the loss chooses the factor to eliminate, and another
rounding could break a tie otherwise (tests/test_czonotope_growth.py compares the two).

Since 2026-11-27 (night) the rows of a candidate are summed side by side (:func:`shifted_l1`:
every row has the same tree, so the innermost loops run over the rows and vectorise, each
row's operations unchanged): 1.3 → 0.4 ms per call on tank30, the same numbers.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar, cast

import numpy as np
from numba import njit

F = TypeVar("F", bound=Callable[..., Any])


def jit(f: F) -> F:
    """``numba.njit(cache=True)``: compiled once and cached on disk; no ``fastmath``."""
    return cast(F, njit(cache=True)(f))


@jit
def _block_sum(buf: np.ndarray, lo: int, n: int) -> float:  # pragma: no cover - compiled
    """NumPy's pairwise sum of ``buf[lo : lo + n]`` for ``n <= 128``."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += buf[lo + i]
        return float(res)
    r0, r1, r2, r3 = buf[lo], buf[lo + 1], buf[lo + 2], buf[lo + 3]
    r4, r5, r6, r7 = buf[lo + 4], buf[lo + 5], buf[lo + 6], buf[lo + 7]
    i = 8
    lim = n - (n % 8)
    while i < lim:
        r0 += buf[lo + i]
        r1 += buf[lo + i + 1]
        r2 += buf[lo + i + 2]
        r3 += buf[lo + i + 3]
        r4 += buf[lo + i + 4]
        r5 += buf[lo + i + 5]
        r6 += buf[lo + i + 6]
        r7 += buf[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += buf[lo + i]
        i += 1
    return float(res)


@jit
def _plan(n: int) -> np.ndarray:  # pragma: no cover - compiled
    """NumPy's pairwise tree of ``n`` terms as a post-order program, the left half first
    (:func:`_pairwise_sum` and :func:`shifted_l1` evaluate it): rows ``(0, lo, cnt)`` push the
    block sum of ``[lo, lo + cnt)`` (``cnt <= 128``), rows ``(1, 0, 0)`` replace the last two
    values by their sum. Every block of a split tree has at least 64 terms, so ``2 n / 64 + 2``
    rows suffice."""
    prog = np.zeros((2 * (n // 64) + 2, 3), dtype=np.int64)
    los = np.empty(64, dtype=np.int64)
    ns = np.empty(64, dtype=np.int64)
    state = np.empty(64, dtype=np.int64)
    top, rows = 0, 0
    los[0], ns[0], state[0] = 0, n, 0
    while top >= 0:
        lo, cnt = los[top], ns[top]
        if cnt <= 128:
            prog[rows, 1], prog[rows, 2] = lo, cnt
            rows += 1
            top -= 1
            continue
        half = cnt // 2
        half -= half % 8
        if state[top] == 0:
            state[top] = 1
            top += 1
            los[top], ns[top], state[top] = lo, half, 0
        elif state[top] == 1:
            state[top] = 2
            top += 1
            los[top], ns[top], state[top] = lo + half, cnt - half, 0
        else:
            prog[rows, 0] = 1
            rows += 1
            top -= 1
    return prog[:rows]


@jit
def _pairwise_sum(buf: np.ndarray, n: int) -> float:  # pragma: no cover - compiled
    """NumPy's pairwise sum of ``buf[:n]``: the tree of halves (``n/2`` rounded down to a
    multiple of 8) down to blocks of at most 128, evaluated along :func:`_plan` with an explicit
    stack (numba's on-disk cache mishandles recursive functions: they crash when loaded)."""
    if n <= 128:
        return _block_sum(buf, 0, n)
    prog = _plan(n)
    vals = np.empty(64)
    nv = 0
    for s in range(prog.shape[0]):
        if prog[s, 0] == 0:
            vals[nv] = _block_sum(buf, prog[s, 1], prog[s, 2])
            nv += 1
        else:  # both halves done: left + right
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
    return float(vals[0])


@jit
def _block_terms(
    Rt: np.ndarray, t: np.ndarray, p: np.ndarray, lo: int, n: int, acc: np.ndarray, out: np.ndarray
) -> None:  # pragma: no cover - compiled
    """``out[k]`` = :func:`_block_sum` of the terms ``|Rt[l, k] - t[k] p[l]|``, ``l`` in
    ``[lo, lo + n)`` (``n <= 128``), for every ``k`` at once (``acc``: the eight running sums
    of every ``k``)."""
    K = t.shape[0]
    if n < 8:
        for k in range(K):
            out[k] = 0.0
        for i in range(lo, lo + n):
            for k in range(K):
                out[k] += abs(Rt[i, k] - t[k] * p[i])
        return
    for r in range(8):
        for k in range(K):
            acc[r, k] = abs(Rt[lo + r, k] - t[k] * p[lo + r])
    i = 8
    lim = n - (n % 8)
    while i < lim:
        for r in range(8):
            for k in range(K):
                acc[r, k] += abs(Rt[lo + i + r, k] - t[k] * p[lo + i + r])
        i += 8
    for k in range(K):
        out[k] = ((acc[0, k] + acc[1, k]) + (acc[2, k] + acc[3, k])) + (
            (acc[4, k] + acc[5, k]) + (acc[6, k] + acc[7, k])
        )
    while i < n:
        for k in range(K):
            out[k] += abs(Rt[lo + i, k] - t[k] * p[lo + i])
        i += 1


@jit
def shifted_l1(R: np.ndarray, T: np.ndarray, P: np.ndarray) -> np.ndarray:  # pragma: no cover
    """``N[k, c] = ‖R_k - T_kc P_c‖₁`` (``R`` (K, m), ``T`` (K, c), ``P`` (c, m), float64), as
    :func:`~.hull._shifted_l1` computes it.

    The ``K`` sums of a candidate have the same pairwise tree (:func:`_plan`, once per call),
    so they are computed side by side: with ``R`` transposed, the innermost loops run over
    ``k`` (each ``k`` the same IEEE operations in the same order as alone; LLVM turns these
    loops into vector instructions, 3x faster on tank30's 120 x 24 x 552 than one row at a
    time)."""
    K, m = R.shape
    c = T.shape[1]
    Rt = np.ascontiguousarray(R.T)
    Tt = np.ascontiguousarray(T.T)
    prog = _plan(m)
    acc = np.empty((8, K))
    vals = np.empty((64, K))  # the stack of partial sums (depth <= log2(m / 64) + 2)
    out = np.empty((K, c))
    for j in range(c):
        nv = 0
        for s in range(prog.shape[0]):
            if prog[s, 0] == 0:
                _block_terms(Rt, Tt[j], P[j], prog[s, 1], prog[s, 2], acc, vals[nv])
                nv += 1
            else:
                for k in range(K):
                    vals[nv - 2, k] = vals[nv - 2, k] + vals[nv - 1, k]
                nv -= 1
        for k in range(K):
            out[k, j] = vals[0, k]
    return out
