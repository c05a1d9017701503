"""Fast evaluation of the linear recursions that every observer's time loop reduces to.

``x[k+1] = M x[k] + v[k]`` over a whole record, vectorised over time by a doubling scan
(Hillis-Steele): after passes with shifts ``1, 2, 4, ...`` each row holds
``sum_i M^i w[k-i]``. ``log2(T)`` matrix products of the whole record instead of ``T`` small ones.
Only used for Schur-stable ``M`` (powers underflow to exactly zero, which ends the scan early);
otherwise, and for large batches, a plain loop over time is used. Results agree with the
sequential loop up to rounding (summation order differs).
"""

from __future__ import annotations

import numpy as np


def affine_recursion(M: np.ndarray, v: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Return ``x`` of shape ``(..., T+1, n)`` with ``x[0] = x0``, ``x[k+1] = M x[k] + v[k]``.

    ``v`` has shape ``(..., T, n)`` (leading batch axes allowed); ``x0`` shape ``(..., n)`` or
    ``(n,)``.
    """
    M = np.asarray(M, dtype=float)
    v = np.asarray(v, dtype=float)
    T, n = v.shape[-2], v.shape[-1]
    lead = v.shape[:-2]
    X = np.empty((*lead, T + 1, n))
    X[..., 0, :] = x0
    X[..., 1:, :] = v
    if T == 0:
        return X
    batch = int(np.prod(lead)) if lead else 1
    stable = True if M.size == 0 else bool(np.max(np.abs(np.linalg.eigvals(M))) < 1.0)
    if not stable or T < 32 or batch >= 64:
        return _loop(M, X)
    P = M.copy()
    s = 1
    while s <= T:
        X[..., s:, :] = X[..., s:, :] + X[..., :-s, :] @ P.T
        P = P @ P
        s *= 2
        if not np.any(P):
            break
    return X


def _loop(M: np.ndarray, X: np.ndarray) -> np.ndarray:
    MT = M.T
    for k in range(1, X.shape[-2]):
        X[..., k, :] = X[..., k - 1, :] @ MT + X[..., k, :]
    return X
