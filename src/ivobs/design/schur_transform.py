"""An orthogonal transformation for ``interval-transformed`` that scales: real Schur coordinates.

Papers: [Efimov2013, Theorem 3] (the split observer, bounded iff ``|R|`` is Schur) applied in the
coordinates ``z = S x`` of [Tang2019, Theorem 5] / [Efimov2013, Theorem 2]; the gain is a
steady-state Kalman gain with a prescribed decay rate (a textbook construction, documented here).

The transformation of [Tang2019, eq. (48)], ``S = O_R⁻¹ O_{A−LC}``, goes through observability
(Krylov) matrices whose condition number grows exponentially with ``n``: beyond about ten states
``S`` cannot be computed accurately, and the nonnegative realisation ``R`` of the spectrum may not
exist at all. This module takes instead

    A − LC = Z R Zᵀ     (real Schur form: ``Z`` orthogonal, ``R`` upper quasi-triangular)

and ``S = Zᵀ`` (``κ(S) = 1``). ``R`` has any sign, so the observer runs the split form
``z̄+ = R⁺ z̄ − R⁻ z̲ + …`` (sound for every ``R``, [Efimov2013, Lemma 1]), whose bounds stay
bounded iff ``ρ(|R|) < 1``. ``|R|`` is block upper triangular, so ``ρ(|R|)`` is the largest
spectral radius of its diagonal blocks: ``|λ|`` for a real eigenvalue, ``|a| + |b|`` for a
``2×2`` block of a complex pair ``a ± ib`` (LAPACK's standardised form has equal diagonal
entries and off-diagonal entries of product ``−b²``): ``ρ(|R|) = max_λ |Re λ| + |Im λ|``. The
real modal form (``S = V⁻¹``, blocks ``[[a, b], [−b, a]]``) has the same ``ρ(|R|)`` and no
off-diagonal coupling; both are tried (the modal one only when ``κ(V) <= 1e10``) and the one
with the smaller steady-state width is kept. Hence ``ρ(|R|) < 1`` whenever every
eigenvalue of ``A − LC`` lies in the diamond ``|Re λ| + |Im λ| < 1``, in particular whenever
``ρ(A − LC) < 1/√2``.

**The gain.** ``L = α L_α`` with ``L_α = A_α P Cᵀ (C P Cᵀ + V)⁻¹`` the steady-state Kalman gain
of ``A_α = A / α`` (``P`` from :func:`scipy.linalg.solve_discrete_are`, process covariance
``W = E diag(Δ/2)² Eᵀ``, noise ``V = F diag(Δ/2)² Fᵀ``, both regularised): ``A_α − L_α C`` is
Schur, so every eigenvalue of ``A − LC`` has modulus ``< α``. It exists iff every unobservable
eigenvalue of ``A`` has modulus ``< α`` (the pair ``(A/α, C)`` detectable). The candidates
``α ∈ {0.7, 1}`` are tried (a decay that guarantees the diamond below, and the plain Kalman
gain, usually the narrower when it fits; each is one Riccati solve, the dominant cost) and the
one with the smallest steady-state width ``Σ_i (|S⁻¹| (I − |R|)⁻¹ |S(E − LF)| Δ)_i`` among
those with ``ρ(|R|) < 1`` is kept. Each step is
``O(n³)`` dense linear algebra (no search, no Krylov matrix): hundreds of states in seconds.

When no candidate works (an unobservable complex pair outside the diamond, or ``(A, C)`` not
detectable) :class:`~ivobs.DesignError` says so.
"""

from __future__ import annotations

import numpy as np

from ..errors import DesignError
from ..linalg import spectral_radius

__all__ = [
    "ALPHAS",
    "MAX_SCHUR_STATES",
    "decay_kalman_gain",
    "modal_transform",
    "schur_design",
    "schur_transform",
]

ALPHAS = (0.7, 1.0)
"""Decay rates tried for the gain (module docstring)."""

MAX_SCHUR_STATES = 1000
"""Above this many states the dense ``O(n³)`` design is refused (pass ``L=`` and ``S=``)."""


def decay_kalman_gain(
    A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, delta: np.ndarray, alpha: float
) -> np.ndarray | None:
    """``L`` with every eigenvalue of ``A − LC`` of modulus ``< alpha`` (module docstring), or
    None when the Riccati equation has no stabilising solution."""
    from scipy.linalg import solve_discrete_are

    n, p = A.shape[0], C.shape[0]
    r2 = (0.5 * np.asarray(delta, dtype=float)) ** 2
    W = (E * r2[None, :]) @ E.T if E.size else np.zeros((n, n))
    V = (F * r2[None, :]) @ F.T if F.size else np.zeros((p, p))
    W = W + 1e-6 * max(float(np.trace(W)) / max(n, 1), 1e-12) * np.eye(n)
    V = V + 1e-6 * max(float(np.trace(V)) / max(p, 1), float(np.trace(W)) / n, 1e-12) * np.eye(p)
    Aa = A / alpha
    try:
        P = solve_discrete_are(Aa.T, C.T, W, V)
    except (ValueError, np.linalg.LinAlgError):
        return None
    La = Aa @ P @ C.T @ np.linalg.inv(C @ P @ C.T + V)
    L: np.ndarray = alpha * La
    return L if np.all(np.isfinite(L)) else None


def schur_transform(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(S, R)`` with ``S = Zᵀ`` orthogonal and ``R = S M Sᵀ`` upper quasi-triangular."""
    from scipy.linalg import schur

    R, Z = schur(M, output="real")
    return Z.T.copy(), R


def modal_transform(M: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(S, R)`` with ``S = V⁻¹`` for the real eigenvector basis ``V`` (columns ``Re v``,
    ``Im v`` for a complex pair) and ``R = S M S⁻¹`` block diagonal (``[[a, b], [−b, a]]`` per
    pair); None when ``V`` is (nearly) singular."""
    lam, Vc = np.linalg.eig(M)
    n = M.shape[0]
    V = np.empty((n, n))
    i = 0
    while i < n:
        if abs(lam[i].imag) > 0.0 and i + 1 < n:
            V[:, i], V[:, i + 1] = Vc[:, i].real, Vc[:, i].imag
            i += 2
        else:
            V[:, i] = Vc[:, i].real
            i += 1
    V /= np.maximum(np.linalg.norm(V, axis=0), 1e-300)
    if not np.all(np.isfinite(V)) or np.linalg.cond(V) > 1e10:
        return None
    S = np.linalg.inv(V)
    return S, S @ M @ V


def _width(R: np.ndarray, S: np.ndarray, G: np.ndarray, delta: np.ndarray) -> float:
    n = R.shape[0]
    try:
        wz = np.linalg.solve(np.eye(n) - np.abs(R), np.abs(S @ G) @ delta)
    except np.linalg.LinAlgError:
        return np.inf
    w = np.abs(np.linalg.inv(S)) @ wz
    return float(w.sum()) if np.all(np.isfinite(w)) and np.all(wz >= 0) else np.inf


def schur_design(
    A: np.ndarray,
    C: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    delta: np.ndarray,
    who: str,
    L: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(L, S, R)``: the gain (given, or the best decay-rate Kalman gain), ``S = Zᵀ`` and
    ``R = S (A − LC) Sᵀ`` with ``ρ(|R|) < 1`` (module docstring); :class:`DesignError` when
    no candidate gives it."""
    n = A.shape[0]
    if n > MAX_SCHUR_STATES:
        raise DesignError(
            f"{who}: the Schur-coordinates design is dense (O(nx³)) and refused above "
            f"{MAX_SCHUR_STATES} states (nx = {n}); pass L= and S="
        )
    if not np.any(np.asarray(delta) > 0) or E.size == 0:
        E, F, delta = np.eye(n), np.zeros((C.shape[0], n)), np.ones(n)
    gains = [L] if L is not None else [decay_kalman_gain(A, C, E, F, delta, a) for a in ALPHAS]
    best: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
    radii = []
    for Lc in gains:
        if Lc is None:
            continue
        M = A - Lc @ C
        for cand in (schur_transform(M), modal_transform(M)):
            if cand is None:
                continue
            S, R = cand
            rho = spectral_radius(np.abs(R))  # the full |R|: round-off outside the blocks
            radii.append(rho)
            if rho >= 1.0:
                continue
            w = _width(R, S, E - Lc @ F, delta)
            if best is None or w < best[0]:
                best = (w, Lc, S, R)
    if best is None:
        what = (
            f"the spectral radius of |R| is {min(radii):.6g} >= 1"
            if radii
            else "no decay-rate Kalman gain exists ((A, C) is not detectable, or an unobservable "
            "eigenvalue of A has modulus >= 1)"
        )
        raise DesignError(
            f"{who}: no Schur-coordinates transformation with |R| Schur: {what}; the split form "
            "in Schur coordinates needs every eigenvalue of A − LC in |Re λ| + |Im λ| < 1"
        )
    return best[1], best[2], best[3]
