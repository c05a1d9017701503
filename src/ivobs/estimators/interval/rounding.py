"""Floating-point error of the interval recursion, bounded so that the bounds stay guaranteed.

The recursion of :mod:`ivobs.estimators.interval` (module docstring) is exact in real
arithmetic; here is what its evaluation in floating point can lose, and how the loop and the
vectorised path cover it.

**Rounding** (``interval``, ``interval-split``). The terms one step adds are not all of
the size of the data: ``L_k y`` is ``|L|`` times larger, and ``A − L_k C`` is formed in floating
point. By the standard bound on sums ([Higham2002, Chapter 3]:
``|fl(Σ t_i) − Σ t_i| <= γ_m Σ |t_i|``, ``γ_m = m u / (1 − m u)``, ``u = 2⁻⁵³``;
``m = 2 n_r + n_u + 2 n_y + 2 n_d + 6`` with ``n_r`` the nonzeros per row of
``|A| + |L||C|``), one step of the loop is off by at most

    δ_k = γ_m (a_z ‖z_k‖_∞ + a_y ‖y_k‖_∞ + a_u ‖u_k‖_∞ + a_d ‖d‖_∞)

with ``a_z = 3 ‖|A| + |L||C|‖_∞`` (the products ``Q_k z``, the rounding of ``Q_k`` itself acting
on the true state, which lies in the box), ``a_y = ‖L‖_∞``, ``a_u = 2 ‖|B| + |L||D_u|‖_∞``,
``a_d = 3 ‖|E| + |L||F|‖_∞`` (Lemma 1 on the computed ``E − L_k F``) and ``‖d‖`` the largest
bound magnitude (:class:`RoundingBound`). *Loop* (``step()``, short records, missing samples):
every step widens its new bounds by ``δ_k``, so they enclose the exact recursion from the
computed box for every missing pattern (also when ``|A − L_k C|`` is not Schur), by induction.
*Vectorised path* (complete data): the errors add up to at most ``κ max_j δ_j`` with
``κ = ‖(I − |A − LC|)⁻¹‖_∞``; the outward margin ``ROUNDING (1 + |bound| + s_k)`` of
:mod:`ivobs.estimators.rounding` is enlarged to ``ROUNDING (1 + μ |bound| + ν s_k)`` with
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
from typing import Any

import numpy as np

from ...errors import DesignError
from ...linalg import gamma as gamma_n
from ...model import LinearSystem
from ...sets import Box
from ..rounding import ROUNDING

__all__ = [
    "CONSISTENCY_TOL",
    "Margins",
    "RoundingBound",
    "largest",
    "margins",
    "norm_inf",
    "rounding_bound",
    "transform_conversion",
    "transform_step_error",
]

CONSISTENCY_TOL = 1e-9
"""Relative slack of the consistency test ``y[k] ∈ C[x̲, x̄] + D_u u + F[d]`` (round-off)."""


def norm_inf(M: np.ndarray) -> float:
    """``‖M‖_∞`` (largest absolute row sum; 0 for an empty matrix)."""
    return float(np.linalg.norm(M, np.inf))


def largest(*arrays: np.ndarray) -> float:
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
    gam = gamma_n(n + 1)
    g = norm_inf(np.abs(Si @ S - np.eye(n)) + gam * (np.abs(Si) @ np.abs(S)))
    if not g < 0.5:
        raise DesignError(
            f"{who}: the transformation S is numerically singular (‖S⁻¹S − I‖ = {g:.3g} in "
            f"floating point, cond(S) = {np.linalg.cond(S):.3g}): no guaranteed bounds through "
            "x = S⁻¹ z; give another L, R, e1, e2 or S"
        )
    return g, gam * norm_inf(Si)


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
    ``z = S x`` (``S ≠ I``; module docstring): the computed step differs from the
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
    gam = gamma_n(2 * n + 2 * ny + nu + 2 * nd + 8)
    aS, aL = np.abs(S), np.abs(Lk)
    Mh = A - Lk @ C
    res = np.abs(Q @ S - S @ Mh) + gam * (np.abs(Q) @ aS + aS @ np.abs(Mh))
    c_x = norm_inf(res + gam * (aS @ (np.abs(A) + aL @ np.abs(C))))
    c_z = gam * norm_inf(Q)
    c_y = gam * (norm_inf(Lz) + 2.0 * norm_inf(aS @ aL))
    c_u = gam * (norm_inf(Bz) + 2.0 * norm_inf(aS @ (np.abs(B) + aL @ np.abs(Du))))
    c_d = gam * (norm_inf(Gz) + 2.0 * norm_inf(aS @ (np.abs(E) + aL @ np.abs(F))))
    return np.array([c_x, c_z, c_y, c_u, c_d])


@dataclass(frozen=True)
class RoundingBound:
    """The floating-point model of the recursion with a gain ``L`` (``S = I``; module
    docstring). One step's error is at most
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
    gamma = gamma_n(m)
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


@dataclass(frozen=True)
class Margins:
    """What the estimator adds to the base rounding margin for a gain ``L`` (``S = I``):
    ``mu``, ``nu`` (at least 1: the factors on the bound's magnitude and on the data scale),
    ``ctol`` (the consistency test's slack, :data:`CONSISTENCY_TOL` times ``max(mu, nu)``),
    ``bound`` (:class:`RoundingBound`) and ``blocks``: where the blocks of ``v = [z̲; z̄;
    y_obs; u]`` start and their coefficients ``(a_z, a_y, a_u)`` (:meth:`local_error`)."""

    mu: float
    nu: float
    ctol: float
    bound: RoundingBound
    blocks: tuple[np.ndarray, np.ndarray]

    def local_error(self, v: np.ndarray, dmax: float) -> float:
        """The rounding bound of one step of the loop (module docstring),
        ``γ (a_z ‖z‖_∞ + a_y ‖y_obs‖_∞ + a_u ‖u‖_∞ + a_d ‖d‖_∞)``, for ``v = [z̲; z̄; y_obs; u]``
        (fresh; overwritten): the largest entry of each block (one ``reduceat``); ``dmax``: the
        largest magnitude of the bounds of ``d``."""
        rb = self.bound
        idx, coef = self.blocks
        e = float(coef.dot(np.maximum.reduceat(np.abs(v, out=v), idx)))
        if rb.a_d:
            e += rb.a_d * dmax
        return rb.gamma * e


def margins(sys: LinearSystem, L: np.ndarray, D: Any, who: str) -> Margins:
    """The :class:`Margins` of :func:`rounding_bound` (``S = I``); :class:`DesignError` when
    ``(I − |A − LC|)⁻¹`` cannot be evaluated."""
    rb = rounding_bound(sys, L, D)
    if not np.isfinite(rb.mu + rb.nu):
        raise DesignError(
            f"{who}: (I − |A − LC|)⁻¹ could not be evaluated (|A − LC| has spectral "
            "radius too close to 1): the rounding of the recursion cannot be bounded"
        )
    mu, nu = max(1.0, rb.mu), max(1.0, rb.nu)
    sizes = np.array([2 * sys.nx, sys.ny, sys.nu])
    keep = sizes > 0  # the blocks of v = [z̲; z̄; y_obs; u] (reduceat needs nonempty ones)
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    blocks = (starts[keep], np.array([rb.a_z, rb.a_y, rb.a_u])[keep])
    return Margins(mu, nu, CONSISTENCY_TOL * max(mu, nu), rb, blocks)
