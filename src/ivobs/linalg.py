"""Matrix facts every method needs: stability, sign structure, observability.

Pure functions of matrices (no systems, no time loops). Tolerances are explicit arguments.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._validate import as_matrix
from .errors import IvobsError

__all__ = [
    "UNIT_ROUNDOFF",
    "controllability_matrix",
    "gamma",
    "is_controllable",
    "is_hurwitz",
    "is_metzler",
    "is_nonnegative",
    "is_observable",
    "is_schur",
    "observability_index",
    "observability_indices",
    "observability_matrix",
    "observability_rank",
    "spectral_radius",
]


UNIT_ROUNDOFF = float(np.finfo(float).eps) / 2
"""``u = 2⁻⁵³``: a rounded IEEE double operation returns ``x (1 + δ)`` with ``|δ| <= u``."""


def gamma(n: int, unit: float = UNIT_ROUNDOFF) -> float:
    """``γ_n = n u / (1 - n u)`` ([Higham2002, Lemma 3.1]): an expression whose every term passes
    through at most ``n`` roundings differs from the exact one by at most ``γ_n`` times the same
    expression on absolute values (a sum or dot product of ``n`` terms). ``unit = 2u`` (``ε``)
    gives a conservative variant that also absorbs the rounding of the error terms themselves.
    ``inf`` when ``n u >= 1/2``."""
    nu = n * unit
    if not nu < 0.5:
        return float("inf")
    return nu / (1.0 - nu)


def spectral_radius(M: Any) -> float:
    """``max |λ(M)|``."""
    M = as_matrix("M", M)
    if M.size == 0:
        return 0.0
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def is_schur(M: Any, margin: float = 0.0) -> bool:
    """Schur stable: every eigenvalue strictly inside the circle of radius ``1 - margin``."""
    return spectral_radius(M) < 1.0 - margin


def is_hurwitz(M: Any, margin: float = 0.0) -> bool:
    """Hurwitz stable: every eigenvalue has real part ``< -margin``."""
    M = as_matrix("M", M)
    return bool(np.max(np.linalg.eigvals(M).real) < -margin)


def is_nonnegative(M: Any, tol: float = 0.0) -> bool:
    """Every entry ``>= -tol`` (the cooperativity condition of discrete-time observers)."""
    return bool(np.all(np.asarray(M, dtype=float) >= -tol))


def is_metzler(M: Any, tol: float = 0.0) -> bool:
    """Every off-diagonal entry ``>= -tol`` (cooperativity in continuous time)."""
    M = np.asarray(M, dtype=float)
    return bool(np.all(M - np.diag(np.diag(M)) >= -tol))


def _rank_tol(M: np.ndarray) -> float:
    s = np.linalg.svd(M, compute_uv=False) if M.size else np.zeros(0)
    tol: float = (s[0] if s.size else 0.0) * max(M.shape) * np.finfo(float).eps * 10
    return tol


def observability_matrix(A: Any, C: Any, steps: int | None = None) -> np.ndarray:
    """``[C; CA; ...; CA^(steps-1)]`` (``steps = n`` by default)."""
    A = as_matrix("A", A)
    C = as_matrix("C", C, cols=A.shape[0], vector="row")
    n = A.shape[0]
    steps = n if steps is None else int(steps)
    blocks = [C]
    for _ in range(steps - 1):
        blocks.append(blocks[-1] @ A)
    return np.vstack(blocks)


def observability_rank(A: Any, C: Any) -> int:
    """Rank of the observability matrix (numerical rank, SVD with a relative tolerance)."""
    O = observability_matrix(A, C)
    return int(np.linalg.matrix_rank(O, tol=_rank_tol(O)))


def is_observable(A: Any, C: Any) -> bool:
    """``rank [C; CA; ...; CA^(n-1)] = n``."""
    return observability_rank(A, C) == int(np.asarray(A).shape[0])


def observability_indices(A: Any, C: Any) -> list[int]:
    """Observability (Luenberger/Kronecker) indices ``m_i``, one per output.

    Rows ``c_i A^j`` are scanned by increasing power ``j`` and output ``i``; a row is kept when it
    is linearly independent of those kept before. ``m_i`` counts the kept rows of output ``i``;
    ``sum m_i`` is the observability rank (``n`` for an observable pair). [Dinh2024, Propositions
    3–4] uses these as the block sizes of its target dynamics (``n_z = sum m_i``).
    """
    A = as_matrix("A", A)
    C = as_matrix("C", C, cols=A.shape[0], vector="row")
    n, p = A.shape[0], C.shape[0]
    kept: list[np.ndarray] = []
    m = [0] * p
    active = [True] * p
    rows = C.copy()
    tol = _rank_tol(observability_matrix(A, C))
    for _ in range(n):
        for i in range(p):
            if not active[i]:
                continue
            cand = np.vstack([*kept, rows[i]]) if kept else rows[i : i + 1]
            if np.linalg.matrix_rank(cand, tol=tol) > len(kept):
                kept.append(rows[i])
                m[i] += 1
            else:
                active[i] = False  # once dependent, higher powers of this output are too
        rows = rows @ A
        if len(kept) == n:
            break
    return m


def observability_index(A: np.ndarray, C: np.ndarray) -> int:
    """The smallest ``ν`` with ``rank [C; CA; …; CA^(ν−1)] = nx`` (forward powers, which stay
    well conditioned for a stable ``A``; ``nx + 1`` when the pair is not observable)."""
    nx = int(A.shape[0])
    rows = np.zeros((0, nx))
    blk = C
    for nu in range(1, nx + 1):
        rows = np.vstack([rows, blk / max(float(np.abs(blk).max(initial=0.0)), 1e-300)])
        if int(np.linalg.matrix_rank(rows)) == nx:
            return nu
        blk = blk @ A
    return nx + 1


def controllability_matrix(A: Any, B: Any) -> np.ndarray:
    """``[B, AB, ..., A^(n-1)B]``."""
    A = as_matrix("A", A)
    B = as_matrix("B", B, rows=A.shape[0])
    blocks = [B]
    for _ in range(A.shape[0] - 1):
        blocks.append(A @ blocks[-1])
    return np.hstack(blocks)


def is_controllable(A: Any, B: Any) -> bool:
    """``rank [B, AB, ..., A^(n-1)B] = n``."""
    K = controllability_matrix(A, B)
    return int(np.linalg.matrix_rank(K, tol=_rank_tol(K))) == int(np.asarray(A).shape[0])


def check_observable(A: Any, C: Any, who: str) -> None:
    """Raise :class:`IvobsError` naming ``who`` when ``(A, C)`` is not observable."""
    r = observability_rank(A, C)
    n = np.asarray(A).shape[0]
    if r < n:
        raise IvobsError(
            f"pair (A, C) is not observable: rank {r} of {n}; {who} needs observability "
            "(add a sensor, or remove the unobservable states from the model)"
        )
