"""Balancing the state coordinates before a design: a diagonal similarity ``x = diag(dv) x̃``.

A plant whose states have very different magnitudes (a position in km next to a current in mA)
gives LMIs and LPs whose coefficients span many orders of magnitude, and interior-point solvers
then stop at "inaccurate" or "infeasible" answers. Every design of this package therefore solves
its problem for the balanced model ``Ã = D⁻¹ A D``, ``B̃ = D⁻¹ B``, ``C̃ = C D``, ``Ẽ = D⁻¹ E``
(``D = diag(dv)``; ``u``, ``y`` and ``d`` keep their units), maps the result back (a Luenberger
gain: ``L = D L̃``, since ``A − LC = D (Ã − L̃ C̃) D⁻¹``) and checks the certificate on the
original matrices.

``dv`` comes from :func:`scipy.linalg.matrix_balance` (LAPACK ``gebal``, no permutation) of the
square matrix ``[[A, E, 0], [0, 0, 0], [C, F, 0]]`` over the coordinates ``(x, d, y)``: the rows
of ``d`` and the columns of ``y`` are zero, so ``gebal`` leaves those coordinates alone and
equalises, for each state, the norm of its row of ``[A E]`` with that of its column of
``[A; C]``. The entries of ``dv`` are powers of 2, so scaling by them is exact in floating point.
A well-scaled plant gets ``dv`` close to ones (often exactly ones).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import matrix_balance

__all__ = ["state_scaling"]


def state_scaling(
    A: np.ndarray, C: np.ndarray, E: np.ndarray | None = None, F: np.ndarray | None = None
) -> np.ndarray:
    """The diagonal ``dv`` of the balancing similarity ``x = diag(dv) x̃`` (module docstring)."""
    n, p = A.shape[0], C.shape[0]
    m = 0 if E is None else E.shape[1]
    N = n + m + p
    M = np.zeros((N, N))
    M[:n, :n] = np.abs(A)
    M[n + m :, :n] = np.abs(C)
    if E is not None and m:
        M[:n, n : n + m] = np.abs(E)
        if F is not None:
            M[n + m :, n : n + m] = np.abs(F)
    if not np.all(np.isfinite(M)) or not np.any(M):
        return np.ones(n)
    with np.errstate(all="ignore"):  # gebal on entries near the float range: checked below
        _, (scale, _perm) = matrix_balance(M, permute=False, separate=True)
    dv: np.ndarray = np.asarray(scale[:n], dtype=float)
    if not (np.all(np.isfinite(dv)) and np.all(dv > 0.0)):
        return np.ones(n)
    return dv
