"""Interval observers built on cooperative (monotone) error dynamics: one family, three members.

Papers: Tang, Wang, Wang, Raïssi, Shen, *Interval estimation methods for discrete-time LTI
systems*, IEEE TAC 2019 (``seeds/002_b3ef…``), Section V, Theorems 4–5, eqs. (36)–(48);
Efimov, Perruquetti, Raïssi, Zolghadri, *On interval observer design for time-invariant
discrete-time systems* (``seeds/003_f19a…``), Theorems 1–3, eqs. (3)–(8), Remark 1.

ivobs' model ``x+ = A x + B u + E d``, ``y = C x + D_u u + F d`` (one disturbance ``d`` in both
equations; ``D_u`` is the feedthrough) gives, for any gain ``L``,

    x+ = (A − LC) x + (B − L D_u) u + L y + (E − LF) d                          (*)

so with ``G = E − LF`` the Lemma-1 bounds ``G⁺ d_lo − G⁻ d_hi <= G d <= G⁺ d_hi − G⁻ d_lo``
play the role of 002's ``d̲, d̄`` (eq. 37: for ``d = [w; v]``, ``E = [E 0]``, ``F = [0 F]`` they
are exactly ``E⁺w̄ − E⁻w̲ + (−LF)⁺v̄ − (−LF)⁻v̲``) and of 003's ``b̲ − LV``, ``b̄ + LV``.

* ``interval`` — 002 eq. (36) = 003 eq. (3): ``A − LC`` nonnegative and Schur (Theorem 4 /
  Theorem 1);
* ``interval-transformed`` — 002 Theorem 5 (eqs. 42–43) = 003 Theorem 2: observer (36) for
  ``z = S x`` with ``R = S (A − LC) S⁻¹ >= 0``, bounds mapped back by Lemma 1;
* ``interval-split`` — 003 Theorem 3, eq. (5): same coordinates, ``D = A − LC = D⁺ − D⁻`` of any
  sign, stable iff ``|D| = D⁺ + D⁻`` is Schur.

All three propagate one recursion, the split form of (*) in coordinates ``z = S x``
(``S = I`` except for ``interval-transformed``), with ``Q = S (A − LC) S⁻¹``::

    z̄+ = Q⁺ z̄ − Q⁻ z̲ + S(B − L D_u) u + S L y + (SG)⁺ d_hi − (SG)⁻ d_lo
    z̲+ = Q⁺ z̲ − Q⁻ z̄ + S(B − L D_u) u + S L y + (SG)⁺ d_lo − (SG)⁻ d_hi

Soundness: multiply (*) by ``S``; Lemma 1 bounds ``Q z`` over ``[z̲, z̄]`` and ``SG d`` over the
``d`` box, so ``z̲ <= z <= z̄`` carries over by induction from ``z̲_0 <= S x_0 <= z̄_0`` (Lemma 1
on ``x0``). When ``Q >= 0`` (``Q⁻ = 0``) this *is* 002's (36)/(42) and 003's (3)/(4); for
``interval-split`` it is 003's (5). The midpoint obeys ``c+ = Q c + …`` and the radius
``r+ = |Q| r + radius(SG d)`` (``|Q| = Q⁺ + Q⁻``): bounded iff ``|Q|`` is Schur. (The stacked
bounds follow ``[[Q⁺, −Q⁻], [−Q⁻, Q⁺]]``, not 003's error matrix Σ; both are Schur iff
``|Q|`` is.) The vectorised path runs exactly these two linear recursions.

**Missing samples** (NaN in ``y[k]``): the gain's columns of the missing components are set to
zero for that step, ``L_k = L diag(observed)``; (*) holds for *any* gain, so the same Lemma-1
step with ``Q_k = S(A − L_k C)S⁻¹`` (which may have negative entries even when ``Q`` has none:
the split form covers it) stays sound; with every component missing it is the model's prediction
``x+ ∈ A[x̲, x̄] + B u + E[d]``. **Inconsistent data**: when ``y[k]`` lies outside
``C[x̲_k, x̄_k] + D_u u_k + F[d]`` no state in the box explains it (a fault); it is reported and
treated as missing. The width of the bounds grows during a gap of output ``j`` alone at the rate
``ρ(|A − L_(j) C|)`` (``design.missing_radius``); the default gains are the smallest among the
width-optimal ones (:mod:`ivobs.design.cooperative`, audit A8), so that no gap multiplies the
bounds by the size of a needlessly large gain.

**Rounding** (``interval``, ``interval-split``; audit A8). The terms one step adds are not all of
the size of the data: ``L_k y`` is ``|L|`` times larger, and ``A − L_k C`` is formed in floating
point. By the standard bound on sums (``|fl(Σ t_i) − Σ t_i| <= γ_m Σ |t_i|``,
``γ_m = m u / (1 − m u)``, ``u = 2⁻⁵³``; ``m = 2 n_r + n_u + 2 n_y + 2 n_d + 6`` with ``n_r`` the
nonzeros per row of ``|A| + |L||C|``), one step of the loop is off by at most

    δ_k = γ_m (a_z ‖z_k‖_∞ + a_y ‖y_k‖_∞ + a_u ‖u_k‖_∞ + a_d ‖d‖_∞)

with ``a_z = 3 ‖|A| + |L||C|‖_∞`` (the products ``Q_k z``, the rounding of ``Q_k`` itself acting
on the true state, which lies in the box), ``a_y = ‖L‖_∞``, ``a_u = 2 ‖|B| + |L||D_u|‖_∞``,
``a_d = 3 ‖|E| + |L||F|‖_∞`` (Lemma 1 on the computed ``E − L_k F``) and ``‖d‖`` the largest
bound magnitude (:class:`RoundingBound`). *Loop* (``step()``, short records, missing samples):
every step widens its new bounds by ``δ_k``, so they enclose the exact recursion from the
computed box for every missing pattern (also when ``|A − L_k C|`` is not Schur), by induction.
*Vectorised path* (complete data): the errors add up to at most ``κ max_j δ_j`` with
``κ = ‖(I − |A − LC|)⁻¹‖_∞``; the outward margin ``ROUNDING (1 + |bound| + s_k)`` of
:mod:`ivobs.estimators.base` is enlarged to ``ROUNDING (1 + μ |bound| + ν s_k)`` with
``μ = κ γ_m a_z / ROUNDING``, ``ν = κ γ_m (a_y + a_u' + a_d') / ROUNDING`` (``a_u'``, ``a_d'``: the
same terms relative to the data scale ``s_k``) whenever they exceed 1 (taking, like the base
margin, the bound's own magnitude for the running maximum of ``‖z_j‖``; the block evaluation of
:class:`~ivobs._recursion.LinearFilter` reorders the same sums). The consistency test's slack
grows by ``max(1, μ, ν)``. On the paper examples ``μ, ν < 0.6`` (nothing changes there); with a
gain ``L = (−999999.1, 10⁶)`` they are about 100.

**Rounding in** ``z = S x`` (``interval-transformed``). The recursion runs with computed
matrices ``Q = fl(S M̂ Si)``, ``S L_k``, ``S (B − L_k D_u)``, ``S (E − L_k F)`` (``M̂ = fl(A − L_k
C)``, ``Si`` the computed ``S⁻¹``), while the true ``z = S x`` obeys the exact ones. On the true
state the matrix error is ``(Q − S M S⁻¹) z = (Q S − S M̂) x + S (M̂ − M) x``: an evaluated
residual acting on ``x`` (no ``cond(S)`` factor). With the errors of the other products and of
the evaluation, one step is off by at most ``c_x ‖x‖ + c_z ‖z‖ + c_y ‖y‖ + c_u ‖u‖ + c_d ‖d‖``
(:func:`transform_step_error`); the loop adds it to the new ``z`` bounds at every step, the
vectorised path adds ``‖Si‖ κ_z`` times its running maximum to the ``x`` bounds
(``κ_z = ‖(I − |Q|)⁻¹‖_∞``). The box of ``x = S⁻¹ z`` is widened for the computed inverse
(``|Si S − I|``, :func:`transform_conversion`) and ``z_0`` for the products with ``S``. On the
paper examples these terms are below ``1e-12`` relative; with a large gain and an
ill-conditioned ``S`` (nearly unobservable systems far from the origin: ``|L| ~ 10⁶``,
``cond(S) ~ 10⁷``, ``|x| ~ 10⁶``) they are the real floating-point error of the design and
dominate the width: prefer ``interval-split``, or give ``poles=`` with a smaller gain.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._recursion import (
    LinearFilter,
    SplitFilter,
    csr_accumulate,
    matrix_product,
    redo_streams,
    within_band,
)
from .._validate import as_matrix, as_vector
from ..design._lmi import MAX_LMI_STATES
from ..design.cooperative import (
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
from ..design.similarity import (
    check_transform,
    default_design,
    default_e1,
    nonnegative_realization,
    place_real_poles,
    similarity_transform,
    transformed_width,
)
from ..errors import DesignError, IvobsError
from ..linalg import gamma as _gamma
from ..linalg import spectral_radius
from ..model import LinearSystem
from ..sets import Box, image_bounds, neg, pos
from . import register
from .base import ROUNDING, Design, Estimator

__all__ = [
    "IntervalDesign",
    "IntervalObserver",
    "SplitDesign",
    "SplitIntervalObserver",
    "TransformedDesign",
    "TransformedIntervalObserver",
]

CONSISTENCY_TOL = 1e-9
"""Relative slack of the consistency test ``y[k] ∈ C[x̲, x̄] + D_u u + F[d]`` (round-off)."""


@dataclass(frozen=True)
class IntervalDesign(Design):
    """``L``: gain; ``D = A − LC`` (003's notation; nonnegative); ``spectral_radius`` of ``D``;
    ``gain``: how ``L`` was obtained (``'lmi'``, ``'lmi+width'``, ``'given'``);
    ``steady_width``: ``(I − D)⁻¹ |E − LF| Δ``, the limit of the bounds' width for constant
    bounds (None for callable bounds); ``missing_radius``: ``ρ(|A − L_(j) C|)`` for each output
    ``j`` missing alone (``L_(j)``: column ``j`` of ``L`` zeroed, the gain used then), the growth
    rate of the width during a gap of that output (None for sparse systems)."""

    L: np.ndarray
    D: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None
    missing_radius: np.ndarray | None = None


@dataclass(frozen=True)
class SplitDesign(Design):
    """``L``: gain; ``D = A − LC`` (any sign); ``spectral_radius`` of ``|D| = D⁺ + D⁻``;
    ``gain``: ``'width'``, ``'margin'``, ``'lmi'`` or ``'given'``; ``steady_width``:
    ``(I − |D|)⁻¹ |E − LF| Δ`` (None for callable bounds); ``missing_radius``: as for
    :class:`IntervalDesign`."""

    L: np.ndarray
    D: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None
    missing_radius: np.ndarray | None = None


@dataclass(frozen=True)
class TransformedDesign(Design):
    """``L``: gain (``A − LC`` Schur); ``poles``: eigenvalues of ``A − LC``; ``S``: the
    transformation ``z = S x``; ``R = S (A − LC) S⁻¹`` (nonnegative up to round-off; this is the
    matrix the observer propagates); ``e1``, ``e2``: the rows of eq. (48) (None when ``S`` was
    given); ``spectral_radius`` of ``|R|``; ``gain``: ``'search'`` (ivobs' default design),
    ``'given-poles'`` or ``'given'``; ``steady_width``: ``|S⁻¹|(I − |R|)⁻¹|S(E − LF)| Δ``."""

    L: np.ndarray
    R: np.ndarray
    S: np.ndarray
    e1: np.ndarray | None
    e2: np.ndarray | None
    poles: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None


@dataclass(frozen=True)
class _StepMatrices:
    """What one step needs for a given set of observed components."""

    Qp: np.ndarray  # Q⁺
    Qn: np.ndarray  # Q⁻
    Bz: np.ndarray  # S (B − L_k D_u)
    Lz: np.ndarray  # S L_k
    Gz: np.ndarray  # S (E − L_k F)
    Gp: np.ndarray  # (S (E − L_k F))⁺
    Gn: np.ndarray  # (S (E − L_k F))⁻
    # S ≠ I: coefficients of one step's error on (‖x‖∞, ‖z‖∞, ‖y‖∞, ‖u‖∞, ‖d‖∞)
    err: np.ndarray | None = None


def _bad_streams(
    res: np.ndarray, rad: np.ndarray, y: np.ndarray, ctol: float = CONSISTENCY_TOL
) -> Any:
    """The loop's test ``|res| <= rad + tol`` (:meth:`_CooperativeObserver._consistent`) over
    a record or a batch: None when it passes; for a batch the ``(B,)`` mask of streams that
    fail; True when the single record fails (the caller falls back to its loop)."""
    fail = np.abs(res) > rad + ctol * (1.0 + np.abs(y) + 2.0 * rad)
    if not fail.any():
        return None
    return fail.reshape(fail.shape[0], -1).any(axis=1) if y.ndim == 3 else True


def _hull(
    Mp: np.ndarray, Mn: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Lemma 1 with precomputed ``M⁺``, ``M⁻`` (finite bounds)."""
    return Mp @ lo - Mn @ hi, Mp @ hi - Mn @ lo


def design_delta(sys: LinearSystem) -> np.ndarray:
    """Widths ``Δ`` of the ``d`` box used by the width objectives: constant bounds as they
    are, time-varying bounds their largest width per component, callable bounds (003 Remark 1)
    ones (no better information before the data arrive)."""
    box = sys.d
    if box is None:
        return np.zeros(0)
    if isinstance(box, Box):
        w = box.hi - box.lo
        return w.max(axis=0) if box.is_time_varying else w
    return np.ones(sys.nd)


@dataclass(frozen=True)
class _SparseStep:
    """One step of a sparse system (``S = I``): the stacked matrix acting on ``[z̄; z̲]``."""

    S2: Any  # CSR [[Q⁺, −Q⁻], [−Q⁻, Q⁺]], Q = A − L_k C: one sparse product per step
    K: Any  # CSC [[L_k, B_z], [L_k, B_z]]: the known inputs [y; u] of both bounds
    Bz: np.ndarray
    Lz: np.ndarray
    Gz: np.ndarray
    Gp: np.ndarray
    Gn: np.ndarray


MAX_DENSE_DESIGN = MAX_LMI_STATES
"""Above this many states the dense design steps of this module (LMI (41), the width and margin
linear programs, similarity transforms) are refused with a :class:`~ivobs.DesignError`: pass a
gain ``L=`` (checked sparsely for ``scipy.sparse`` systems)."""


_SCALES = (
    "pass a gain L=... to 'interval' or 'interval-split' (checked with sparse algebra when A is "
    "scipy.sparse, one sparse product per step; e.g. ivobs.scenarios.heat_gain for heat-1d; "
    "docs/scale.md)"
)


def check_design_size(sys: LinearSystem, who: str, step: str) -> None:
    """:class:`DesignError` when a dense design step would run on more than
    :data:`MAX_DENSE_DESIGN` states, pointing to what scales."""
    if sys.nx > MAX_DENSE_DESIGN:
        raise DesignError(
            f"{who}: {step} is a dense design step (O(nx^2) variables or O(nx^3) work) and does "
            f"not scale to nx = {sys.nx} > {MAX_DENSE_DESIGN} states; {_SCALES}"
        )


def sparse_radius(P: Any) -> float:
    """Spectral radius of a sparse nonnegative matrix: ARPACK (Perron root, the largest in
    modulus), or the smaller of the largest row and column sums (an upper bound, Perron–
    Frobenius) when ARPACK does not converge. Small matrices: dense eigenvalues."""
    n = P.shape[0]
    if n <= MAX_DENSE_DESIGN:
        return spectral_radius(P.toarray())
    from scipy.sparse.linalg import ArpackNoConvergence, eigs

    bound = float(min(abs(P).sum(axis=1).max(), abs(P).sum(axis=0).max()))
    try:
        val = eigs(P, k=1, which="LM", tol=1e-8, ncv=min(n - 1, 40), return_eigenvectors=False)
    except ArpackNoConvergence:
        return bound
    return min(float(np.abs(val[0])), bound)


def sparse_gain_check(sys: LinearSystem, L: np.ndarray, who: str, nonnegative: bool) -> Any:
    """``D = A − LC`` as a sparse matrix, checked as :func:`check_nonnegative_schur` /
    :func:`check_abs_schur` do, without dense algebra (``scipy.sparse`` systems)."""
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
                f"{coo.data[j]:.6g} < 0 (002 Theorem 4 / 003 Assumption 2.B need A − LC >= 0); "
                "use 'interval-split' or 'interval-transformed' with this gain"
            )
    rho = sparse_radius(abs(D))
    if rho >= 1.0:
        what = "A − LC is not Schur" if nonnegative else "|A − LC| = D⁺ + D⁻ is not Schur"
        ref = "003 Assumption 2.A" if nonnegative else "003 Theorem 3"
        raise DesignError(f"{who}: {what}: spectral radius {rho:.6g} >= 1 ({ref})")
    return D


def _norm_inf(M: np.ndarray) -> float:
    """``‖M‖_∞`` (largest absolute row sum; 0 for an empty matrix)."""
    return float(np.linalg.norm(M, np.inf))


def _largest(*arrays: np.ndarray) -> float:
    """``max |a_i|`` over all the entries of ``arrays`` (0 when they are empty)."""
    return max((float(np.max(np.abs(a), initial=0.0)) for a in arrays), default=0.0)


def transform_conversion(S: np.ndarray, Si: np.ndarray, who: str) -> tuple[float, float]:
    """Rounding of ``x = S⁻¹ z`` evaluated with the computed inverse ``Si`` (module docstring,
    "Rounding", ``S ≠ I``): ``(g, c)`` with ``g >= ‖Si S − I‖_∞`` (the residual plus the
    rounding of its evaluation, ``γ_{n+1} |Si| |S|``) and ``c = γ_{n+1} ‖Si‖_∞``. For the true
    ``z = S x`` in a box of magnitude ``ζ`` whose image by Lemma 1 of ``Si`` has magnitude
    ``ξ``: ``|x − Si z| <= |Si S − I| |x|``, so ``‖x‖ <= (ξ + c ζ) / (1 − g)`` and the box of
    ``x`` is the image widened by ``c ζ + g (ξ + c ζ) / (1 − g)``. ``DesignError`` when
    ``g >= 1/2`` (``S`` numerically singular)."""
    n = S.shape[0]
    gam = _gamma(n + 1)
    g = _norm_inf(np.abs(Si @ S - np.eye(n)) + gam * (np.abs(Si) @ np.abs(S)))
    if not g < 0.5:
        raise DesignError(
            f"{who}: the transformation S is numerically singular (‖S⁻¹S − I‖ = {g:.3g} in "
            f"floating point, cond(S) = {np.linalg.cond(S):.3g}): no guaranteed bounds through "
            "x = S⁻¹ z; give another L, R, e1, e2 or S"
        )
    return g, gam * _norm_inf(Si)


def transform_step_error(
    S: np.ndarray,
    Si: np.ndarray,
    A: np.ndarray,
    Lk: np.ndarray,
    C: np.ndarray,
    B: np.ndarray,
    Du: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    Q: np.ndarray,
    mats: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> np.ndarray:
    """Coefficients ``(c_x, c_z, c_y, c_u, c_d)`` of the error of one step of the recursion in
    ``z = S x`` (``S ≠ I``; module docstring, "Rounding"): the computed step differs from the
    exact ``z+ = S M S⁻¹ z + S L_k y + S(B − L_k D_u) u + S(E − L_k F) d`` (``M = A − L_k C``,
    true ``z = S x``) by at most ``c_x ‖x‖ + c_z ‖z‖ + c_y ‖y‖ + c_u ‖u‖ + c_d ‖d‖``
    (∞-norms; ``x``, ``z``: the true state, bounded by its boxes):

    * ``(Q − S M S⁻¹) z = (Q S − S M̂) x + S (M̂ − M) x`` with ``M̂ = fl(A − L_k C)``: the
      residual ``Q S − S M̂`` is evaluated (plus ``γ (|Q| |S| + |S| |M̂|)`` for its rounding)
      and ``|M̂ − M| <= γ (|A| + |L_k| |C|)`` — no ``cond(S)`` factor: the error acts on
      ``x``, not on ``S⁻¹`` applied to ``z``;
    * the computed ``S L_k``, ``S (B − L_k D_u)``, ``S (E − L_k F)``: ``γ |S|`` times the
      absolute values of their factors;
    * the evaluation of the step (split form, sums of ``m`` terms): ``γ_m`` times
      ``‖Q‖ ‖z‖ + ‖S L_k‖ ‖y‖ + ‖S (B − L_k D_u)‖ ‖u‖ + ‖S (E − L_k F)‖ ‖d‖``.
    """
    n, ny, nu, nd = A.shape[0], C.shape[0], B.shape[1], E.shape[1]
    Bz, Lz, Gz = mats
    gam = _gamma(2 * n + 2 * ny + nu + 2 * nd + 8)
    aS, aL = np.abs(S), np.abs(Lk)
    Mh = A - Lk @ C
    res = np.abs(Q @ S - S @ Mh) + gam * (np.abs(Q) @ aS + aS @ np.abs(Mh))
    c_x = _norm_inf(res + gam * (aS @ (np.abs(A) + aL @ np.abs(C))))
    c_z = gam * _norm_inf(Q)
    c_y = gam * (_norm_inf(Lz) + 2.0 * _norm_inf(aS @ aL))
    c_u = gam * (_norm_inf(Bz) + 2.0 * _norm_inf(aS @ (np.abs(B) + aL @ np.abs(Du))))
    c_d = gam * (_norm_inf(Gz) + 2.0 * _norm_inf(aS @ (np.abs(E) + aL @ np.abs(F))))
    return np.array([c_x, c_z, c_y, c_u, c_d])


@dataclass(frozen=True)
class RoundingBound:
    """The floating-point model of the recursion with a gain ``L`` (``S = I``; module
    docstring, "Rounding"). One step's error is at most
    ``gamma (a_z ‖z‖_∞ + a_y ‖y‖_∞ + a_u ‖u‖_∞ + a_d ‖d‖_∞)`` (``‖d‖``: the largest bound
    magnitude); ``kappa = ‖(I − |A − LC|)⁻¹‖_∞`` amplifies it over the steps with complete
    measurements; ``mu``, ``nu``: the factors on the bounds' magnitude and on the data scale
    that the outward margin of the vectorised path needs beyond
    :data:`~ivobs.estimators.base.ROUNDING`."""

    kappa: float
    gamma: float
    a_z: float
    a_y: float
    a_u: float
    a_d: float
    mu: float
    nu: float


def rounding_bound(sys: LinearSystem, L: np.ndarray, D: Any) -> RoundingBound:
    """:class:`RoundingBound` of the recursion with gain ``L`` and ``D = A − LC`` (dense or
    ``scipy.sparse``; ``|D|`` Schur): ``mu = κ γ a_z / ROUNDING`` and
    ``nu = κ γ (a_y + a_u' + a_d') / ROUNDING``, where ``a_u'``, ``a_d'`` bound the input and
    disturbance terms relative to the base data scale ``s`` (which bounds ``g_j |u_j|``,
    ``|E| |d|``, ``|F| |d|``)."""
    n, ny, nu, nd = sys.nx, sys.ny, sys.nu, sys.nd
    absL = np.abs(L)
    if sys.is_sparse:
        from scipy.sparse import identity
        from scipy.sparse.linalg import spsolve

        Aa = abs(sys.sparse("A"))
        Ca = abs(sys.sparse("C"))
        Da = abs(D).tocsc()
        with np.errstate(all="ignore"):
            kap = np.atleast_1d(spsolve((identity(n, format="csc") - Da).tocsc(), np.ones(n)))
    else:
        Aa, Ca = np.abs(sys.A_at(0)), np.abs(sys.C_at(0))
        with np.errstate(all="ignore"):
            kap = np.linalg.solve(np.eye(n) - np.abs(D), np.ones(n))
    # (I − |D|)⁻¹ >= 0 when |D| is Schur: its row sums are the amplification of each component
    kappa = float(kap.max()) if np.all(np.isfinite(kap)) and kap.min() >= 1.0 - 1e-9 else np.inf
    # terms per row of Q_k = A − L_k C (any pattern): products with structural zeros are exact
    if sys.is_sparse:
        from scipy.sparse import csr_matrix

        P = ((Aa != 0).astype(float) + csr_matrix(absL) @ (Ca != 0).astype(float)).tocsr()
        P.eliminate_zeros()
        row_nnz = int(np.max(np.diff(P.indptr), initial=1))
    else:
        P = (Aa != 0) | (absL @ (Ca != 0) != 0)
        row_nnz = int(np.max(P.sum(axis=1), initial=1))
    m = 2 * max(row_nnz, 1) + nu + 2 * ny + 2 * nd + 6
    gamma = _gamma(m)
    # Q_k z (with the rounding of Q_k = A − L_k C itself and the true state inside the box)
    a_z = 3.0 * float(np.max(np.asarray(Aa @ np.ones(n)).ravel() + absL @ (Ca @ np.ones(n))))
    a_y = float(np.max(absL.sum(axis=1), initial=0.0))  # L_k y
    a_u = a_u_s = 0.0  # (B − L_k D_u) u, and the same relative to the data scale
    if nu:
        B, Du = np.abs(sys.B_at(0)), np.abs(sys.D_at(0))
        Mu = 2.0 * (B + absL @ Du)
        a_u = float(np.max(Mu.sum(axis=1)))
        g = np.max(np.vstack([B, Du]), axis=0)  # the base scale bounds g_j |u_j|
        a_u_s = float(np.max((Mu[:, g > 0] / g[g > 0]).sum(axis=1), initial=0.0))
    a_d = a_d_s = 0.0  # (E − L_k F) d and its Lemma-1 bounds
    if nd:
        E, F = np.abs(sys.E_at(0)), np.abs(sys.F_at(0))
        a_d = 3.0 * float(np.max((E + absL @ F).sum(axis=1)))
        # |E| |d| <= s, |F| |d| <= s (base scale) for Box bounds; nothing is known for callables
        a_d_s = 3.0 * (1.0 + a_y) if isinstance(sys.d, Box) else 0.0
    mu = kappa * gamma * a_z / ROUNDING
    nu_ = kappa * gamma * (a_y + a_u_s + a_d_s) / ROUNDING
    return RoundingBound(kappa, gamma, a_z, a_y, a_u, a_d, mu, nu_)


class _CooperativeObserver(Estimator):
    """Shared machinery (module docstring): the split-form recursion in ``z = S x``."""

    needs_x0: ClassVar[bool] = True
    _S: np.ndarray | None = None
    _Si: np.ndarray | None = None
    # rounding factors beyond the base margin (module docstring, "Rounding"); 1: none
    _mu: float = 1.0
    _nu: float = 1.0
    _ctol: float = CONSISTENCY_TOL
    _rounding: RoundingBound | None = None  # None: the base margin only (S ≠ I)

    def _set_rounding(self, L: np.ndarray, D: Any) -> None:
        """The margin factors of :func:`rounding_bound` (``S = I``)."""
        rb = rounding_bound(self.sys, L, D)
        if not np.isfinite(rb.mu + rb.nu):
            raise DesignError(
                f"{self.name}: (I − |A − LC|)⁻¹ could not be evaluated (|A − LC| has spectral "
                "radius too close to 1): the rounding of the recursion cannot be bounded"
            )
        self._mu, self._nu = max(1.0, rb.mu), max(1.0, rb.nu)
        sizes = np.array([2 * self.sys.nx, self.sys.ny, self.sys.nu])
        keep = sizes > 0  # the blocks of v = [z̲; z̄; y_obs; u] (reduceat needs nonempty ones)
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        self._round_blocks = (starts[keep], np.array([rb.a_z, rb.a_y, rb.a_u])[keep])
        self._ctol = CONSISTENCY_TOL * max(self._mu, self._nu)
        self._rounding = rb

    def _local_error(self, v: np.ndarray, dbox: Box | None) -> float:
        """The rounding bound of one step of the loop (module docstring, "Rounding"),
        ``γ (a_z ‖z‖_∞ + a_y ‖y_obs‖_∞ + a_u ‖u‖_∞ + a_d ‖d‖_∞)``, for ``v = [z̲; z̄; y_obs; u]``
        (fresh; overwritten): the largest entry of each block (one ``reduceat``)."""
        rb = self._rounding
        assert rb is not None
        idx, coef = self._round_blocks
        e = float(coef.dot(np.maximum.reduceat(np.abs(v, out=v), idx)))
        if rb.a_d and dbox is not None:
            dm = self.__dict__.get("_dmax") if self.sys.has_constant_bounds else None
            if dm is None:
                dm = float(max(np.abs(dbox.lo).max(), np.abs(dbox.hi).max()))
                if self.sys.has_constant_bounds:
                    self.__dict__["_dmax"] = dm
            e += rb.a_d * dm
        return rb.gamma * e

    def _widen(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """In place: ``(mu − 1) ROUNDING |bound|`` on top of the base margin (when ``mu > 1``)."""
        if self._mu > 1.0:
            m = np.maximum(np.abs(lo), np.abs(hi))
            m *= (self._mu - 1.0) * ROUNDING
            lo -= m
            hi += m
        return lo, hi

    def _step_scale(self, k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> float:
        s = super()._step_scale(k, u_k, y_k, t_k)
        return s * self._nu if self._nu > 1.0 else s

    def _data_scale(self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> np.ndarray:
        s = super()._data_scale(u, y, t)
        if self._nu > 1.0:
            s *= self._nu
        return s

    def _setup(self, L: np.ndarray, S: np.ndarray | None = None) -> None:
        sys = self.sys
        # sparse A (large systems, S = I): one sparse product of the stacked system per step
        self._sparse = sys.is_sparse and S is None
        A = None if self._sparse else sys.A_at(0)
        B, C, Du, E, F = (sys.B_at(0), sys.C_at(0), sys.D_at(0), sys.E_at(0), sys.F_at(0))
        self._A, self._B, self._C, self._Du, self._E, self._F = A, B, C, Du, E, F
        self._L = L
        self._S = S
        self._Si = None if S is None else np.linalg.inv(S)
        self._Si_pm = None if S is None else (pos(self._Si), neg(self._Si))
        if S is not None:
            assert self._Si is not None
            self._tconv = transform_conversion(S, self._Si, self.name)
        self._C_pm = (pos(C), neg(C))
        self._F_pm = (pos(F), neg(F))
        self._cache: dict[bytes, Any] = {}
        self._g_cache: dict[bytes, np.ndarray] = {}
        if self._sparse:  # Lemma 1 for C on the few states it reads (point sensors)
            Cc = sys.sparse("C").tocoo()
            Rp = np.zeros((Cc.nnz, sys.ny))
            Rn = np.zeros((Cc.nnz, sys.ny))
            Rp[np.arange(Cc.nnz), Cc.row] = np.maximum(Cc.data, 0.0)
            Rn[np.arange(Cc.nnz), Cc.row] = np.maximum(-Cc.data, 0.0)
            # centre/radius form: C c = ½ (x̲ + x̄)[cols] (Rp − Rn), |C| r = ½ (x̄ − x̲)[cols] |R|
            self._C_gather = (Cc.col.astype(np.intp), 0.5 * (Rp - Rn), 0.5 * (Rp + Rn))
            # the same on the stacked state [z̄; z̲]: [C c, |C| r] = z[cols2] @ R2
            Rs, Ra = self._C_gather[1:]
            self._C_stacked = (
                np.concatenate([Cc.col, sys.nx + Cc.col]).astype(np.intp),
                np.block([[Rs, Ra], [Rs, -Ra]]),
            )
        self.valid_from = 0

    def _matrices(self, observed: np.ndarray) -> Any:
        key = observed.tobytes()
        if key not in self._cache:
            Lk = self._L * observed[None, :]
            Bz = self._B - Lk @ self._Du
            Gz = self._E - Lk @ self._F
            if self._sparse:
                self._cache[key] = self._sparse_step(Lk, Bz, Gz)
                return self._cache[key]
            Q = self._A - Lk @ self._C
            err = None
            if self._S is not None:
                S, Si = self._S, self._Si
                assert Si is not None
                Q = S @ Q @ Si
                Bz, Lz, Gz = S @ Bz, S @ Lk, S @ Gz
                err = transform_step_error(S, Si, self._A, Lk, self._C, self._B, self._Du,
                                           self._E, self._F, Q, (Bz, Lz, Gz))  # fmt: skip
                Lk = Lz
            self._cache[key] = _StepMatrices(pos(Q), neg(Q), Bz, Lk, Gz, pos(Gz), neg(Gz), err)
        return self._cache[key]

    def _sparse_step(self, Lk: np.ndarray, Bz: np.ndarray, Gz: np.ndarray) -> _SparseStep:
        from scipy.sparse import bmat, csc_matrix, csr_matrix

        Q = (self.sys.sparse("A") - csr_matrix(Lk) @ self.sys.sparse("C")).tocsr()
        Qp, Qn = Q.maximum(0).tocsr(), (-Q).maximum(0).tocsr()
        S2 = bmat([[Qp, -Qn], [-Qn, Qp]], format="csr")
        S2.eliminate_zeros()
        K = csc_matrix(np.vstack([np.hstack([Lk, Bz])] * 2))  # few columns: CSC
        return _SparseStep(S2, K, Bz, Lk, Gz, pos(Gz), neg(Gz))

    def _initial_state(self) -> dict[str, Any]:
        assert self.x0 is not None
        lo, hi = self.x0.lo.copy(), self.x0.hi.copy()
        if self._S is not None:
            # 002 (42a-b), widened by the rounding of the products (γ_{n+1} |S| |x0|)
            mag = np.abs(self._S) @ np.maximum(np.abs(lo), np.abs(hi))
            lo, hi = image_bounds(self._S, lo, hi)
            mag *= _gamma(self.sys.nx + 1)
            lo, hi = lo - mag, hi + mag
        if self.__dict__.get("_sparse"):  # one stacked vector [z̄; z̲]
            return {"z": np.concatenate([hi, lo])}
        return {"lo": lo, "hi": hi}

    def _to_x(self, k: int, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._Si is None:
            return lo, hi
        if k == 0:  # 002 (42): the prior box itself at k = 0
            assert self.x0 is not None
            return self.x0.lo.copy(), self.x0.hi.copy()
        assert self._Si_pm is not None
        xlo, xhi = _hull(*self._Si_pm, lo, hi)  # 002 (42e-f)
        # the computed inverse and the rounding of the products (transform_conversion)
        g, c = self._tconv
        cz = c * _largest(lo, hi)
        xi = _largest(xlo, xhi)
        e = cz + g * (xi + cz) / (1.0 - g)
        return xlo - e, xhi + e

    def _consistent(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        u: np.ndarray,
        y: np.ndarray,
        obs: np.ndarray,
        dbox: Box,
    ) -> bool:
        """``y`` (observed components) ∈ ``C[lo, hi] + D_u u + F[d]`` up to round-off."""
        if self._sparse:
            return self._consistent_sparse(lo, hi, u, y, obs, dbox)
        plo, phi = _hull(*self._C_pm, lo, hi)
        if self.sys.has_constant_bounds:  # Lemma 1 of F on the bounds, once
            f = self.__dict__.get("_f_const")
            if f is None:
                f = self.__dict__["_f_const"] = _hull(*self._F_pm, dbox.lo, dbox.hi)
            flo, fhi = f
        else:
            flo, fhi = _hull(*self._F_pm, dbox.lo, dbox.hi)
        du = self._Du @ u
        plo, phi = plo + du + flo, phi + du + fhi
        tol = self._ctol * (1.0 + np.abs(y) + (phi - plo))  # NaN (missing) compares False
        bad = ((y < plo - tol) | (y > phi + tol)) & obs
        return not bool(np.any(bad))

    def _consistent_sparse(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        u: np.ndarray,
        y: np.ndarray,
        obs: np.ndarray,
        dbox: Box,
    ) -> bool:
        """:meth:`_consistent` in centre/radius form on the few states ``C`` reads (sparse
        systems): ``|y − C c − D_u u − F c_d| <= |C| r + |F| r_d`` up to round-off."""
        cols, Rs, Ra = self._C_gather
        clo, chi = lo[cols], hi[cols]
        yc = (clo + chi) @ Rs
        yr = (chi - clo) @ Ra
        if u.shape[0]:
            yc += self._Du @ u
        fd = self._f_mid(dbox)
        yc += fd[0]
        yr += fd[1]
        dev = np.abs(y - yc)
        dev -= yr
        if not (dev > 0.0).any():  # NaN (missing) compares False
            return True
        tol = self._ctol * (1.0 + np.abs(y) + 2.0 * yr)
        return not bool(np.any((dev > tol) & obs))

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        if self._sparse:
            return self._step_sparse(state, k, u_k, y_k)
        zlo, zhi = state["lo"], state["hi"]
        xlo, xhi = self._to_x(k, zlo, zhi)
        obs = ~np.isnan(y_k)
        dbox = self.sys.d_at(k, y_k)
        if obs.any() and not self._consistent(xlo, xhi, u_k, y_k, obs, dbox):
            state["_inconsistent"] = True
            obs = np.zeros_like(obs)
        m = self._matrices(obs)
        y_obs = np.where(obs, y_k, 0.0)
        known = m.Bz @ u_k + m.Lz @ y_obs
        glo, ghi = _hull(m.Gp, m.Gn, dbox.lo, dbox.hi)
        state["hi"] = m.Qp @ zhi - m.Qn @ zlo + known + ghi
        state["lo"] = m.Qp @ zlo - m.Qn @ zhi + known + glo
        if self._rounding is not None:  # this step's rounding, inside the state (any pattern)
            e = self._local_error(np.concatenate([zlo, zhi, y_obs, u_k]), dbox)
            state["hi"] += e
            state["lo"] -= e
        elif m.err is not None:  # S ≠ I: transform_step_error, on the true x and z
            norms = np.array([_largest(xlo, xhi), _largest(zlo, zhi), _largest(y_obs),
                              _largest(u_k), _largest(dbox.lo, dbox.hi)])  # fmt: skip
            e = float(m.err @ norms)
            state["hi"] += e
            state["lo"] -= e
        return xlo, xhi

    def _step_sparse(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`_step` for sparse ``A`` (``S = I``): ``[z̄; z̲]+ = S2 [z̄; z̲] + K [y; u] + v``
        with the stacked CSR matrix ``S2 = [[Q⁺, −Q⁻], [−Q⁻, Q⁺]]``, ``K = [[L_k, B_z];
        [L_k, B_z]]`` (sparse) and ``v = [ḡ; g̲]``: two compiled sparse products per step
        (:func:`~ivobs._recursion.csr_accumulate`)."""
        z = state["z"]
        n = z.shape[0] // 2
        obs = y_k == y_k  # not NaN
        full = bool(obs.all())
        const = self.sys.has_constant_bounds
        dbox = self.sys.d if const and self.sys.nd else self.sys.d_at(k, y_k)
        if full and not self._consistent_stacked(z, u_k, y_k, dbox):
            full = False
            obs = np.zeros_like(obs)
            state["_inconsistent"] = True
        elif not full and obs.any():
            if not self._consistent(z[n:], z[:n], u_k, y_k, obs, dbox):
                state["_inconsistent"] = True
                obs = np.zeros_like(obs)
        fast = self.__dict__.get("_fast") if full and const else None
        if fast is None:
            m = self._matrices(obs)
            fast = (m, self._input_bounds(m, obs, dbox))
            if full and const:
                self.__dict__["_fast"] = fast
        m, v = fast
        nz = v.copy()
        csr_accumulate(m.S2, z, nz)
        csr_accumulate(m.K, np.concatenate([y_k if full else np.where(obs, y_k, 0.0), u_k]), nz)
        if self._rounding is not None:  # this step's rounding, inside the state (any pattern)
            yo = y_k if full else np.where(obs, y_k, 0.0)
            e = self._local_error(np.concatenate([z, yo, u_k]), dbox if self.sys.nd else None)
            nz[:n] += e
            nz[n:] -= e
        state["z"] = nz
        return z[n:], z[:n]

    def _consistent_stacked(self, z: np.ndarray, u: np.ndarray, y: np.ndarray, dbox: Box) -> bool:
        """:meth:`_consistent_sparse` for a complete ``y`` on the stacked state."""
        cols2, R2 = self._C_stacked
        ny = y.shape[0]
        p = z[cols2] @ R2  # [C c, |C| r]
        fd = self._f_mid(dbox)
        yc = p[:ny] + fd[0]
        if u.shape[0]:
            yc += self._Du @ u
        yr = p[ny:] + fd[1]
        dev = np.abs(y - yc)
        if not (dev > yr).any():
            return True
        tol = self._ctol * (1.0 + np.abs(y) + 2.0 * yr)
        return not bool(np.any(dev - yr > tol))

    def _f_mid(self, dbox: Box) -> tuple[np.ndarray, np.ndarray]:
        """Centre and radius of ``F d`` over the bounds (cached for constant bounds)."""
        const = self.sys.has_constant_bounds
        fd = self.__dict__.get("_f_mid_c") if const else None
        if fd is None:
            flo, fhi = _hull(*self._F_pm, dbox.lo, dbox.hi)
            fd = (0.5 * (flo + fhi), 0.5 * (fhi - flo))
            if const:
                self.__dict__["_f_mid_c"] = fd
        return fd

    def _input_bounds(self, m: Any, obs: np.ndarray, dbox: Box) -> np.ndarray:
        """``[ḡ; g̲]`` (Lemma 1 of ``G_k = E − L_k F`` on the bounds of ``d``), cached per
        missing pattern when the bounds are constant."""
        const = self.sys.has_constant_bounds
        key = obs.tobytes()
        hit = self._g_cache.get(key) if const else None
        if hit is None:
            glo, ghi = _hull(m.Gp, m.Gn, dbox.lo, dbox.hi)
            hit = np.concatenate([ghi, glo])
            if const:
                self._g_cache[key] = hit
        return hit

    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Midpoint and radius recursions (module docstring); ``None`` (loop) for callable
        bounds, missing samples, time-varying bounds shorter than the record, or an
        inconsistent measurement (the loop reports it and predicts without it).

        The midpoint ``c+ = Q c + S L y + S(B − L D_u) u + gc`` and the innovation
        ``y − C S⁻¹ c − D_u u − fc`` are outputs of one :class:`~ivobs._recursion.SplitFilter`
        pass; the radius ``r+ = |Q| r + gr`` does not depend on the data (computed once per
        record length, shared by the streams of a batch)."""
        box = self.sys.d
        T = y.shape[-2]
        if not T or (box is not None and not isinstance(box, Box)):
            return None  # (an empty record: the loop)
        if box is not None and box.is_time_varying and box.lo.shape[0] < T:
            return None
        if np.isnan(y).any():
            return None
        if self._sparse:
            return self._run_sparse(u, y, T)
        if self._S is not None and not np.isfinite(self._transform_kappa()):
            return None  # |Q| not Schur in floating point: the loop bounds each step's error
        vec = self._vector_terms(T)
        filt, rad, yrad, gsig, fsig = vec
        nx = self.sys.nx
        hi = np.empty((*y.shape[:-1], nx))
        sig = [y, u] if gsig is None else [y, u, gsig, fsig]
        (xc, innov), shared = filt.run(sig, x0=self._centre0(), out=[hi, None], temp=[1])
        s_x, s_i = (None, None) if shared is None else shared
        if self._Si is not None:  # 002 (42): the prior box itself at k = 0
            assert self.x0 is not None
            row0 = self.x0.center - (0.0 if s_x is None else s_x[0])
            xc[..., 0, :] = row0
            inn0 = y[..., 0, :] - self.x0.center @ self._C.T - u[..., 0, :] @ self._Du.T
            inn0 -= self._fc0 + (0.0 if s_i is None else s_i[0])
            innov[..., 0, :] = inn0
        # the loop's test is |res| <= pr + tol(|y|, pr); without |y| the band is narrower, so
        # passing it decides without touching y again
        bad = None
        if not within_band(innov, s_i, yrad + self._ctol * (1.0 + 2.0 * yrad)):
            bad = _bad_streams(innov if s_i is None else innov + s_i, yrad, y, self._ctol)
            if bad is True:
                return None
        del innov
        lo = np.empty_like(hi)
        if s_x is None:
            np.subtract(xc, rad, out=lo)
            xc += rad
        else:
            np.add(xc, s_x - rad, out=lo)
            xc += s_x + rad
        self._widen(lo, xc)
        if self._S is not None:
            extra = self._transform_margin(lo, xc, u, y)
            lo -= extra
            xc += extra
        if bad is not None:  # only the streams with an inconsistent measurement by the loop
            return redo_streams(self, u, y, t, lo, xc, bad)
        return lo, xc

    def _transform_kappa(self) -> float:
        """``κ_z = ‖(I − |Q|)⁻¹‖_∞`` of the step with every output observed (``S ≠ I``):
        how the steps' errors add up in ``z`` (``inf`` if ``|Q|`` is not Schur)."""
        kap = self.__dict__.get("_kappa_z")
        if kap is None:
            m = self._matrices(np.ones(self.sys.ny, dtype=bool))
            n = self.sys.nx
            with np.errstate(all="ignore"):
                try:
                    v = np.linalg.solve(np.eye(n) - (m.Qp + m.Qn), np.ones(n))
                except np.linalg.LinAlgError:
                    v = np.full(n, np.inf)
            ok = np.all(np.isfinite(v)) and v.min() >= 1.0 - 1e-9
            kap = self.__dict__["_kappa_z"] = float(v.max()) if ok else np.inf
        return kap

    def _transform_margin(
        self, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, y: np.ndarray
    ) -> np.ndarray:
        """The rounding of the vectorised path in ``z = S x`` (``S ≠ I``; module docstring,
        "Rounding"): per step, ``‖Si‖ κ_z max_{j<=k} δ_j`` plus the conversion to ``x``
        (:func:`transform_conversion`), with ``δ_j`` from :func:`transform_step_error` on the
        running maxima of ``‖x‖`` (the bounds), ``‖z‖ <= 2 ‖S‖ ‖x‖``, ``‖y‖``, ``‖u‖`` and
        ``‖d‖``. When the margin from each stream's whole-record maxima is below
        ``1e-3 ROUNDING`` that one is used (whole-array reductions): shape ``(..., 1, 1)``;
        else the running maxima are taken per block of ``T / 64`` steps (the maximum up to
        the end of a step's block): shape ``(..., T, 1)``."""
        assert self._S is not None and self._Si is not None
        m = self._matrices(np.ones(self.sys.ny, dtype=bool))
        assert m.err is not None
        c_x, c_z, c_y, c_u, c_d = m.err
        nS, nSi, kap = _norm_inf(self._S), _norm_inf(self._Si), self._transform_kappa()
        g, c = self._tconv
        box = self.sys.d
        Dm = 0.0
        if isinstance(box, Box):
            Dm = _largest(box.lo, box.hi)

        def margin(X: Any, Y: Any, U: Any) -> Any:
            delta = (c_x + 2.0 * nS * c_z) * X + c_y * Y + c_u * U + c_d * Dm
            zeta = 2.0 * nS * X
            return nSi * kap * delta + c * zeta + g * (X + c * zeta) / (1.0 - g)

        lead = y.shape[:-2]
        B = int(np.prod(lead))

        def largest(a: np.ndarray) -> np.ndarray:  # max |a| per stream (u may be shared)
            flat = a.reshape(B, -1) if a.ndim == y.ndim else a.reshape(1, -1)
            if not flat.shape[1]:
                return np.zeros(flat.shape[0])
            return np.maximum(flat.max(axis=1), -flat.min(axis=1))

        extra = margin(np.maximum(largest(hi), largest(lo)), largest(y), largest(u))
        if float(np.max(extra)) <= 1e-3 * ROUNDING:
            return extra.reshape(*lead, 1, 1)

        # per block of K steps (64 blocks: contiguous reductions), then the running maximum
        # over blocks: at step k, the maximum up to the end of k's block (>= the one up to k)
        T = y.shape[-2]
        K = max(1, -(-T // 64))
        starts = np.arange(0, T, K)

        def running(a: np.ndarray) -> np.ndarray:
            if not a.shape[-1]:
                return np.zeros((*a.shape[:-2], starts.size))
            r = np.maximum(
                np.maximum.reduceat(a, starts, axis=-2).max(axis=-1),
                -np.minimum.reduceat(a, starts, axis=-2).min(axis=-1),
            )
            return np.maximum.accumulate(r, axis=-1, out=r)

        X = np.maximum(running(hi), running(lo))
        extra = margin(X, running(y), running(u))
        return np.repeat(extra, K, axis=-1)[..., :T, None]

    def _disturbance_images(self, T: int) -> tuple[Any, ...]:
        """The step matrices with every output observed and Lemma 1's bounds of the disturbance
        terms over ``T`` steps: ``(m, glo, ghi, flo, fhi)``, ``[glo, ghi] ∋ (S(E − LF)) d`` and
        ``[flo, fhi] ∋ F d`` (``(T, ·)`` for time-varying bounds; zeros without ``d``)."""
        box = self.sys.d
        n, ny = self.sys.nx, self.sys.ny
        m = self._matrices(np.ones(ny, dtype=bool))
        if box is None:
            return m, np.zeros(n), np.zeros(n), np.zeros(ny), np.zeros(ny)
        dlo, dhi = (box.lo[:T], box.hi[:T]) if box.is_time_varying else (box.lo, box.hi)
        glo, ghi = image_bounds(m.Gz, dlo, dhi)
        flo, fhi = image_bounds(self._F, dlo, dhi)
        return m, glo, ghi, flo, fhi

    def _run_sparse(
        self, u: np.ndarray, y: np.ndarray, T: int
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Sparse ``A``: the bounds themselves, ``[z̄; z̲]+ = S2 [z̄; z̲] + v[k]``, one sparse
        product per step with every input term ``v`` precomputed by one matrix product
        (:class:`~ivobs._recursion.LinearFilter`, loop form); then the consistency of ``y``."""
        n = self.sys.nx
        m, glo, ghi, flo, fhi = self._disturbance_images(T)
        two = np.vstack
        W = [two([m.Lz, m.Lz]), two([m.Bz, m.Bz])]
        sig = [y, u]
        g = None
        if glo.ndim == 2:  # time-varying bounds: one more (shared) input
            W.append(np.eye(2 * n))
            sig.append(np.broadcast_to(np.hstack([ghi, glo]), (*y.shape[:-2], T, 2 * n)))
        else:
            g = np.concatenate([ghi, glo])
        filt = LinearFilter(m.S2, W, [], g=g)
        lead = y.shape[:-2]
        sig = [np.broadcast_to(a, (*lead, *a.shape[-2:])) for a in sig]
        X = filt.states(sig, x0=self._initial_state()["z"])
        hi, lo = X[..., :n], X[..., n:]
        # consistency of y[k] with C[x̲_k, x̄_k] + D_u u + F[d] (the loop's test), on the few
        # states C reads
        cols, Rs, Ra = self._C_gather
        clo, chi = lo[..., cols], hi[..., cols]
        yc = (clo + chi) @ Rs
        yc += matrix_product(u, self._Du.T) + 0.5 * (flo + fhi)
        yr = (chi - clo) @ Ra + 0.5 * (fhi - flo)
        bad = _bad_streams(y - yc, yr, y, self._ctol)
        if bad is True:
            return None
        self._widen(lo, hi)
        if bad is not None and bad.any():
            return redo_streams(self, u, y, None, lo, hi, bad)
        return lo, hi

    def _centre0(self) -> np.ndarray:
        z0 = self._initial_state()
        return 0.5 * (z0["lo"] + z0["hi"])

    def _vector_terms(self, T: int) -> tuple[Any, ...]:
        """What the vectorised path needs for a record of ``T`` steps (cached): the filter, the
        radius ``(T, nx)`` in ``x`` coordinates, the output band radius ``|C| r + fr`` and,
        for time-varying bounds, the known-input signals ``gc`` and ``fc``."""
        cached = self.__dict__.get("_vec")
        if cached is not None and cached[0] == T:
            return cached[1]
        n, ny = self.sys.nx, self.sys.ny
        m, glo, ghi, flo, fhi = self._disturbance_images(T)
        gc, gr = 0.5 * (glo + ghi), 0.5 * (ghi - glo)
        fc, fr = 0.5 * (flo + fhi), 0.5 * (fhi - flo)
        Q = m.Qp - m.Qn
        H = np.eye(n) if self._Si is None else self._Si
        tv = gc.ndim == 2
        W = [m.Lz, m.Bz] + ([np.eye(n), np.zeros((n, ny))] if tv else [])
        J = [[None] * len(W), [np.eye(ny), -self._Du] + ([None, -np.eye(ny)] if tv else [])]
        filt = SplitFilter(
            Q, W, [H, -self._C @ H], J, g=None if tv else gc, h=[None, None if tv else -fc]
        )
        z0 = self._initial_state()
        r0 = 0.5 * (z0["hi"] - z0["lo"])
        if tv:
            rad = LinearFilter(m.Qp + m.Qn, [np.eye(n)], [np.abs(H)]).run([gr], x0=r0)[0]
        else:
            rad = LinearFilter(m.Qp + m.Qn, [], [np.abs(H)], g=gr).run([], T=T, x0=r0)[0]
        if self._Si is not None:
            assert self.x0 is not None
            rad[0] = self.x0.radius
        yrad = rad @ np.abs(self._C).T + fr
        self._fc0 = fc[0] if tv else fc
        terms = (filt, rad, yrad, gc if tv else None, fc if tv else None)
        self.__dict__["_vec"] = (T, terms)
        return terms

    # -- shared design helpers ------------------------------------------------------------
    def _check_gain(self, L: Any) -> np.ndarray:
        return as_matrix("L", L, self.sys.nx, self.sys.ny, vector="col")

    def _steady(self, D: Any, L: np.ndarray) -> np.ndarray | None:
        if self.sys.nd and not isinstance(self.sys.d, Box):
            return None
        G = self._E - L @ self._F
        if self._sparse:  # (I − |D|)⁻¹ |G| Δ by a sparse solve
            from scipy.sparse import identity
            from scipy.sparse.linalg import spsolve

            M = (identity(D.shape[0], format="csc") - abs(D)).tocsc()
            return np.atleast_1d(spsolve(M, np.abs(G) @ design_delta(self.sys)))
        return steady_width(D, G, design_delta(self.sys))

    def _missing_radius(self, L: np.ndarray) -> np.ndarray | None:
        if self.sys.is_sparse:
            return None
        return missing_radius(self.sys.A_at(0), self.sys.C_at(0), L)

    def _given_gain(self, L: Any, nonnegative: bool) -> tuple[np.ndarray, Any, float]:
        """A user's gain, checked (sparse algebra for sparse systems): ``(L, D, ρ)`` with ``ρ``
        the spectral radius of ``D`` (``nonnegative``) or of ``|D|``."""
        L = self._check_gain(L)
        if self.sys.is_sparse:
            D = sparse_gain_check(self.sys, L, self.name, nonnegative)
            return L, D, sparse_radius(abs(D))
        A, C = self.sys.A_at(0), self.sys.C_at(0)
        if nonnegative:
            D = check_nonnegative_schur(A, C, L, self.name)
            return L, D, spectral_radius(D)
        D = check_abs_schur(A, C, L, self.name)
        return L, D, spectral_radius(np.abs(D))


@register
class IntervalObserver(_CooperativeObserver):
    """Interval observer with ``A − LC`` nonnegative and Schur (002 eqs. 36–37, Theorem 4;
    003 eq. 3, Theorem 1; bounds from measurements as in 003 Remark 1)::

        x̄[k+1] = A x̄ + B u + L (y − C x̄ − D_u u) + Ḡ,    Ḡ = G⁺ d_hi − G⁻ d_lo
        x̲[k+1] = A x̲ + B u + L (y − C x̲ − D_u u) + G̲,    G̲ = G⁺ d_lo − G⁻ d_hi,  G = E − LF

    Errors ``x̄ − x``, ``x − x̲`` obey ``e+ = (A − LC) e + (nonnegative input)``: a
    nonnegative ``A − LC`` keeps them nonnegative (002 Lemma 3), Schur keeps them bounded.
    ``d`` bounds may be callables ``(k, y_k) -> Box`` (003 Remark 1, the Hénon example).

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Gain** (``L=`` to give one; it must make ``A − LC`` nonnegative and Schur):
    ``gain="lmi"``: LMI (41) of 002 with diagonal ``P`` (a margin maximised,
    :func:`ivobs.design.cooperative.nonnegative_gain`); ``gain="width"`` (default): that gain
    refined by linear programs that lower the steady-state width ``(I − D)⁻¹|G|Δ`` while keeping
    ``D >= 0`` (:func:`ivobs.design.cooperative.refine_width`; never wider than the LMI gain,
    and among equally good gains the smallest, e.g. with redundant noise-free sensors; a gap of
    one output that the LMI gain rides out stays bounded). When no gain makes ``A − LC``
    nonnegative and Schur (002 Example 2, 003 §IV.A) a :class:`~ivobs.DesignError` says so: use
    ``interval-split`` or ``interval-transformed``.

    Missing samples, inconsistent data and the vectorised path: see the module docstring.
    """

    name = "interval"
    order = 40
    summary = "interval observer, A − LC nonnegative and Schur (002 eq. 36, 003 Theorem 1)"
    reference = "002 Section V.A, eqs. (36)-(41); 003 Theorem 1, eq. (3)"

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        gain: str = "width",
        **base_options: Any,
    ):
        super().__init__(sys, x0, **base_options)
        if L is None:
            if gain not in ("lmi", "width"):
                raise IvobsError(f"gain: expected 'lmi' or 'width', got {gain!r}")
            check_design_size(sys, self.name, f"the gain design gain={gain!r} (LMI (41))")
            A, _, C, _, E, F = sys.matrices_at(0)
            L = nonnegative_gain(A, C, self.name)
            if gain == "width":
                L = refine_width(A, C, E, F, design_delta(sys), L, nonnegative=True)
                gain = "lmi+width"
        else:
            gain = "given"
        L, D, rho = self._given_gain(L, nonnegative=True)
        self._setup(L)
        self._set_rounding(L, D)
        self.design = IntervalDesign(
            L=L,
            D=D,
            spectral_radius=rho,
            gain=gain,
            steady_width=self._steady(D, L),
            missing_radius=self._missing_radius(L),
        )


@register
class SplitIntervalObserver(_CooperativeObserver):
    """Interval observer in the original coordinates with ``D = A − LC = D⁺ − D⁻`` of any sign
    (003 Theorem 3, eq. 5; error system (6); Corollary 1)::

        x̄[k+1] = D⁺ x̄ − D⁻ x̲ + (B − L D_u) u + L y + Ḡ
        x̲[k+1] = D⁺ x̲ − D⁻ x̄ + (B − L D_u) u + L y + G̲        (Ḡ, G̲ as for ``interval``)

    Sound for every ``L`` (Lemma 1); bounded iff ``|D| = D⁺ + D⁻`` is Schur (003's copositive
    argument: the radius obeys ``r+ = |D| r + …``).

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Gain** (``L=`` to give one; ``|A − LC|`` must be Schur):
    ``gain="lmi"``: LMIs (7)–(8) of 003 (Corollary 1; they force ``D >= 0``, the same LMI as
    002's (41)); ``gain="margin"``: a local minimum of ``ρ(|A − LC|)`` by linear programs on
    ``|A − LC| v <= s v`` alternating with the Perron vector ``v``
    (:func:`ivobs.design.cooperative.abs_schur_gain`); ``gain="width"`` (default): that gain
    refined to lower the steady-state width ``(I − |D|)⁻¹|G|Δ``
    (:func:`ivobs.design.cooperative.refine_width`). Both linear programs return the smallest
    gain among their optimal ones (audit A8). :class:`~ivobs.DesignError` when no gain
    with ``ρ(|A − LC|) < 1`` is found.

    Missing samples, rounding and the vectorised path: see the module docstring.
    """

    name = "interval-split"
    order = 60
    summary = "interval observer with D⁺/D⁻, |A − LC| Schur (003 Theorem 3, eq. 5)"
    reference = "003 Theorem 3, eqs. (5)-(8), Corollary 1"

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        gain: str = "width",
        **base_options: Any,
    ):
        super().__init__(sys, x0, **base_options)
        if L is None:
            if gain not in ("lmi", "margin", "width"):
                raise IvobsError(f"gain: expected 'width', 'margin' or 'lmi', got {gain!r}")
            what = "LMIs (7)-(8)" if gain == "lmi" else "linear programs on |A − LC|"
            check_design_size(sys, self.name, f"the gain design gain={gain!r} ({what})")
            A, _, C, _, E, F = sys.matrices_at(0)
            if gain == "lmi":
                L = nonnegative_gain(A, C, self.name)
            else:
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
                        f"{self.name}: no gain found with |A − LC| Schur: the best spectral "
                        f"radius of |A − LC| found is {rho:.6g} >= 1 (003 Theorem 3){why}; try "
                        "'interval-transformed' (needs only A − LC Schur)"
                    )
                if gain == "width":
                    L = refine_width(A, C, E, F, design_delta(sys), L, nonnegative=False)
        else:
            gain = "given"
        L, D, rho = self._given_gain(L, nonnegative=False)
        self._setup(L)
        self._set_rounding(L, D)
        self.design = SplitDesign(
            L=L,
            D=D,
            spectral_radius=rho,
            gain=gain,
            steady_width=self._steady(D, L),
            missing_radius=self._missing_radius(L),
        )


@register
class TransformedIntervalObserver(_CooperativeObserver):
    """Interval observer in coordinates ``z = S x`` where ``R = S (A − LC) S⁻¹`` is nonnegative
    (002 Theorem 5, eqs. 42–43, 48; 003 Theorem 2, eq. 4)::

        z̲_0, z̄_0 = Lemma 1 of S on x0                                           (42a-b)
        z̄+ = R z̄ + S(B − L D_u) u + S L y + ḡ,  z̲+ = R z̲ + … + g̲,  g = bounds of S(E − LF) d
                                                                                 (42c-d, 43)
        x̲, x̄ = Lemma 1 of S⁻¹ on [z̲, z̄]  (k >= 1; the prior box at k = 0)       (42e-f)

    ``A − LC`` only needs to be Schur. ``S = O_R⁻¹ O_{A−LC}`` (eq. 48) with the observability
    matrices of ``(R, e2)`` and ``(A − LC, e1)``.

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Design** (each step can be given). ``L=``, or ``poles=`` (distinct real poles placed by
    SciPy's ``place_poles``). By default (:func:`ivobs.design.similarity.default_design`) ivobs
    places distinct poles in ``(0, 1)`` (then ``R = diag(λ)`` is a nonnegative realisation),
    lowers the steady-state width ``|V|(I − Λ)⁻¹|V⁻¹ G| Δ`` of the observer in modal coordinates
    by Nelder–Mead over ``L``, then searches ``(L, e1)`` jointly over every real spectrum the
    realisation below supports (a local search; ``design.gain == 'search'``). ``R=``: a
    nonnegative matrix with the spectrum of ``A − LC`` (default
    :func:`ivobs.design.similarity.nonnegative_realization`: diagonal/bidiagonal, Suleimanova
    companion blocks, 3×3 circulants for complex pairs; ``DesignError`` with the reason when the
    spectrum has no such realisation, e.g. 003's planar example with ``L = (0.3, 0.6)``:
    ``{0, −0.5}``, negative trace). ``e1=``, ``e2=``: the rows of eq. (48) (defaults: observable
    choices with the smallest steady-state width). ``S=``: the transformation itself.

    The observer propagates with ``S (A − LC) S⁻¹`` (``design.R``), which equals the requested
    ``R`` up to round-off; the split form makes any round-off-sized negative entry sound.
    """

    name = "interval-transformed"
    order = 50
    summary = "interval observer in z = S x with nonnegative R (002 Theorem 5, 003 Theorem 2)"
    reference = "002 Section V.B, Theorem 5, eqs. (42)-(48); 003 Theorem 2, eq. (4)"

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        poles: Any = None,
        R: Any = None,
        S: Any = None,
        e1: Any = None,
        e2: Any = None,
        **base_options: Any,
    ):
        super().__init__(sys, x0, **base_options)
        # every step here (pole placement, the realisation R, S by eq. (48), the dense n x n
        # transform used at every step) is dense
        check_design_size(sys, self.name, "the similarity transform (002 eq. 48)")
        A, _, C, _, E, F = sys.matrices_at(0)
        n, who = sys.nx, self.name
        delta = design_delta(sys)
        if L is not None and poles is not None:
            raise IvobsError("L, poles: give the gain L or the poles to place, not both")
        if S is not None and (e1 is not None or e2 is not None):
            raise IvobsError("e1, e2: they only serve to compute S by eq. (48); S was given")
        e1_search = None
        if L is not None:
            L, gain = self._check_gain(L), "given"
        elif poles is None:
            L, e1_search = default_design(A, C, lambda L_: E - L_ @ F, delta, who)
            gain = "search"
        else:
            poles = as_vector("poles", poles, n)
            if np.any(np.abs(poles) >= 1.0):
                raise IvobsError(f"poles: expected values inside (−1, 1), got {poles}")
            L, gain = place_real_poles(A, C, poles, who), "given-poles"
        M = A - L @ C
        rho = spectral_radius(M)
        if rho >= 1.0:
            raise DesignError(f"{who}: A − LC is not Schur: spectral radius {rho:.6g} >= 1")
        G = E - L @ F
        R_given = None if R is None else self._check_R(R)
        if S is not None:
            S = as_matrix("S", S, n, n)
            e1_, e2_ = None, None
        else:
            if R_given is None:
                R_t, e2_default = nonnegative_realization(np.linalg.eigvals(M))
                R_t = np.asarray(R_t)
            else:
                R_t, e2_default = R_given, None
            e2_ = (
                self._default_e2(R_t)
                if (e2 is None and e2_default is None)
                else (e2_default if e2 is None else as_vector("e2", e2, n))
            )
            if e1 is not None:
                e1_ = as_vector("e1", e1, n)
            elif e1_search is not None and R_given is None and e2 is None:
                e1_ = e1_search
            else:
                e1_ = default_e1(M, R_t, e2_, G, delta, who)
            S = similarity_transform(M, R_t, e1_, e2_, who)
            R_given = None  # S was built from R: check_transform checks nonnegativity only
        Rs = check_transform(M, S, who, R_given)
        self._setup(L, S)
        steady = None
        if not (sys.nd and not isinstance(sys.d, Box)):
            steady = transformed_width(M, G, delta, S)
        self.design = TransformedDesign(
            L=L,
            R=Rs,
            S=S,
            e1=e1_,
            e2=e2_,
            poles=np.linalg.eigvals(M),
            spectral_radius=spectral_radius(np.abs(Rs)),
            gain=gain,
            steady_width=steady,
        )

    def _check_R(self, R: Any) -> np.ndarray:
        R = as_matrix("R", R, self.sys.nx, self.sys.nx)
        if np.any(R < 0):
            i, j = np.unravel_index(int(np.argmin(R)), R.shape)
            raise DesignError(
                f"{self.name}: R is not nonnegative: entry ({i + 1}, {j + 1}) = {R[i, j]:.6g} "
                "< 0 (002 Theorem 5 / 003 Theorem 2 need R >= 0)"
            )
        return R

    @staticmethod
    def _default_e2(R: np.ndarray) -> np.ndarray:
        """A row making ``(R, e2)`` well observable: ones, then unit vectors (best conditioned)."""
        from ..linalg import observability_matrix

        n = R.shape[0]
        cands = [np.ones(n), *np.eye(n)]
        conds = [np.linalg.cond(observability_matrix(R, c[None, :])) for c in cands]
        return cands[int(np.argmin(conds))]
