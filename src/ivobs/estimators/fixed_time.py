"""The fixed-time (parity-space) interval estimator of paper 001 (Wang, Dinh, Zhang, Raïssi,
Shen, IFAC 2020).

At every step ``k >= s`` the state is reconstructed from the last ``s + 1`` samples only::

    x̂_k = T (𝐲_k - Mu 𝐮_k)                 (001 eq. 7),  T Mx = I  (eq. 8)
    x_k ∈ <x̂_k, -T Md blkdiag(Wd)>          (eq. 10)
    x̂_k - |T Md| 𝐫_k <= x_k <= x̂_k + |T Md| 𝐫_k    (eq. 11, 𝐫_k the stacked bound radii)

with the stacked matrices of eq. (6) (:mod:`ivobs.design.parity`) and the optimal ``T`` of
Theorem 1 (eq. 13). There is no recursion: errors do not propagate, and without disturbance
``x̂_k = x_k`` exactly from ``k = s`` on (Remark 3, "fixed-time convergence").
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._recursion import LinearFilter, is_shared, scratch, within_band
from .._validate import as_bool, as_int, as_matrix
from ..design.parity import (
    forward_window,
    gamma,
    general_T,
    injection_candidates,
    invertible_injection,
    is_invertible,
    optimal_T,
    pinv_perp,
    stack_window,
    width_optimal_T,
    window_bound,
)
from ..errors import DesignError, IvobsError
from ..linalg import check_observable
from ..model import LinearSystem
from ..sets import Box, image_bounds
from . import register
from .base import ROUNDING, Design, Estimator, check_size, outward

__all__ = ["FixedTimeDesign", "FixedTimeEstimator"]

_EPS = np.finfo(float).eps
_CACHE_SIZE = 16384
MAX_WINDOW = 1000
"""Largest window ``s`` (past samples in the stacked matrices of 001 eq. (6))."""
ACCURACY = 1e-9
"""A design whose certified error exceeds ``ACCURACY ‖G_i‖₁ ‖w‖_∞`` (:meth:`FixedTimeEstimator.
_certify`) is replaced by an output injection (001 Remark 1), when one does better."""
_CHUNK = 1 << 16
_BLOCK = 1024


def _rows_matmul(X: np.ndarray, Mt: np.ndarray) -> np.ndarray:
    """``X @ Mt`` for a tall, thin ``X`` ``(..., n, w)``, as a stack of ``_BLOCK``-row products.

    One tall product with a handful of columns makes OpenBLAS start its threads for almost no
    work per thread, which is slow (and very slow on a busy machine); a stack of small
    products runs each one on one thread, at memory speed.
    """
    n = X.shape[-2]
    nb = n // _BLOCK
    if X.ndim != 2 or nb < 2:
        return X @ Mt
    out = np.empty((n, Mt.shape[1]))
    kb = nb * _BLOCK
    out[:kb].reshape(nb, _BLOCK, -1)[...] = X[:kb].reshape(nb, _BLOCK, -1) @ Mt
    out[kb:] = X[kb:] @ Mt
    return out


@dataclass(frozen=True)
class FixedTimeDesign(Design):
    """The offline design of 001 (for a time-varying system: the window ending at ``k = s``).

    ``T`` (eq. 13 or the user's), ``s``, the stacked matrices ``Mx``, ``Mu``, ``Md`` (eq. 6),
    ``Mx_pinv`` (``Mx†``), ``Mx_perp`` (``Mx⊥``), the SVD factors ``U1``, ``S1``, ``V1`` of
    ``Mx⊥ Md`` and their number ``r`` (Theorem 1; empty when ``T`` or ``S`` was given; with
    ``criterion="width"`` they describe Theorem 1's ``T``, not the LP's), ``S``
    (when given), ``H = -T Md blkdiag(Wd)`` (eq. 10; ``None`` for bounds that vary with time),
    the output-injection gain ``L`` of Remark 1 (``None`` when ``A`` is invertible) with ``My``,
    the stack of the known input ``L y``, and ``Mc``, the stack of the known centre of ``d``
    (Section 2; ``None`` for symmetric constant bounds).
    """

    s: int
    T: np.ndarray
    Mx: np.ndarray
    Mu: np.ndarray
    Md: np.ndarray
    Mx_pinv: np.ndarray
    Mx_perp: np.ndarray
    U1: np.ndarray
    S1: np.ndarray
    V1: np.ndarray
    r: int
    S: np.ndarray | None = None
    H: np.ndarray | None = None
    L: np.ndarray | None = None
    My: np.ndarray | None = None
    Mc: np.ndarray | None = None
    weighted: bool = False
    criterion: str = "frobenius"


@dataclass(frozen=True)
class _Kernel:
    """Gains of one window (one missing-data pattern, one step for time-varying systems).

    On the window vector ``w = [z_k; …; z_{k-s}]``, ``z = [u; y; c]`` (``y`` zero where missing,
    ``c`` the centre of ``d``) and the stacked radii ``𝐫``: ``GQ w = [x̂; ρ]`` (estimate, eq. 7,
    and parity residual ``ρ = N(𝐲 - Mv 𝐯)``, ``N Mx = 0``); ``HP 𝐫 = [|T Md| 𝐫; |N Md| 𝐫]``
    (radius, eq. 11, and the bound of ``ρ``). ``rad_coef``, ``tol_coef``: rounding margins per
    unit of ``‖w‖_∞`` (see :meth:`FixedTimeEstimator._finish`).
    """

    ok: bool
    rank: int
    nx: int = 0
    GQ: np.ndarray | None = None
    HP: np.ndarray | None = None
    rad_coef: np.ndarray | None = None
    tol_coef: np.ndarray | None = None
    accuracy: float = np.inf


@register
class FixedTimeEstimator(Estimator):
    """Fixed-time parity-space interval estimator (paper 001, eqs. 6-13, Theorem 1).

    Data used: the box of ``x[k]`` uses ``y[k-s..k]`` and ``u[k-s..k]`` (and nothing older), so
    it is valid from ``k = s`` (``valid_from = s``); rows before are NaN. No prior on ``x[0]``
    is needed (``needs_x0 = False``).

    Options
    -------
    s : window length minus one, ``s >= nx - 1`` (001 Lemma 2). Default ``nx - 1``. A larger
        ``s`` starts later and gives ``T`` more freedom: ``‖T Md‖_F`` never grows with ``s``,
        but the boxes may (see ``criterion``).
    T : an explicit ``(nx, (s+1)·ny)`` matrix with ``T Mx = I`` (eq. 8), e.g. to reproduce a
        published design. Default: the optimal ``T`` of Theorem 1 (eq. 13).
    S : the free matrix of the general solution ``T = Mx† + S Mx⊥`` (Lemma 2), instead of ``T``.
    L : the output-injection gain of Remark 1 (``A - LC`` invertible). Default: none when ``A`` is
        invertible and the design with ``A`` is accurate; otherwise (``A`` singular, or so
        ill-conditioned that the certified error of the window gain exceeds :data:`ACCURACY`
        of the data scale) a small, well-conditioned gain
        (:func:`ivobs.design.parity.invertible_injection`; if that design is not accurate
        either, the narrowest accurate one among
        :func:`ivobs.design.parity.injection_candidates`).
        ``L y`` becomes a known input and the noise ``(E - LF) d``.
    criterion : ``"frobenius"`` (default, the paper's Theorem 1: minimise ``‖T Md‖_F``) or
        ``"width"`` (not in the paper: minimise each box width ``Σ_j |(T Md Wd)_ij|`` of eq. 11
        by one linear program per state at design time,
        :func:`ivobs.design.parity.width_optimal_T`; time-invariant systems, constant bounds).
        The Frobenius optimum is not the narrowest box, and its boxes can widen as ``s`` grows
        (see ``docs/fixed_time.md``); the width optimum never widens with ``s``.
    weighted : with ``"frobenius"``, minimise ``‖T Md Wd‖_F`` (bounds-aware) instead of the
        paper's ``‖T Md‖_F``. Default False (the paper). Constant bounds only.
    check_consistency : test the parity residual ``N(𝐲 - Mu 𝐮)``, ``N Mx = 0``, against its
        bounds ``|N Md| 𝐫``; a violation means the data contradict the model (reported as
        inconsistent, the box is then predicted from the previous one). Default True.

    Asymmetric bounds (001 Section 2): ``d = c + δ``, ``|δ| <= r``; ``E c``, ``F c`` enter as a
    known input (``Mc``). Time-varying systems (Remark 4): the stacked matrices and ``T_k`` are
    recomputed per window (closed form: one SVD), cached. ``D u`` in the output equation is kept
    (``Mu`` gets ``D`` on its block diagonal).

    Missing samples (NaN in ``y``): the rows of the stack that are missing, or that involve a
    missing ``y`` through ``L y``, are removed; if the remaining ``Mx`` still has rank ``nx``,
    the optimal ``T`` (Theorem 1, weighted by the bounds under ``criterion="width"``) of that
    reduced stack gives a box (computed once per missing pattern, cached; a user ``T`` or ``S``
    and the width LP apply to complete windows only), which is intersected with the prediction
    from the previous box, ``x_k ∈ A[x_{k-1}] + B u_{k-1} + E[d_{k-1}]`` (Lemma 1 of 003 /
    :func:`ivobs.image_bounds`): both contain ``x_k``, and a reduced window can be poor (it may
    have to differentiate the few outputs left). Otherwise the box is that prediction: sound,
    and finite once a box exists. Complete windows are never intersected (the paper's numbers).
    ``x0``, when given, is used for nothing else than this prediction before the first box;
    a window at ``k >= s`` without enough data and without any earlier box raises
    :class:`IvobsError`.

    Rounding (what is guaranteed): the window gain ``G`` (``x̂ = G w``) is computed through the
    inverses of eq. (4) and an SVD, so ``T Mx = I``, the cancellation of the known inputs and
    ``|T Md|`` hold only to rounding, amplified by the conditioning of ``A`` (or of ``A - LC``).
    Each gain is therefore *certified* on the forward form of the window, which needs no
    inverse (:func:`ivobs.design.parity.window_bound`, :meth:`_certify`): the coefficients of
    ``x_k - G w`` in the anchor state, the known inputs and the disturbances are computed in
    extended precision with a ``γ_n`` bound (``γ_n = n ε / (1 - n ε)``), ``G`` is refined once
    by them, and the radius is ``|R_δ| 𝐫`` (``= |T Md| 𝐫`` of eq. 11 up to rounding) plus the
    certified remainder ``(Σ_j |R_v|_ij + a_i κ) ‖w‖_∞`` (``a_i κ``: the residual of
    ``T Mx = I`` times a bound of the anchor state from the same window). On top, the radius
    carries ``64 (s+1) n_z ε ‖G_i‖₁ ‖w‖_∞`` for the evaluation of ``G w`` in ``float64`` (at
    most ``(s+1) n_z`` roundings per entry, and the ``ε/2`` of the recorded data), and the
    base adds its outward margin. Exact arithmetic on the model as given is assumed (the model
    matrices are exact, the data are the recorded ``float64`` values of the true signals).
    """

    name = "fixed-time"
    order = 10
    summary = "fixed-time parity-space estimator with the optimal T of Theorem 1 (001)"
    reference = "Wang, Dinh, Zhang, Raïssi, Shen, IFAC 2020 (paper 001)"
    supports_time_varying = True
    needs_x0 = False

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        s: int | None = None,
        T: Any = None,
        S: Any = None,
        L: Any = None,
        criterion: str = "frobenius",
        weighted: bool = False,
        check_consistency: bool = True,
        on_inconsistent: str = "warn",
    ):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)
        nx, ny = sys.nx, sys.ny
        check_size(
            self.name,
            nx,
            "uses the stacked matrices of 001 eq. (6) over s + 1 >= nx "
            "samples (O(nx^2 ny) entries and work)",
        )
        self.s = self._check_s(s, nx)
        self._tv = sys.is_time_varying
        self._criterion = criterion
        weighted = as_bool("weighted", weighted)
        self._check_design_options(T, S, weighted)
        self._const_bounds = sys.has_constant_bounds
        self._nc = self._centre_size()
        self._nz = sys.nu + ny + self._nc
        self._weighted = weighted
        self._check = as_bool("check_consistency", check_consistency)
        self._L_user = None if L is None else as_matrix("L", L, nx, ny)
        self._S = None if S is None else as_matrix("S", S, nx, (self.s + 1) * ny)
        self._T_user = None if T is None else as_matrix("T", T, nx, (self.s + 1) * ny)
        self._mats_cache: OrderedDict[int, tuple[np.ndarray, ...]] = OrderedDict()
        self._kern_cache: OrderedDict[Any, _Kernel] = OrderedDict()
        self._model_cache: OrderedDict[int, tuple[np.ndarray, ...]] = OrderedDict()
        self._L_lti: np.ndarray | None = None
        if not self._tv:
            try:
                check_observable(sys.A, sys.C, "the fixed-time estimator (001 Lemma 2)")
            except IvobsError as exc:  # a design impossibility, as for the other methods
                raise DesignError(str(exc)) from None
            self._L_lti = self._injection(sys.A, sys.C, self._L_user, "A")
        elif self._L_user is not None:
            self._L_lti = self._L_user
        self._sel = self._selection()
        # s + 2 slots: the window z_k .. z_(k-s) plus z_(k-1) kept for the prediction through a
        # missing sample even when s = 0 (u_(k-1) and the bounds of d_(k-1), audit finding A2)
        self._slots = self.s + 2
        self._ring = [(p - np.arange(self.s + 1)) % self._slots for p in range(self._slots)]
        if self._T_user is not None:
            self._T_user = self._check_T(self._T_user, self._stack(self.s)[0])
        choose = not self._tv and self._L_user is None and self._T_user is None
        try:
            self.design = self._design(self.s)
            error = None
        except DesignError as exc:  # e.g. Theorem 1's check on an ill-conditioned A
            if not choose or self._L_lti is not None:
                raise
            error = exc
        if choose:
            self._choose_injection(error)
        self.valid_from = self.s

    # -- validation -----------------------------------------------------------------------
    @staticmethod
    def _check_s(s: Any, nx: int) -> int:
        if s is None:
            return max(nx - 1, 0)
        s = as_int("s", s, 0)
        if s > MAX_WINDOW:
            raise IvobsError(
                f"s: expected a window of at most {MAX_WINDOW} past samples (the stacked "
                f"matrices of 001 eq. (6) have (s + 1) ny rows and as many columns per input "
                f"and disturbance), got s = {s}"
            )
        if s < nx - 1:
            raise IvobsError(
                f"s: the fixed-time estimator needs s >= nx - 1 = {nx - 1} (001 Lemma 2: the "
                f"window y[k-s..k] must observe the {nx} states), got s = {s}"
            )
        return s

    def _check_design_options(self, T: Any, S: Any, weighted: bool) -> None:
        crit = self._criterion
        if crit not in ("frobenius", "width"):
            raise IvobsError(f"criterion: expected 'frobenius' or 'width', got {crit!r}")
        if crit == "width" and (T is not None or S is not None or weighted):
            raise IvobsError(
                "criterion: 'width' designs T itself; do not combine with T, S or weighted"
            )
        if crit == "width" and (self._tv or not self.sys.has_constant_bounds):
            raise IvobsError(
                "criterion: 'width' needs a time-invariant system with constant bounds d (a "
                "linear program at design time); use 'frobenius' (closed form per step)"
            )
        if T is not None and S is not None:
            raise IvobsError("T, S: give at most one (T directly, or S in T = Mx† + S Mx⊥)")
        if weighted and (T is not None or S is not None):
            raise IvobsError("weighted: applies to the optimal T only; do not combine with T or S")
        if T is not None and self._tv:
            raise IvobsError(
                "T: a fixed T cannot satisfy T Mx(k) = I for every k of a time-varying system; "
                "pass S (T_k = Mx(k)† + S Mx(k)⊥) or nothing (optimal T_k)"
            )
        if weighted and not self.sys.has_constant_bounds:
            raise IvobsError("weighted: needs constant bounds d (a Box with constant bounds)")

    def _centre_size(self) -> int:
        """Columns of ``c`` (the centre of ``d``) in ``z``: 0 for symmetric constant bounds."""
        sys = self.sys
        if sys.nd == 0:
            return 0
        if self._const_bounds:
            box = sys.d
            assert isinstance(box, Box)
            return 0 if np.all(box.lo + box.hi == 0) else sys.nd
        return sys.nd

    @staticmethod
    def _check_T(T: np.ndarray, Mx: np.ndarray) -> np.ndarray:
        """Accept a ``T`` with ``T Mx = I`` up to printed precision and project it onto the
        constraint, ``T + (I - T Mx) Mx†``, so that eq. (9) holds to rounding (a published
        ``T`` rounded to 4 decimals misses ``T Mx = I`` by ~1e-4, which would void eq. 9)."""
        nx = Mx.shape[1]
        resid = float(np.max(np.abs(T @ Mx - np.eye(nx))))
        if not resid <= 1e-3:
            raise IvobsError(
                f"T: does not satisfy T Mx = I (001 eq. 8): max |T Mx - I| = {resid:.2e} "
                "(> 1e-3); pass a left inverse of Mx (see est.design.Mx), or S, or nothing"
            )
        return T + (np.eye(nx) - T @ Mx) @ np.linalg.pinv(Mx)

    def _quality(self) -> tuple[float, float]:
        """``(accuracy, width)`` of the complete window: the certified error per unit of
        ``‖G_i‖₁ ‖w‖_∞`` (:meth:`_certify`, worst state) and ``Σ_i (|T Md| 𝐫)_i`` (unit radii
        for bounds that vary with time)."""
        kern = self._kernel(self.s, np.zeros((self.s + 1, self.sys.ny), dtype=bool))
        if not kern.ok:
            return np.inf, np.inf
        assert kern.HP is not None
        nx, nd = self.sys.nx, self.sys.nd
        r = np.ones(nd)
        if self._const_bounds and nd:
            box = self.sys.d
            assert isinstance(box, Box)
            r = box.radius
        return kern.accuracy, float(np.sum(kern.HP[:nx] @ np.tile(r, self.s + 1)))

    def _use_injection(self, L: np.ndarray | None) -> None:
        """Redesign with the output injection ``L`` (``None``: the backward propagation with
        ``A`` itself)."""
        self._L_lti = L
        self._mats_cache.clear()
        self._kern_cache.clear()
        self.design = self._design(self.s)

    def _choose_injection(self, error: DesignError | None) -> None:
        """Remark 1 when ``A`` is invertible but ill-conditioned, or when the injection placed
        first is not accurate (audit findings A3, A3b): if the certified error of the complete
        window (:meth:`_quality`) exceeds :data:`ACCURACY` of the data scale, every gain of
        :func:`ivobs.design.parity.injection_candidates` is tried, and the one with the
        narrowest box among the accurate ones is kept (the most accurate one if none is).
        Nothing changes for a well-conditioned design (the paper's examples). ``error``: the
        design with ``A`` itself failed (re-raised if no injection works either)."""
        options: list[tuple[float, float, np.ndarray | None]] = []
        if error is None:
            acc, width = self._quality()
            if acc <= ACCURACY:
                return
            options.append((acc, width, self._L_lti))
        for L in injection_candidates(self.sys.A, self.sys.C):
            try:
                self._use_injection(L)
                options.append((*self._quality(), L))
            except DesignError:
                continue
        if not options:
            assert error is not None
            raise error
        good = [o for o in options if o[0] <= ACCURACY]
        best = min(good, key=lambda o: o[1]) if good else min(options, key=lambda o: o[0])
        self._use_injection(best[2])

    def _injection(self, A: np.ndarray, C: np.ndarray, L: np.ndarray | None, where: str) -> Any:
        """Remark 1: ``L`` with ``A - LC`` invertible (``None`` when ``A`` already is)."""
        if L is not None:
            if not is_invertible(A - L @ C):
                raise DesignError(
                    f"L: {where} - LC is not invertible; the backward propagation (001 eq. 4) "
                    "needs it (001 Remark 1): choose L placing the poles of A - LC away from 0"
                )
            return L
        if is_invertible(A):
            return None
        return invertible_injection(A, C)

    # -- model per step ---------------------------------------------------------------------
    def _matrices(self, j: int) -> tuple[np.ndarray, ...]:
        """``(A', Bv, C, Dv, E', F, L)`` at step ``j`` for the known input ``v = [u; y; c]``:
        ``A' = A - LC``, ``Bv = [B - LD, L, E - LF]``, ``Dv = [D, 0, F]``, ``E' = E - LF``
        (001 Remark 1 and Section 2; ``L = 0`` when ``A`` is invertible)."""
        key = 0 if not self._tv else j
        hit = self._mats_cache.get(key)
        if hit is not None:
            return hit
        A, B, C, D, E, F = self.sys.matrices_at(j)
        nx, ny = self.sys.nx, self.sys.ny
        if self._tv:
            L = self._injection(A, C, self._L_lti, f"A({j})")
        else:
            L = self._L_lti
        Lm = np.zeros((nx, ny)) if L is None else L
        Ep = E - Lm @ F
        Bv = [B - Lm @ D, Lm]
        Dv = [D, np.zeros((ny, ny))]
        if self._nc:
            Bv.append(Ep)
            Dv.append(F)
        out = (A - Lm @ C, np.hstack(Bv), C, np.hstack(Dv), Ep, F, Lm)
        self._mats_cache[key] = out
        if len(self._mats_cache) > _CACHE_SIZE:
            self._mats_cache.popitem(last=False)
        return out

    def _stack(self, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Mx, Mv, Md)`` of the window ending at ``k`` (001 eq. 6, Remark 4)."""
        mats = [self._matrices(k - i)[:6] for i in range(self.s + 1)]
        return stack_window(mats)

    def _selection(self) -> np.ndarray:
        """``Sel`` with ``Sel w = 𝐲`` (the outputs of the window vector ``w``)."""
        s, ny, nu, nz = self.s, self.sys.ny, self.sys.nu, self._nz
        Sel = np.zeros(((s + 1) * ny, (s + 1) * nz))
        for i in range(s + 1):
            Sel[i * ny : (i + 1) * ny, i * nz + nu : i * nz + nu + ny] = np.eye(ny)
        return Sel

    # -- design -----------------------------------------------------------------------------
    def _weights(self) -> np.ndarray | None:
        """Column weights ``Wd`` of the criterion (``None``: the paper's ``‖T Md‖_F``)."""
        if not (self._weighted or self._criterion == "width") or self.sys.nd == 0:
            return None
        box = self.sys.d
        assert isinstance(box, Box)
        return np.tile(box.radius, self.s + 1)

    def _T_full(self, Mx: np.ndarray, Md: np.ndarray) -> tuple[np.ndarray, Any]:
        if self._T_user is not None:
            return self._T_user, None
        if self._S is not None:
            return general_T(Mx, self._S), None
        opt = optimal_T(Mx, Md, self._weights())
        if self._criterion == "width":
            return width_optimal_T(Mx, Md, self._weights()), opt
        return opt.T, opt

    def _design(self, k: int) -> FixedTimeDesign:
        """The design of the window ending at ``k`` (``k = s`` for :attr:`design`)."""
        s, nx, ny, nu, nz, nc = self.s, self.sys.nx, self.sys.ny, self.sys.nu, self._nz, self._nc
        Mx, Mv, Md = self._stack(k)
        _, _, _, rank = pinv_perp(Mx)
        if rank < nx:
            where = "the window k = 0..s" if not self._tv else f"the window ending at k = {k}"
            raise DesignError(
                f"pair (A, C) is not observable over {where}: the stacked matrix Mx (001 eq. 6) "
                f"has rank {rank} of {nx}; the fixed-time estimator needs rank nx (increase s)"
            )
        T, opt = self._T_full(Mx, Md)
        if opt is None:
            Mx_pinv, Mx_perp, _, _ = pinv_perp(Mx)
            U1, S1, V1, r = np.zeros((Mx.shape[0], 0)), np.zeros((0, 0)), np.zeros((0, 0)), 0
        else:
            Mx_pinv, Mx_perp, U1, S1, V1, r = (
                opt.Mx_pinv,
                opt.Mx_perp,
                opt.U1,
                opt.S1,
                opt.V1,
                opt.rank,
            )
        cols = np.arange((s + 1) * nz).reshape(s + 1, nz)
        H = None
        if self._const_bounds and self.sys.nd:
            box = self.sys.d
            assert isinstance(box, Box)
            H = -T @ Md * np.tile(box.radius, s + 1)[None, :]
        elif self.sys.nd == 0:
            H = np.zeros((nx, 0))
        L = self._matrices(k)[6] if self._L_lti is not None or self._tv else None
        if self._tv and L is not None and not np.any(L):
            L = None
        return FixedTimeDesign(
            s=s,
            T=T,
            Mx=Mx,
            Mu=Mv[:, cols[:, :nu].ravel()],
            Md=Md,
            Mx_pinv=Mx_pinv,
            Mx_perp=Mx_perp,
            U1=U1,
            S1=S1,
            V1=V1,
            r=r,
            S=self._S,
            H=H,
            L=L,
            My=Mv[:, cols[:, nu : nu + ny].ravel()] if L is not None else None,
            Mc=Mv[:, cols[:, nu + ny :].ravel()] if nc else None,
            weighted=self._weighted,
            criterion=self._criterion,
        )

    def design_at(self, k: int) -> FixedTimeDesign:
        """The design of the window ending at step ``k >= s`` (time-varying systems: ``T_k``)."""
        k = as_int("k", k, self.s)
        return self._design(k) if self._tv else self.design

    def _kernel(self, k: int, missing: np.ndarray) -> _Kernel:
        """The window gains for step ``k`` and missing pattern ``missing`` ((s+1, ny) bool)."""
        key = (k if self._tv else 0, missing.tobytes())
        hit = self._kern_cache.get(key)
        if hit is not None:
            return hit
        kern = self._make_kernel(k, missing)
        self._kern_cache[key] = kern
        if len(self._kern_cache) > _CACHE_SIZE:
            self._kern_cache.popitem(last=False)
        return kern

    def _make_kernel(self, k: int, missing: np.ndarray) -> _Kernel:
        nx, ny, nu, nz, s = self.sys.nx, self.sys.ny, self.sys.nu, self._nz, self.s
        Mx, Mv, Md = self._stack(k)
        rows = ~missing.ravel()
        if not rows.all():
            # a missing y_{k-j} is also an unknown input through L y (Remark 1): drop the rows
            # that depend on it
            ycols = (np.arange(s + 1)[:, None] * nz + nu + np.arange(ny)[None, :]).ravel()
            miss_cols = ycols[missing.ravel()]
            rows &= np.all(Mv[:, miss_cols] == 0, axis=1)
        MxR = Mx[rows]
        if MxR.shape[0] < nx:
            return _Kernel(ok=False, rank=int(np.linalg.matrix_rank(MxR)) if MxR.size else 0)
        _, _, N, rank = pinv_perp(MxR)
        if rank < nx:
            return _Kernel(ok=False, rank=rank)
        if rows.all():  # the design's T (time-invariant: computed once, e.g. the width LP)
            T_R = self._T_full(Mx, Md)[0] if self._tv else self.design.T
        else:
            try:
                T_R = optimal_T(MxR, Md[rows], self._weights()).T
            except DesignError:
                return _Kernel(ok=False, rank=rank)
        K = self._sel - Mv
        T_pad = np.zeros((nx, Mx.shape[0]))
        T_pad[:, rows] = T_R
        G = T_pad @ K
        N_pad = np.zeros((N.shape[0] if self._check else 0, Mx.shape[0]))
        if self._check:
            N_pad[:, rows] = N
        GQ = np.vstack([G, N_pad @ K])
        cert = self._certify(k, missing, GQ)
        if cert is None:  # the window does not determine its oldest state: use the prediction
            return _Kernel(ok=False, rank=rank)
        GQ, HP, extra = cert
        # rounding of the evaluation x̂ = G w (and of the recorded data), |G_i| |w| <= l1_i ‖w‖_∞
        l1 = np.abs(GQ).sum(axis=1) * (64.0 * (s + 1) * nz * _EPS)
        return _Kernel(
            ok=True,
            rank=rank,
            nx=nx,
            GQ=GQ,
            HP=HP,
            rad_coef=l1[:nx] + extra[:nx],
            tol_coef=l1[nx:] * (1e-9 / (64.0 * (s + 1) * nz * _EPS)) + extra[nx:],
            accuracy=float(np.max(extra[:nx] / np.maximum(np.abs(GQ[:nx]).sum(axis=1), 1e-300))),
        )

    def _certify(
        self, k: int, missing: np.ndarray, GQ: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The window gain ``GQ`` (rows ``x̂``, then ``ρ``), refined, and its certified radius.

        ``GQ`` was computed from the stacked matrices of eq. (6), i.e. from the inverses of
        eq. (4) (of ``A - LC`` with an output injection) and an SVD: rounding, amplified by the
        conditioning of ``A``, makes ``T Mx = I``, the cancellation of the known inputs and
        ``|T Md|`` inexact (audit findings A3, A3b). :func:`ivobs.design.parity.window_bound`
        evaluates what ``GQ`` actually does on the forward form of the window (products of
        the original model matrices only, with a ``γ_n`` rounding bound): for the true
        trajectory ``x_k - G w = R_x x_{k-a} + R_v 𝐯 + R_δ 𝛅`` exactly, ``a`` the oldest lag
        that ``GQ`` uses, ``𝐯`` the known inputs and centres (entries of ``w``), ``|δ| <= 𝐫``.
        With ``‖x_{k-a}‖_∞ <= κ ‖w‖_∞ + ν 𝐫`` (the same window) and ``a_i = Σ_j |R_x|_ij``:

        ``|x_k - x̂_k|_i <= (|R_δ| + a ν)_i 𝐫 + (Σ_j |R_v|_ij + a_i κ) ‖w‖_∞``

        returned as ``(GQ, HP, extra)``: ``GQ`` after one step of iterative refinement (it
        moves by the size of its error only), ``HP`` (times ``1 + γ`` for the evaluation of
        ``HP 𝐫``) replaces ``|T Md|``; ``extra`` is added to the per-``‖w‖_∞`` radius. With
        re-centred bounds, ``c = (lo + hi)/2`` and ``r = (hi - lo)/2`` are rounded:
        ``|d - c| <= (1 + ε) r + ε |c|``, ``|c| <= ‖w‖_∞``. None when the window does not
        determine ``x_{k-a}`` (the prediction is used instead).
        """
        s, nx, nz, nd = self.s, self.sys.nx, self._nz, self.sys.nd
        used = np.any(GQ.reshape(GQ.shape[0], s + 1, nz) != 0.0, axis=(0, 2))
        lag = int(np.nonzero(used)[0].max()) if used.any() else 0
        mats = [self._model(k - i) for i in range(s + 1)]
        fw = forward_window(mats, centre=bool(self._nc), lag=lag, missing=missing)
        wb = window_bound(GQ, nx, fw)
        if not np.isfinite(wb.kappa):
            return None
        ax = wb.Rx.sum(axis=1)
        HP = wb.Rd + ax[:, None] * wb.nu[None, :]
        extra = wb.Rv.sum(axis=1) + ax * wb.kappa
        if self._nc:
            extra += _EPS * (1.0 + _EPS) * HP.sum(axis=1)
            HP *= 1.0 + _EPS
        HP *= 1.0 + gamma((s + 1) * nd + 2)
        return wb.G, HP, extra

    def _model(self, j: int) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, E, F)`` of the original system at step ``j`` (no injection)."""
        key = j if self._tv else 0
        hit = self._model_cache.get(key)
        if hit is None:
            hit = self._model_cache[key] = self.sys.matrices_at(key)
            if len(self._model_cache) > _CACHE_SIZE:
                self._model_cache.popitem(last=False)
        return hit

    # -- online -----------------------------------------------------------------------------
    def _initial_state(self) -> dict[str, Any]:
        s, nx, ny, nd = self.s, self.sys.nx, self.sys.ny, self.sys.nd
        return {
            "z": np.zeros((s + 2, self._nz)),
            "ymiss": np.ones((s + 2, ny)),
            "dlo": np.zeros((s + 2, nd)),
            "dhi": np.zeros((s + 2, nd)),
            "lo": np.zeros(nx),
            "hi": np.zeros(nx),
            "has_box": False,
        }

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        s, nu, ny = self.s, self.sys.nu, self.sys.ny
        p = k % self._slots
        miss = np.isnan(y_k)
        dbox = self.sys.d_at(k, y_k)
        z = state["z"][p]
        z[:nu] = u_k
        z[nu : nu + ny] = np.where(miss, 0.0, y_k) if miss.any() else y_k
        if self._nc:
            z[nu + ny :] = 0.5 * (dbox.lo + dbox.hi)
        state["ymiss"][p] = miss
        state["dlo"][p] = dbox.lo
        state["dhi"][p] = dbox.hi
        raw: tuple[np.ndarray, np.ndarray] | None = None
        if k < s:
            if self.x0 is not None:
                raw = (self.x0.lo, self.x0.hi) if k == 0 else self._predict_state(state, k)
        else:
            idx = self._ring[p]
            ymiss = state["ymiss"][idx]
            kern = self._kernel(k, ymiss > 0.5)
            incons = False
            if kern.ok:
                w = state["z"][idx].ravel()
                r = 0.5 * (state["dhi"][idx] - state["dlo"][idx]).ravel()
                lo, hi, incons = self._evaluate_one(kern, w, r)
                raw = (lo, hi)
            reduced = bool(ymiss.any())
            if raw is None or incons or reduced:
                prior = None
                if state["has_box"]:
                    prior = self._predict_state(state, k)
                elif k == 0 and self.x0 is not None:
                    prior = (self.x0.lo, self.x0.hi)  # s = 0: the prior box of x[0] itself
                if prior is None and raw is None:
                    raise self._no_box_error(k, kern.rank)
                if prior is not None:
                    raw, incons = self._combine(raw, incons, prior)
            if incons:
                state["_inconsistent"] = True
        if raw is None:
            return np.full(self.sys.nx, np.nan), np.full(self.sys.nx, np.nan)
        lo, hi = np.asarray(raw[0], dtype=float), np.asarray(raw[1], dtype=float)
        m = ROUNDING * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))  # as the base's outward()
        state["lo"], state["hi"] = lo - m, hi + m
        state["has_box"] = True
        return lo, hi

    @staticmethod
    def _combine(
        raw: tuple[np.ndarray, np.ndarray] | None,
        incons: bool,
        prior: tuple[np.ndarray, np.ndarray],
    ) -> tuple[tuple[np.ndarray, np.ndarray], bool]:
        """The box of a window with missing samples (or none usable, or inconsistent), given the
        prediction ``prior`` from the previous box: the prediction when there is no usable
        window box or the data are inconsistent, else the intersection of the two (both
        contain ``x_k``); an empty intersection means inconsistent data."""
        if raw is None or incons:
            return prior, incons
        lo, hi = np.maximum(raw[0], prior[0]), np.minimum(raw[1], prior[1])
        if bool((lo > hi).any()):
            return prior, True
        return (lo, hi), False

    def _no_box_error(self, k: int, rank: int) -> IvobsError:
        why = (
            f"the available rows of Mx have rank {rank} < nx = {self.sys.nx}"
            if rank < self.sys.nx
            else "the available samples do not determine the oldest state of the window, so "
            "its gain cannot be certified (singular A)"
        )
        return IvobsError(
            f"y: at step {k} the window y[{k - self.s}..{k}] has too many missing samples "
            f"({why}) and no earlier box exists to predict from; give a prior "
            "x0=ivobs.Box(...) or a larger s"
        )

    def _predict_state(self, state: dict[str, Any], k: int) -> tuple[np.ndarray, np.ndarray]:
        q = (k - 1) % self._slots  # never the slot of step k (s + 2 slots)
        u_prev = state["z"][q, : self.sys.nu]
        return self._predict(state["lo"], state["hi"], u_prev, state["dlo"][q], state["dhi"][q], k)

    def _predict(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        u_prev: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
        k: int,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``x_k ∈ A[x_{k-1}] + B u_{k-1} + E[d_{k-1}]`` (Lemma 1 of 003, model at ``k - 1``);
        leading axes allowed (many windows at once, time-invariant systems)."""
        A, B, _, _, E, _ = self.sys.matrices_at(k - 1)
        a_lo, a_hi = image_bounds(A, lo, hi)
        e_lo, e_hi = image_bounds(E, dlo, dhi)
        bu = u_prev @ B.T
        return a_lo + bu + e_lo, a_hi + bu + e_hi

    def _evaluate_one(
        self, kern: _Kernel, w: np.ndarray, r: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """One window ``w`` with radii ``r``: :meth:`_finish` for a single row (fast path of
        :meth:`_step`)."""
        assert kern.GQ is not None and kern.HP is not None and kern.rad_coef is not None
        assert kern.tol_coef is not None
        nx = kern.nx
        out = kern.GQ @ w
        rhp = kern.HP @ r
        wmax = float(np.abs(w).max()) if w.size else 0.0
        rad = wmax * kern.rad_coef + rhp[:nx]
        bad = False
        if out.shape[0] > nx:
            bound = wmax * kern.tol_coef + (rhp[nx:] * (1.0 + 1e-9) + 1e-9)
            bad = bool((np.abs(out[nx:]) > bound).any())
        return out[:nx] - rad, out[:nx] + rad, bad

    def _evaluate(
        self, kern: _Kernel, W: np.ndarray, R: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Bounds (eq. 11) and the parity test for windows ``W`` ``(n, (s+1)nz)`` with radii
        ``R`` ``(n, (s+1)nd)``."""
        assert kern.GQ is not None and kern.HP is not None
        out = _rows_matmul(W, kern.GQ.T)
        wmax = np.max(np.abs(W), axis=1, initial=0.0)
        return self._finish(kern, out, _rows_matmul(R, kern.HP.T), wmax)

    def _finish(
        self,
        kern: _Kernel,
        out: np.ndarray,
        rhp: np.ndarray,
        wmax: np.ndarray,
        dest: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """From ``[x̂; ρ]`` (``out``), ``[|T Md| 𝐫; |N Md| 𝐫]`` (``rhp``, the certified
        disturbance gains ``HP 𝐫`` of :meth:`_certify`) and ``‖w‖_∞``: the bounds ``x̂ ∓ rad``
        and the inconsistency flags ``|ρ| > |N Md| 𝐫`` (tolerance ``1e-9`` relative).
        ``rad = rhp + rad_coef ‖w‖_∞``, ``rad_coef`` the evaluation rounding
        ``64 (s+1) n_z ε ‖G_i‖₁`` plus the certified remainder of :meth:`_certify`.
        Written into ``dest = (lo, hi, bad)`` when given (``out`` is then overwritten).
        """
        assert kern.rad_coef is not None and kern.tol_coef is not None
        nx = kern.nx
        if dest is None:
            shape = out.shape[:-1]
            dest = (np.empty((*shape, nx)), np.empty((*shape, nx)), np.empty(shape, dtype=bool))
        lo, hi, bad = dest
        xhat = out[..., :nx]
        rad = wmax[..., None] * kern.rad_coef
        rad += rhp[..., :nx]
        np.subtract(xhat, rad, out=lo)
        np.add(xhat, rad, out=hi)
        bad[...] = False
        if out.shape[-1] > nx:
            res = np.abs(out[..., nx:], out=out[..., nx:])
            res -= wmax[..., None] * kern.tol_coef
            over = res > rhp[..., nx:] * (1.0 + 1e-9) + 1e-9
            for j in range(over.shape[-1]):  # an OR per column: faster than any() over a short axis
                bad |= over[..., j]
        return lo, hi, bad

    # -- offline, vectorised ----------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The whole record at once: every window is one row of a matrix product (eq. 7, 11).

        Windows are grouped by missing pattern (one kernel each); windows that need the model
        prediction (too few data, or inconsistent) are then filled in time order, as the loop
        does. Falls back to the loop (``None``) for bounds computed from the measurement and
        for time-varying systems with missing samples.
        """
        sys, s, nx = self.sys, self.s, self.sys.nx
        if sys.nd and not isinstance(sys.d, Box):
            return None
        lead, T = y.shape[:-2], y.shape[-2]
        if not T:
            return None  # an empty record: the loop
        y3 = y.reshape(-1, T, sys.ny)
        u3 = u.reshape(int(np.prod(u.shape[:-2])), T, sys.nu)  # (also for nu = 0)
        miss = np.isnan(y3)
        any_miss = bool(miss.any())
        if self._tv and any_miss:
            return None
        Bn = y3.shape[0]
        if T > s and not self._tv and not any_miss and self._const_bounds:
            fast = self._windows_filter(u3, y3)
            if fast is not None:
                lo, hi, incons = fast
                if incons.any():  # predicted from the previous box, in time order (as the loop)
                    dlo, dhi = self._bounds_rows(T)
                    none = np.zeros_like(incons)
                    self._fill_predictions(incons.copy(), none, incons, u3, miss, dlo, dhi, lo, hi)
                return lo.reshape(*lead, T, nx), hi.reshape(*lead, T, nx), incons.reshape(*lead, T)
        lo = np.full((Bn, T, nx), np.nan)
        hi = np.full_like(lo, np.nan)
        need = np.zeros((Bn, T), dtype=bool)
        incons = np.zeros((Bn, T), dtype=bool)
        if T > s:
            dlo, dhi = self._bounds_rows(T)
            c, R = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo)
            for b0, b1, k0, k1 in self._chunks(Bn, T):
                t0 = k0 - s  # each chunk carries the s samples before its first window
                mc = miss[b0:b1, t0:k1]
                yc = y3[b0:b1, t0:k1]
                parts = [u3[b0:b1, t0:k1], np.where(mc, 0.0, yc) if any_miss else yc]
                if self._nc:
                    parts.append(np.broadcast_to(c[t0:k1], (b1 - b0, k1 - t0, self._nc)))
                Z = np.concatenate(parts, axis=-1)
                # views of the results: the window functions fill rows s: (steps k0:k1)
                out = tuple(a[b0:b1, t0:k1] for a in (lo, hi, need, incons))
                if self._tv:
                    self._windows_tv(Z, R[t0:k1], t0, *out)
                elif not any_miss or not mc.any():
                    self._windows_full(Z, R[t0:k1], *out)
                else:
                    self._windows_patterns(Z, R[t0:k1], mc, *out)
            need |= incons
            # windows with a missing sample are intersected with the prediction (as the loop)
            pats = np.zeros((Bn, T), dtype=bool)
            if any_miss:
                row_miss = miss.any(axis=-1)
                for i in range(s + 1):
                    pats[:, s:] |= row_miss[:, s - i : T - i]
            if need.any() or pats.any():
                self._fill_predictions(need, pats & ~need, incons, u3, miss, dlo, dhi, lo, hi)
        return lo.reshape(*lead, T, nx), hi.reshape(*lead, T, nx), incons.reshape(*lead, T)

    def _window_filter(self, kern: _Kernel) -> tuple[LinearFilter, np.ndarray]:
        """Eqs. (7), (11) and the parity residual for complete windows as one linear filter of
        ``(u, y, ‖w‖_∞)``: the window ``z_(k-1) .. z_(k-s)`` is the state of a shift register
        (``z = [u; y; c]``), the outputs are ``x̂ ∓ (|T Md| 𝐫 + γ_i ‖w‖_∞)`` (the bounds,
        :meth:`_finish`) and ``ρ`` (the residual). Cached."""
        hit = self.__dict__.get("_wfilt")
        if hit is not None:
            return hit
        assert kern.GQ is not None and kern.HP is not None and kern.rad_coef is not None
        s, nu, ny, nz, nx = self.s, self.sys.nu, self.sys.ny, self._nz, self.sys.nx
        n = s * nz
        M = np.zeros((n, n))
        for i in range(1, s):  # block i of x[k+1] is block i-1 of x[k]
            M[i * nz : (i + 1) * nz, (i - 1) * nz : i * nz] = np.eye(nz)
        Wz = np.eye(n, nz)  # z_k enters block 0 (s = 0: no state)
        G0, Gs = kern.GQ[:, :nz], kern.GQ[:, nz:]
        cols_u, cols_y = slice(0, nu), slice(nu, nu + ny)
        g = None
        hc = np.zeros(G0.shape[0])
        if self._nc:
            box = self.sys.d
            assert isinstance(box, Box)
            c = box.center
            g = Wz[:, nu + ny :] @ c
            hc = G0[:, nu + ny :] @ c
        rhp = kern.HP @ np.tile(self.sys.d.radius if self.sys.nd else np.zeros(0), s + 1)
        rc = kern.rad_coef[:, None]
        H = [Gs[:nx], Gs[:nx], Gs[nx:]]
        J = [
            [G0[:nx, cols_u], G0[:nx, cols_y], -rc],
            [G0[:nx, cols_u], G0[:nx, cols_y], rc],
            [G0[nx:, cols_u], G0[nx:, cols_y], None],
        ]
        h = [hc[:nx] - rhp[:nx], hc[:nx] + rhp[:nx], hc[nx:]]
        W = [Wz[:, cols_u], Wz[:, cols_y], np.zeros((n, 1))]
        filt = LinearFilter(M, W, H, J, g=g, h=h, block=min(64, max(8, s + 1)))
        self.__dict__["_wfilt"] = (filt, rhp[nx:] * (1.0 + 1e-9) + 1e-9)
        return self.__dict__["_wfilt"]

    def _windows_filter(
        self, u3: np.ndarray, y3: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Time-invariant, constant bounds, no missing sample: every window of the record (or
        batch ``(B, T, ·)``) by :meth:`_window_filter`; rows before ``s`` are NaN. Returns
        ``(lo, hi, inconsistent)`` or None when the complete window has no kernel."""
        s, T = self.s, y3.shape[1]
        kern = self._kernel(s, np.zeros((s + 1, self.sys.ny), dtype=bool))
        if not kern.ok:
            return None
        filt, thr = self._window_filter(kern)
        # ‖w_k‖_∞ over the window z_k .. z_(k-s), z = [u; y; c]: column maxima, then lags
        zmax = np.abs(y3[..., 0], out=scratch(self, "zmax", y3.shape[:2]))
        for j in range(1, y3.shape[-1]):
            np.maximum(zmax, np.abs(y3[..., j]), out=zmax)
        shared_u = is_shared(u3, 1)
        umax = np.max(np.abs(u3[0] if shared_u else u3), axis=-1, initial=0.0)
        np.maximum(zmax, umax, out=zmax)
        if self._nc:
            box = self.sys.d
            assert isinstance(box, Box)
            np.maximum(zmax, float(np.max(np.abs(box.center))), out=zmax)
        wmax = scratch(self, "wmax", y3.shape[:2])
        wmax[...] = zmax
        for i in range(1, s + 1):
            np.maximum(wmax[:, i:], zmax[:, : T - i], out=wmax[:, i:])
        lo, hi, rho = filt.run([u3, y3, wmax[..., None]], temp=[2])
        inc = np.zeros(y3.shape[:2], dtype=bool)
        band = self.__dict__.get("_band")
        if band is None or band.shape[0] != T:  # (T, nρ): rows before s (no window) ignored
            band = np.empty((T, thr.shape[0]))
            band[:s], band[s:] = np.inf, thr
            self.__dict__["_band"] = band
        if rho.shape[-1] and not within_band(rho, None, band):
            assert kern.tol_coef is not None
            over = np.abs(rho[:, s:]) - wmax[:, s:, None] * kern.tol_coef > thr
            inc[:, s:] = over.any(axis=-1)
        lo[:, :s] = np.nan
        hi[:, :s] = np.nan
        return lo, hi, inc

    def _chunks(self, Bn: int, T: int) -> list[tuple[int, int, int, int]]:
        """``(b0, b1, k0, k1)``: streams ``b0:b1``, windows ending at ``k0:k1``, about
        :data:`_CHUNK` windows each (bounded memory for large batches, cache-friendly)."""
        s = self.s
        bstep = max(1, _CHUNK // T)
        tstep = T if bstep > 1 else _CHUNK
        return [
            (b0, min(Bn, b0 + bstep), k0, min(T, k0 + tstep))
            for b0 in range(0, Bn, bstep)
            for k0 in range(s, T, tstep)
        ]

    def _bounds_rows(self, T: int) -> tuple[np.ndarray, np.ndarray]:
        nd = self.sys.nd
        if nd == 0:
            return np.zeros((T, 0)), np.zeros((T, 0))
        box = self.sys.d
        assert isinstance(box, Box)
        if not box.is_time_varying:
            return np.broadcast_to(box.lo, (T, nd)), np.broadcast_to(box.hi, (T, nd))
        self.sys.d_at(T - 1)  # raises a clear error when the bounds do not cover the record
        return box.lo[:T], box.hi[:T]

    def _windows_full(
        self,
        Z: np.ndarray,
        R: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        need: np.ndarray,
        incons: np.ndarray,
    ) -> None:
        """No missing sample, time-invariant: every window of the chunk at once (rows ``s:``).

        ``Σ_i z_{k-i} G_iᵀ`` over the lags, each term one product over the whole chunk (a
        sliding window of the record, without copying it).
        """
        s = self.s
        kern = self._kernel(s, np.zeros((s + 1, self.sys.ny), dtype=bool))
        if not kern.ok:  # cannot happen for a complete window (checked at design)
            need[:, s:] = True
            return
        assert kern.GQ is not None and kern.HP is not None
        out = self._lag_product(Z, kern.GQ)
        if self._const_bounds:
            rhp = kern.HP @ np.tile(R[0], s + 1)
        else:
            rhp = self._lag_product(R[None], kern.HP)[0]
        wmax = self._window_max(Z)
        self._finish(kern, out, rhp, wmax, (lo[:, s:], hi[:, s:], incons[:, s:]))

    def _lag_product(self, Z: np.ndarray, M: np.ndarray) -> np.ndarray:
        """``Σ_i Z[:, k-i] M_iᵀ`` for every window end ``k >= s`` of ``Z`` ``(B, T, n)``, with
        ``M`` ``(r, (s+1) n)`` lag-major: shape ``(B, T - s, r)``."""
        s, T = self.s, Z.shape[-2]
        M3 = M.reshape(M.shape[0], s + 1, -1)
        if Z.shape[0] == 1:
            out = _rows_matmul(Z[0, s:], M3[:, 0].T)
            for i in range(1, s + 1):
                out += _rows_matmul(Z[0, s - i : T - i], M3[:, i].T)
            return out[None]
        out = Z[:, s:] @ M3[:, 0].T
        for i in range(1, s + 1):
            out += Z[:, s - i : T - i] @ M3[:, i].T
        return out

    def _window_max(self, Z: np.ndarray) -> np.ndarray:
        """``‖w_k‖_∞`` of every window of the chunk, shape ``(B, T - s)``."""
        s, T = self.s, Z.shape[-2]
        zmax = np.zeros(Z.shape[:-1])
        for j in range(Z.shape[-1]):  # column by column: much faster than a reduce over n_z
            np.maximum(zmax, np.abs(Z[..., j]), out=zmax)
        wmax = zmax[:, s:].copy()
        for i in range(1, s + 1):
            np.maximum(wmax, zmax[:, s - i : T - i], out=wmax)
        return wmax

    def _gather(self, X: np.ndarray, b: np.ndarray, k: np.ndarray) -> np.ndarray:
        """Lag-major window vectors ``[X[b, k]; X[b, k-1]; …; X[b, k-s]]`` (rows)."""
        lags = k[:, None] - np.arange(self.s + 1)[None, :]
        return X[b[:, None], lags].reshape(len(k), -1)

    def _windows_patterns(
        self,
        Z: np.ndarray,
        R: np.ndarray,
        miss: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        need: np.ndarray,
        incons: np.ndarray,
    ) -> None:
        """Missing samples, time-invariant: one kernel per missing pattern (cached)."""
        s, ny, T = self.s, self.sys.ny, Z.shape[-2]
        # pattern of the window ending at k: miss[k - i] for lags i = 0..s
        pats = np.stack([miss[:, s - i : T - i] for i in range(s + 1)], axis=-2)
        flat = pats.reshape(-1, (s + 1) * ny)
        if flat.shape[1] <= 62:
            code = flat.astype(np.int64) @ (np.int64(1) << np.arange(flat.shape[1], dtype=np.int64))
            ucode, inv = np.unique(code, return_inverse=True)
            patterns = [(int(c) >> np.arange(flat.shape[1])) & 1 for c in ucode]
        else:
            uniq, inv = np.unique(flat, axis=0, return_inverse=True)
            patterns = list(uniq)
        codes = inv.reshape(Z.shape[0], T - s)
        Rb = np.broadcast_to(R, (Z.shape[0], *R.shape))
        for j, pattern in enumerate(patterns):
            b, kk = np.nonzero(codes == j)
            kk = kk + s
            kern = self._kernel(s, np.asarray(pattern, dtype=bool).reshape(s + 1, ny))
            if not kern.ok:
                need[b, kk] = True
                continue
            W, Rw = self._gather(Z, b, kk), self._gather(Rb, b, kk)
            lo[b, kk], hi[b, kk], incons[b, kk] = self._evaluate(kern, W, Rw)

    def _windows_tv(
        self,
        Z: np.ndarray,
        R: np.ndarray,
        t0: int,
        lo: np.ndarray,
        hi: np.ndarray,
        need: np.ndarray,
        incons: np.ndarray,
    ) -> None:
        """Time-varying, no missing sample: the per-step gains ``T_k`` (closed form, cached)
        stacked over the chunk and applied to all its windows and streams in one product.
        ``t0`` is the step of the chunk's first row."""
        from numpy.lib.stride_tricks import sliding_window_view

        s, nx, ny, T = self.s, self.sys.nx, self.sys.ny, Z.shape[-2]
        full = np.zeros((s + 1, ny), dtype=bool)
        kerns = [self._kernel(t0 + k, full) for k in range(s, T)]
        ok = np.array([kn.ok for kn in kerns])
        need[:, s:] = ~ok
        if not ok.any():
            return
        good = [kn for kn in kerns if kn.ok]
        assert all(kn.GQ is not None and kn.HP is not None for kn in good)

        def stacked(name: str, fill: Any) -> np.ndarray:
            arrs = [getattr(kn, name) if kn.ok else None for kn in kerns]
            like = getattr(good[0], name)
            return np.stack([a if a is not None else np.full_like(like, fill) for a in arrs])

        def lag_major(V: np.ndarray) -> np.ndarray:
            # sliding view (..., K, n, s+1), time ascending -> lag-major rows (..., K, (s+1) n)
            return np.flip(V, axis=-1).swapaxes(-1, -2).reshape(*V.shape[:-2], -1)

        W = lag_major(sliding_window_view(Z, s + 1, axis=-2))
        Rw = lag_major(sliding_window_view(R, s + 1, axis=0))
        kern = _Kernel(
            ok=True,
            rank=nx,
            nx=nx,
            GQ=None,
            HP=None,
            rad_coef=stacked("rad_coef", 0.0),
            tol_coef=stacked("tol_coef", 0.0),
        )
        out = np.einsum("bkw,krw->bkr", W, stacked("GQ", 0.0))
        rhp = np.einsum("kw,krw->kr", Rw, stacked("HP", 0.0))
        wmax = np.max(np.abs(W), axis=-1, initial=0.0)
        lo[:, s:], hi[:, s:], incons[:, s:] = self._finish(kern, out, rhp, wmax)
        incons[:, s:] &= ok

    def _fill_predictions(
        self,
        need: np.ndarray,
        inter: np.ndarray,
        incons: np.ndarray,
        u3: np.ndarray,
        miss: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
    ) -> None:
        """Windows that use the previous box, in time order, as the loop does (:meth:`_combine`):
        ``need`` (no usable window, or inconsistent: the prediction) and ``inter`` (a window
        with missing samples: its box intersected with the prediction). The first window
        (``k = s``) predicts from ``x0`` propagated forward, if given; later ones from the box
        at ``k - 1``, level by level: all windows whose predecessor is settled at once."""
        s = self.s
        for b in np.nonzero(need[:, s] | inter[:, s])[0]:
            prior = self._first_prior(int(b), u3, dlo, dhi)
            raw = None if need[b, s] and not incons[b, s] else (lo[b, s], hi[b, s])
            if prior is None and raw is None:
                kern = self._kernel(s, miss[b, s - np.arange(s + 1)])
                raise self._no_box_error(s, kern.rank)
            if prior is not None:
                box, incons[b, s] = self._combine(raw, bool(incons[b, s]), prior)
                lo[b, s], hi[b, s] = box
        pending = need | inter
        pending[:, : s + 1] = False
        while pending.any():
            ready = pending.copy()
            ready[:, 1:] &= ~pending[:, :-1]  # the previous box is known
            b, k = np.nonzero(ready)
            plo, phi = outward(lo[b, k - 1], hi[b, k - 1])
            if self._tv:
                pred = [
                    self._predict(plo[j], phi[j], u3[bj, kj - 1], dlo[kj - 1], dhi[kj - 1], kj)
                    for j, (bj, kj) in enumerate(zip(b.tolist(), k.tolist()))
                ]
                p_lo, p_hi = np.array([p[0] for p in pred]), np.array([p[1] for p in pred])
            else:
                p_lo, p_hi = self._predict(plo, phi, u3[b, k - 1], dlo[k - 1], dhi[k - 1], 1)
            # need: the prediction; inter: the intersection (empty -> inconsistent, prediction)
            i_lo, i_hi = np.maximum(lo[b, k], p_lo), np.minimum(hi[b, k], p_hi)
            empty = inter[b, k] & (i_lo > i_hi).any(axis=-1)
            use_pred = need[b, k] | empty
            lo[b, k] = np.where(use_pred[:, None], p_lo, i_lo)
            hi[b, k] = np.where(use_pred[:, None], p_hi, i_hi)
            incons[b, k] |= empty
            pending &= ~ready

    def _first_prior(
        self, b: int, u3: np.ndarray, dlo: np.ndarray, dhi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The prediction of the box at ``k = s`` from ``x0`` (None without ``x0``)."""
        s = self.s
        if self.x0 is None:
            return None
        if s == 0:
            return self.x0.lo, self.x0.hi  # the prior box of x[0] itself
        plo, phi = outward(np.array(self.x0.lo), np.array(self.x0.hi))
        for j in range(1, s):
            plo, phi = outward(*self._predict(plo, phi, u3[b, j - 1], dlo[j - 1], dhi[j - 1], j))
        return self._predict(plo, phi, u3[b, s - 1], dlo[s - 1], dhi[s - 1], s)
