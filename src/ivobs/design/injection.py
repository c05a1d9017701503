"""Output injection for the backward propagation of the fixed-time estimator
[Wang2020, Remark 1].

The stacked matrices of [Wang2020, eq. (6)] need ``A⁻¹`` (the backward propagation of
eq. (4)). When ``A`` is singular or ill-conditioned, the output injection
``x[k+1] = (A - LC) x + (B - LD) u + L y + (E - LF) d`` propagates backwards with ``A - LC``
instead, and ``L y`` becomes a known input. This module decides invertibility
(:func:`is_invertible`) and finds small gains ``L`` with ``A - LC`` well-conditioned
(:func:`injection_candidates`, :func:`invertible_injection`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DesignError

__all__ = [
    "SINGULAR_RCOND",
    "injection_candidates",
    "invertible_injection",
    "is_invertible",
    "rcond",
]

SINGULAR_RCOND = 1e-8
"""``A`` counts as non-invertible when ``σ_min(A) <= SINGULAR_RCOND · max(1, σ_max(A))``."""

_EPS = np.finfo(float).eps


def rcond(M: np.ndarray) -> float:
    """``σ_min(M) / max(1, σ_max(M))`` (1 for an empty matrix)."""
    if M.size == 0:
        return 1.0
    sv = np.linalg.svd(M, compute_uv=False)
    return float(sv[-1] / max(1.0, sv[0]))


def is_invertible(A: np.ndarray) -> bool:
    """``σ_min(A) > SINGULAR_RCOND · max(1, σ_max(A))`` (the test that triggers Remark 1)."""
    return rcond(np.asarray(A, dtype=float)) > SINGULAR_RCOND


def _place(A: np.ndarray, C: np.ndarray, poles: np.ndarray) -> np.ndarray | None:
    """``L`` with the eigenvalues of ``A - LC`` at ``poles`` (``scipy.signal.place_poles`` on
    the dual pair ``(Aᵀ, C_rᵀ)``, ``C_r`` an orthonormal-row factor of ``C``: place_poles needs
    full column rank), or None when the placement fails."""
    from scipy.signal import place_poles

    U, sv, Vt = np.linalg.svd(C, full_matrices=False)
    r = int(np.sum(sv > max(C.shape) * _EPS * (sv[0] if sv.size else 0.0)))
    if r == 0:
        return None
    Cr = sv[:r, None] * Vt[:r]  # C = U_r C_r
    try:
        Lr = place_poles(A.T, Cr.T, poles).gain_matrix.T
    except Exception:  # scipy raises ValueError/LinAlgError with its own wording
        return None
    L = Lr @ U[:, :r].T
    return L if np.all(np.isfinite(L)) else None


def injection_candidates(A: Any, C: Any) -> list[np.ndarray]:
    """Gains ``L`` with ``A - LC`` invertible [Wang2020, Remark 1], from the least to the most
    intrusive; the caller picks one (:func:`invertible_injection`, or by the resulting design).

    1. *Minimal-norm* gains that only lift the small singular directions of ``A``: with
       ``A = U Σ Vᵀ`` and ``V₀``, ``U₀`` the directions with ``σ <= 10⁻³ σ_max``,
       ``L = -α U₀ (C V₀)⁺`` gives ``(A - LC) V₀ = U₀ (Σ₀ + α)`` (``C V₀`` has full column rank
       when ``(A, C)`` is observable: a null vector of ``A`` not seen by ``C`` is unobservable),
       for ``α`` equal to the largest, the smallest remaining and their geometric mean of the
       other singular values.
    2. Pole placement keeping the eigenvalues of ``A`` larger than ``10⁻³ ρ(A)`` and moving
       the others to distinct reals of magnitude ``ρ(A) / 2``.
    3. Pole placement at ``0.5 … 0.9`` (distinct, nonzero, moderate).

    A large gain (poles moved far, e.g. from ``-0.99`` to ``0.9``) makes the stacked matrices
    of ``A - LC`` large and their rounding large (a gain of 156 left the state outside its box
    by 4e-6 before certification), hence this order.
    """
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    nx = A.shape[0]
    out: list[np.ndarray] = []
    U, sv, Vt = np.linalg.svd(A)
    small = sv <= 1e-3 * max(sv[0], np.finfo(float).tiny)
    if small.any() and not small.all():
        U0, V0 = U[:, small], Vt[small].T
        CV = C @ V0
        if np.linalg.matrix_rank(CV) == V0.shape[1]:
            big = sv[~small]
            for alpha in sorted({big[0], float(np.sqrt(big[0] * big[-1])), big[-1]}):
                out.append(-alpha * U0 @ np.linalg.pinv(CV))
    lam = np.linalg.eigvals(A)
    rho = float(np.max(np.abs(lam))) if lam.size else 0.0
    if rho > 0:
        keep = np.abs(lam) > 1e-3 * rho
        moved = int(np.sum(~keep))
        if 0 < moved < nx:
            kept = lam[keep]
            new = 0.5 * rho * np.linspace(1.0, 0.6, moved) if moved > 1 else np.array([0.5 * rho])
            while np.any(np.abs(kept[:, None] - new[None, :]) < 1e-3 * rho):
                new = new * 0.9
            L = _place(A, C, np.concatenate([kept, new]))
            if L is not None:
                out.append(L)
    poles = np.linspace(0.5, 0.9, nx) if nx > 1 else np.array([0.7])
    L = _place(A, C, poles)
    if L is not None:
        out.append(L)
    return [L for L in out if is_invertible(A - L @ C)]


def invertible_injection(A: Any, C: Any) -> np.ndarray:
    """A gain ``L`` with ``A - LC`` invertible [Wang2020, Remark 1]: among
    :func:`injection_candidates`, the one with the smallest ``cond(A - LC) (1 + ‖LC‖/‖A‖)``
    (a well-conditioned ``A - LC`` reached with a small gain). Output injection keeps
    ``(A - LC, C)`` observable whenever ``(A, C)`` is. Raises :class:`DesignError` when no
    candidate works (``C = 0``, unobservable pair)."""
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    if not np.any(C):
        raise DesignError("output injection ([Wang2020, Remark 1]): C = 0, no gain can change A")
    cands = injection_candidates(A, C)
    if not cands:
        raise DesignError(
            "output injection ([Wang2020, Remark 1]): found no L with A - LC invertible (is (A, C) "
            "observable?); pass an explicit L"
        )
    norm_A = max(float(np.linalg.norm(A, 2)), 1e-300)
    # the inverse of eq. (4) stays accurate and the known input L y small against the dynamics
    return min(
        cands, key=lambda L: np.linalg.cond(A - L @ C) * (1 + np.linalg.norm(L @ C, 2) / norm_A)
    )
