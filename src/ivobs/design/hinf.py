"""H∞ observer gain [Tang2019, Theorem 1, problem (20)]: by Riccati equations (default) or by
the LMI; and the gain of the Luenberger-type estimators (:func:`designed_gain`).

``method="riccati"`` (default, :func:`ivobs.design.riccati.hinf_riccati_gain`): bisection on
``γ`` with the H∞ Riccati equation, ``O(nx³)`` per ``γ``, certified by the bounded-real lemma
(a ``P`` satisfying (16) strictly, checked). ``method="lmi"``: problem (20) as the paper states
it, solved by CVXPY/Clarabel (below; refused above 200 states). Both reach the same ``γ`` on the
paper's examples (docs/gains.md). An answer the solver reports as inaccurate is kept only when
its gain passes the bounded-real certificate (:func:`ivobs.design.riccati.bounded_real_certificate`)
at the solver's ``γ`` or a somewhat larger one, which is then the ``γ`` returned.

For the Luenberger observer ``x̂+ = A x̂ + B u + L (y - C x̂ - D u)`` the estimation error
``e = x - x̂`` of the model ``x+ = A x + B u + E d``, ``y = C x + D u + F d`` obeys

    e+ = (A - L C) e + (E - L F) d = A_e e + B_e d                        [Tang2019, eq. (15)]

(ivobs' one correlated disturbance ``d``; [Tang2019]'s ``d = [w; v]``, ``E = [E 0]``,
``F = [0 F]`` gives ``B_e = [E  -LF]``, its eq. (15)). [Tang2019, Theorem 1]: if ``P ≻ 0`` and
``Y`` satisfy

    [ I - P           *         * ]
    [ 0          -γ² I_nd       * ]  ≺ 0                                [Tang2019, eq. (16)]
    [ PA - YC     PE - YF      -P ]

then with ``L = P⁻¹ Y`` the error system is stable and ``‖(zI - A_e)⁻¹ B_e‖∞ < γ`` (the
``(2, 3)`` block ``PE - YF = P B_e`` is (16)'s ``[PE  -YF]`` in the paper's split form). The gain
minimises ``γ²`` subject to (16) (problem (20)). The strict inequality is imposed with a small
margin (``≼ -margin I``); the returned gain is then checked: ``A - LC`` must be Schur.

Without a disturbance (``nd = 0``) ``γ`` plays no role; the LMI then only asks
``V(e+) - V(e) < -|e|²`` for ``V = eᵀPe``, and ``trace(P)`` (which bounds ``Σ_k |e_k|²`` from
``e_0``) is minimised instead; ``gamma`` is returned as 0.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from .._validate import as_matrix
from ..errors import DesignError, IvobsError
from ..linalg import spectral_radius
from ._lmi import check_size, solve, sym
from .balance import state_scaling

__all__ = ["GAINS", "DesignedGain", "check_gain", "designed_gain", "hinf_gain"]

GAINS = ("radius", "hinf", "hinf-lmi")
"""Designs of :func:`designed_gain`: ``"radius"`` (default; :mod:`ivobs.design.radius`), the H∞
gain by Riccati equations, the H∞ gain by the LMI; the default tries them in this order (the
radius gain is the tightest for the box, the LMI the most expensive)."""

MARGIN = 1e-8
"""Default margin of the strict LMI (16): the block matrix is required ``≼ -MARGIN I``."""


def hinf_gain(
    A: Any, C: Any, E: Any, F: Any, *, method: str = "riccati"
) -> tuple[np.ndarray, float, np.ndarray]:
    """Observer gain minimising the H∞ norm from ``d`` to ``e`` [Tang2019, Theorem 1,
    problem (20)].

    Parameters
    ----------
    A : (nx, nx), C : (ny, nx), E : (nx, nd), F : (ny, nd)
        The model ``x+ = A x + B u + E d``, ``y = C x + D u + F d`` (``B``, ``D`` play no role).
    method : ``"riccati"`` (default) or ``"lmi"`` (module docstring)

    Returns
    -------
    L : (nx, ny) gain ``P⁻¹ Y``
    gamma : the attained ``γ`` (``‖(zI - (A - LC))⁻¹ (E - LF)‖∞ < γ``)
    P : (nx, nx) the Lyapunov matrix (``P ≻ I``)

    Raises
    ------
    DesignError
        The LMI has no solution (e.g. ``(A, C)`` not detectable), the solver is inaccurate, or
        the extracted ``A - LC`` is not Schur (the message gives its spectral radius).
    """
    A = as_matrix("A", A)
    nx = A.shape[0]
    if A.shape != (nx, nx):
        raise DesignError(f"A: expected a square matrix, got shape {A.shape}")
    C = as_matrix("C", C, None, nx, vector="row")
    ny = C.shape[0]
    E = as_matrix("E", E, nx, None)
    nd = E.shape[1]
    F = as_matrix("F", F, ny, nd, vector="row")
    if method == "riccati":
        from .riccati import hinf_riccati_gain

        return hinf_riccati_gain(A, C, E, F)
    if method != "lmi":
        raise IvobsError(f"method: expected 'riccati' or 'lmi', got {method!r}")
    return _hinf_lmi(A, C, E, F)


def _hinf_lmi(
    A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray
) -> tuple[np.ndarray, float, np.ndarray]:
    """Problem (20) by CVXPY (the LMI (16), balanced coordinates)."""
    import cvxpy as cp

    nx, ny, nd = A.shape[0], C.shape[0], E.shape[1]
    check_size(nx, "hinf_gain ([Tang2019] LMI (16))")

    # balanced coordinates x = D x̃ (ivobs.design.balance): the congruence diag(D, I, D) maps
    # (16) for (P, Y) onto the same LMI for P̃ = DPD, Ỹ = DY, Ã = D⁻¹AD, C̃ = CD, Ẽ = D⁻¹E with
    # D² in place of I: the same problem (same γ, same gain L = P⁻¹Y = D P̃⁻¹Ỹ), better scaled
    dv = state_scaling(A, C, E, F)
    At, Ct, Et = A * dv[None, :] / dv[:, None], C * dv[None, :], E / dv[:, None]
    P = cp.Variable((nx, nx), symmetric=True)
    Y = cp.Variable((nx, ny))
    g = cp.Variable(nonneg=True)  # γ²
    W = np.diag(dv**2)
    blocks = [[W - P, np.zeros((nx, nd)), (P @ At - Y @ Ct).T]]
    blocks.append([np.zeros((nd, nx)), -g * np.eye(nd), (P @ Et - Y @ F).T])
    blocks.append([P @ At - Y @ Ct, P @ Et - Y @ F, -P])
    if nd == 0:
        blocks = [
            [b for j, b in enumerate(row) if j != 1] for i, row in enumerate(blocks) if i != 1
        ]
    # cvxpy re-exports its (unannotated) atoms implicitly, which strict typing does not see
    lmi = sym(cp.bmat(blocks))  # type: ignore[attr-defined]
    Dm = np.concatenate([dv, np.ones(nd), dv])  # (the middle block is empty when nd = 0)
    cons = [lmi << -MARGIN * np.diag(Dm**2)]
    objective = cp.Minimize(g) if nd else cp.Minimize(cp.trace(P / dv[:, None] / dv[None, :]))  # type: ignore[attr-defined]

    def extract() -> tuple[np.ndarray, float, np.ndarray]:
        Pt = np.asarray(P.value, dtype=float)
        Pt = 0.5 * (Pt + Pt.T)
        L = dv[:, None] * np.linalg.solve(Pt, np.asarray(Y.value, dtype=float))
        gamma = float(np.sqrt(max(float(np.asarray(g.value, dtype=float)), 0.0))) if nd else 0.0
        return L, gamma, Pt / dv[:, None] / dv[None, :]

    proven: list[tuple[np.ndarray, float, np.ndarray]] = []

    def certify() -> bool:
        """An inaccurate answer is kept when its gain passes the bounded-real certificate (the
        LMI (16) proven on the numbers) at its γ or a larger one (:data:`~ivobs.design.riccati.
        BACK_OFF`); that γ is returned."""
        from .riccati import BACK_OFF, bounded_real_certificate

        try:
            L, gamma, _ = extract()
        except np.linalg.LinAlgError:
            return False
        if not nd or not spectral_radius(A - L @ C) < 1.0:
            return False
        for factor in (1.0001, *BACK_OFF):
            Pc = bounded_real_certificate(A - L @ C, E - L @ F, gamma * factor)
            if Pc is not None:
                proven.append((L, gamma * factor, Pc))
                return True
        return False

    solve(cp.Problem(objective, cons), "hinf_gain: problem (20) of [Tang2019] (LMI (16))", certify)
    if proven:
        return proven[0]
    L, gamma, Pv = extract()
    check_gain(A, C, L, "hinf_gain: the solver's gain L = P⁻¹Y")
    return L, gamma, Pv


def check_gain(A: np.ndarray, C: np.ndarray, L: np.ndarray, who: str) -> float:
    """Return the spectral radius of ``A - LC``; raise :class:`DesignError` unless ``< 1``."""
    rho = spectral_radius(A - L @ C)
    if not rho < 1.0:
        raise DesignError(
            f"{who}: A - LC is not Schur stable (spectral radius {rho:.6g} >= 1); the error "
            "e+ = (A - LC) e + (E - LF) d would not stay bounded. Pass a stabilising gain, or "
            "omit L to design the H∞ gain of [Tang2019, Theorem 1]"
        )
    return rho


class DesignedGain(NamedTuple):
    """A gain of :func:`designed_gain`: ``L``; ``gamma`` and ``P`` (the H∞ bound and its
    certificate, None for the other designs); ``rho``, the spectral radius of ``A - LC``;
    ``gain``, the design that produced it (``"user"`` for ``L=``); ``fallback``: None when it is
    the one asked for (or the default's first choice), else what failed before it."""

    L: np.ndarray
    gamma: float | None
    P: np.ndarray | None
    rho: float
    gain: str
    fallback: str | None


def designed_gain(sys: Any, L: Any, who: str, gain: str | None = None) -> DesignedGain:
    """The gain of a Luenberger-type estimator: the user's ``L`` (checked) or the design
    ``gain`` (:data:`GAINS`), cached per system (:mod:`ivobs.design.cache`). ``sys`` is a
    time-invariant :class:`~ivobs.LinearSystem`.

    Default (``gain=None``): the designs of :data:`GAINS` in that order, cheapest and tightest
    first, the first that passes its certificate (``fallback`` says what failed before it).
    An explicit ``gain`` that fails raises :class:`DesignError` naming the design that works
    for this system, if one does (it is tried for the message only).
    """
    A, _, C, _, E, F = sys.matrices_at(0)
    if L is not None:
        if gain is not None:
            raise IvobsError(
                f"gain: pass either an explicit gain L=... or a design gain={gain!r}, not both"
            )
        Lm = as_matrix("L", L, sys.nx, sys.ny)
        rho = check_gain(A, C, Lm, f"L ({who})")
        return DesignedGain(Lm, None, None, rho, "user", None)
    if gain is not None and gain not in GAINS:
        raise IvobsError(f"gain: expected one of {', '.join(map(repr, GAINS))}, got {gain!r}")
    r = sys.d_at(0).radius if sys.has_constant_bounds else None
    failed: list[str] = []
    for g in GAINS if gain is None else (gain,):
        try:
            out = _cached_design(g, A, C, E, F, r)
        except DesignError as exc:
            failed.append(f"gain={g!r}: {exc}")
            continue
        return DesignedGain(*out, gain=g, fallback="; ".join(failed) or None)
    if gain is None:
        raise DesignError(
            f"{who}: no observer gain could be designed ({'; '.join(failed)}); pass an "
            "explicit gain L=..."
        )
    for g in GAINS:  # the first other design that succeeds, named in the message
        if g != gain:
            try:
                _cached_design(g, A, C, E, F, r)
            except DesignError:
                continue
            hint = f"; gain={g!r} designs a stabilising gain for this system"
            raise DesignError(f"{failed[0]}{hint}") from None
    raise DesignError(failed[0]) from None


def _cached_design(
    gain: str, A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, r: np.ndarray | None
) -> tuple[np.ndarray, float | None, np.ndarray | None, float]:
    from .cache import cached, fingerprint

    r = r if gain == "radius" else None
    key = fingerprint("observer_gain", gain, A, C, E, F, r)
    return cached(key, lambda: _design(gain, A, C, E, F, r))


def _design(
    gain: str, A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, r: np.ndarray | None
) -> tuple[np.ndarray, float | None, np.ndarray | None, float]:
    """One design of :func:`designed_gain`, its certificate checked."""
    if gain == "radius":
        from .radius import radius_gain

        # time-varying bounds: the design weighs every disturbance channel alike
        Lm, _ = radius_gain(A, C, E, F, np.ones(E.shape[1]) if r is None else r)
        rho = check_gain(A, C, Lm, "radius_gain: the optimised gain")
        return Lm, None, None, rho
    Lm, gamma, P = hinf_gain(A, C, E, F, method="lmi" if gain == "hinf-lmi" else "riccati")
    return Lm, gamma, P, check_gain(A, C, Lm, f"hinf_gain ({gain})")
