"""The Sylvester equation ``T A = A_z T + B_z C`` ([Dinh2024, eq. (4)]), the conditions of
[Dinh2024, Proposition 1] on a target pair, and the predicted width of the bounds of observer (3).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.linalg import solve_sylvester

from ..._validate import as_matrix
from ...errors import DesignError, IvobsError
from ...linalg import (
    is_controllable,
    is_hurwitz,
    is_metzler,
    is_nonnegative,
    is_schur,
    spectral_radius,
)

__all__ = ["check_target", "predicted_width", "solve_transform"]


def solve_transform(A: np.ndarray, C: np.ndarray, A_z: np.ndarray, B_z: np.ndarray) -> np.ndarray:
    """``T`` with ``T A = A_z T + B_z C`` ([Dinh2024, eq. (4)]), by SciPy's Sylvester solver.

    Written as ``(-A_z) T + T A = B_z C`` for :func:`scipy.linalg.solve_sylvester`
    (Matlab: ``T = sylvester(A_z, -A, -B_z*C)``, Algorithm 1 step 2). Raises
    :class:`DesignError` when the equation is singular (``A_z`` and ``A`` share an eigenvalue) or
    the computed solution does not satisfy it to working accuracy.
    """
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
            T: np.ndarray = solve_sylvester(-A_z, A, Q)
        except (np.linalg.LinAlgError, ValueError) as exc:
            raise DesignError(f"Sylvester equation T A = A_z T + B_z C (eq. 4): {exc}") from None
    if not np.all(np.isfinite(T)):
        raise DesignError(
            "Sylvester equation T A = A_z T + B_z C (eq. 4): non-finite solution; "
            "choose eig(A_z) away from eig(A)"
        )
    res = np.linalg.norm(T @ A - A_z @ T - Q)
    scale = float(np.linalg.norm(T) * (np.linalg.norm(A) + np.linalg.norm(A_z)) + np.linalg.norm(Q))
    if res > 1e-8 * max(scale, 1e-300):
        raise DesignError(
            f"Sylvester equation T A = A_z T + B_z C (eq. 4) solved with relative residual "
            f"{res / scale:.2e}: eig(A_z) is too close to eig(A); move them apart"
        )
    return T


def check_target(
    A_z: Any, B_z: Any, continuous: bool, A: Any = None, *, who: str = "A_z"
) -> tuple[np.ndarray, np.ndarray]:
    """Check the conditions of [Dinh2024, Proposition 1] (LTI) / [Dinh2024, Propositions 3-4]
    (LTV) on a target pair.

    Discrete time: ``A_z`` nonnegative and Schur; continuous time: Metzler and Hurwitz;
    ``(A_z, B_z)`` controllable; when ``A`` is given (time-invariant systems), no common
    eigenvalue. Nothing more ([Dinh2024, Proposition 1]; invertibility of ``T`` is checked on
    the solution): in continuous time a target slower than a plant mode is allowed (the
    sampled-data observer keeps ``T`` at its fixed point, :mod:`.flow`). Raises
    :class:`DesignError` naming the failed condition.
    """
    A_z = as_matrix(who, A_z)
    if A_z.shape[0] != A_z.shape[1]:
        raise IvobsError(f"{who}: expected a square matrix, got shape {A_z.shape}")
    B_z = as_matrix("B_z", B_z, rows=A_z.shape[0])
    if continuous:
        if not is_metzler(A_z):
            raise DesignError(
                f"{who}: must be Metzler (off-diagonal entries >= 0) in continuous "
                "time ([Dinh2024, Proposition 1])"
            )
        if not is_hurwitz(A_z):
            top = float(np.max(np.linalg.eigvals(A_z).real))
            raise DesignError(f"{who}: must be Hurwitz; its spectral abscissa is {top:.4g} >= 0")
    else:
        if not is_nonnegative(A_z):
            raise DesignError(
                f"{who}: must be nonnegative in discrete time ([Dinh2024, Proposition 1]); "
                f"smallest entry {A_z.min():.4g}"
            )
        if not is_schur(A_z):
            raise DesignError(
                f"{who}: must be Schur; its spectral radius is {spectral_radius(A_z):.4g} >= 1"
            )
    if not is_controllable(A_z, B_z):
        raise DesignError(
            f"({who}, B_z) is not controllable ([Dinh2024, Proposition 1]): give B_z "
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
