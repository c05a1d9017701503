"""Default targets: a diagonal target for time-invariant systems, block targets for
time-varying systems ([Dinh2024, Propositions 1, 3-4]).

How the default target is chosen (:func:`default_target`). The width of the bounds of observer
(3) does not depend on the data: in ``z`` it obeys ``w+ = A_z w + |T E - B_z F| Δd`` exactly,
so its steady state, mapped back by (3.c-d), is the closed form
(:func:`~ivobs.design.sylvester.equation.predicted_width`)::

    w_x = |T⁻¹| (I - A_z)⁻¹ |T E - B_z F| Δd        (continuous time: (-A_z)⁻¹)

``A_z = diag(a)`` is taken diagonal (nonnegative ``a ∈ [0, 0.95]`` in DT, ``a ∈ [-20 s, a_max]``
in CT with ``s = max(1, ρ(A))`` and ``a_max`` from the flow rule of :mod:`.flow`), which makes
``(A_z, B_z)`` controllable as soon as the rows of
``B_z`` belonging to one eigenvalue are independent, and each row of ``T`` explicit:
``t_i = b_i C (A - a_i I)⁻¹``. A few candidates (eigenvalue spreads × ``B_z`` patterns: output
directions cycled, least-noisy output directions first, a seeded random draw) are scored by
``log Σ w_x``; the best is refined by L-BFGS-B with the analytic gradient of that score
(``tune=True``), and kept only if it still passes every check. Without disturbances the score is
the transient ``|T⁻¹| (I - A_z)⁻¹ |T| w0`` (the summed width decay from the prior box).
Rows of ``(T, B_z)`` are finally scaled to unit norm of ``T``'s rows (the bounds do not change,
``cond(T)`` improves).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import block_diag

from ..._validate import as_matrix
from ...errors import DesignError
from ...linalg import is_controllable, is_observable, observability_indices, spectral_radius
from .equation import solve_transform
from .flow import CT_RANGE, flow_cap

__all__ = ["DT_RANGE", "TargetChoice", "block_target", "default_target"]

DT_RANGE = (0.0, 0.95)
"""Range of the diagonal of the default discrete-time ``A_z``."""

_RELAXED_COND = 1e13


@dataclass(frozen=True)
class TargetChoice:
    """The default target found by :func:`default_target` and how it scored."""

    A_z: np.ndarray
    B_z: np.ndarray
    T: np.ndarray
    score: float
    tuned: bool


# ------------------------------------------------------------------------------------------
# Default target for time-invariant systems
# ------------------------------------------------------------------------------------------
def _rows(a: np.ndarray, Bz: np.ndarray, A: np.ndarray, C: np.ndarray) -> tuple[Any, ...]:
    """``T`` for diagonal ``A_z = diag(a)``: ``t_i = b_i C (A - a_i I)⁻¹``, and the pieces."""
    n = A.shape[0]
    R = np.linalg.inv(A[None, :, :] - a[:, None, None] * np.eye(n)[None])
    CR = np.einsum("pj,ijk->ipk", C, R)
    T = np.einsum("ip,ipk->ik", Bz, CR)
    return T, R, CR


def _score(
    v: np.ndarray,
    A: np.ndarray,
    C: np.ndarray,
    Ex: np.ndarray,
    Fx: np.ndarray,
    delta: np.ndarray,
    continuous: bool,
    grad: bool = True,
) -> tuple[float, np.ndarray]:
    """``log Σ w_x`` and its gradient in ``v = (a, vec B_z)`` (see the module docstring)."""
    n, p = A.shape[0], C.shape[0]
    a, Bz = v[:n], v[n:].reshape(n, p)
    bad = (1e300, np.zeros_like(v))
    with np.errstate(all="ignore"):
        try:
            T, R, CR = _rows(a, Bz, A, C)
            P = np.linalg.inv(T)
        except np.linalg.LinAlgError:
            return bad
        G = T @ Ex - Bz @ Fx
        Dg = 1.0 / (-a if continuous else 1.0 - a)
        # |G| smoothed for the gradient: exact zeros of G (noise cancelled by B_z) are kinks
        eps = 1e-6 * (np.max(np.abs(G)) if grad else 0.0)
        absG = np.sqrt(G * G + eps * eps) if grad else np.abs(G)
        g = absG @ delta
        c = Dg * g
        arow = np.abs(P).sum(axis=0)
        s = float(arow @ c)
        if not np.isfinite(s) or s <= 0:
            return bad
        if not grad:
            return float(np.log(s)), np.zeros_like(v)
        gT = -P.T @ (np.sign(P) * c[None, :]) @ P.T
        H = (arow * Dg)[:, None] * (G / absG) * delta[None, :]
        gT += H @ Ex.T
        gB = -H @ Fx.T + np.einsum("ik,ipk->ip", gT, CR)
        ga = arow * g * Dg**2 + np.einsum("ip,ipl,il->i", Bz, np.einsum("ipk,ikl->ipl", CR, R), gT)
    out = np.concatenate([ga, gB.ravel()]) / s
    if not np.all(np.isfinite(out)):
        return bad
    return float(np.log(s)), out


def _b_patterns(C: np.ndarray, F: np.ndarray, delta: np.ndarray, n: int) -> list[np.ndarray]:
    """Candidate ``B_z``: output directions cycled; least-noisy directions first; random."""
    p = C.shape[0]
    pats = [np.eye(p)[np.arange(n) % p]]
    if p > 1:
        if F.size and np.any(F):
            U, _, _ = np.linalg.svd(F * delta[None, :], full_matrices=True)
            quiet = U[:, ::-1].T  # ascending noise
            pats.append(quiet[np.arange(n) % p])
        pats.append(np.random.default_rng(0).normal(size=(n, p)))
    return pats


def _spreads(n: int, continuous: bool, scale: float, cap: float) -> list[np.ndarray]:
    """Candidate eigenvalues; in CT shifted left so that the slowest is at most ``cap``."""
    grids = (
        [(0.25, 0.75), (0.5, 1.5), (1.0, 3.0), (2.0, 6.0), (4.0, 12.0)]
        if continuous
        else [(0.02, 0.2), (0.05, 0.4), (0.1, 0.6), (0.3, 0.8), (0.0, 0.9)]
    )
    out = []
    for lo, hi in grids:
        a = np.linspace(lo, hi, n) if n > 1 else np.array([0.5 * (lo + hi)])
        if continuous:
            a = -scale * a
            a = a + min(0.0, cap - float(a.max()))
        out.append(a)
    return out


def _acceptable(
    a: np.ndarray,
    Bz: np.ndarray,
    A: np.ndarray,
    C: np.ndarray,
    continuous: bool,
    max_cond: float,
    sep: float,
) -> np.ndarray | None:
    """``T`` for the diagonal target if every condition of Proposition 1 holds (and, in CT, the
    flow rule ``max a < min Re λ(A)``), else None."""
    eig = np.linalg.eigvals(A)
    if np.min(np.abs(a[:, None] - eig[None, :])) < sep:
        return None
    if (continuous and np.any(a >= 0)) or (not continuous and (np.any(a < 0) or np.any(a >= 1))):
        return None
    if continuous and not float(np.max(a)) < float(np.min(eig.real)) - sep:
        return None
    if not is_controllable(np.diag(a), Bz):
        return None
    try:
        T = solve_transform(A, C, np.diag(a), Bz)
    except DesignError:
        return None
    norms = np.linalg.norm(T, axis=1)
    if np.any(norms == 0) or np.linalg.cond(T / norms[:, None]) > max_cond:
        return None  # judged on unit rows: the final scaling of (T, B_z)
    return T


def default_target(
    A: Any,
    C: Any,
    E: Any,
    F: Any,
    delta: Any,
    *,
    continuous: bool,
    w0: Any = None,
    tune: bool = True,
    max_cond: float = 1e7,
) -> TargetChoice:
    """A diagonal target ``(A_z, B_z)`` and ``T`` for a time-invariant pair ``(A, C)``.

    See the module docstring for the candidates, the score (predicted steady-state width), the
    gradient refinement and, in continuous time, the flow rule every eigenvalue of ``A_z`` obeys
    (``max a <= min Re λ(A) - 0.05 max(1, ρ(A))``). Raises :class:`DesignError` when no
    candidate gives an invertible ``T`` with ``cond(T) <= max_cond`` (then ``(A, C)`` is
    practically unobservable).
    """
    A = as_matrix("A", A)
    C = as_matrix("C", C, cols=A.shape[0], vector="row")
    n, p = A.shape[0], C.shape[0]
    if not is_observable(A, C):
        raise DesignError(
            "pair (A, C) is not observable: no invertible Sylvester transformation "
            "T exists ([Dinh2024, Assumption 1 (I)]); the kkl method needs observability"
        )
    E = np.asarray(E, dtype=float).reshape(n, -1)
    F = np.asarray(F, dtype=float).reshape(p, -1)
    delta = np.asarray(delta, dtype=float).ravel()
    if delta.size and np.any(delta > 0):
        Ex, Fx, wt = E, F, delta
    else:  # no disturbance: score the transient from the prior box instead
        Ex, Fx = np.eye(n), np.zeros((p, n))
        wt = np.ones(n) if w0 is None else np.maximum(np.asarray(w0, dtype=float).ravel(), 1e-12)
    scale = max(1.0, spectral_radius(A)) if continuous else 1.0
    sep = 1e-6 * scale
    cap = flow_cap(A) if continuous else DT_RANGE[1]  # CT: the flow rule with margin
    # candidates with cond(T) <= max_cond; ill-conditioned ones only serve as starting points
    best: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
    start: tuple[float, np.ndarray, np.ndarray, np.ndarray] | None = None
    least_cond = np.inf
    for a in _spreads(n, continuous, scale, cap):
        for Bz in _b_patterns(C, F, delta if delta.size else np.zeros(0), n):
            T = _acceptable(a, Bz, A, C, continuous, _RELAXED_COND, sep)
            if T is None:
                continue
            s, _ = _score(np.concatenate([a, Bz.ravel()]), A, C, Ex, Fx, wt, continuous, False)
            cond = np.linalg.cond(T / np.linalg.norm(T, axis=1)[:, None])
            least_cond = min(least_cond, cond)
            if start is None or s < start[0]:
                start = (s, a, Bz, T)
            if cond <= max_cond and (best is None or s < best[0]):
                best = (s, a, Bz, T)
    tuned = False
    if tune and start is not None:
        from scipy.optimize import minimize

        lo, hi = (CT_RANGE[0], cap / scale) if continuous else DT_RANGE
        s0 = best if best is not None else start
        v0 = np.concatenate([s0[1] / scale, s0[2].ravel()])
        bounds = [(lo, hi)] * n + [(None, None)] * (n * p)

        def fun(v: np.ndarray) -> tuple[float, np.ndarray]:  # eigenvalues in units of `scale`
            w = v.copy()
            w[:n] *= scale
            f, g = _score(w, A, C, Ex, Fx, wt, continuous)
            g[:n] *= scale
            return f, g

        with np.errstate(all="ignore"):
            res = minimize(
                fun, v0, jac=True, method="L-BFGS-B", bounds=bounds, options={"maxiter": 150}
            )
        res.x[:n] *= scale
        a, Bz = res.x[:n], res.x[n:].reshape(n, p)
        T = _acceptable(a, Bz, A, C, continuous, max_cond, sep)
        if T is not None:
            s, _ = _score(res.x, A, C, Ex, Fx, wt, continuous, False)
            if best is None or s < best[0] - 1e-9:
                best, tuned = (s, a.copy(), Bz.copy(), T), True
    if best is None:
        raise DesignError(
            "kkl: no diagonal target (A_z, B_z) gave an invertible Sylvester solution T with "
            f"cond(T) <= max_cond = {max_cond:.0e} (best cond(T) = {least_cond:.2e}); the pair "
            "(A, C) is close to unobservable. Pass A_z and B_z explicitly, or raise max_cond"
        )
    s, a, Bz, T = best
    norms = np.linalg.norm(T, axis=1)
    T, Bz = T / norms[:, None], Bz / norms[:, None]  # diagonal A_z commutes with the scaling
    return TargetChoice(A_z=np.diag(a), B_z=Bz, T=T, score=float(np.exp(s)), tuned=tuned)


# ------------------------------------------------------------------------------------------
# Block targets for time-varying systems ([Dinh2024, Propositions 3-4, eqs. (11.a), (16.a)])
# ------------------------------------------------------------------------------------------
def block_target(
    A_0: Any, C_0: Any, *, continuous: bool
) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """``(Ã, B̃)`` of (16.a) (DT) or (11.a) (CT), before the factor ``gamma`` or ``ell``.

    ``Ã = diag(Ã_1, ..., Ã_ny)``, ``B̃ = diag(B̃_1, ..., B̃_ny)`` with one block of size ``m_i`` per
    output, ``n_z = Σ m_i``. ``m_i`` are the observability indices of the pair frozen at the first
    step, ``(A(0), C(0))`` (when that pair is not observable, ``m_i = nx`` for every output, which
    is always enough). Blocks: DT ``Ã_i = diag(0.1, 0.2, ..., 0.1 m_i)`` (``linspace(0.05, 0.95)``
    for ``m_i > 9``), as in [Dinh2024, Example 3]; CT ``Ã_i = diag(-1, -2, ..., -m_i)``, as in
    [Dinh2024, Example 2]; ``B̃_i = (1, ..., 1)``. Each block is controllable (distinct
    eigenvalues, nonzero ``B̃_i``).
    """
    A_0 = as_matrix("A(0)", A_0)
    C_0 = as_matrix("C(0)", C_0, cols=A_0.shape[0], vector="row")
    n, p = A_0.shape[0], C_0.shape[0]
    m = observability_indices(A_0, C_0)
    if sum(m) < n:
        m = [n] * p
    diag = []
    for mi in m:
        steps = np.arange(1.0, mi + 1)
        diag.append(
            -steps if continuous else 0.1 * steps if mi <= 9 else np.linspace(0.05, 0.95, mi)
        )
    return np.diag(np.concatenate(diag)), block_diag(*[np.ones((mi, 1)) for mi in m]), m
