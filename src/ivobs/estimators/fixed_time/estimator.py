"""The ``fixed-time`` method: the parity-space interval estimator of [Wang2020] behind the
:class:`~ivobs.estimators.base.Estimator` protocol (design in :mod:`.design` and :mod:`.gains`,
the step in :mod:`.recursion`, the whole-record path in :mod:`.vectorised`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validate import as_bool, as_int, as_matrix
from ...errors import DesignError
from ...model import LinearSystem
from ...sets import Box
from .. import register
from ..base import Estimator, check_size
from ..state import Step
from .design import (
    PAPER_WINDOW_STATES,
    FixedTimeDesign,
    WindowDesigner,
    check_design_options,
    check_window,
    observability_index,
    rank_advice,
)
from .gains import WindowGain, WindowGains, choose_injection
from .recursion import FixedTimeRecursion, FixedTimeState
from .vectorised import WindowBatch

__all__ = ["FixedTimeEstimator"]


@register
class FixedTimeEstimator(Estimator):
    """Fixed-time parity-space interval estimator [Wang2020, eqs. (6)-(13), Theorem 1].

    At every step ``k >= s`` the state is reconstructed from the last ``s + 1`` samples only::

        x̂_k = T (𝐲_k - Mu 𝐮_k)                 (eq. 7),  T Mx = I  (eq. 8)
        x_k ∈ <x̂_k, -T Md blkdiag(Wd)>          (eq. 10)
        x̂_k - |T Md| 𝐫_k <= x_k <= x̂_k + |T Md| 𝐫_k    (eq. 11, 𝐫_k the stacked bound radii)

    with the stacked matrices of eq. (6) (:mod:`ivobs.design.parity`) and the optimal ``T`` of
    Theorem 1 (eq. 13). There is no recursion: errors do not propagate, and without disturbance
    ``x̂_k = x_k`` exactly from ``k = s`` on (Remark 3, "fixed-time convergence").

    Data used: the box of ``x[k]`` uses ``y[k-s..k]`` and ``u[k-s..k]`` (and nothing older), so
    it is valid from ``k = s`` (``valid_from = s``); rows before are NaN. No prior on ``x[0]``
    is needed (``needs_x0 = False``).

    Other Parameters
    ----------------
    s : window length minus one, ``s >= nx - 1`` ([Wang2020, Lemma 2]). Default ``nx - 1``. A
        larger ``s`` starts later and gives ``T`` more freedom: ``‖T Md‖_F`` never grows with
        ``s``, but the boxes may (see ``criterion``).
    T : an explicit ``(nx, (s+1)·ny)`` matrix with ``T Mx = I`` (eq. 8), e.g. to reproduce a
        published design. Default: the optimal ``T`` of Theorem 1 (eq. 13).
    S : the free matrix of the general solution ``T = Mx† + S Mx⊥`` (Lemma 2), instead of ``T``.
    L : the output-injection gain of Remark 1 (``A - LC`` invertible). Default: none when ``A`` is
        invertible and the design with ``A`` is accurate; otherwise (``A`` singular, or so
        ill-conditioned that the certified error of the window gain exceeds
        :data:`~.gains.ACCURACY` of the data scale) a small, well-conditioned gain
        (:func:`ivobs.design.injection.invertible_injection`; if that design is not accurate
        either, the narrowest accurate one among
        :func:`ivobs.design.injection.injection_candidates`).
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

    Notes
    -----
    Asymmetric bounds ([Wang2020, Section 2]): ``d = c + δ``, ``|δ| <= r``; ``E c``, ``F c``
    enter as a known input (``Mc``). Time-varying systems (Remark 4): the stacked matrices and
    ``T_k`` are recomputed per window (closed form: one SVD), cached. ``D u`` in the output
    equation is kept (``Mu`` gets ``D`` on its block diagonal).

    Missing samples (NaN in ``y``): the rows of the stack that are missing, or that involve a
    missing ``y`` through ``L y``, are removed; if the remaining ``Mx`` still has rank ``nx``,
    the optimal ``T`` (Theorem 1, weighted by the bounds under ``criterion="width"``) of that
    reduced stack gives a box (computed once per missing pattern, cached; a user ``T`` or ``S``
    and the width LP apply to complete windows only), which is intersected with the prediction
    from the previous box, ``x_k ∈ A[x_{k-1}] + B u_{k-1} + E[d_{k-1}]`` ([Efimov2013, Lemma 1],
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
    inverse (:func:`ivobs.design.certify.window_bound`, :class:`.gains.WindowGains`): the
    coefficients of ``x_k - G w`` in the anchor state, the known inputs and the disturbances are
    computed in extended precision with a ``γ_n`` bound (``γ_n = n ε / (1 - n ε)``,
    [Higham2002, Lemma 3.1]), ``G`` is refined once by them, and the radius is ``|R_δ| 𝐫``
    (``= |T Md| 𝐫`` of eq. 11 up to rounding) plus the certified remainder
    ``(Σ_j |R_v|_ij + a_i κ) ‖w‖_∞`` (``a_i κ``: the residual of ``T Mx = I`` times a bound of
    the anchor state from the same window). On top, the radius carries
    ``64 (s+1) n_z ε ‖G_i‖₁ ‖w‖_∞`` for the evaluation of ``G w`` in ``float64`` (at most
    ``(s+1) n_z`` roundings per entry, and the ``ε/2`` of the recorded data), and the base adds
    its outward margin. Exact arithmetic on the model as given is assumed (the model matrices
    are exact, the data are the recorded ``float64`` values of the true signals).
    """

    name = "fixed-time"
    order = 10
    summary = "fixed-time parity-space estimator with the optimal T of Theorem 1 [Wang2020]"
    reference = "[Wang2020, eqs. (6)-(13), Theorem 1, Remarks 1 and 4]"
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
        **options: Any,
    ):
        super().__init__(sys, x0, **options)
        nx, ny = sys.nx, sys.ny
        check_size(
            self.name,
            nx,
            "uses the stacked matrices of [Wang2020, eq. (6)] over s + 1 >= nx "
            "samples (O(nx^2 ny) entries and work)",
        )
        index = None
        if s is None and not sys.is_time_varying and nx > PAPER_WINDOW_STATES:
            index = observability_index(sys.A_at(0), sys.C_at(0))
        self.s = check_window(s, nx, ny, index)
        weighted = as_bool("weighted", weighted)
        check_design_options(sys, criterion, T, S, weighted)
        check = as_bool("check_consistency", check_consistency)
        L_user = None if L is None else as_matrix("L", L, nx, ny)
        S_user = None if S is None else as_matrix("S", S, nx, (self.s + 1) * ny)
        T_user = None if T is None else as_matrix("T", T, nx, (self.s + 1) * ny)
        self._designer = WindowDesigner(
            sys, self.s, T=T_user, S=S_user, L=L_user, criterion=criterion, weighted=weighted
        )
        self._gains = WindowGains(self._designer, check)
        self.design = self._initial_design(
            choose=not sys.is_time_varying and L is None and T is None
        )
        if not sys.is_time_varying and not self._gains.complete(self.s).ok:
            raise DesignError(
                f"{self.name}: the gain of the complete window (s = {self.s}) cannot be "
                "certified: the window does not determine the state to within the rounding of "
                "its stacked matrices (every box would be the model's prediction alone, which "
                "diverges when |A| is not Schur). " + rank_advice(sys, self.s)
            )
        self._recursion = FixedTimeRecursion(self._gains, self.x0)
        self._batch = WindowBatch(self._gains, self.x0)
        self.valid_from = self.s

    def _initial_design(self, choose: bool) -> FixedTimeDesign:
        """The design of the window ``0..s``; for a time-invariant system without a given ``L``
        or ``T``, the output injection of [Wang2020, Remark 1] is chosen by the certified
        accuracy (:func:`.gains.choose_injection`)."""
        des = self._designer
        try:
            des.design = des.window(self.s)
            error = None
        except DesignError as exc:  # e.g. Theorem 1's check on an ill-conditioned A
            if not choose or des.L is not None:
                raise
            error = exc
        if choose:
            choose_injection(self._gains, error)
        assert des.design is not None
        return des.design

    def design_at(self, k: int) -> FixedTimeDesign:
        """The design of the window ending at step ``k >= s`` (time-varying systems: ``T_k``)."""
        k = as_int("k", k, self.s)
        if self._designer.tv:
            return self._designer.window(k)
        assert isinstance(self.design, FixedTimeDesign)
        return self.design

    def _kernel(self, k: int, missing: np.ndarray) -> WindowGain:
        """The certified gain of the window ending at ``k`` with missing pattern ``missing``."""
        return self._gains.get(k, missing)

    # -- online ---------------------------------------------------------------------------
    def _initial_state(self) -> FixedTimeState:
        return self._recursion.initial_state()

    def _step(
        self, state: FixedTimeState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[FixedTimeState]:
        return self._recursion.step(state, u_k, y_k)

    # -- offline, vectorised ----------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        return self._batch.run(u, y)
