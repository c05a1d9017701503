"""The ``exact`` estimator: its design (the window), its online state (the kept history) and
its step (push a block, solve, prove, remember). The formulation is in the package docstring
(:mod:`ivobs.estimators.exact`)."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..._progress import Progress
from ..._validate import as_int
from ...errors import IvobsError
from ...model import LinearSystem
from ...sets import Box
from .. import register
from .._balanced import balancing
from ..base import Design, Estimator, check_size
from ..state import OnlineState, Step
from .highs import (
    INFEASIBLE,
    OK,
    WarmStartedLP,
    WarmStarts,
    check_basis_codes,
    with_saved_bases,
)
from .program import TrajectoryLP
from .rows import dynamics, measurement, outside_prediction, prediction, widen

__all__ = ["Exact", "ExactDesign", "ExactState", "appended"]


def appended(
    state: Any, rows: dict[str, np.ndarray], used: bool, window: int | None
) -> dict[str, Any]:
    """The history arrays of ``state`` with step ``k``'s ``rows`` and ``used`` flag appended,
    the oldest beyond ``window`` steps dropped (None: all kept): new arrays, the old ones are
    untouched."""
    new: dict[str, Any] = {}
    for key, val in rows.items():
        hist = np.vstack([getattr(state, key), np.asarray(val, dtype=float)[None, :]])
        new[key] = hist if window is None else hist[-window:]
    used_hist = np.append(state.used, used)
    new["used"] = used_hist if window is None else used_hist[-window:]
    return new


@dataclass(frozen=True)
class ExactDesign(Design):
    """``window``: number of past steps ``N`` kept in the program (``None``: the full
    horizon)."""

    window: int | None = None


@dataclass(frozen=True)
class ExactState(OnlineState):
    """The kept history (every step, or the last ``N`` in a moving window), from which the
    program is rebuilt; one row per kept step ``j``:

    ``x_lo``, ``x_hi`` (·, nx): the box proven for ``x[j]`` (widened), a variable bound of the
    later programs; ``y`` (·, ny), ``u`` (·, nu): the data (NaN in ``y``: missing);
    ``d_lo``, ``d_hi`` (·, nd): the box of ``d[j]``; ``used`` (·,): whether ``y[j]`` entered
    the program (False: dropped as inconsistent); ``p_lo``, ``p_hi`` (·, nx): the interval
    prediction of ``x[j]`` (the row ranges and shifts of the program). ``relaxed``: HiGHS needs
    the row ranges (not the equalities) since a rounding made the equalities infeasible.
    ``basis_min``, ``basis_max``: the simplex bases the next step of the two chains starts from
    (HiGHS status codes of the columns, then of the rows), so that a restored state continues
    with the same solves as the run that saved it. Filled when the state is saved (while
    running, the warm-started models hold them); empty: a cold start. A basis is only a
    starting point: any basis gives the same guaranteed bounds (S).

    The warm-started HiGHS models are not part of the state (:class:`~.highs.WarmStarts`)."""

    x_lo: np.ndarray
    x_hi: np.ndarray
    y: np.ndarray
    u: np.ndarray
    d_lo: np.ndarray
    d_hi: np.ndarray
    used: np.ndarray
    p_lo: np.ndarray
    p_hi: np.ndarray
    relaxed: bool = False
    basis_min: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    basis_max: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (
        ("x_lo", "x_hi"),
        ("d_lo", "d_hi"),
        ("p_lo", "p_hi"),
    )

    @property
    def history(self) -> tuple[np.ndarray, ...]:
        """The arrays of the kept history (what identifies its warm-started program)."""
        return (self.x_lo, self.x_hi, self.y, self.u, self.d_lo, self.d_hi, self.used,
                self.p_lo, self.p_hi)  # fmt: skip


@register
class Exact(Estimator):
    """Exact interval hull of the states consistent with the data (two LPs per state per step).

    Parameters
    ----------
    sys : LinearSystem (discrete time; time-varying matrices and bounds allowed)
    x0 : Box, the prior box on ``x[0]`` (required)
    window : None (full horizon, the reference; cost grows with ``k``) or an int ``N >= 1``
        (moving window of ``N`` past steps whose first state is bounded by this estimator's own
        box: bounded cost per step, still guaranteed, never tighter than the full horizon)
    progress : None (a progress bar in ``run()`` when stderr is a terminal), True or False
    on_inconsistent : 'warn', 'raise' or 'ignore' (measurements that make the LP infeasible)

    Notes
    -----
    Data used for the box of ``x[k]``: ``x0``, ``d``, ``u[0..k]``, ``y[0..k]``. See the package
    docstring for the formulation and the safe (solver-tolerance independent) bounds.

    Online, the program is kept warm-started from step to step (:meth:`step`, :meth:`run`, and
    :meth:`advance` from the state the previous call returned). Every step starts from the
    simplex bases the previous one ended on, and nothing else, and :meth:`state` saves those
    bases: a restored state rebuilds the same program and continues identically to the run
    that saved it. Each solve is capped at 20,000 simplex iterations; a program stopped there
    still gives a guaranteed (possibly wider) box, and a ``RuntimeWarning`` says at which
    step.
    """

    name = "exact"
    order = 100
    summary = "linear-programming reference: the tightest guaranteed box from the same data"
    reference = "set-membership hull [Tang2019, Section I] by LP with HiGHS; [Neumaier2004]"
    supports_time_varying = True
    needs_x0 = True
    proven_rounding = True  # safe bounds (S) and proven variable bounds: package docstring

    design: ExactDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        window: int | None = None,
        progress: bool | None = None,
        **options: Any,
    ):
        super().__init__(sys, x0, **options)
        check_size(self.name, sys.nx, "solves 2 nx linear programs over the whole trajectory")
        if progress is not None and not isinstance(progress, bool):
            raise IvobsError(f"progress: expected None, True or False, got {progress!r}")
        self.design = ExactDesign(window=None if window is None else as_int("window", window, 1))
        self.progress = progress
        self.valid_from = 0
        self._warm = WarmStarts()
        self._x_scale = balancing(sys.A_at(0), sys.C_at(0), sys.E_at(0), sys.F_at(0))

    # -- state ----------------------------------------------------------------------------
    def _initial_state(self) -> ExactState:
        s = self.sys
        return ExactState(
            x_lo=np.zeros((0, s.nx)),
            x_hi=np.zeros((0, s.nx)),
            y=np.zeros((0, s.ny)),
            u=np.zeros((0, s.nu)),
            d_lo=np.zeros((0, s.nd)),
            d_hi=np.zeros((0, s.nd)),
            used=np.zeros(0, dtype=bool),
            p_lo=np.zeros((0, s.nx)),
            p_hi=np.zeros((0, s.nx)),
        )

    # -- one step -------------------------------------------------------------------------
    def _step(
        self, state: ExactState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ExactState]:
        k, sys = state.k, self.sys
        warm = None if self._branching else self._warm.take(state.history, (k, state.relaxed))
        if warm is None:
            bases = self._bases(state)
            warm = self._rebuild(state)
            if bases is not None:
                warm.start(bases)
        lp, capped = warm.lp, warm.capped
        d_k = sys.d_at(k, y_k)
        if k > 0:
            prev = (state.x_lo[-1], state.x_hi[-1], state.d_lo[-1], state.d_hi[-1])
            dyn = dynamics(sys, k - 1, state.u[-1], *prev)
            p_lo, p_hi = prediction(sys, k - 1, state.u[-1], prev, dyn.tau)
        else:
            assert self.x0 is not None
            dyn = None
            p_lo, p_hi = self.x0.lo.copy(), self.x0.hi.copy()
        meas = measurement(sys, k, u_k, y_k, True, p_lo, p_hi, d_k.lo, d_k.hi)
        gross = outside_prediction(meas, p_lo, p_hi, d_k.lo, d_k.hi)
        if gross:  # certainly inconsistent already by interval arithmetic: no LP needed
            meas = measurement(sys, k, u_k, y_k, False, p_lo, p_hi, d_k.lo, d_k.hi)
        lp.push(dyn, meas, (p_lo, p_hi), (d_k.lo, d_k.hi), 0.5 * (p_lo + p_hi))
        N = self.design.window
        if N is not None and len(lp.n_dyn) > N + 1:
            lp.pop_front()
        lo, hi, verdict = warm.last_x_box()
        used, inconsistent = True, False
        if gross:
            used, inconsistent = False, True
        elif verdict != OK:
            # certified: a fault under the model's assumptions; unsure: dropped without a report
            used, inconsistent = False, verdict == INFEASIBLE
            lp.free_last_measurement()
            lo, hi, _ = warm.last_x_box()  # if still not OK: the variable bounds (the prediction)
        # both bounds are proven: if they cross, the data are inconsistent; the hull stays valid
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        if warm.capped > capped:
            warnings.warn(
                f"exact: step {k}: {warm.capped - capped} linear program(s) stopped at the "
                "iteration budget; the box is guaranteed (safe bound of the last multipliers) "
                "but may be wider than the exact hull",
                RuntimeWarning,
                stacklevel=2,
            )
        x_lo, x_hi = lp.tighten_last_x(*widen(lo, hi))
        rows = {"x_lo": x_lo, "x_hi": x_hi, "y": y_k, "u": u_k, "d_lo": d_k.lo, "d_hi": d_k.hi,
                "p_lo": p_lo, "p_hi": p_hi}  # fmt: skip
        new = self._remember(state, rows, used, lp.relaxed)
        if not self._branching:
            # the base counts the step: the program is that of the state at k + 1
            self._warm.put(new.history, (k + 1, new.relaxed), warm)
        return Step(new, lo, hi, inconsistent)

    def _remember(
        self, state: ExactState, rows: dict[str, np.ndarray], used: bool, relaxed: bool
    ) -> ExactState:
        """The state with step ``k``'s rows appended to the history (the oldest dropped in a
        moving window): new arrays, the old ones are untouched."""
        return replace(state, relaxed=relaxed, **appended(state, rows, used, self.design.window))

    def _rebuild(self, state: ExactState) -> WarmStartedLP:
        """The program of the kept history (empty at step 0; after ``restore()`` the same
        program), with new HiGHS models."""
        sys, k = self.sys, state.k
        lp = TrajectoryLP(sys.nx, sys.nd, sys.ny, self._x_scale)
        warm = WarmStartedLP(lp)
        lp.relaxed = bool(state.relaxed)
        m = state.x_lo.shape[0]
        for i, j in enumerate(range(k - m, k)):
            dyn = None
            if i > 0:
                prev = (state.x_lo[i - 1], state.x_hi[i - 1], state.d_lo[i - 1], state.d_hi[i - 1])
                dyn = dynamics(sys, j - 1, state.u[i - 1], *prev)
            p_lo, p_hi = state.p_lo[i], state.p_hi[i]
            d_lo, d_hi = state.d_lo[i], state.d_hi[i]
            meas = measurement(sys, j, state.u[i], state.y[i], bool(state.used[i]),
                               p_lo, p_hi, d_lo, d_hi)  # fmt: skip
            x_b = (state.x_lo[i], state.x_hi[i])
            lp.push(dyn, meas, x_b, (d_lo, d_hi), 0.5 * (p_lo + p_hi))
        return warm

    def _bases(self, state: ExactState) -> tuple[Any, Any] | None:
        """The bases the next step of ``state`` starts from: saved with it, or those of its
        warm-started program; None if neither (a cold start)."""
        # the chain's program: the kept steps, and in a full moving window the one before
        N = self.design.window
        n_col = (state.k if N is None else min(state.k, N + 1)) * (self.sys.nx + self.sys.nd)
        return self._warm.start_of(state, (state.k, state.relaxed), n_col)

    def save_state(self, st: Any) -> dict[str, Any]:
        """The state with the bases of its warm-started program (see :class:`ExactState`)."""
        if isinstance(st, ExactState):
            st = with_saved_bases(st, self._bases)
        return super().save_state(st)

    def check_state(self, state: Any) -> ExactState:
        """As :meth:`Estimator.check_state`, and the bases are checked (status codes 0-4)."""
        st = super().check_state(state)
        assert isinstance(st, ExactState)
        check_basis_codes(st)
        return st

    # -- offline loop with a progress bar --------------------------------------------------
    def _loop(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None, bar: Any = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if bar is not None and bar.enabled:
            return super()._loop(u, y, t, bar)
        desc = "exact" if self.design.window is None else f"exact (window {self.design.window})"
        with Progress(y.shape[0], desc, enabled=self.progress) as own:
            return super()._loop(u, y, t, own)
