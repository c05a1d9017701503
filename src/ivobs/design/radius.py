"""An observer gain that minimises the box of the error's reachable set (the ``"radius"`` gain).

For the Luenberger observer of [Tang2019, eq. (10)] with ``d ∈ [c - r, c + r]``, the exact
interval hull of the error's reachable set tends to [Tang2019, eq. (21)]

    ρ∞(L) = Σ_{k>=0} |M^k G R| 1,      M = A - L C,  G = E - L F,  R = diag(r),

whatever the prior box (its term ``|M^k| h0`` vanishes). ``reachability`` attains ``ρ∞`` and
``zonotope`` attains it up to its reduction error ([Tang2019, Theorem 6]), so the tightest
gain for both is the one that minimises ``ρ∞``, not an H∞ bound (which is a 2-norm over
frequencies and leaves the box free along the flat directions of its optimum: docs/gains.md).

The design minimises the mean of ``ρ∞`` over the states, truncated at ``K`` terms,

    J(L) = (1/nx) Σ_{k<K} Σ_{i,j} |(M^k G R)_{ij}|,

a nonsmooth function of ``L``. It starts from the best of a few Kalman-type gains (process
part weighted by ``q``, :func:`ivobs.design.riccati.kalman_gain`; a large ``q`` is the
"inflated process noise" gain that [Combastel2015] relates to the zonotope's size) and descends
on a smoothed ``J`` (``|x| ≈ √(x² + ε²) - ε``) by L-BFGS (SciPy), with the gradient by the
adjoint recursion ``W_m = S_{m+1} + Mᵀ W_{m+1}``, ``∂J/∂M = Σ_m W_m X_mᵀ``,
``∂J/∂G = S_0 + Mᵀ W_0`` (``X_k = M^k G R``, ``S_k`` the derivative of the smoothed ``|·|``).

Certificate: the result is kept only if ``A - LC`` is Schur (eigenvalues) and its exact
(unsmoothed) ``J`` over ``2K`` terms is below the start's; otherwise the start is returned.
Work is bounded: the descent is skipped when one evaluation would exceed the budget (large
systems then get the best Kalman-type gain).
"""

from __future__ import annotations

import numpy as np

from ..errors import DesignError
from ..linalg import spectral_radius
from .riccati import kalman_gain

__all__ = ["HORIZON", "radius_gain", "radius_objective"]

HORIZON = 50
"""``K``: terms of ``ρ∞`` in the objective."""

WEIGHTS = (1.0, 1e2, 1e4, 1e6)
"""``q`` of the Kalman-type starting gains."""

WORK = 1.5e9
"""Budget (multiply-adds) of the descent; one evaluation costs about ``2 K nx² nd``."""

MAX_ITER = 80
"""Iterations of L-BFGS at most."""

SMOOTH = 1e-3
"""``ε`` of the smoothed ``|·|``, relative to the largest entry of ``G R`` at the start."""


def _powers(M: np.ndarray, X0: np.ndarray, K: int) -> np.ndarray:
    """``M^k X0`` for ``k = 0..K`` (shape ``(K + 1, *X0.shape)``)."""
    X = np.empty((K + 1, *X0.shape))
    X[0] = X0
    for k in range(1, K + 1):
        np.matmul(M, X[k - 1], out=X[k])
    return X


def radius_objective(M: np.ndarray, GR: np.ndarray, K: int = HORIZON) -> float:
    """``J = mean((I - |M^K|)⁻¹ Σ_{k<K} |M^k G R| 1)``, a bound on the mean of ``ρ∞`` (module
    docstring); ``inf`` when ``|M^K|`` is not a contraction."""
    n = M.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        X = _powers(M, np.hstack([GR, np.eye(n)]), K)
    s = np.abs(X[:K, :, : GR.shape[1]]).sum(axis=(0, 2))
    return _bound(np.abs(X[K, :, GR.shape[1] :]), s)[0]


def _bound(N: np.ndarray, s: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """``(mean v, v, λ)`` with ``v = (I - N)⁻¹ s``, ``λ = (I - N)⁻ᵀ 1 / n``; ``inf`` unless
    ``N >= 0`` has spectral radius < 1 (then ``(I - N)⁻¹ >= 0`` and ``v`` bounds
    ``Σ_k |M^k G R| 1``: ``ρ∞ <= s + N ρ∞``)."""
    n = N.shape[0]
    if not np.all(np.isfinite(N)) or not np.all(np.isfinite(s)) or spectral_radius(N) >= 1.0:
        return np.inf, s, s
    IN = np.eye(n) - N
    v = np.linalg.solve(IN, s)
    lam = np.linalg.solve(IN.T, np.full(n, 1.0 / n))
    if not (np.all(v >= 0.0) and np.all(lam >= 0.0)):
        return np.inf, v, lam
    return float(v.mean()), v, lam


def _smoothed(
    x: np.ndarray,
    A: np.ndarray,
    C: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    r: np.ndarray,
    K: int,
    eps: float,
) -> tuple[float, np.ndarray]:
    """Smoothed ``J`` and its gradient with respect to ``L`` (flattened): powers of ``M``
    applied to ``[G R, I]``; the adjoint recursion of the module docstring with the weights
    ``λ`` on the rows of the sum and ``λ vᵀ`` on ``|M^K|``."""
    n, ny = C.shape[1], C.shape[0]
    nd = E.shape[1]
    L = x.reshape(n, ny)
    M = A - L @ C
    GR = (E - L @ F) * r
    # a trial gain far from Schur overflows: J = inf (returned as 1e300) for the line search
    with np.errstate(over="ignore", invalid="ignore"):
        X = _powers(M, np.hstack([GR, np.eye(n)]), K)
        Xd = X[:K, :, :nd]
        Rt = np.sqrt(Xd * Xd + eps * eps)
        s = (Rt - eps).sum(axis=(0, 2))
        NK = X[K, :, nd:]
        RN = np.sqrt(NK * NK + eps * eps)
    if not (np.all(np.isfinite(Rt)) and np.all(np.isfinite(RN))):
        return 1e300, np.zeros_like(x)
    f, v, lam = _bound(RN - eps, s)
    if not np.isfinite(f):
        return 1e300, np.zeros_like(x)
    S = np.zeros_like(X)
    S[:K, :, :nd] = lam[None, :, None] * Xd / Rt
    S[K, :, nd:] = np.outer(lam, v) * NK / RN
    W = np.zeros((n, nd + n))
    gM = np.zeros((n, n))
    for m in range(K - 1, -1, -1):
        W = S[m + 1] + M.T @ W
        gM += W @ X[m].T
    gGR = (S[0] + M.T @ W)[:, :nd]
    gL = -gM @ C.T - (gGR * r) @ F.T
    return f, gL.ravel()


def radius_gain(
    A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, r: np.ndarray
) -> tuple[np.ndarray, float]:
    """Gain minimising the steady-state box ``ρ∞`` (module docstring); returns ``(L, J)``
    with ``J`` the certified objective (exact, ``2K`` terms). Raises :class:`DesignError` when
    no Kalman-type start is found (``(A, C)`` not detectable)."""
    from scipy.optimize import minimize

    n, ny = C.shape[1], C.shape[0]
    r = np.asarray(r, dtype=float)
    if not E.shape[1] or not np.any(r):  # no disturbance: ρ∞ = 0 for every gain; the
        # Kalman gain with Q = I makes the prior box shrink at a rate set by the Riccati weight
        return kalman_gain(A, C, np.eye(n), np.zeros((ny, n)), 1.0), 0.0
    K = HORIZON
    best: tuple[float, np.ndarray] | None = None
    errors = []
    for q in WEIGHTS:
        try:
            L = kalman_gain(A, C, E, F, q)
        except DesignError as exc:
            errors.append(str(exc))
            continue
        J = radius_objective(A - L @ C, (E - L @ F) * r, K)
        if best is None or J < best[0]:
            best = (J, L)
    if best is None:
        raise DesignError(
            "radius_gain: no Kalman-type starting gain makes A - LC Schur stable; (A, C) may "
            f"not be detectable ({errors[0] if errors else ''}): pass an explicit gain L=..."
        )
    J0, L0 = best
    evals = int(WORK / max(1.0, 2.0 * K * n * n * (n + E.shape[1])))
    if evals < 10 or not np.isfinite(J0):
        return L0, J0
    eps = SMOOTH * max(float(np.abs((E - L0 @ F) * r).max()), 1e-300)
    res = minimize(
        _smoothed,
        L0.ravel(),
        args=(A, C, E, F, r, K, eps),
        jac=True,
        method="L-BFGS-B",
        options={"maxiter": MAX_ITER, "maxfun": min(evals, 2 * MAX_ITER)},
    )
    L1 = np.asarray(res.x, dtype=float).reshape(n, ny)
    if not np.all(np.isfinite(L1)) or not spectral_radius(A - L1 @ C) < 1.0:
        return L0, J0
    J1 = radius_objective(A - L1 @ C, (E - L1 @ F) * r, K)
    return (L1, J1) if J1 < J0 else (L0, J0)
