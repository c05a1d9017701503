"""The offline design of the fixed-time estimator [Wang2020]: no time loop here.

For the window ending at step ``k`` (``s + 1`` samples), :class:`WindowDesigner` builds

* the model of the known input ``v = [u; y; c]`` (``c`` the centre of ``d``, Section 2), with the
  output injection ``L`` of [Wang2020, Remark 1] when ``A`` is not invertible;
* the stacked matrices ``Mx, Mu, Md`` of [Wang2020, eq. (6)] (per window for a time-varying
  system, [Wang2020, Remark 4]), by :func:`ivobs.design.parity.stack_window`;
* ``T`` with ``T Mx = I`` (eq. (8)): the optimum of [Wang2020, Theorem 1, eq. (13)], the general
  solution ``Mx† + S Mx⊥`` of Lemma 2, a user's ``T``, or the width-optimal LP (not in the paper);

and returns them as a :class:`FixedTimeDesign`. The window gains applied to the data, and their
certification, are in :mod:`.gains`.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..._validate import as_int
from ...design.injection import invertible_injection, is_invertible
from ...design.parity import general_T, optimal_T, pinv_perp, stack_window, width_optimal_T
from ...errors import DesignError, IvobsError
from ...linalg import check_observable, observability_index
from ...model import LinearSystem
from ..base import Design
from .window import centre_radius

__all__ = [
    "MAX_WINDOW",
    "FixedTimeDesign",
    "WindowDesigner",
    "check_T",
    "check_design_options",
    "check_window",
    "injection",
    "rank_advice",
]

CACHE_SIZE = 16384
"""Entries kept per cache (matrices per step, gains per step and missing pattern)."""
MAX_WINDOW = 1000
"""Largest window ``s`` (past samples in the stacked matrices of [Wang2020, eq. (6)])."""


@dataclass(frozen=True)
class FixedTimeDesign(Design):
    """The offline design of [Wang2020] (for a time-varying system: the window ending at
    ``k = s``).

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


# -- validation of the options ------------------------------------------------------------------
PAPER_WINDOW_STATES = 10
"""Up to this many states the default window is ``s = nx − 1`` ([Wang2020, Lemma 2])."""


def check_window(s: Any, nx: int, ny: int = 1, index: int | None = None) -> int:
    """The window ``s``. Default: ``nx − 1`` ([Wang2020, Lemma 2]) up to
    :data:`PAPER_WINDOW_STATES` states; above, ``ν + 1`` with ``ν`` the observability index
    (``index``): the stacked matrices of eq. (6) hold ``A⁻ʲ`` for ``j <= s``, whose conditioning
    grows exponentially with ``s`` (``nx − 1`` on a random 30-state plant with 2 outputs leaves
    ``Mx`` with numerical rank 2 of 30), while ``T Mx = I`` only needs ``s >= ν − 1``. A window
    needs ``(s + 1) ny >= nx`` rows; whether ``Mx`` has rank ``nx`` is checked by the design."""
    if s is None:
        if nx <= PAPER_WINDOW_STATES or index is None or index > nx:
            return max(nx - 1, 0)
        return int(min(nx - 1, index + 1))
    s = as_int("s", s, 0)
    if s > MAX_WINDOW:
        raise IvobsError(
            f"s: expected a window of at most {MAX_WINDOW} past samples (the stacked "
            f"matrices of [Wang2020, eq. (6)] have (s + 1) ny rows and as many columns per input "
            f"and disturbance), got s = {s}"
        )
    need = -(-nx // max(ny, 1)) - 1
    if s < need:
        raise IvobsError(
            f"s: the fixed-time estimator needs (s + 1) ny >= nx, i.e. s >= {need} (the window "
            f"y[k-s..k] must observe the {nx} states, [Wang2020, Lemma 2]), got s = {s}"
        )
    return int(s)


def check_design_options(sys: LinearSystem, criterion: str, T: Any, S: Any, weighted: bool) -> None:
    """The combinations of ``criterion``, ``T``, ``S`` and ``weighted`` that make sense."""
    tv = sys.is_time_varying
    if criterion not in ("frobenius", "width"):
        raise IvobsError(f"criterion: expected 'frobenius' or 'width', got {criterion!r}")
    if criterion == "width" and (T is not None or S is not None or weighted):
        raise IvobsError(
            "criterion: 'width' designs T itself; do not combine with T, S or weighted"
        )
    if criterion == "width" and (tv or not sys.has_constant_bounds):
        raise IvobsError(
            "criterion: 'width' needs a time-invariant system with constant bounds d (a "
            "linear program at design time); use 'frobenius' (closed form per step)"
        )
    if T is not None and S is not None:
        raise IvobsError("T, S: give at most one (T directly, or S in T = Mx† + S Mx⊥)")
    if weighted and (T is not None or S is not None):
        raise IvobsError("weighted: applies to the optimal T only; do not combine with T or S")
    if T is not None and tv:
        raise IvobsError(
            "T: a fixed T cannot satisfy T Mx(k) = I for every k of a time-varying system; "
            "pass S (T_k = Mx(k)† + S Mx(k)⊥) or nothing (optimal T_k)"
        )
    if weighted and not sys.has_constant_bounds:
        raise IvobsError("weighted: needs constant bounds d (a Box with constant bounds)")


def check_T(T: np.ndarray, Mx: np.ndarray) -> np.ndarray:
    """Accept a ``T`` with ``T Mx = I`` up to printed precision and project it onto the
    constraint, ``T + (I - T Mx) Mx†``, so that eq. (9) holds to rounding (a published
    ``T`` rounded to 4 decimals misses ``T Mx = I`` by ~1e-4, which would void eq. 9)."""
    nx = Mx.shape[1]
    resid = float(np.max(np.abs(T @ Mx - np.eye(nx))))
    if not resid <= 1e-3:
        raise IvobsError(
            f"T: does not satisfy T Mx = I ([Wang2020, eq. (8)]): max |T Mx - I| = {resid:.2e} "
            "(> 1e-3); pass a left inverse of Mx (see est.design.Mx), or S, or nothing"
        )
    projected: np.ndarray = T + (np.eye(nx) - T @ Mx) @ np.linalg.pinv(Mx)
    return projected


def injection(A: np.ndarray, C: np.ndarray, L: np.ndarray | None, where: str) -> Any:
    """[Wang2020, Remark 1]: ``L`` with ``A - LC`` invertible (``None`` when ``A`` already
    is)."""
    if L is not None:
        if not is_invertible(A - L @ C):
            raise DesignError(
                f"L: {where} - LC is not invertible; the backward propagation ([Wang2020, "
                "eq. (4)]) needs it ([Wang2020, Remark 1]): choose L placing the poles of A - LC "
                "away from 0"
            )
        return L
    if is_invertible(A):
        return None
    return invertible_injection(A, C)


def _centre_size(sys: LinearSystem) -> int:
    """Columns of ``c`` (the centre of ``d``) in ``z``: 0 for symmetric constant bounds."""
    box = sys.d_at(0) if sys.has_constant_bounds else None
    return 0 if box is not None and np.all(box.lo == -box.hi) else int(sys.nd)


class WindowDesigner:
    """The design of each window ``k - s .. k`` (cached per step for time-varying systems).

    ``L``: the output injection in use (``None``: the backward propagation with ``A``);
    :meth:`redesign` replaces it. ``design``: the design of the window ending at ``k = s``.
    """

    def __init__(
        self,
        sys: LinearSystem,
        s: int,
        *,
        T: np.ndarray | None,
        S: np.ndarray | None,
        L: np.ndarray | None,
        criterion: str,
        weighted: bool,
    ):
        self.sys = sys
        self.s = s
        self.tv = sys.is_time_varying
        self.const_bounds = sys.has_constant_bounds
        self.nc = _centre_size(sys)
        self.nz = sys.nu + sys.ny + self.nc
        """Entries of ``z = [u; y; c]`` per sample of the window vector ``w``."""
        self.centre, self.radius = np.zeros(sys.nd), np.zeros(sys.nd)
        """The constant bounds of ``d`` as ``c ± r`` (:func:`centre_radius`), if they are."""
        if self.const_bounds:
            box = sys.d_at(0)
            self.centre, self.radius = centre_radius(box.lo, box.hi)
        self.criterion = criterion
        self.weighted = weighted
        self.S = S
        self.L_user = L
        self.T_user: np.ndarray | None = None
        self.L: np.ndarray | None = None
        self.design: FixedTimeDesign | None = None
        self._mats: OrderedDict[int, tuple[np.ndarray, ...]] = OrderedDict()
        self._stacks: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        if not self.tv:
            A, _, C, _, _, _ = sys.matrices_at(0)
            try:
                check_observable(A, C, "the fixed-time estimator ([Wang2020, Lemma 2])")
            except IvobsError as exc:  # a design impossibility, as for the other methods
                raise DesignError(str(exc)) from None
            self.L = injection(A, C, L, "A")
        elif L is not None:
            self.L = L
        if T is not None:
            self.T_user = check_T(T, self.stack(s)[0])

    # -- the model of one step --------------------------------------------------------------
    def matrices(self, j: int) -> tuple[np.ndarray, ...]:
        """``(A', Bv, C, Dv, E', F, L)`` at step ``j`` for the known input ``v = [u; y; c]``:
        ``A' = A - LC``, ``Bv = [B - LD, L, E - LF]``, ``Dv = [D, 0, F]``, ``E' = E - LF``
        ([Wang2020, Remark 1 and Section 2]; ``L = 0`` when ``A`` is invertible)."""
        key = 0 if not self.tv else j
        hit = self._mats.get(key)
        if hit is not None:
            return hit
        A, B, C, D, E, F = self.sys.matrices_at(j)
        nx, ny = self.sys.nx, self.sys.ny
        L = injection(A, C, self.L, f"A({j})") if self.tv else self.L
        Lm = np.zeros((nx, ny)) if L is None else L
        Ep = E - Lm @ F
        Bv = [B - Lm @ D, Lm]
        Dv = [D, np.zeros((ny, ny))]
        if self.nc:
            Bv.append(Ep)
            Dv.append(F)
        out = (A - Lm @ C, np.hstack(Bv), C, np.hstack(Dv), Ep, F, Lm)
        self._mats[key] = out
        if len(self._mats) > CACHE_SIZE:
            self._mats.popitem(last=False)
        return out

    def stack(self, k: int, lags: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Mx, Mv, Md)`` of the window of ``lags`` samples (default ``s + 1``) ending at
        ``k`` ([Wang2020, eq. (6), Remark 4])."""
        n = self.s + 1 if lags is None else lags
        if self.tv:
            return stack_window([self.matrices(k - i)[:6] for i in range(n)])
        hit = self._stacks.get(n)
        if hit is None:
            hit = stack_window([self.matrices(0)[:6]] * n)
            for M in hit:
                M.flags.writeable = False  # (shared by every window of that length)
            self._stacks[n] = hit
        return hit

    def selection(self, lags: int) -> np.ndarray:
        """``Sel`` with ``Sel w = 𝐲`` (the outputs of a window vector ``w`` of ``lags``
        samples)."""
        ny, nu, nz = self.sys.ny, self.sys.nu, self.nz
        Sel = np.zeros((lags * ny, lags * nz))
        for i in range(lags):
            Sel[i * ny : (i + 1) * ny, i * nz + nu : i * nz + nu + ny] = np.eye(ny)
        return Sel

    # -- T ----------------------------------------------------------------------------------
    def weights(self, lags: int | None = None) -> np.ndarray | None:
        """Column weights ``Wd`` of the criterion over ``lags`` samples (default ``s + 1``;
        ``None``: the paper's ``‖T Md‖_F``)."""
        if not (self.weighted or self.criterion == "width") or self.sys.nd == 0:
            return None
        box = self.sys.d_at(0)
        return np.tile(box.radius, self.s + 1 if lags is None else lags)

    def T_full(self, Mx: np.ndarray, Md: np.ndarray) -> tuple[np.ndarray, Any]:
        """``T`` of a complete window, and Theorem 1's quantities (``None`` for a given ``T``
        or ``S``)."""
        if self.T_user is not None:
            return self.T_user, None
        if self.S is not None:
            return general_T(Mx, self.S), None
        opt = optimal_T(Mx, Md, self.weights())
        if self.criterion == "width":
            return width_optimal_T(Mx, Md, self.weights()), opt
        return opt.T, opt

    # -- the design ---------------------------------------------------------------------------
    def redesign(self, L: np.ndarray | None) -> FixedTimeDesign:
        """Design again with the output injection ``L`` (``None``: the backward propagation
        with ``A`` itself); the result becomes :attr:`design`."""
        self.L = L
        self._mats.clear()
        self._stacks.clear()
        self.design = self.window(self.s)
        return self.design

    def window(self, k: int) -> FixedTimeDesign:
        """The design of the window ending at ``k`` (``k = s`` for :attr:`design`)."""
        sys, s = self.sys, self.s
        nx, ny, nu, nz, nc = sys.nx, sys.ny, sys.nu, self.nz, self.nc
        Mx, Mv, Md = self.stack(k)
        Mx_pinv, Mx_perp, _, rank = pinv_perp(Mx)
        if rank < nx:
            where = "the window k = 0..s" if not self.tv else f"the window ending at k = {k}"
            raise DesignError(
                f"pair (A, C) is not observable over {where}: the stacked matrix Mx ([Wang2020, "
                f"eq. (6)]) has rank {rank} of {nx}; the fixed-time estimator needs rank nx. "
                f"{rank_advice(sys, s)}"
            )
        T, opt = self.T_full(Mx, Md)
        U1, S1, V1, r = np.zeros((Mx.shape[0], 0)), np.zeros((0, 0)), np.zeros((0, 0)), 0
        if opt is not None:  # Theorem 1's quantities
            Mx_pinv, Mx_perp, r = opt.Mx_pinv, opt.Mx_perp, opt.rank
            U1, S1, V1 = opt.U1, opt.S1, opt.V1
        cols = np.arange((s + 1) * nz).reshape(s + 1, nz)
        H = None
        if self.const_bounds and sys.nd:
            H = -T @ Md * np.tile(sys.d_at(0).radius, s + 1)[None, :]
        elif sys.nd == 0:
            H = np.zeros((nx, 0))
        L = self.matrices(k)[6] if self.L is not None or self.tv else None
        if self.tv and L is not None and not np.any(L):
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
            S=self.S,
            H=H,
            L=L,
            My=Mv[:, cols[:, nu : nu + ny].ravel()] if L is not None else None,
            Mc=Mv[:, cols[:, nu + ny :].ravel()] if nc else None,
            weighted=self.weighted,
            criterion=self.criterion,
        )


def rank_advice(sys: LinearSystem, s: int) -> str:
    """What to do about a rank-deficient ``Mx``: a larger ``s`` if the window is shorter than
    the observability index ``ν``, else a smaller one (the rank is numerical: ``A⁻ʲ`` for large
    ``j`` swamps the other rows), else the pair is not observable."""
    if sys.is_time_varying:
        return "Increase s, or check the observability of the pair over the window"
    nu = observability_index(sys.A_at(0), sys.C_at(0))
    if nu > sys.nx:
        return "(A, C) is not observable: no window determines the state"
    if s < nu - 1:
        return f"Increase s to at least ν − 1 = {nu - 1} (ν: the observability index)"
    why = (
        f"(A, C) is observable with index ν = {nu}, so the rank is lost numerically: the "
        f"backward powers A⁻ʲ (j <= s = {s}) of eq. (6) are too ill-conditioned"
    )
    if s > nu + 1:
        return f"{why}; use a smaller window, s = {nu - 1} .. {nu + 1}"
    return (
        f"{why}, and no shorter window observes the state (s >= ν − 1 = {nu - 1}): the "
        "fixed-time estimator cannot be designed for this pair in floating point; use "
        "'interval-transformed' or 'kkl'"
    )
