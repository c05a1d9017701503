"""The offline design of ``interval-transformed``: the gain ``L`` and the transformation ``S``
(``z = S x``), checked ([Tang2019, Theorem 5, eq. (48)], [Efimov2013, Theorem 2]).

Three routes, tried in this order by ``transform="auto"``: the paper's eq. (48) after ivobs'
search (up to :data:`SEARCH_MAX_STATES` states); ``S = I`` with the width-optimal gain when some
gain makes ``A − LC`` itself nonnegative and Schur; real Schur (or modal) coordinates
(:mod:`ivobs.design.schur_transform`), which need only ``A − LC`` Schur with its spectrum in the
diamond ``|Re λ| + |Im λ| < 1``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._validate import as_matrix, as_vector
from ...design.cooperative import NONNEG_TOL
from ...design.schur_transform import schur_design
from ...design.similarity import (
    check_transform,
    default_design,
    default_e1,
    nonnegative_realization,
    place_real_poles,
    similarity_transform,
    transformed_width,
)
from ...design.width_lp import MAX_LP_STATES, width_gain
from ...errors import DesignError, IvobsError
from ...linalg import observability_matrix, spectral_radius
from ...model import LinearSystem
from ..base import Design
from .design import check_design_size, check_gain

__all__ = ["SEARCH_MAX_STATES", "TransformedDesign", "transformed_design"]


@dataclass(frozen=True)
class TransformedDesign(Design):
    """``L``: gain (``A − LC`` Schur); ``poles``: eigenvalues of ``A − LC``; ``S``: the
    transformation ``z = S x``; ``R = S (A − LC) S⁻¹`` (nonnegative up to round-off; this is the
    matrix the observer propagates); ``e1``, ``e2``: the rows of [Tang2019, eq. (48)] (None when
    ``S`` was given); ``spectral_radius`` of ``|R|``; ``gain``: ``'search'`` (ivobs' default
    design), ``'given-poles'`` or ``'given'``; ``steady_width``:
    ``|S⁻¹|(I − |R|)⁻¹|S(E − LF)| Δ``."""

    L: np.ndarray
    R: np.ndarray
    S: np.ndarray
    e1: np.ndarray | None
    e2: np.ndarray | None
    poles: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None


def transformed_design(
    sys: LinearSystem,
    who: str,
    *,
    L: Any,
    poles: Any,
    R: Any,
    S: Any,
    e1: Any,
    e2: Any,
    transform: str = "auto",
) -> TransformedDesign:
    """The design of ``interval-transformed`` ([Tang2019, Theorem 5, eq. (48)], [Efimov2013,
    Theorem 2]): the gain (given, placed poles or ivobs' search), then ``S`` (given, or by
    eq. (48) from a nonnegative realisation ``R`` of the spectrum of ``A − LC``), checked.
    ``transform="schur"`` (and ``"auto"`` above :data:`SEARCH_MAX_STATES` states or where the
    search fails): real Schur coordinates (:mod:`ivobs.design.schur_transform`)."""
    if transform not in ("auto", "search", "schur"):
        raise IvobsError(f"transform: expected 'auto', 'search' or 'schur', got {transform!r}")
    A, _, C, _, E, F = sys.matrices_at(0)
    delta = sys.d_widths()
    if L is not None and poles is not None:
        raise IvobsError("L, poles: give the gain L or the poles to place, not both")
    if S is not None and (e1 is not None or e2 is not None):
        raise IvobsError("e1, e2: they only serve to compute S by eq. (48); S was given")
    paper_options = R is not None or S is not None or e1 is not None or e2 is not None
    if transform == "schur" and paper_options:
        raise IvobsError("transform: 'schur' computes S and R itself; do not pass R, S, e1, e2")
    if transform == "schur" or (
        transform == "auto" and not paper_options and sys.nx > SEARCH_MAX_STATES
    ):
        return _schur(sys, who, L, poles)
    # every step here (pole placement, the realisation R, S by eq. (48), the dense n x n
    # transform used at every step) is dense
    check_design_size(sys, who, "the similarity transform ([Tang2019, eq. (48)])")
    e1_search = None
    if L is not None:
        L, gain = check_gain(sys, L), "given"
    elif poles is None:
        try:
            L, e1_search = default_design(A, C, lambda L_: E - L_ @ F, delta, who)
        except DesignError:
            if transform == "search" or paper_options:
                raise
            return _schur(sys, who, None, None)
        gain = "search"
    else:
        poles = as_vector("poles", poles, sys.nx)
        if np.any(np.abs(poles) >= 1.0):
            raise IvobsError(f"poles: expected values inside (−1, 1), got {poles}")
        L, gain = place_real_poles(A, C, poles, who), "given-poles"
    M = A - L @ C
    rho = spectral_radius(M)
    if rho >= 1.0:
        raise DesignError(f"{who}: A − LC is not Schur: spectral radius {rho:.6g} >= 1")
    G = E - L @ F
    R_given = None if R is None else _check_R(sys, R, who)
    if S is not None:
        S = as_matrix("S", S, sys.nx, sys.nx)
        e1_, e2_ = None, None
    else:
        S, e1_, e2_ = _transform(M, G, delta, R_given, e1, e2, e1_search, who)
        R_given = None  # S was built from R: check_transform checks nonnegativity only
    return _made(sys, L, S, check_transform(M, S, who, R_given), gain, e1_, e2_)


SEARCH_MAX_STATES = 8
"""Above this many states ``transform="auto"`` uses Schur coordinates: eq. (48) goes through
observability matrices whose condition number grows exponentially with ``nx``."""


def _schur(sys: LinearSystem, who: str, L: Any, poles: Any) -> TransformedDesign:
    """The design in real Schur coordinates (:func:`ivobs.design.schur_transform.schur_design`):
    ``S = Zᵀ`` orthogonal, ``R`` quasi-triangular with ``ρ(|R|) < 1``, checked."""
    A, _, C, _, E, F = sys.matrices_at(0)
    delta = sys.d_widths()
    gain = "schur"
    if L is None and poles is None and sys.nx <= MAX_LP_STATES:
        # S = I is a valid transformation when some gain makes A − LC itself nonnegative and
        # Schur ([Tang2019, Theorem 5] with S = I, R = A − LC): the width-optimal one, which
        # no orthogonal S beats on the box (|S⁻¹| spreads every radius over all states)
        try:
            L = width_gain(A, C, E, F, delta, nonnegative=True, who=who)
        except DesignError:
            L = None
        else:
            return _made(sys, L, np.eye(sys.nx), A - L @ C, "identity")
    if L is not None:
        L, gain = check_gain(sys, L), "given"
        M = A - L @ C
        if M.min() >= -NONNEG_TOL * max(1.0, float(np.abs(A).max())) and spectral_radius(M) < 1:
            return _made(sys, L, np.eye(sys.nx), M, gain)  # a cooperative gain: S = I
    elif poles is not None:
        poles = as_vector("poles", poles, sys.nx)
        L, gain = place_real_poles(A, C, poles, who), "given-poles"
    L, S, _ = schur_design(A, C, E, F, delta, who, L)
    return _made(sys, L, S, check_transform(A - L @ C, S, who, None, nonnegative=False), gain)


def _made(
    sys: LinearSystem,
    L: np.ndarray,
    S: np.ndarray,
    R: np.ndarray,
    gain: str,
    e1: np.ndarray | None = None,
    e2: np.ndarray | None = None,
) -> TransformedDesign:
    """The design of the gain ``L`` and the transformation ``S`` with ``R = S (A − LC) S⁻¹``
    (checked by the caller), its steady-state width (:func:`transformed_width`; None for
    callable bounds)."""
    A, _, C, _, E, F = sys.matrices_at(0)
    M = A - L @ C
    steady = None
    if not sys.bounds_depend_on_y:
        steady = transformed_width(M, E - L @ F, sys.d_widths(), S)
    return TransformedDesign(
        L=L,
        R=R,
        S=S,
        e1=e1,
        e2=e2,
        poles=np.linalg.eigvals(M),
        spectral_radius=spectral_radius(np.abs(R)),
        gain=gain,
        steady_width=steady,
    )


def _transform(
    M: np.ndarray,
    G: np.ndarray,
    delta: np.ndarray,
    R_given: np.ndarray | None,
    e1: Any,
    e2: Any,
    e1_search: np.ndarray | None,
    who: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(S, e1, e2)`` of [Tang2019, eq. (48)]: ``S = O_R⁻¹ O_{A−LC}`` for the nonnegative
    ``R`` (given, or :func:`~ivobs.design.similarity.nonnegative_realization` of the spectrum
    of ``M = A − LC``) and the rows ``e1``, ``e2`` (given or default)."""
    n = M.shape[0]
    e2_default: np.ndarray | None
    if R_given is None:
        R_t, e2_default = nonnegative_realization(np.linalg.eigvals(M))
        R_t = np.asarray(R_t)
    else:
        R_t, e2_default = R_given, None
    if e2 is not None:
        e2_ = as_vector("e2", e2, n)
    elif e2_default is not None:
        e2_ = e2_default
    else:
        e2_ = _default_e2(R_t)
    if e1 is not None:
        e1_ = as_vector("e1", e1, n)
    elif e1_search is not None and R_given is None and e2 is None:
        e1_ = e1_search
    else:
        e1_ = default_e1(M, R_t, e2_, G, delta, who)
    return similarity_transform(M, R_t, e1_, e2_, who), e1_, e2_


def _check_R(sys: LinearSystem, given: Any, who: str) -> np.ndarray:
    R = as_matrix("R", given, sys.nx, sys.nx)
    if np.any(R < 0):
        i, j = np.unravel_index(int(np.argmin(R)), R.shape)
        raise DesignError(
            f"{who}: R is not nonnegative: entry ({i + 1}, {j + 1}) = {R[i, j]:.6g} "
            "< 0 ([Tang2019, Theorem 5] / [Efimov2013, Theorem 2] need R >= 0)"
        )
    return R


def _default_e2(R: np.ndarray) -> np.ndarray:
    """A row making ``(R, e2)`` well observable: ones, then unit vectors (best conditioned)."""
    n = R.shape[0]
    cands: list[np.ndarray] = [np.ones(n), *np.eye(n)]
    conds = [np.linalg.cond(observability_matrix(R, c[None, :])) for c in cands]
    return cands[int(np.argmin(conds))]
