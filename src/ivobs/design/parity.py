"""Parity-space design of the fixed-time estimator [Wang2020].

For ``x[k+1] = A x + B v + E d``, ``y = C x + D v + F d`` with invertible ``A``, the backward
propagation [Wang2020, eqs. (4)-(5)], with ``Ã = A⁻¹``, ``B̃ = -A⁻¹B``, ``Ẽ = -A⁻¹E``, stacks the
last ``s + 1`` outputs ``𝐲_k = [y_k; …; y_{k-s}]`` as [Wang2020, eq. (6)]::

    𝐲_k = Mx x_k + Mu 𝐮_k + Md 𝐝_k,     𝐮_k = [u_k; …; u_{k-s}],  𝐝_k = [d_k; …; d_{k-s}]

    Mx = [C; C Ã; …; C Ã^s]
    Mu block (i, j) = C Ã^{i-j} B̃  (1 <= j <= i),  + D on the diagonal (i = j, also i = j = 0)
    Md block (i, j) = C Ã^{i-j} Ẽ  (1 <= j <= i),  + F on the diagonal

(the paper has ``D = 0``; ``D u_{k-i}`` enters row block ``i`` directly). Any ``T`` with
``T Mx = I`` (eq. 8) gives ``x̂_k = T(𝐲_k - Mu 𝐮_k) = x_k + T Md 𝐝_k`` (eqs. 7, 9); the
general solution is ``T = Mx† + S Mx⊥`` (Lemmas 1 and 2), and Theorem 1 (eq. 13) gives the
one minimising ``‖T Md‖_F``.

Time-varying systems [Wang2020, Remark 4]: :func:`stack_window` takes the matrices of each step
of the window. Non-invertible ``A`` [Wang2020, Remark 1]: :mod:`ivobs.design.injection` finds
small gains ``L`` with ``A - LC`` well-conditioned; ``L y`` then enters as a known input.

Certification of a computed window gain (not in the paper): :mod:`ivobs.design.certify`
(:func:`~ivobs.design.certify.forward_window`, :func:`~ivobs.design.certify.window_bound`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import DesignError, IvobsError
from .injection import is_invertible, rcond

_EPS = np.finfo(float).eps

__all__ = ["OptimalT", "general_T", "optimal_T", "pinv_perp", "stack_window", "width_optimal_T"]


def stack_window(
    mats: Sequence[tuple[np.ndarray, ...]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stacked matrices ``(Mx, Mu, Md)`` of [Wang2020, eq. (6)] for one window of ``s + 1`` steps.

    ``mats[i] = (A, B, C, D, E, F)`` at step ``k - i`` for ``i = 0 … s`` (most recent first);
    ``A`` at step ``k`` itself is not used. Time-varying form (Remark 4): with
    ``Ψ(k-i, k) = A_{k-i}⁻¹ ⋯ A_{k-1}⁻¹``,

    * row block ``i`` of ``Mx`` is ``C_{k-i} Ψ(k-i, k)``,
    * block ``(i, j)`` of ``Mu`` (``1 <= j <= i``) is ``-C_{k-i} Ψ(k-i, k-j+1) B_{k-j}``, plus
      ``D_{k-i}`` when ``j = i``; likewise ``Md`` with ``E`` and ``F``.

    For constant matrices these are ``C Ã^i``, ``C Ã^{i-j} B̃`` and ``C Ã^{i-j} Ẽ`` (eqs. 5-6).
    Raises :class:`DesignError` if an ``A`` of the window is not invertible.
    """
    s = len(mats) - 1
    _, B0, C0, _, E0, _ = mats[0]
    nx, nu, ny, nd = B0.shape[0], B0.shape[1], C0.shape[0], E0.shape[1]
    Mx = np.zeros(((s + 1) * ny, nx))
    Mu = np.zeros(((s + 1) * ny, (s + 1) * nu))
    Md = np.zeros(((s + 1) * ny, (s + 1) * nd))
    P = np.eye(nx)  # Ψ(k-i, k)
    RB: list[np.ndarray] = []  # Ψ(k-i, k-j+1) B_{k-j}, j = 1..i
    RE: list[np.ndarray] = []
    for i, (_, _, C, D, _, F) in enumerate(mats):
        if i > 0:
            A_prev, B_prev, _, _, E_prev, _ = mats[i]  # matrices at step k-i
            if not is_invertible(A_prev):
                raise DesignError(
                    f"A at lag {i} of the window is not invertible (reciprocal condition number "
                    f"{rcond(A_prev):.1e}); the backward propagation ([Wang2020, eq. (4)]) "
                    "needs A⁻¹: use an output injection L ([Wang2020, Remark 1])"
                )
            Ainv = np.linalg.inv(A_prev)
            P = Ainv @ P
            RB = [Ainv @ M for M in RB] + [Ainv @ B_prev]
            RE = [Ainv @ M for M in RE] + [Ainv @ E_prev]
        r = slice(i * ny, (i + 1) * ny)
        Mx[r] = C @ P
        for j in range(1, i + 1):
            Mu[r, j * nu : (j + 1) * nu] = -C @ RB[j - 1]
            Md[r, j * nd : (j + 1) * nd] = -C @ RE[j - 1]
        Mu[r, i * nu : (i + 1) * nu] += D
        Md[r, i * nd : (i + 1) * nd] += F
    return Mx, Mu, Md


def pinv_perp(Mx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``(Mx†, Mx⊥, N, rank)``: ``Mx† = (MxᵀMx)⁻¹Mxᵀ``, ``Mx⊥ = I - Mx Mx†`` ([Wang2020], Notation),
    and ``N`` an orthonormal basis of the left null space (``N Mx = 0``, ``NᵀN = Mx⊥``).

    From one SVD ``Mx = U Σ Vᵀ``: ``Mx† = V Σ⁻¹ U₁ᵀ`` and ``Mx⊥ = U₂ U₂ᵀ`` (exactly symmetric
    and idempotent up to rounding, unlike ``I - Mx Mx†`` formed by subtraction). ``rank`` counts
    singular values above ``max(m, n) · ε · σ_max``; ``Mx†`` is only meaningful at full column
    rank (checked by the callers).
    """
    m, n = Mx.shape
    U, sv, Vt = np.linalg.svd(Mx, full_matrices=True)
    tol = max(m, n) * _EPS * (sv[0] if sv.size else 0.0)
    rank = int(np.sum(sv > tol))
    r = min(rank, n)
    Mx_pinv = (Vt[:r].T * (1.0 / sv[:r])) @ U[:, :r].T  # (the kept singular values are > tol >= 0)
    U2 = U[:, r:]
    return Mx_pinv, U2 @ U2.T, U2.T.copy(), rank


@dataclass(frozen=True)
class OptimalT:
    """[Wang2020, Theorem 1]: ``T``, and the quantities of eq. (13)."""

    T: np.ndarray
    Mx_pinv: np.ndarray
    Mx_perp: np.ndarray
    U1: np.ndarray
    S1: np.ndarray
    V1: np.ndarray
    rank: int


def _check_full_rank(Mx: np.ndarray, rank: int) -> None:
    nx = Mx.shape[1]
    if rank < nx:
        raise DesignError(
            f"T Mx = I ([Wang2020, eq. (8)]) has no solution: the stacked observability matrix "
            f"Mx has rank {rank} < nx = {nx}; the window must observe the state ([Wang2020, "
            "Lemma 2]: observable (A, C) and s >= nx - 1)"
        )


def optimal_T(Mx: np.ndarray, Md: np.ndarray, W: np.ndarray | None = None) -> OptimalT:
    """``T`` minimising ``‖T Md W‖_F`` subject to ``T Mx = I`` [Wang2020, Theorem 1, eq. (13)].

    ``T = Mx† - Mx† Md V1ᵀ S1⁻¹ U1ᵀ Mx⊥`` with ``Mx⊥ Md = U1 S1 V1`` the compact SVD
    (eq. 17). The paper's criterion is ``W = I`` (the default); ``W`` (a nonnegative vector, the
    bound radii per column of ``Md``) weighs the disturbance by its size.

    Rank decision: ``‖Mx⊥‖₂ = 1``, so the rounding level of the computed ``Mx⊥ Md`` is about
    ``ε ‖Md‖₂``; singular values at or below ``10 · max(m, n) · ε · ‖Md‖₂`` are rounding, not
    signal, and are dropped. Keeping one would divide by it and blow up ``T``; dropping a genuine
    one only forfeits optimality, never ``T Mx = I`` (any ``X`` in ``Mx† + X Mx⊥`` satisfies it).
    The result is verified: ``T Mx = I`` to rounding and ``‖T Md‖ <= ‖Mx† Md‖`` (the ``S = 0``
    solution), else :class:`DesignError`.
    """
    m = Mx.shape[0]
    Mx_pinv, Mx_perp, N, rank = pinv_perp(Mx)
    _check_full_rank(Mx, rank)
    Mdw = Md if W is None else Md * W[None, :]
    if Mdw.shape[1] == 0 or N.shape[0] == 0:
        empty = np.zeros((m, 0))
        return OptimalT(
            Mx_pinv, Mx_pinv, Mx_perp, empty, np.zeros((0, 0)), np.zeros((0, Mdw.shape[1])), 0
        )
    # Mx⊥ Md = Nᵀ (N Md): the SVD of the small factor N Md carries the same singular values.
    Uh, sv, V = np.linalg.svd(N @ Mdw, full_matrices=False)
    md_norm = float(np.linalg.norm(Mdw, 2))
    tol = 10.0 * max(m, Mdw.shape[1]) * _EPS * md_norm
    r = int(np.sum(sv > tol))
    U1 = N.T @ Uh[:, :r]
    S1 = np.diag(sv[:r])
    V1 = V[:r]
    T = Mx_pinv - (Mx_pinv @ Mdw @ V1.T / sv[:r]) @ U1.T @ Mx_perp
    _verify(T, Mx, Mdw, Mx_pinv)
    return OptimalT(T, Mx_pinv, Mx_perp, U1, S1, V1, r)


def _verify(T: np.ndarray, Mx: np.ndarray, Mdw: np.ndarray, Mx_pinv: np.ndarray) -> None:
    nx = Mx.shape[1]
    cond = np.linalg.cond(Mx)
    resid = float(np.max(np.abs(T @ Mx - np.eye(nx))))
    if not resid <= 1e-8 * max(1.0, cond):
        raise DesignError(
            f"optimal T: T Mx = I ([Wang2020, eq. (8)]) holds only to {resid:.1e} (cond(Mx) = "
            f"{cond:.1e}); the stacked matrices are too ill-conditioned: reduce s or rescale the "
            "states"
        )
    base = float(np.linalg.norm(Mx_pinv @ Mdw))
    if not float(np.linalg.norm(T @ Mdw)) <= base * (1 + 1e-8) + 1e-12:
        raise DesignError(
            "optimal T: ‖T Md‖_F exceeds that of T = Mx† ([Wang2020, Theorem 1] violated by "
            "rounding); the stacked matrices are too ill-conditioned: reduce s or rescale the "
            "states"
        )


def general_T(Mx: np.ndarray, S: np.ndarray) -> np.ndarray:
    """The general solution ``T = Mx† + S Mx⊥`` of ``T Mx = I`` [Wang2020, Lemmas 1 and 2]."""
    Mx_pinv, Mx_perp, _, rank = pinv_perp(Mx)
    _check_full_rank(Mx, rank)
    if S.shape != (Mx.shape[1], Mx.shape[0]):
        raise IvobsError(
            f"S: expected shape ({Mx.shape[1]}, {Mx.shape[0]}) (nx, (s+1)·ny), got {S.shape}"
        )
    T: np.ndarray = Mx_pinv + S @ Mx_perp
    return T


def width_optimal_T(Mx: np.ndarray, Md: np.ndarray, W: np.ndarray | None = None) -> np.ndarray:
    """``T`` minimising each box width of eq. (11), ``Σ_j |(T Md Wd)_ij|``, s.t. ``T Mx = I``.

    Not in [Wang2020] (whose Theorem 1 minimises ``‖T Md‖_F``): one linear program per state
    (HiGHS), ``min Σ a`` s.t. ``-a <= (Md W)ᵀ t_i <= a``, ``Mxᵀ t_i = e_i``. The LP solution
    satisfies ``T Mx = I`` only to the solver's tolerance, so it is projected back,
    ``T ← T + (I - T Mx) Mx†``, which restores ``T Mx = I`` to rounding.
    """
    from scipy.optimize import linprog

    Mx_pinv, _, _, rank = pinv_perp(Mx)
    _check_full_rank(Mx, rank)
    P = Md if W is None else Md * W[None, :]
    m, nx = Mx.shape
    p = P.shape[1]
    if p == 0:
        return Mx_pinv
    c = np.concatenate([np.zeros(m), np.ones(p)])
    A_ub = np.block([[P.T, -np.eye(p)], [-P.T, -np.eye(p)]])
    A_eq = np.hstack([Mx.T, np.zeros((nx, p))])
    bounds = [(None, None)] * m + [(0, None)] * p
    T = np.empty((nx, m))
    for i in range(nx):
        res = linprog(
            c,
            A_ub=A_ub,
            b_ub=np.zeros(2 * p),
            A_eq=A_eq,
            b_eq=np.eye(nx)[i],
            bounds=bounds,
            method="highs",
        )
        if res.status != 0:
            raise DesignError(
                f"width-optimal T: the linear program for state {i} failed ({res.message})"
            )
        T[i] = res.x[:m]
    projected: np.ndarray = T + (np.eye(nx) - T @ Mx) @ Mx_pinv
    return projected
