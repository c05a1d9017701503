"""Observer gains by Riccati equations: the H∞ gain by bisection on ``γ`` and the Kalman-type
predictor gain, each checked by a certificate computed on the original matrices.

The error of the observer ``x̂+ = A x̂ + B u + L (y - C x̂ - D u)`` obeys ``e+ = M e + G d``,
``M = A - L C``, ``G = E - L F`` [Tang2019, eq. (15)].

**H∞ gain by a Riccati equation.** ``‖(zI - M)⁻¹ G‖∞ = ‖(zI - Mᵀ)⁻¹ I ... ‖``: transposed,
the problem is an H∞ *state-feedback* problem for the dual plant

    ξ+ = Aᵀ ξ + w + Cᵀ v,      ζ = Eᵀ ξ + Fᵀ v,      v = -Lᵀ ξ,

(``ζ = Gᵀ ξ``, ``ξ+ = Mᵀ ξ + w``), whose static state feedback exists for a given ``γ`` iff the
H∞ algebraic Riccati equation

    X = 𝒜ᵀ X 𝒜 + Q - (𝒜ᵀ X ℬ + S)(R + ℬᵀ X ℬ)⁻¹(ℬᵀ X 𝒜 + Sᵀ),
    𝒜 = Aᵀ,  ℬ = [I  Cᵀ],  Q = E Eᵀ,  R = diag(-γ² I, F Fᵀ),  S = [0  E Fᵀ]

has a stabilising solution ``X ⪰ 0`` with ``γ² I - X ≻ 0`` [Stoorvogel1992, Ch. 3]; the central
feedback is then ``L = (A X̃ Cᵀ + E Fᵀ)(F Fᵀ + C X̃ Cᵀ)⁻¹`` with ``X̃ = X + X (γ² I - X)⁻¹ X``
(as ``γ → ∞``, ``X̃ → X`` and ``L`` becomes the Kalman predictor gain). :func:`hinf_riccati_gain`
bisects on ``γ`` with :func:`scipy.linalg.solve_discrete_are` and certifies the result by the
bounded-real lemma (:func:`bounded_real_certificate`): a ``P`` satisfying [Tang2019, LMI (16)]
with ``Y = P L`` strictly, checked by the eigenvalues of the assembled block matrix. Cost
``O(nx³)`` per ``γ`` instead of the LMI's ``O(nx⁶)``-like interior-point steps. Near the optimal
``γ`` the central gain attains almost ``γ`` and, when ``A - LC`` contracts slowly, its
certificate cannot be proven; the central gains of larger ``γ`` (:data:`BACK_OFF`) are then
tried and the first certified is returned with its ``γ`` (a sampled cart-pole: ``γ`` 4.99 fails,
``1.1 × 4.99`` is certified).

**Kalman-type gain.** :func:`kalman_gain`: the steady-state predictor gain of the model with the
process part of ``d`` weighted by ``q`` (``Q = q E Eᵀ``, ``S = √q E Fᵀ``, ``R = F Fᵀ``). It is
the starting point of the radius-minimising design (:mod:`ivobs.design.radius`).

Every design is solved in the balanced coordinates of :mod:`ivobs.design.balance` (``L = D L̃``)
and checked on the original matrices: ``A - LC`` Schur, and for the H∞ gain the LMI (16).
"""

from __future__ import annotations

import numpy as np

from ..errors import DesignError
from ..linalg import spectral_radius
from .balance import state_scaling

__all__ = ["bounded_real_certificate", "hinf_riccati_gain", "kalman_gain"]

RTOL = 1e-4
"""Relative accuracy of the bisection on ``γ`` up to :data:`RTOL_LARGE_N` states (the returned
``γ`` is within a few ``rtol`` of the smallest attained)."""

RTOL_LARGE, LARGE_N = 1e-2, 60
"""Above ``LARGE_N`` states the bisection stops at ``RTOL_LARGE``: each ``γ`` costs a Riccati
equation of ``O(nx³)``, and the box widths do not depend on the last digits of ``γ``."""

BACK_OFF = (1.01, 1.03, 1.1, 1.3, 2.0, 4.0)
"""When the bisection's gain fails its certificate: the central gains of ``γ`` these times
larger are tried in turn (the first certified is returned, with that ``γ``)."""

STRICT = 1e-6
"""Slack of the certificate, relative to the diagonal of ``P`` (:func:`bounded_real_certificate`):
LMI (16) then holds strictly, by a margin above rounding."""


def _regular(R: np.ndarray) -> np.ndarray:
    """``R`` plus a tiny multiple of ``I`` when singular (outputs without measurement noise): the
    Riccati equation needs it invertible; the certificate decides whether the gain is good."""
    scale = max(1.0, float(np.abs(R).max(initial=0.0)))
    w = np.linalg.eigvalsh(R) if R.size else np.ones(1)
    if w.min() > 1e-10 * scale:
        return R
    return R + 1e-10 * scale * np.eye(R.shape[0])


def kalman_gain(A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, q: float) -> np.ndarray:
    """Steady-state Kalman predictor gain with the process noise weighted by ``q`` (module
    docstring); raises :class:`DesignError` if the Riccati equation has no stabilising
    solution or ``A - LC`` is not Schur."""
    from scipy.linalg import solve_discrete_are

    dv = state_scaling(A, C, E, F)
    At, Ct, Et = A * dv[None, :] / dv[:, None], C * dv[None, :], E / dv[:, None]
    Es = np.sqrt(q) * Et
    R = _regular(F @ F.T)
    try:
        X = solve_discrete_are(At.T, Ct.T, Es @ Es.T, R, s=Es @ F.T)
        Lt = np.linalg.solve(R + Ct @ X @ Ct.T, Ct @ X @ At.T + F @ Es.T).T
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DesignError(
            f"kalman_gain: the Riccati equation has no stabilising solution ({exc}); (A, C) may "
            "not be detectable"
        ) from None
    L: np.ndarray = dv[:, None] * Lt
    if not np.all(np.isfinite(L)) or not spectral_radius(A - L @ C) < 1.0:
        raise DesignError("kalman_gain: the Riccati gain does not make A - LC Schur stable")
    return L


def _hinf_central(
    At: np.ndarray, Ct: np.ndarray, Et: np.ndarray, F: np.ndarray, dv: np.ndarray, gamma: float
) -> np.ndarray | None:
    """The central H∞ gain (balanced coordinates) at ``γ``, or None when ``γ`` is not attained
    (no stabilising solution, ``X`` not ⪰ 0, or ``γ² I - D X D`` not ≻ 0)."""
    from scipy.linalg import solve_discrete_are

    n, ny = Ct.shape[1], Ct.shape[0]
    # the performance output is e = D ẽ (original units): ℬ1 = D in the dual plant
    Dz = np.diag(dv)
    Bb = np.hstack([Dz, Ct.T])
    R = np.zeros((n + ny, n + ny))
    R[:n, :n] = -(gamma**2) * np.eye(n)
    R[n:, n:] = _regular(F @ F.T)
    S = np.hstack([np.zeros((n, n)), Et @ F.T])
    try:
        X = solve_discrete_are(At.T, Bb, Et @ Et.T, R, s=S)
        X = 0.5 * (X + X.T)
        if not np.all(np.isfinite(X)) or np.linalg.eigvalsh(X).min() < -1e-9 * max(
            1.0, float(np.abs(X).max())
        ):
            return None
        DXD = dv[:, None] * X * dv[None, :]
        Gm = gamma**2 * np.eye(n) - DXD
        if np.linalg.eigvalsh(Gm).min() <= 0.0:
            return None
        XD = X * dv[None, :]
        Xt = X + XD @ np.linalg.solve(Gm, XD.T)
        Lt: np.ndarray = np.linalg.solve(R[n:, n:] + Ct @ Xt @ Ct.T, Ct @ Xt @ At.T + F @ Et.T).T
    except (np.linalg.LinAlgError, ValueError):
        return None
    return Lt if np.all(np.isfinite(Lt)) else None


def bounded_real_certificate(M: np.ndarray, G: np.ndarray, gamma: float) -> np.ndarray | None:
    """``P ≻ 0`` with [Tang2019, LMI (16)] strict for ``A_e = M``, ``B_e = G`` (``Y = P L``):

        [ I - P    0        Mᵀ P ]
        [ 0       -γ² I     Gᵀ P ]  ≺ 0,
        [ P M      P G      -P   ]

    i.e. ``‖(zI - M)⁻¹ G‖∞ < γ`` and ``M`` Schur (bounded-real lemma); None if none is found.

    Solved and checked in balanced coordinates (:mod:`ivobs.design.balance`, ``M̃ = D⁻¹ M D``,
    ``G̃ = D⁻¹ G``): the congruence ``diag(D, I, D)`` maps (16) onto the same LMI for
    ``P̃ = D P D`` with ``D²`` in place of ``I``. ``P̃`` is the stabilising solution of
    ``P̃ = M̃ᵀ P̃ M̃ + Q + M̃ᵀ P̃ G̃ (γ² I - G̃ᵀ P̃ G̃)⁻¹ G̃ᵀ P̃ M̃`` with ``Q = D² + STRICT diag(P̃₀)``
    (``P̃₀`` the solution for ``Q = D²``), so (16) holds with a slack; the block matrix
    is assembled, scaled by its diagonal (a congruence: definiteness is kept) and its largest
    eigenvalue checked ``< 0``."""
    from scipy.linalg import solve_discrete_are

    n, nd = G.shape
    if not spectral_radius(M) < 1.0:
        return None
    dv = state_scaling(M, np.zeros((0, n)), G)
    Mt, Gt, D2 = M * dv[None, :] / dv[:, None], G / dv[:, None], np.diag(dv**2)
    try:
        # the slack of (16) is taken relative to P̃'s diagonal (a slack relative to D² alone
        # is below rounding for states whose weight D² is far smaller than P̃)
        Pt = solve_discrete_are(Mt, Gt, D2, -(gamma**2) * np.eye(nd))
        Q = D2 + STRICT * np.diag(np.abs(np.diag(Pt)))
        Pt = solve_discrete_are(Mt, Gt, Q, -(gamma**2) * np.eye(nd))
    except (np.linalg.LinAlgError, ValueError):
        return None
    Pt = 0.5 * (Pt + Pt.T)
    if not np.all(np.isfinite(Pt)):
        return None
    PM, PG = Pt @ Mt, Pt @ Gt
    lmi = np.block(
        [[D2 - Pt, np.zeros((n, nd)), PM.T], [np.zeros((nd, n)), -(gamma**2) * np.eye(nd), PG.T],
         [PM, PG, -Pt]]
    )  # fmt: skip
    diag = np.diag(lmi)
    if not np.all(diag < 0.0):
        return None
    s = 1.0 / np.sqrt(-diag)
    if np.linalg.eigvalsh(lmi * s[:, None] * s[None, :]).max() >= -1e-12:
        return None
    P: np.ndarray = Pt / dv[:, None] / dv[None, :]
    return P


def hinf_riccati_gain(
    A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray
) -> tuple[np.ndarray, float, np.ndarray]:
    """The H∞ observer gain of [Tang2019, problem (20)] by bisection on ``γ`` with the Riccati
    equation of the module docstring; ``(L, γ, P)`` with ``P`` the bounded-real certificate of
    ``‖(zI - (A - LC))⁻¹ (E - LF)‖∞ < γ`` (LMI (16), checked). ``γ`` is within ``rtol`` of the
    smallest the bisection reaches. Raises :class:`DesignError` if no ``γ`` is attained (e.g.
    ``(A, C)`` not detectable) or no gain passes its certificate."""
    n = A.shape[0]
    rtol = RTOL if n <= LARGE_N else RTOL_LARGE
    if E.shape[1] == 0:  # no disturbance: any stabilising gain; the Kalman one with Q = I
        L = kalman_gain(A, C, np.eye(n), np.zeros((C.shape[0], n)), 1.0)
        return L, 0.0, np.eye(n)
    dv = state_scaling(A, C, E, F)
    At, Ct, Et = A * dv[None, :] / dv[:, None], C * dv[None, :], E / dv[:, None]
    # a γ attained: the H∞ norm of the Kalman gain's error system is finite; start above it
    hi = 1.0 + float(np.abs(E).sum() + np.abs(F).sum())
    Lhi = None
    for _ in range(40):
        Lhi = _hinf_central(At, Ct, Et, F, dv, hi)
        if Lhi is not None:
            break
        hi *= 10.0
    if Lhi is None:
        raise DesignError(
            "hinf_riccati_gain (problem (20) of [Tang2019]): no γ up to 1e40 gives a "
            "stabilising solution of the H∞ Riccati equation; (A, C) may not be detectable: "
            "pass an explicit gain L=..."
        )
    lo = 0.0
    while lo == 0.0 or hi > lo * (1.0 + rtol):
        mid = hi / 4.0 if lo == 0.0 else np.sqrt(lo * hi)
        if lo == 0.0 and mid < 1e-12 * (1.0 + hi):
            break
        Lmid = _hinf_central(At, Ct, Et, F, dv, mid)
        if Lmid is None:
            lo = mid
        else:
            hi, Lhi = mid, Lmid
    L = dv[:, None] * Lhi
    M, G = A - L @ C, E - L @ F
    # certificate on the original matrices, at γ a little above the bisection's
    for gamma in hi * (1.0 + rtol) ** np.arange(1, 6):
        P = bounded_real_certificate(M, G, float(gamma))
        if P is not None:
            return L, float(gamma), P
    # near the optimum the central gain attains almost γ itself and its certificate's Riccati
    # equation is ill-conditioned (a slowly contracting A - LC); the central gain of a larger
    # γ leaves a margin its certificate can prove
    for factor in BACK_OFF:
        Lt = _hinf_central(At, Ct, Et, F, dv, hi * factor)
        if Lt is None:
            continue
        L = dv[:, None] * Lt
        P = bounded_real_certificate(A - L @ C, E - L @ F, float(hi * factor))
        if P is not None:
            return L, float(hi * factor), P
    raise DesignError(
        "hinf_riccati_gain: the Riccati gain failed its bounded-real certificate (LMI (16) of "
        f"[Tang2019] at γ = {hi:.6g}, and at γ up to {BACK_OFF[-1]:g} times that); the design "
        "is refused: pass an explicit gain L=..., or another design (gain='radius')"
    )
