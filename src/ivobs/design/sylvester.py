"""Sylvester (KKL) transformations for interval observers (paper 004, Dinh & Tran).

A target pair ``(A_z, B_z)`` — Schur and nonnegative in discrete time, Hurwitz and Metzler in
continuous time, ``(A_z, B_z)`` controllable, ``eig(A_z)`` disjoint from ``eig(A)`` — and the
solution ``T`` of the Sylvester equation (004, eq. 4, ``F = A``, ``H = C``, paper's ``(A, B)`` =
``(A_z, B_z)``)::

    T A = A_z T + B_z C

turn ``z = T x`` into a cooperative system ``z+ = A_z z + B_z y + ...`` for which interval bounds
are immediate (Proposition 1). Nothing here loops over time.

How the default target is chosen (:func:`default_target`). The width of the bounds of observer
(3) does not depend on the data: in ``z`` it obeys ``w+ = A_z w + |T E - B_z F| Δd`` exactly,
so its steady state, mapped back by (3.c-d), is the closed form (:func:`predicted_width`)::

    w_x = |T⁻¹| (I - A_z)⁻¹ |T E - B_z F| Δd        (continuous time: (-A_z)⁻¹)

``A_z = diag(a)`` is taken diagonal (nonnegative ``a ∈ [0, 0.95]`` in DT, ``a ∈ [-20 s, a_max]``
in CT with ``s = max(1, ρ(A))`` and ``a_max`` from the flow rule below), which makes
``(A_z, B_z)`` controllable as soon as the rows of
``B_z`` belonging to one eigenvalue are independent, and each row of ``T`` explicit:
``t_i = b_i C (A - a_i I)⁻¹``. A few candidates (eigenvalue spreads × ``B_z`` patterns: output
directions cycled, least-noisy output directions first, a seeded random draw) are scored by
``log Σ w_x``; the best is refined by L-BFGS-B with the analytic gradient of that score
(``tune=True``), and kept only if it still passes every check. Without disturbances the score is
the transient ``|T⁻¹| (I - A_z)⁻¹ |T| w0`` (the summed width decay from the prior box).
Rows of ``(T, B_z)`` are finally scaled to unit norm of ``T``'s rows (the bounds do not change,
``cond(T)`` improves).

The flow rule (continuous time). With sampled measurements the observer carries ``T(t)``, which
between samples follows ``dT/dt = A_z T - T A`` (the sampled-data form of (10.b), see
:mod:`ivobs.estimators.kkl`). That flow is the linear map ``T ↦ A_z T - T A`` whose eigenvalues
are ``λ_i(A_z) - λ_j(A)``, so it is stable iff (:func:`flow_gap`, :func:`check_flow`)::

    max Re λ(A_z) < min Re λ(A)          (every target mode faster than every plant mode)

Otherwise any deviation of ``T`` from its periodic solution (rounding, a missing sample, an
irregular grid) grows like ``exp((max Re λ(A_z) - min Re λ(A)) t)``, the rows of ``T`` align
and ``T`` stops being invertible. The default target keeps a margin: ``a_max = min(-0.05 s,
min Re λ(A) - 0.05 s)`` (:data:`FLOW_MARGIN`), so deviations decay at least like
``exp(-0.05 s t)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.linalg import solve_sylvester

from .._validate import as_matrix
from ..errors import DesignError, IvobsError
from ..linalg import (
    is_controllable,
    is_hurwitz,
    is_metzler,
    is_nonnegative,
    is_observable,
    is_schur,
    observability_indices,
    spectral_radius,
)

__all__ = [
    "CT_RANGE",
    "DT_RANGE",
    "FLOW_MARGIN",
    "TargetChoice",
    "block_target",
    "check_flow",
    "check_target",
    "condition_number",
    "default_target",
    "flow_cap",
    "flow_gap",
    "predicted_width",
    "solve_transform",
]

DT_RANGE = (0.0, 0.95)
"""Range of the diagonal of the default discrete-time ``A_z``."""

_RELAXED_COND = 1e13

CT_RANGE = (-20.0, -0.05)
"""Range of the diagonal of the default continuous-time ``A_z``, in units of ``max(1, ρ(A))``
(the upper end is lowered further by the flow rule, see :func:`flow_cap`)."""

FLOW_MARGIN = 0.05
"""Margin of the flow rule of the default continuous-time target, in units of ``max(1, ρ(A))``:
``max Re λ(A_z) <= min Re λ(A) - FLOW_MARGIN * max(1, ρ(A))``."""


@dataclass(frozen=True)
class TargetChoice:
    """The default target found by :func:`default_target` and how it scored."""

    A_z: np.ndarray
    B_z: np.ndarray
    T: np.ndarray
    score: float
    candidates: int
    tuned: bool


def condition_number(T: np.ndarray) -> float:
    """``σ_max(T) / σ_min(T)`` (``inf`` when ``T`` is rank deficient)."""
    s = np.linalg.svd(T, compute_uv=False)
    if s.size == 0 or s[-1] <= 0 or not np.all(np.isfinite(s)):
        return float("inf")
    return float(s[0] / s[-1])


def solve_transform(A: Any, C: Any, A_z: Any, B_z: Any) -> np.ndarray:
    """``T`` with ``T A = A_z T + B_z C`` (004 eq. 4), by SciPy's Sylvester solver.

    Written as ``(-A_z) T + T A = B_z C`` for :func:`scipy.linalg.solve_sylvester`
    (Matlab: ``T = sylvester(A_z, -A, -B_z*C)``, Algorithm 1 step 2). Raises
    :class:`DesignError` when the equation is singular (``A_z`` and ``A`` share an eigenvalue) or
    the computed solution does not satisfy it to working accuracy.
    """
    A = as_matrix("A", A)
    A_z = as_matrix("A_z", A_z)
    C = as_matrix("C", C, cols=A.shape[0], vector="row")
    B_z = as_matrix("B_z", B_z, rows=A_z.shape[0], cols=C.shape[0])
    Q = B_z @ C
    ez, ea = np.linalg.eigvals(A_z), np.linalg.eigvals(A)
    gap = float(np.min(np.abs(ez[:, None] - ea[None, :]))) if ez.size and ea.size else np.inf
    if gap <= 1e-10 * (1.0 + np.abs(ez).max() + np.abs(ea).max()):
        raise DesignError(
            f"Sylvester equation T A = A_z T + B_z C (eq. 4) is singular: A_z and A share an "
            f"eigenvalue (distance {gap:.1e}); choose eig(A_z) away from eig(A)"
        )
    with np.errstate(all="ignore"):
        try:
            T = solve_sylvester(-A_z, A, Q)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise DesignError(f"Sylvester equation T A = A_z T + B_z C (eq. 4): {exc}") from None
    if not np.all(np.isfinite(T)):
        raise DesignError(
            "Sylvester equation T A = A_z T + B_z C (eq. 4): non-finite solution; "
            "choose eig(A_z) away from eig(A)"
        )
    res = np.linalg.norm(T @ A - A_z @ T - Q)
    scale = np.linalg.norm(T) * (np.linalg.norm(A) + np.linalg.norm(A_z)) + np.linalg.norm(Q)
    if res > 1e-8 * max(scale, 1e-300):
        raise DesignError(
            f"Sylvester equation T A = A_z T + B_z C (eq. 4) solved with relative residual "
            f"{res / scale:.2e}: eig(A_z) is too close to eig(A); move them apart"
        )
    return T


def flow_gap(A_z: Any, A: Any) -> float:
    """``max Re λ(A_z) - min Re λ(A)``: the spectral abscissa of ``T ↦ A_z T - T A``.

    Negative iff the flow ``dT/dt = A_z T - T A`` of the continuous-time observer is stable (its
    eigenvalues are ``λ_i(A_z) - λ_j(A)``); see the module docstring.
    """
    ez = np.linalg.eigvals(np.asarray(A_z, dtype=float))
    ea = np.linalg.eigvals(np.asarray(A, dtype=float))
    return float(np.max(ez.real) - np.min(ea.real))


def flow_cap(A: Any) -> float:
    """Largest eigenvalue allowed for the default continuous-time target: ``min(-0.05 s,
    min Re λ(A) - 0.05 s)``, ``s = max(1, ρ(A))`` (the flow rule with margin, module docstring)."""
    A = np.asarray(A, dtype=float)
    s = max(1.0, spectral_radius(A))
    slowest_allowed = float(np.min(np.linalg.eigvals(A).real)) - FLOW_MARGIN * s
    return min(CT_RANGE[1] * s, slowest_allowed)


def check_flow(A_z: Any, A: Any, *, who: str = "A_z", frozen: str = "") -> float:
    """Raise :class:`DesignError` unless ``max Re λ(A_z) < min Re λ(A)`` (continuous time).

    The sampled-data observer integrates ``dT/dt = A_z T - T A`` between samples; that flow is
    stable iff this holds (module docstring). ``frozen`` (e.g. ``" at t = 0"``) says where a
    time-varying ``A(t)`` was frozen. Returns the gap ``max Re λ(A_z) - min Re λ(A)``.
    """
    gap = flow_gap(A_z, A)
    ez = np.linalg.eigvals(np.asarray(A_z, dtype=float)).real
    ea = np.linalg.eigvals(np.asarray(A, dtype=float)).real
    s = max(1.0, spectral_radius(A))
    if not gap < -1e-9 * s:
        raise DesignError(
            f"{who}: the flow dT/dt = A_z T - T A{frozen} of the continuous-time observer is "
            f"unstable: max Re eig(A_z) = {ez.max():.4g} is not below min Re eig(A) = "
            f"{ea.min():.4g} (needed: every eigenvalue of A_z faster than every mode of the "
            "plant, else T(t) drifts and loses invertibility during the run); choose eig(A_z) "
            f"< {ea.min():.4g}" + (" (a larger ell)" if frozen else "")
        )
    return gap


def check_target(
    A_z: Any, B_z: Any, continuous: bool, A: Any = None, *, who: str = "A_z"
) -> tuple[np.ndarray, np.ndarray]:
    """Check the conditions of 004 Proposition 1 (LTI) / 3-4 (LTV) on a target pair.

    Discrete time: ``A_z`` nonnegative and Schur; continuous time: Metzler and Hurwitz;
    ``(A_z, B_z)`` controllable; when ``A`` is given (time-invariant systems), no common
    eigenvalue and, in continuous time, the flow rule ``max Re λ(A_z) < min Re λ(A)``
    (:func:`check_flow`). Raises :class:`DesignError` naming the failed condition.
    """
    A_z = as_matrix(who, A_z)
    if A_z.shape[0] != A_z.shape[1]:
        raise IvobsError(f"{who}: expected a square matrix, got shape {A_z.shape}")
    B_z = as_matrix("B_z", B_z, rows=A_z.shape[0])
    if continuous:
        if not is_metzler(A_z):
            raise DesignError(
                f"{who}: must be Metzler (off-diagonal entries >= 0) in continuous "
                "time (004 Proposition 1)"
            )
        if not is_hurwitz(A_z):
            top = float(np.max(np.linalg.eigvals(A_z).real))
            raise DesignError(f"{who}: must be Hurwitz; its spectral abscissa is {top:.4g} >= 0")
    else:
        if not is_nonnegative(A_z):
            raise DesignError(
                f"{who}: must be nonnegative in discrete time (004 Proposition 1); "
                f"smallest entry {A_z.min():.4g}"
            )
        if not is_schur(A_z):
            raise DesignError(
                f"{who}: must be Schur; its spectral radius is {spectral_radius(A_z):.4g} >= 1"
            )
    if not is_controllable(A_z, B_z):
        raise DesignError(
            f"({who}, B_z) is not controllable (004 Proposition 1): give B_z "
            "nonzero rows (independent rows for a repeated eigenvalue)"
        )
    if A is not None:
        ez, ea = np.linalg.eigvals(A_z), np.linalg.eigvals(np.asarray(A, dtype=float))
        gap = float(np.min(np.abs(ez[:, None] - ea[None, :])))
        if gap < 1e-8 * max(1.0, spectral_radius(A)):
            raise DesignError(
                f"{who}: shares an eigenvalue with A (distance {gap:.2e}); "
                "Proposition 1 needs eig(A_z) disjoint from eig(A)"
            )
        if continuous:
            check_flow(A_z, A, who=who)
    return A_z, B_z


def predicted_width(
    T: np.ndarray,
    A_z: np.ndarray,
    B_z: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    delta: np.ndarray,
    continuous: bool,
) -> np.ndarray:
    """Steady-state width of the bounds of observer (3) for disturbance widths ``delta``.

    ``|T⁻¹| (I - A_z)⁻¹ |T E - B_z F| Δd`` (DT), ``(-A_z)⁻¹`` in CT: the fixed point of the
    width recursion of (3.a) mapped by (3.c-d); it is reached whatever the data.
    """
    G = T @ E - B_z @ F
    M = -A_z if continuous else np.eye(A_z.shape[0]) - A_z
    wz = np.linalg.solve(M, np.abs(G) @ np.asarray(delta, dtype=float))
    return np.abs(np.linalg.pinv(T)) @ wz


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


def _spreads(n: int, continuous: bool, scale: float, cap: float = 0.0) -> list[np.ndarray]:
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
    if np.any(norms == 0) or condition_number(T / norms[:, None]) > max_cond:
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
            "T exists (004 Assumption 1 (I)); the kkl method needs observability"
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
    count, least_cond = 0, np.inf
    for a in _spreads(n, continuous, scale, cap):
        for Bz in _b_patterns(C, F, delta if delta.size else np.zeros(0), n):
            T = _acceptable(a, Bz, A, C, continuous, _RELAXED_COND, sep)
            if T is None:
                continue
            s, _ = _score(np.concatenate([a, Bz.ravel()]), A, C, Ex, Fx, wt, continuous, False)
            cond = condition_number(T / np.linalg.norm(T, axis=1)[:, None])
            least_cond = min(least_cond, cond)
            if start is None or s < start[0]:
                start = (s, a, Bz, T)
            if cond <= max_cond:
                count += 1
                if best is None or s < best[0]:
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
                count += 1
    if best is None:
        raise DesignError(
            "kkl: no diagonal target (A_z, B_z) gave an invertible Sylvester solution T with "
            f"cond(T) <= max_cond = {max_cond:.0e} (best cond(T) = {least_cond:.2e}); the pair "
            "(A, C) is close to unobservable. Pass A_z and B_z explicitly, or raise max_cond"
        )
    s, a, Bz, T = best
    norms = np.linalg.norm(T, axis=1)
    T, Bz = T / norms[:, None], Bz / norms[:, None]  # diagonal A_z commutes with the scaling
    return TargetChoice(
        A_z=np.diag(a), B_z=Bz, T=T, score=float(np.exp(s)), candidates=count, tuned=tuned
    )


# ------------------------------------------------------------------------------------------
# Block targets for time-varying systems (004 Propositions 3-4, eqs. 11.a and 16.a)
# ------------------------------------------------------------------------------------------
def block_target(
    A0: Any, C0: Any, *, continuous: bool, indices: Any = None
) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """``(Ã, B̃)`` of (16.a) (DT) or (11.a) (CT), before the factor ``gamma`` or ``ell``.

    ``Ã = diag(Ã_1, ..., Ã_ny)``, ``B̃ = diag(B̃_1, ..., B̃_ny)`` with one block of size ``m_i`` per
    output, ``n_z = Σ m_i``. ``m_i`` are the observability indices of the pair frozen at the first
    step, ``(A(0), C(0))`` (when that pair is not observable, ``m_i = nx`` for every output, which
    is always enough). Blocks: DT ``Ã_i = diag(0.1, 0.2, ..., 0.1 m_i)`` (``linspace(0.05, 0.95)``
    for ``m_i > 9``), as in Example 3; CT ``Ã_i = diag(-1, -2, ..., -m_i)``, as in Example 2;
    ``B̃_i = (1, ..., 1)``. Each block is controllable (distinct eigenvalues, nonzero ``B̃_i``).
    """
    A0 = as_matrix("A(0)", A0)
    C0 = as_matrix("C(0)", C0, cols=A0.shape[0], vector="row")
    n, p = A0.shape[0], C0.shape[0]
    if indices is None:
        m = observability_indices(A0, C0)
        if sum(m) < n:
            m = [n] * p
    else:
        m = [int(v) for v in np.ravel(indices)]
    nz = sum(m)
    At = np.zeros((nz, nz))
    Bt = np.zeros((nz, p))
    r = 0
    for i, mi in enumerate(m):
        if continuous:
            diag = -np.arange(1.0, mi + 1)
        else:
            diag = 0.1 * np.arange(1.0, mi + 1) if mi <= 9 else np.linspace(0.05, 0.95, mi)
        At[r : r + mi, r : r + mi] = np.diag(diag)
        Bt[r : r + mi, i] = 1.0
        r += mi
    return At, Bt, m
