"""The offline design of ``interval`` and ``interval-split``: the gain ``L``, checked, with the
numbers the papers report about it (``interval-transformed``: :mod:`.transformed`).

Nothing here loops over time: the default gains come from the width-optimal linear program of
:mod:`ivobs.design.width_lp`; the papers' LMI (41) of [Tang2019] (= LMIs (7)–(8) of
[Efimov2013]), the alternating LPs on ``|A − LC|`` and the local width refinement from
:mod:`ivobs.design.cooperative`; user gains of ``scipy.sparse`` systems are checked with sparse
algebra.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, TypeVar

import numpy as np

from ..._validate import as_matrix
from ...design._lmi import MAX_LMI_STATES
from ...design.cooperative import (
    NONNEG_TOL,
    abs_schur_gain,
    check_abs_schur,
    check_nonnegative_schur,
    fixed_radius,
    missing_radius,
    nonnegative_gain,
    refine_width,
    steady_width,
)
from ...design.width_lp import MAX_LP_STATES, width_gain
from ...errors import DesignError, IvobsError
from ...linalg import spectral_radius
from ...model import LinearSystem
from ..base import Design

__all__ = [
    "MAX_DENSE_DESIGN",
    "IntervalDesign",
    "SplitDesign",
    "check_design_size",
    "gain_design",
    "sparse_gain_check",
    "sparse_radius",
]


@dataclass(frozen=True)
class _GainDesign(Design):
    """The fields of :class:`IntervalDesign` and :class:`SplitDesign`."""

    L: np.ndarray
    D: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None
    missing_radius: np.ndarray | None = None


@dataclass(frozen=True)
class IntervalDesign(_GainDesign):
    """``L``: gain; ``D = A − LC`` ([Efimov2013]'s notation; nonnegative); ``spectral_radius``
    of ``D``; ``gain``: how ``L`` was obtained (``'lmi'``, ``'lmi+width'``, ``'given'``);
    ``steady_width``: ``(I − D)⁻¹ |E − LF| Δ``, the limit of the bounds' width for constant
    bounds (None for callable bounds); ``missing_radius``: ``ρ(|A − L_(j) C|)`` for each output
    ``j`` missing alone (``L_(j)``: column ``j`` of ``L`` zeroed, the gain used then), the growth
    rate of the width during a gap of that output (None for sparse systems)."""


@dataclass(frozen=True)
class SplitDesign(_GainDesign):
    """``L``: gain; ``D = A − LC`` (any sign); ``spectral_radius`` of ``|D| = D⁺ + D⁻``;
    ``gain``: ``'width'``, ``'margin'``, ``'lmi'`` or ``'given'``; ``steady_width``:
    ``(I − |D|)⁻¹ |E − LF| Δ`` (None for callable bounds); ``missing_radius``: as for
    :class:`IntervalDesign`."""


MAX_DENSE_DESIGN = MAX_LMI_STATES
"""Above this many states the dense design steps of this package (LMI (41), the width and margin
linear programs, similarity transforms) are refused with a :class:`~ivobs.DesignError`: pass a
gain ``L=`` (checked sparsely for ``scipy.sparse`` systems)."""


_SCALES = (
    "pass a gain L=... to 'interval' or 'interval-split' (checked with sparse algebra when A is "
    "scipy.sparse, one sparse product per step; e.g. ivobs.scenarios.heat_gain for heat-1d; "
    "docs/scale.md)"
)


def check_design_size(
    sys: LinearSystem, who: str, step: str, limit: int = MAX_DENSE_DESIGN
) -> None:
    """:class:`DesignError` when a design step with ``O(nx²)`` variables or ``O(nx³)`` work would
    run on more than ``limit`` states (:data:`MAX_DENSE_DESIGN`; the sparse width LP:
    :data:`~ivobs.design.width_lp.MAX_LP_STATES`), pointing to what scales."""
    if sys.nx > limit:
        raise DesignError(
            f"{who}: {step} has O(nx^2) variables or O(nx^3) work and does not scale to "
            f"nx = {sys.nx} > {limit} states; {_SCALES}"
        )


def sparse_radius(P: Any) -> float:
    """Spectral radius of a sparse nonnegative matrix: ARPACK (Perron root, the largest in
    modulus), or the smaller of the largest row and column sums (an upper bound, Perron–
    Frobenius) when ARPACK does not converge. Small matrices: dense eigenvalues. ARPACK starts
    from the positive vector of ones (not a random one), so that the same design gives the same
    number (it is part of the design's fingerprint, which a saved state must match)."""
    n = P.shape[0]
    if n <= MAX_DENSE_DESIGN:
        return spectral_radius(P.toarray())
    from scipy.sparse.linalg import ArpackNoConvergence, eigs

    bound = float(min(abs(P).sum(axis=1).max(), abs(P).sum(axis=0).max()))
    try:
        val = eigs(P, k=1, which="LM", tol=1e-8, ncv=min(n - 1, 40), v0=np.ones(n),
                   return_eigenvectors=False)  # fmt: skip
    except ArpackNoConvergence:
        return bound
    return min(float(np.abs(val[0])), bound)


def sparse_gain_check(
    sys: LinearSystem, L: np.ndarray, who: str, nonnegative: bool
) -> tuple[Any, float]:
    """``(D, ρ)``: ``D = A − LC`` as a sparse matrix, checked as
    :func:`check_nonnegative_schur` / :func:`check_abs_schur` do, without dense algebra
    (``scipy.sparse`` systems), and ``ρ(|D|)``."""
    from scipy.sparse import csr_matrix

    A = sys.sparse("A")
    D = (A - csr_matrix(L) @ sys.sparse("C")).tocsr()
    D.eliminate_zeros()
    if nonnegative:
        tol = NONNEG_TOL * max(1.0, float(abs(A).max()) if A.nnz else 0.0)
        if D.nnz and D.data.min() < -tol:
            coo = D.tocoo()
            j = int(np.argmin(coo.data))
            raise DesignError(
                f"{who}: A − LC is not nonnegative: entry ({coo.row[j] + 1}, {coo.col[j] + 1}) = "
                f"{coo.data[j]:.6g} < 0 ([Tang2019, Theorem 4] / [Efimov2013, Assumption 2.B] "
                "need A − LC >= 0); use 'interval-split' or 'interval-transformed' with this gain"
            )
    rho = sparse_radius(abs(D))
    if rho >= 1.0:
        what = "A − LC is not Schur" if nonnegative else "|A − LC| = D⁺ + D⁻ is not Schur"
        ref = "[Efimov2013, Assumption 2.A]" if nonnegative else "[Efimov2013, Theorem 3]"
        raise DesignError(f"{who}: {what}: spectral radius {rho:.6g} >= 1 ({ref})")
    return D, rho


def check_gain(sys: LinearSystem, L: Any) -> np.ndarray:
    """The option ``L`` as an ``(nx, ny)`` matrix (named in the error)."""
    return as_matrix("L", L, sys.nx, sys.ny, vector="col")


def given_gain(
    sys: LinearSystem, L: Any, who: str, nonnegative: bool
) -> tuple[np.ndarray, Any, float]:
    """A gain, checked (sparse algebra for sparse systems): ``(L, D, ρ)`` with ``D = A − LC``
    and ``ρ`` the spectral radius of ``D`` (``nonnegative``) or of ``|D|``."""
    L = check_gain(sys, L)
    if sys.is_sparse:
        return (L, *sparse_gain_check(sys, L, who, nonnegative))
    A, C = sys.A_at(0), sys.C_at(0)
    if nonnegative:
        D = check_nonnegative_schur(A, C, L, who)
        return L, D, spectral_radius(D)
    D = check_abs_schur(A, C, L, who)
    return L, D, spectral_radius(np.abs(D))


D = TypeVar("D", bound=_GainDesign)

_GAINS = {True: ("width", "lmi+width", "lmi"), False: ("width", "margin+width", "margin", "lmi")}
"""The ``gain=`` designs of ``interval`` (``A − LC`` nonnegative) and ``interval-split``."""


def gain_design(kind: type[D], sys: LinearSystem, L: Any, gain: str, who: str) -> D:
    """The design of ``interval`` (``kind`` :class:`IntervalDesign`: ``A − LC`` nonnegative and
    Schur) or ``interval-split`` (:class:`SplitDesign`: ``|A − LC|`` Schur): a given gain, the
    steady-state-width-optimal gain of one linear program (``gain="width"``,
    :func:`ivobs.design.width_lp.width_gain`), LMI (41) of [Tang2019] (= LMIs (7)–(8) of
    [Efimov2013], ``"lmi"``), the smallest ``ρ(|A − LC|)`` found (``"margin"``, split only),
    or either refined by the local width LPs (``"lmi+width"``, ``"margin+width"``);
    :class:`DesignError` when no such gain is found. With the design: the steady-state width
    ``(I − |D|)⁻¹ |E − LF| Δ`` (a sparse solve for sparse systems; None for callable bounds)
    and the growth rates during single-output gaps (None for sparse systems)."""
    nonnegative = kind is IntervalDesign
    if L is None:
        names = _GAINS[nonnegative]
        if gain not in names:
            listed = ", ".join(map(repr, names[:-1]))
            raise IvobsError(f"gain: expected {listed} or {names[-1]!r}, got {gain!r}")
        A, _, C, _, E, F = sys.matrices_at(0)
        if gain == "width":
            check_design_size(sys, who, "the width linear program", MAX_LP_STATES)
            L = width_gain(A, C, E, F, sys.d_widths(), nonnegative=nonnegative, who=who)
        else:
            what = "LMI (41)" if nonnegative else "LMIs (7)-(8)"
            what = what if gain.startswith("lmi") else "linear programs on |A − LC|"
            check_design_size(sys, who, f"the gain design gain={gain!r} ({what})")
            L = nonnegative_gain(A, C, who) if gain.startswith("lmi") else _margin_gain(A, C, who)
            if gain.endswith("+width"):
                L = refine_width(A, C, E, F, sys.d_widths(), L, nonnegative=nonnegative)
    else:
        gain = "given"
    L, D_, rho = given_gain(sys, L, who, nonnegative)
    G = sys.E_at(0) - L @ sys.F_at(0)
    if sys.bounds_depend_on_y:
        steady = None
    elif sys.is_sparse:
        from scipy.sparse import identity
        from scipy.sparse.linalg import spsolve

        M = (identity(D_.shape[0], format="csc") - abs(D_)).tocsc()
        steady = np.atleast_1d(spsolve(M, np.abs(G) @ sys.d_widths()))
    else:
        steady = steady_width(D_, G, sys.d_widths())
    return kind(
        L=L,
        D=D_,
        spectral_radius=rho,
        gain=gain,
        steady_width=steady,
        missing_radius=None if sys.is_sparse else missing_radius(sys.A_at(0), sys.C_at(0), L),
    )


def _margin_gain(A: np.ndarray, C: np.ndarray, who: str) -> np.ndarray:
    """The gain of the smallest ``ρ(|A − LC|)`` found (:func:`abs_schur_gain`), or a
    :class:`DesignError` when it is not below 1."""
    L, rho = abs_schur_gain(A, C)
    if rho >= 1.0:
        low = fixed_radius(A, C)
        why = (
            f"; no gain can do better than {low:.6g}: the unmeasured states (zero "
            "columns of C) keep |A| on their block"
            if low >= 1.0
            else ""
        )
        raise DesignError(
            f"{who}: no gain found with |A − LC| Schur: the best spectral "
            f"radius of |A − LC| found is {rho:.6g} >= 1 ([Efimov2013, Theorem 3]){why}; "
            "try 'interval-transformed' (needs only A − LC Schur)"
        )
    return L
