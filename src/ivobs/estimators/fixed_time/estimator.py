"""The ``fixed-time`` method: the parity-space interval estimator of [Wang2020] behind the
:class:`~ivobs.estimators.base.Estimator` protocol (design in :mod:`.design` and :mod:`.gains`,
the whole-record path in :mod:`.batch`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..._validate import as_bool, as_int, as_matrix
from ...errors import DesignError
from ...linalg import observability_index
from ...model import LinearSystem
from ...sets import Box
from ...sets.rounding import enclose
from .. import register
from ..base import Estimator, check_size
from ..state import OnlineState, Step, evolve
from .batch import RecordWindows
from .design import (
    PAPER_WINDOW_STATES,
    FixedTimeDesign,
    WindowDesigner,
    check_design_options,
    check_window,
    rank_advice,
)
from .gains import WindowGain, WindowGains, choose_injection, evaluate
from .window import centre_radius, combine, no_box_error, predict

__all__ = ["FixedTimeEstimator", "FixedTimeState"]


@dataclass(frozen=True, kw_only=True)
class FixedTimeState(OnlineState):
    """The last ``2 s + 2`` samples, most recent first (row ``i`` holds step ``k - 1 - i``
    before the step of ``k``): ``z = [u; y; c]`` (``y`` zero where missing, ``c`` the centre of
    the bounds of ``d``), ``ymiss`` (1 where ``y`` is missing, and in the rows before step 0),
    ``r`` (the radii of the bounds of ``d``); and the box ``[lo, hi]`` of step ``k - 1``
    (meaningful once ``has_box``)."""

    z: np.ndarray
    ymiss: np.ndarray
    r: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    has_box: bool = False

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"),)


@register
class FixedTimeEstimator(Estimator):
    """Fixed-time parity-space interval estimator [Wang2020, eqs. (6)-(13), Theorem 1].

    At every step ``k >= s`` the state is reconstructed from the last ``s + 1`` samples only::

        x̂_k = T (𝐲_k - Mu 𝐮_k)                 (eq. 7),  T Mx = I  (eq. 8)
        x_k ∈ <x̂_k, -T Md blkdiag(Wd)>          (eq. 10)
        x̂_k - |T Md| 𝐫_k <= x_k <= x̂_k + |T Md| 𝐫_k    (eq. 11, 𝐫_k the stacked bound radii)

    with the stacked matrices of eq. (6) (:mod:`ivobs.design.parity`) and the optimal ``T`` of
    Theorem 1 (eq. 13). There is no recursion: errors do not propagate, and without disturbance
    ``x̂_k = x_k`` from ``k = s`` on (Remark 3, "fixed-time convergence").

    Data used: the box of ``x[k]`` uses ``y[k-s..k]`` and ``u[k-s..k]`` (and nothing older
    unless samples are missing, below), so it is valid from ``k = s`` (``valid_from = s``);
    rows before are NaN. No prior on ``x[0]`` is needed (``needs_x0 = False``).

    Other Parameters
    ----------------
    s : window length minus one, ``s >= nx - 1`` ([Wang2020, Lemma 2]). Default ``nx - 1`` up
        to 10 states, the observability index plus one above. A larger ``s`` starts later and
        gives ``T`` more freedom: ``‖T Md‖_F`` never grows with ``s``, but the boxes may (see
        ``criterion``).
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
        bound ``|N Md| 𝐫`` (rounding included); a violation proves that the data contradict
        the model (reported as inconsistent, the box is then predicted from the previous one).
        Default True; False skips the test (a little faster).

    Notes
    -----
    Asymmetric bounds ([Wang2020, Section 2]): ``d = c + δ``, ``|δ| <= r``; ``E c``, ``F c``
    enter as a known input (``Mc``). Time-varying systems (Remark 4): the stacked matrices and
    ``T_k`` are recomputed per window (closed form: one SVD), cached. ``D u`` in the output
    equation is kept (``Mu`` gets ``D`` on its block diagonal).

    Missing samples (NaN in ``y``): the rows of the stack that are missing, or that involve a
    missing ``y`` through ``L y``, are removed. If the remaining rows of ``Mx`` do not determine
    the state (rank below ``nx``, or no certified gain), the window is extended back one
    sample at a time, up to ``2 s + 2`` samples, until they do: the optimal ``T`` of Theorem 1
    (weighted by the bounds under ``criterion="width"``) of that reduced stack gives a box
    (one gain per missing pattern, cached; a user ``T`` or ``S`` and the width LP apply to
    complete windows only). That box is intersected with the prediction from the previous box,
    ``x_k ∈ A[x_{k-1}] + B u_{k-1} + E[d_{k-1}]`` ([Efimov2013, Lemma 1]): both contain ``x_k``,
    and a reduced window can be poor (it may have to differentiate the few outputs left). The
    box therefore never depends on more than ``2 s + 2`` samples, however many are missing;
    only where even the longest window has too few data is it the prediction alone (sound,
    finite once a box exists). Complete windows are never intersected (the paper's numbers).
    ``x0``, when given, is used for nothing else than this prediction before the first box; a
    window at ``k >= s`` without enough data and without any earlier box raises
    :class:`IvobsError`.

    Rounding (what is proven). The model matrices are exact (the floats given), ``u`` is the
    input applied and ``y`` the measurement or its rounding to the nearest double. (1) The
    window gain ``G`` is computed through the inverses of eq. (4) and an SVD, so ``T Mx = I``
    and the cancellation of the known inputs hold only to rounding; each gain is *certified*
    on the forward form of the window, which needs no inverse
    (:func:`ivobs.design.certify.window_bound`, [Higham2002, Lemma 3.1] in extended precision):
    in exact arithmetic ``|x_k - G w| <= HP 𝐫 + c' ‖w‖_∞`` row by row, ``HP`` the certified
    ``|T Md|`` (:meth:`.gains.WindowGains._certify`). (2) The evaluation ``fl(G w)`` and the
    rounding of the recorded ``y`` add ``γ_{n+2} ‖G_i‖₁ ‖w‖_∞`` and an underflow term; the
    constants of the radius are enlarged so that its own rounding and that of ``x̂ ∓ rad`` are
    covered (:func:`.gains.finish`: the bounds contain ``x_k`` as computed). (3) The parity test
    uses the same proven radius, so an admissible sample is never flagged. (4) The prediction
    and the intersection are :func:`ivobs.sets.image_bounds` (rounding included) and
    ``max``/``min`` (exact). The box kept for the next step is the box returned.
    ``proven_rounding = True``: the base class adds no margin.
    """

    name = "fixed-time"
    order = 10
    summary = "fixed-time parity-space estimator with the optimal T of Theorem 1 [Wang2020]"
    reference = "[Wang2020, eqs. (6)-(13), Theorem 1, Remarks 1 and 4]"
    supports_time_varying = True
    needs_x0 = False
    proven_rounding = True

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
        self._complete: WindowGain | None = None  # the complete window's gain, time-invariant
        if not sys.is_time_varying:
            self._complete = self._gains.complete(self.s)
            if not self._complete.ok:
                raise DesignError(
                    f"{self.name}: the gain of the complete window (s = {self.s}) cannot be "
                    "certified: the window does not determine the state to within the rounding "
                    "of its stacked matrices (every box would be the model's prediction alone, "
                    "which diverges when |A| is not Schur). " + rank_advice(sys, self.s)
                )
        self.valid_from = self.s
        self.memory = 2 * self.s + 2
        """Samples kept: the longest window, extended back through missing samples."""
        des = self._designer
        self._const = (des.centre, des.radius) if des.const_bounds else None
        self._records = None
        if self._complete is not None:  # time-invariant: the whole-record path
            self._records = RecordWindows(self._gains, self._complete, self.x0, self.memory)

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

    # -- online ---------------------------------------------------------------------------
    def _initial_state(self) -> FixedTimeState:
        sys, n = self.sys, self.memory
        r = self._const[1] if self._const is not None else np.zeros(sys.nd)
        return FixedTimeState(
            z=np.zeros((n, self._designer.nz)),
            ymiss=np.ones((n, sys.ny)),
            r=np.tile(r, (n, 1)),
            lo=np.zeros(sys.nx),
            hi=np.zeros(sys.nx),
        )

    def _step(
        self, state: FixedTimeState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[FixedTimeState]:
        """The box of ``x_k``, ``k = state.k``, from the window ``w`` of the samples
        ``k, k-1, …`` ([Wang2020, eqs. (7), (11)], :func:`.gains.evaluate`); where samples are
        missing, or the window contradicts the model, with the prediction from the previous box
        (:func:`.window.combine`)."""
        k, nx, const = state.k, self.sys.nx, self._const
        if const is not None:
            c, r = const
        else:  # d_k ∈ [c - r, c + r]
            box = self.sys.d_at(k, y_k)
            c, r = centre_radius(box.lo, box.hi)
        total = y_k.dot(y_k)
        if total == total and not np.count_nonzero(state.ymiss):  # none missing: the ring, y_k
            ymiss, y_obs = state.ymiss, y_k  # (the flags of the ring, all zero, as they are)
        else:
            miss = np.isnan(y_k)
            ymiss, y_obs = np.concatenate((miss[None], state.ymiss[:-1])), np.where(miss, 0.0, y_k)
        # the samples k, k-1, … (most recent first), each z = [u; y; c]
        z = np.concatenate((u_k, y_obs, c[: self._designer.nc], state.z.ravel()))
        z = z[: state.z.size].reshape(state.z.shape)
        rr = state.r if const is not None else np.concatenate((r[None], state.r[:-1]))
        gain, missing = self._window(k, ymiss)
        bad: Any = False
        if gain is not None:
            n = gain.lags
            w = z[:n].ravel()
            lo, hi, bad = evaluate(gain, w, None if const else rr[:n].ravel())  # eqs. (7), (11)
        else:
            lo = hi = np.full(nx, np.nan)  # (no box)
        if gain is None or bad or missing:
            lo, hi, bad = combine(lo, hi, bad, *self._prediction(state, k))
            if k >= self.s and np.isnan(lo).any():
                rank = self._gains.get(k, ymiss[: self.s + 1] > 0).rank
                raise no_box_error(nx, self.s, k, rank)
        if gain is not None or not np.isnan(lo).any():
            new = evolve(state, z=z, ymiss=ymiss, r=rr, lo=lo, hi=hi, has_box=True)
        else:  # no box yet (k < s without x0)
            new = evolve(state, z=z, ymiss=ymiss, r=rr)
        return Step(new, lo, hi, bool(bad))

    def _window(self, k: int, ymiss: np.ndarray) -> tuple[WindowGain | None, bool]:
        """The gain of the window ending at ``k``: the complete window of ``s + 1`` samples, or,
        where samples are missing, the shortest window (``s + 1`` samples and more, back to
        step 0) whose available samples determine the state (None if there is none); and
        whether it misses samples."""
        s = self.s
        if self._complete is not None and not np.count_nonzero(ymiss[: s + 1]):
            return self._complete, False
        missing = ymiss > 0
        if k < s:
            return None, bool(missing[: k + 1].any())
        for lags in range(s + 1, min(self.memory, k + 1) + 1):
            gain = self._gains.get(k, missing[:lags])
            if gain.ok:
                return gain, bool(missing[:lags].any())
        return None, True

    def _prediction(self, state: FixedTimeState, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The box of ``x_k`` predicted from the previous one (:func:`.window.predict`); ``x0``
        itself at ``k = 0``; NaN when there is neither."""
        if k == 0 or not state.has_box:
            if k == 0 and self.x0 is not None:
                return self.x0.lo, self.x0.hi
            nan = np.full(self.sys.nx, np.nan)
            return nan, nan
        nu, ny, nc = self.sys.nu, self.sys.ny, self._designer.nc
        z, r = state.z[0], state.r[0]  # the sample of step k - 1
        c = z[nu + ny :] if nc else np.zeros_like(r)
        dlo, dhi = enclose(c, r)
        A, B, _, _, E, _ = self.sys.matrices_at(k - 1)
        return predict(np.hstack((A, B, E)), state.lo, state.hi, z[:nu], dlo, dhi)

    # -- offline ------------------------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Every window of the record (or batch) at once (:class:`.batch.RecordWindows`); None
        (the loop over :meth:`_step`) for time-varying systems and bounds that depend on
        ``y``."""
        return None if self._records is None else self._records.run(u, y)
