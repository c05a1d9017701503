"""Kernels shared by the fast paths: reusable temporaries, products over the last axis of batches,
and the checks that send a stream of a batch back to its loop."""

from __future__ import annotations

import threading
import weakref
from typing import Any

import numpy as np

from ...model._matrix import is_scipy_sparse
from ...sets.rounding import upper

__all__ = ["abs_max", "is_shared", "matrix_product", "norm_inf", "redo_streams", "scratch"]

SCRATCH_MAX = 1 << 22
"""Temporaries up to this many elements are reused between calls (:func:`scratch`)."""

_LOCAL = threading.local()


def scratch(owner: Any, name: str, shape: tuple[int, ...], dtype: Any = float) -> np.ndarray:
    """A reusable array for a temporary of ``owner`` (per thread; contents undefined).

    A batch arrives in chunks of a few million numbers; a fresh array of that size costs more
    in first-touch page faults than the arithmetic done on it, so temporaries that never leave
    a call are kept for the next chunk. Larger ones (a long single record) are not kept."""
    if int(np.prod(shape)) > SCRATCH_MAX:
        return np.empty(shape, dtype=dtype)
    store = _LOCAL.__dict__.get("store")
    if store is None:
        store = _LOCAL.store = weakref.WeakKeyDictionary()
    mine: dict[str, np.ndarray] = store.setdefault(owner, {})
    a = mine.get(name)
    if a is None or a.shape != tuple(shape) or a.dtype != np.dtype(dtype):
        a = mine[name] = np.empty(shape, dtype=dtype)
    return a


def _matrix(a: Any, rows: int | None, cols: int | None) -> np.ndarray:
    """A 2-D float array of the given shape (a vector is a column when ``rows`` is known)."""
    m = np.asarray(a, dtype=float)
    if m.ndim == 1:
        m = m.reshape(-1, 1) if rows is not None else m.reshape(1, -1)
    if (rows is not None and m.shape[0] != rows) or (cols is not None and m.shape[1] != cols):
        raise ValueError(f"expected a ({rows}, {cols}) matrix, got {m.shape}")
    return m


def is_shared(a: np.ndarray, lead: int) -> bool:
    """True when a ``(..., T, m)`` signal is the same for every stream of the batch (fewer
    leading axes than ``lead``, or stride 0 along them: ``np.broadcast_to`` of one record)."""
    if a.ndim - 2 < lead:
        return True
    return all(a.strides[i] == 0 or a.shape[i] == 1 for i in range(a.ndim - 2))


def matrix_product(X: np.ndarray, Mt: Any) -> np.ndarray:
    """``X @ Mt`` over the last axis of a ``(..., m)`` array (``Mt`` dense or sparse ``(m, p)``).

    Narrow products (``m, p <= 8``: e.g. the 3 states of a batch of streams) run as one product
    with ``kron(I_8, Mt)`` on rows of 8 samples: BLAS is slow on a very tall, 3-wide product."""
    lead = X.shape[:-1]
    m, p = Mt.shape
    if is_scipy_sparse(Mt):
        return np.asarray((Mt.T @ X.reshape(-1, m).T).T).reshape(*lead, p)
    rows = int(np.prod(lead)) if lead else 1
    out = np.empty((*lead, p))
    if m <= 8 and p <= 8 and rows >= 4096:
        X2 = np.ascontiguousarray(X).reshape(rows, m)
        O2 = out.reshape(rows, p)
        main = rows - rows % 8
        big = np.kron(np.eye(8), Mt)
        np.matmul(X2[:main].reshape(main // 8, 8 * m), big, out=O2[:main].reshape(main // 8, 8 * p))
        if main < rows:
            O2[main:] = X2[main:] @ Mt
    else:
        out.reshape(rows, p)[...] = X.reshape(rows, m) @ Mt
    return out


def abs_max(a: np.ndarray) -> np.ndarray:
    """``max_i |a_i|`` over the last axis (0 when it is empty): exact. Short rows (the states of
    a small system) column by column: NumPy's reduction along a short last axis is slow."""
    n = a.shape[-1]
    if n > 16:
        big: np.ndarray = np.abs(a).max(axis=-1)
        return big
    out = np.zeros(a.shape[:-1])
    for j in range(n):
        np.maximum(out, np.abs(a[..., j]), out=out)
    return out


def norm_inf(M: np.ndarray) -> float:
    """``‖M‖∞`` (the largest row sum of ``|M|``) rounded up (0 for an empty matrix)."""
    return float(upper(np.max(np.abs(M).sum(axis=1), initial=0.0), max(M.shape[-1], 1)))


def redo_streams(
    est: Any,
    u: np.ndarray,
    y: np.ndarray,
    t: np.ndarray | None,
    lo: np.ndarray,
    hi: np.ndarray,
    bad: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The streams ``bad`` of a batch (a measurement found inconsistent by a vectorised path)
    by the estimator's step-by-step loop, which reports the steps and predicts without them;
    the other streams keep their vectorised bounds. Returns ``(lo, hi, inconsistent)``."""
    inc = np.zeros(y.shape[:-1], dtype=bool)
    for b in np.flatnonzero(bad):
        lo[b], hi[b], inc[b] = est._loop(u[b], y[b], t)
    return lo, hi, inc
