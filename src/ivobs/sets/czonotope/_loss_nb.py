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
def _pairwise_sum(buf: np.ndarray, n: int) -> float:  # pragma: no cover - compiled
    """NumPy's pairwise sum of ``buf[:n]``: the tree of halves (``n/2`` rounded down to a
    multiple of 8) down to blocks of at most 128, walked in post-order with explicit stacks
    (numba's on-disk cache mishandles recursive functions: they crash when loaded)."""
    if n <= 128:
        return _block_sum(buf, 0, n)
    los = np.empty(64, dtype=np.int64)
    ns = np.empty(64, dtype=np.int64)
    state = np.empty(64, dtype=np.int64)
    vals = np.empty(64)
    top, nv = 0, 0
    los[0], ns[0], state[0] = 0, n, 0
    while top >= 0:
        lo, cnt = los[top], ns[top]
        if cnt <= 128:
            vals[nv] = _block_sum(buf, lo, cnt)
            nv += 1
            top -= 1
            continue
        half = cnt // 2
        half -= half % 8
        if state[top] == 0:  # the left half first
            state[top] = 1
            top += 1
            los[top], ns[top], state[top] = lo, half, 0
        elif state[top] == 1:  # then the right half
            state[top] = 2
            top += 1
            los[top], ns[top], state[top] = lo + half, cnt - half, 0
        else:  # both done: left + right
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
            top -= 1
    return float(vals[0])


@jit
def shifted_l1(R: np.ndarray, T: np.ndarray, P: np.ndarray) -> np.ndarray:  # pragma: no cover
    """``N[k, c] = ‖R_k - T_kc P_c‖₁`` (``R`` (K, m), ``T`` (K, c), ``P`` (c, m), C-contiguous
    float64), as :func:`~.hull._shifted_l1` computes it."""
    K, m = R.shape
    c = T.shape[1]
    out = np.empty((K, c))
    buf = np.empty(m)
    for k in range(K):
        for j in range(c):
            t = T[k, j]
            for col in range(m):
                buf[col] = abs(R[k, col] - t * P[j, col])
            out[k, j] = _pairwise_sum(buf, m)
    return out
