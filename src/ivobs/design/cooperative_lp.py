"""The linear programs behind the cooperative gains (:mod:`ivobs.design.cooperative`): the column
layout of ``L`` and auxiliary variables, ``T >= ±M`` rows, and the two-stage solve that returns
the smallest gain among the optimal ones (the module docstring of
:mod:`ivobs.design.cooperative`, "Smallest gain among the optimal ones")."""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import linprog

__all__ = [
    "COPOSITIVE_TOL",
    "LP",
    "L_BOUND",
    "OPT_TOL",
    "REG_L1",
    "abs_bound_rows",
    "copositive_lp",
    "output_weights",
    "solve_lp",
]

L_BOUND = 1e6  # box on the gain entries in the LPs (keeps HiGHS away from unbounded rays)

OPT_TOL = (1e-12, 1e-9)
"""Relative slack of an LP's optimal value in the regularising second stage: the
first value, the second if HiGHS calls the first infeasible (its own tolerances are 1e-7)."""
REG_L1 = 1e-3
"""Weight of ``Σ_ij w_j |L_ij|`` (tie-break) next to the largest column norm in that stage."""


class LP:
    """Column layout of the LPs: ``L`` (n·p, row-major), then auxiliary blocks."""

    def __init__(self, n: int, p: int, blocks: dict[str, int]):
        self.n, self.p = n, p
        self.offset: dict[str, int] = {"L": 0}
        size = n * p
        for name, cols in blocks.items():
            self.offset[name] = size
            size += cols
        self.size = size

    def lin(self, A: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``A_ij − Σ_l L_il C_lj`` as rows ``(coef, const)``, row-major in ``(i, j)``: ``D = A −
        LC`` for ``(A, C)``, ``G = E − LF`` for ``(E, F)``."""
        n, p = self.n, self.p
        coef = np.zeros((n * A.shape[1], self.size))
        coef[:, : n * p] = np.kron(np.eye(n), -C.T)
        return coef, A.ravel().copy()

    def aux(self, name: str, rows: int) -> np.ndarray:
        coef = np.zeros((rows, self.size))
        coef[:, self.offset[name] : self.offset[name] + rows] = np.eye(rows)
        return coef

    def gain(self, x: np.ndarray) -> np.ndarray:
        return x[: self.n * self.p].reshape(self.n, self.p)


def abs_bound_rows(
    lin: tuple[np.ndarray, np.ndarray], aux: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Rows of ``T >= M`` and ``T >= −M`` as ``A_ub x <= b_ub`` (``M = coef x + const``)."""
    coef, const = lin
    return np.vstack([coef - aux, -coef - aux]), np.concatenate([-const, const])


def output_weights(C: np.ndarray) -> np.ndarray:
    """Weights ``w_j = ‖C_j‖₁`` (row ``j`` of ``C``) of the gain's columns in the regularising
    stage: ``Σ_i w_j |L_ij|`` bounds what column ``j`` of ``L`` adds to ``|A − L_k C|`` when
    output ``j`` is missing (``|L_:j| |C_j|``), and does not change when an output is rescaled.
    Rows of zeros (an output that only sees ``u`` or ``d``) weigh as the largest row."""
    w = np.abs(C).sum(axis=1)
    return np.where(w > 0.0, w, max(1.0, float(w.max(initial=0.0))))


def solve_lp(
    c: np.ndarray,
    A_ub: np.ndarray,
    b_ub: np.ndarray,
    bounds: list[tuple[Any, Any]],
    gain: tuple[int, np.ndarray],
    parts: list[np.ndarray] | None = None,
) -> np.ndarray | None:
    """HiGHS, then (``gain = (n, w)``: the first ``n·p`` columns are ``L``, row-major) the
    regularising second stage of the module docstring, which keeps each objective part
    (``parts``, default ``[c]``; ``c`` is a weighted sum of them) at its optimal value."""
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")
    if res.status != 0:
        return None
    x: np.ndarray = res.x
    parts = [c] if parts is None else parts
    best = np.array([float(q @ res.x) for q in parts])
    for tol in OPT_TOL:
        reg = _smallest_gain(np.array(parts), best, tol, A_ub, b_ub, bounds, *gain)
        if reg is not None:
            return reg
    return x


def _smallest_gain(
    parts: np.ndarray,
    best: np.ndarray,
    tol: float,
    A_ub: np.ndarray,
    b_ub: np.ndarray,
    bounds: list[tuple[Any, Any]],
    n: int,
    w: np.ndarray,
) -> np.ndarray | None:
    """Second stage: among the points with ``q_iᵀx <= best_i + tol·max(1,
    |best_i|)`` for every objective part ``q_i``, minimise ``t + REG_L1 Σ_ij w_j |L_ij|`` with
    ``t >= Σ_i w_j |L_ij|`` for every column ``j`` (auxiliary ``U >= ±L``): the LP optimum is
    kept (to the tolerance), the gain is the smallest one attaining it, spread over redundant
    outputs. None when HiGHS fails (the caller then tries the next tolerance)."""
    p = w.size
    nL, N = n * p, parts.shape[1]
    size = N + nL + 1
    wU = np.tile(w, n)  # weight of U_ij (row-major, like L)
    eye = np.eye(nL)
    rows = [
        np.hstack([A_ub, np.zeros((A_ub.shape[0], nL + 1))]),
        np.hstack([parts, np.zeros((parts.shape[0], nL + 1))]),
        np.hstack([eye, np.zeros((nL, N - nL)), -eye, np.zeros((nL, 1))]),
        np.hstack([-eye, np.zeros((nL, N - nL)), -eye, np.zeros((nL, 1))]),
    ]
    col = np.zeros((p, size))  # Σ_i w_j U_ij − t <= 0
    col[:, N : N + nL] = np.tile(np.diag(w), n)
    col[:, -1] = -1.0
    rows.append(col)
    slack = tol * np.maximum(1.0, np.abs(best))
    b = np.concatenate([b_ub, best + slack, np.zeros(2 * nL + p)])
    obj = np.zeros(size)
    obj[N : N + nL] = REG_L1 * wU
    obj[-1] = 1.0
    res = linprog(
        obj,
        A_ub=np.vstack(rows),
        b_ub=b,
        bounds=list(bounds) + [(0, None)] * (nL + 1),
        method="highs",
    )
    return res.x[:N] if res.status == 0 else None


COPOSITIVE_TOL = 1e-7
"""Margins ``|s| <= COPOSITIVE_TOL`` of :func:`copositive_lp` are within HiGHS's own tolerances:
neither a gain nor a proof of infeasibility."""


def copositive_lp(A: np.ndarray, C: np.ndarray) -> tuple[np.ndarray | None, float, str]:
    """Decide exactly whether some ``L`` makes ``A − LC`` nonnegative and Schur, by one LP.

    For a nonnegative ``D`` (here ``D = A − LC``), ``ρ(D) < 1`` iff some ``q > 0`` has
    ``Dᵀq < q`` (a linear copositive Lyapunov function ``V(e) = qᵀe`` on ``e >= 0``; Perron–
    Frobenius). With ``Y = diag(q) L`` both conditions are linear in ``(q, Y)``:
    ``diag(q) A − Y C >= 0`` and ``Aᵀq − Cᵀ Yᵀ 1 <= q − s 1``. The conditions are homogeneous
    in ``(q, Y)``, so ``q >= 1`` loses nothing; the LP maximises the margin ``s`` (capped at 1,
    which keeps it bounded). A gain exists iff the optimum ``s* > 0``.

    The LP is infeasible only when no ``L`` makes ``A − LC`` nonnegative at all (the margin row
    can always be met by a small enough ``s``): ``s* = −inf`` then.

    Returns ``(L, s*, status)``: ``L = diag(q)⁻¹ Y`` when ``s* > COPOSITIVE_TOL``, else None;
    ``status`` is HiGHS's message (``s* = nan`` when it neither solved the LP nor proved it
    infeasible)."""
    n, p = A.shape[0], C.shape[0]
    nY = n * p
    size = n + nY + 1  # q, Y (row-major), s
    # −(q_i A_ij − Σ_l Y_il C_lj) <= 0
    nonneg = np.zeros((n * n, size))
    nonneg[:, :n] = np.repeat(np.eye(n), n, axis=0) * -A.ravel()[:, None]
    nonneg[:, n : n + nY] = np.kron(np.eye(n), C.T)
    # Σ_i q_i A_ij − Σ_i Σ_l Y_il C_lj − q_j + s <= 0
    decay = np.zeros((n, size))
    decay[:, :n] = A.T - np.eye(n)
    decay[:, n : n + nY] = np.tile(-C.T, n)
    decay[:, -1] = 1.0
    c = np.zeros(size)
    c[-1] = -1.0
    bounds = [(1.0, None)] * n + [(None, None)] * nY + [(None, 1.0)]
    res = linprog(
        c,
        A_ub=np.vstack([nonneg, decay]),
        b_ub=np.zeros(n * n + n),
        bounds=bounds,
        method="highs",
        options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10},
    )
    if res.status == 2:  # infeasible: no L makes A − LC >= 0
        return None, float("-inf"), str(res.message)
    if res.status != 0:
        return None, float("nan"), str(res.message)
    s = float(res.x[-1])
    if s <= COPOSITIVE_TOL:
        return None, s, str(res.message)
    q = res.x[:n]
    L: np.ndarray = res.x[n : n + nY].reshape(n, p) / q[:, None]
    return L, s, str(res.message)
