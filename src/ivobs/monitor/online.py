"""The online monitor: a guaranteed estimator and a consistency test at every step (the
method is described in :mod:`ivobs.monitor`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_float_array, as_signal
from ..errors import IvobsError
from ..estimators import Estimator, make_estimator
from ..estimators._inputs import check_y_k
from ..estimators.measured import FILTERED
from ..io.systemwrite import equal_systems
from ..model import LinearSystem, NonlinearSystem
from ..result import Estimate
from ..sets import Box
from ._codec import _vector
from .bands import bands_for
from .bias import BiasEstimate
from .isolate import DEFAULT_WINDOW, History, Isolation, WindowTest, isolate
from .latch import Latch
from .offline import check_record, refuse_uncertain
from .persist import monitor_state, restore_monitor
from .records import MonitorRecord, MonitorStep, output_names, stack_steps

__all__ = ["Monitor"]


class Monitor:
    """A guaranteed estimator with an alarm at every step (see the module docstring).

    Parameters
    ----------
    sys : the model: a :class:`~ivobs.LinearSystem` (exactly known or with interval matrices)
        or a discrete-time :class:`~ivobs.NonlinearSystem` (the sampled model of a
        continuous-time one); :mod:`ivobs.monitor.bands` gives its prediction and band.
    method : a method name (``ivobs.methods()``) or an :class:`~ivobs.Estimator` already built
        for ``sys``.
    x0 : prior box on ``x[0]`` (passed to the method, and the first prediction).
    tight : also intersect the prediction with the estimator's own prediction (one extra
        estimator step per step, with ``y[k]`` missing, from the same state).
    margin : relative widening of the band against floating-point rounding.
    clear_after : consecutive steps the held outputs of an open fault must be consistent again
        before the alarm clears (see :mod:`ivobs.monitor`).
    window : steps of recent data a fault's isolation tests (at least; up to half as many
        more), :mod:`ivobs.monitor.isolate`.
    **options : the method's design options (an explicit gain ``L``, ...).

    Notes
    -----
    The monitor takes over the estimator's reports of inconsistent measurements: they become
    alarms instead of warnings. It keeps the estimator's online state itself
    (:attr:`estimator_state`); the estimator's own ``step()`` state is left alone.

    >>> import ivobs
    >>> from ivobs.monitor import Monitor
    >>> sc = ivobs.scenarios.get("servo-motor")
    >>> mon = Monitor(sc.system, "interval-split", x0=sc.x0)          # doctest: +SKIP
    >>> out = mon.update(u_k=[2.0], y_k=[0.01, 0.02])                  # doctest: +SKIP
    >>> out.alarm, out.lower, out.upper                                # doctest: +SKIP
    """

    def __init__(
        self,
        sys: LinearSystem | NonlinearSystem,
        method: str | Estimator = "reachability",
        x0: Box | None = None,
        *,
        tight: bool = True,
        margin: float = 1e-9,
        clear_after: int = 10,
        window: int = DEFAULT_WINDOW,
        **options: Any,
    ):
        if not isinstance(sys, (LinearSystem, NonlinearSystem)):
            raise IvobsError(
                "sys: expected an ivobs.LinearSystem or ivobs.NonlinearSystem, got "
                f"{type(sys).__name__}"
            )
        if isinstance(sys, NonlinearSystem) and sys.is_continuous:
            raise IvobsError(
                "sys: a continuous-time NonlinearSystem (dt=0): monitor its sampled model, "
                "sys.discretize(Ts) (docs/continuous.md)"
            )
        if isinstance(method, Estimator):
            if options:
                raise IvobsError(
                    "options: an Estimator instance was given; its design is fixed, so design "
                    f"options ({', '.join(options)}) cannot apply"
                )
            if method.sys is not sys and not equal_systems(method.sys, sys):
                raise IvobsError("method: the estimator was built for another system")
            est = method
            if x0 is None:
                x0 = est.x0
        else:
            # the boxes met with the strips of the outputs used (every method, filtered)
            options = {**FILTERED, **options}
            est = make_estimator(method, sys, x0=x0, **options)
        if not (isinstance(margin, (int, float)) and 0 <= margin < 1e-3):
            raise IvobsError(f"margin: expected a small relative margin in [0, 1e-3), got {margin}")
        if x0 is not None and not isinstance(x0, Box):
            raise IvobsError(f"x0: expected an ivobs.Box, got {type(x0).__name__}")
        self.sys = sys
        self.estimator = est
        self.x0 = x0
        self.tight = bool(tight)
        self.margin = float(margin)
        if isinstance(clear_after, bool) or not isinstance(clear_after, int) or clear_after < 1:
            raise IvobsError(f"clear_after: expected an integer >= 1 (steps), got {clear_after!r}")
        self.latch = Latch(clear_after)
        if isinstance(window, bool) or not isinstance(window, int) or window < 2:
            raise IvobsError(f"window: expected an integer >= 2 (steps), got {window!r}")
        self.window = window
        self._history = History(window)
        self._test = WindowTest(sys)
        self._bands = bands_for(sys)
        # The estimator's inconsistency reports (in check(), through run()) become alarms, not
        # warnings.
        est.on_inconsistent = "ignore"
        self.reset()

    # -- online ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to step 0."""
        self._est: Any = self.estimator.initial_state()
        self.latch.reset()
        self._trial: tuple[Any, dict[str, Any] | None] | None = None
        self._k = 0
        self._prev: dict[str, Any] | None = None  # box of x[k-1], u[k-1], y[k-1]
        self._bias: BiasEstimate | None = None  # the open fault's bias, estimated (.bias)
        self._isolation: Isolation | None = None  # the open fault's isolation (.isolation)
        self._history.reset()
        self.alarms = 0

    @property
    def k(self) -> int:
        """Number of steps processed."""
        return self._k

    @property
    def method(self) -> str:
        return self.estimator.name

    def update(self, u_k: Any = None, y_k: Any = None, t: float | None = None) -> MonitorStep:
        """Process ``u[k]``, ``y[k]`` (NaN components: missing) and return the step's box and
        alarm."""
        sys = self.sys
        if sys.is_continuous and t is None:
            raise IvobsError("t: a continuous-time system needs the sample time of each step")
        u = np.zeros(0) if (u_k is None and sys.nu == 0) else _vector("u_k", u_k, sys.nu)
        y = check_y_k(sys, y_k).copy()
        k, st = self._k, self._est
        u_e = u if sys.nu else None
        reasons: list[str] = []
        pred = self._prediction(k, self._prev, st, u, t, reasons)
        self._history.anchor(k, st, self._prev, pred)
        band_lo, band_hi = self._band(k, t, pred, u, y)
        out = (y < band_lo) | (y > band_hi)  # False where y is NaN (missing)
        for i in np.flatnonzero(out)[:3]:
            reasons.append(
                f"y{i + 1} = {y[i]:.6g} outside the predicted band "
                f"[{band_lo[i]:.6g}, {band_hi[i]:.6g}]"
            )
        # the policy: outputs of an open fault, and outputs outside the band, never enter the
        # estimate; outputs the method finds inconsistent are traced and left out as well
        bad = set(np.flatnonzero(out).tolist())
        held = self.latch.outputs
        y_use = y.copy()
        y_use[sorted(bad | set(held))] = np.nan
        new, box = self._use(st, u_e, y_use, y, t, reasons)
        if new.inconsistent:
            culprits = self._trace(st, u_e, y_use, t)
            reasons.append(
                f"{self.method}: measurement of {output_names(culprits)} inconsistent with "
                "the model and bounds"
            )
            bad |= set(culprits)
            y_use[list(culprits)] = np.nan
            new, box = self._use(st, u_e, y_use, y, t, reasons)
        lo, hi = box.lo, box.hi
        n_reasons = len(reasons)
        cur = self._current(pred, lo, hi, reasons)
        if len(reasons) > n_reasons:  # disjoint boxes, not traceable: all the outputs used
            bad |= set(np.flatnonzero(~np.isnan(y_use)).tolist())
        prev = None if cur is None else {"lo": cur[0], "hi": cur[1], "u": u, "y": y}
        # which outputs are blamed: those the isolation names when it can, else the band's
        blame, ref = set(bad), (pred, (band_lo, band_hi))
        if reasons and (self.latch.start is None or not bad <= set(held)):
            iso = self._isolate(k, u, y, t, reasons)
            if iso is not None and iso.conclusive:
                blame = set(held) | set(iso.outputs)
                if set(iso.outputs) - bad - set(held):
                    # a faulty output the band did not reject at this step had entered the
                    # estimate: recomputed over the window without the blamed outputs
                    new, prev, ref, box = self._replay(k, tuple(sorted(blame)), u, y, t)
                    lo, hi = box.lo, box.hi
        # an open fault: the held outputs readmitted in a trial beside the reference estimate
        # (which keeps pace when they are missing: such a step does not count)
        held_missing = bool(held) and bool(np.isnan(y[list(held)]).any())
        if held and not reasons:
            trial = self._trial or (st, self._prev)
            why: list[str] = []
            t_new, t_prev = self._trial_step(k, trial, (pred, cur), u, y_use, y, t, why)
            if why:
                reasons.append(f"{output_names(held)} readmitted: {'; '.join(why)}; held out again")
                self._trial = None
            else:
                self._trial = (t_new, t_prev)
        evidence = bool(reasons)
        proven = self._bias_step(k, ref, u, u_e, y, t, reasons)
        start = self.latch.start
        self.latch.observe(k, tuple(sorted(blame)), evidence, held_missing, proven)
        if evidence or proven:
            self._trial = None
        alarm = self.latch.start is not None
        if alarm and (self._bias is None or self._bias.outputs != self.latch.outputs):
            # a new episode, or new outputs in it: the bias estimate starts at this step
            self._begin_bias(k, ref, None, u, u_e, y, t)
        if alarm and not evidence:
            reasons.append(self.latch.describe())
            if self._bias is not None:
                reasons.append(self._bias.describe())
        elif not alarm and start is not None:
            reasons.append(f"cleared: the fault of {output_names(held)} since step {start}")
            if self._trial is not None:  # verified for clear_after steps: it continues
                new, prev = self._trial
            self._trial = None
        if not alarm:
            self._bias = self._isolation = None
        iso = self._isolation
        b_lo, b_hi = self._bias_bounds()
        self.alarms += alarm
        self._history.push(k, u, y, t)
        self._est, self._prev, self._k = new, prev, k + 1
        return MonitorStep(
            k, lo, hi, alarm, "; ".join(reasons), band_lo, band_hi, evidence, tuple(sorted(bad)),
            self.latch.start, self.latch.outputs if alarm else (), b_lo, b_hi,
            () if iso is None else iso.candidates, "" if iso is None else iso.text,
        )  # fmt: skip

    def _isolate(
        self, k: int, u: np.ndarray, y: np.ndarray, t: float | None, reasons: list[str]
    ) -> Isolation | None:
        """The isolation of the window ending at step ``k`` (:mod:`ivobs.monitor.isolate`),
        kept as the open fault's when it names outputs (or opens the episode); None where none
        can be run: one output (nothing to tell apart), a model without a window test, a
        window without a prior. Within an episode, an isolation of the last ``window // 4``
        steps is reused rather than run again at every contradiction."""
        last = self._isolation
        if last is not None and self.latch.start is not None and k - last.end < self.window // 4:
            return last
        a = self._history.start(k)
        if self._test.method is None or self.sys.ny < 2 or a is None or a.pred is None:
            return None
        if not (np.all(np.isfinite(a.pred[0])) and np.all(np.isfinite(a.pred[1]))):
            return None
        rows = [r for r in self._history.rows if r[0] >= a.k] + [(k, u, y, t)]
        n, sys = len(rows), self.sys
        U = np.array([r[1] for r in rows]).reshape(n, sys.nu)
        Y = np.array([r[2] for r in rows]).reshape(n, sys.ny)
        # discrete-time windows count steps; a time column only labels them
        T = np.array([r[3] for r in rows], dtype=float) if sys.is_continuous else None
        try:
            iso = isolate(self._test, Box(a.pred[0], a.pred[1]), a.k, U, Y, T)
        except IvobsError:
            return None  # the window's method refused it (a prior it cannot start from)
        reasons.append(iso.describe())
        if iso.conclusive or self.latch.start is None or last is None:
            self._isolation = iso
        return iso

    def _replay(
        self, k: int, hold: tuple[int, ...], u: np.ndarray, y: np.ndarray, t: float | None
    ) -> tuple[Any, dict[str, Any] | None, tuple[Any, tuple[np.ndarray, np.ndarray]], Box]:
        """The reference estimate recomputed from the window's anchor to step ``k`` with the
        outputs ``hold`` left out (and, as in :meth:`update`, the outputs outside their band;
        every output at a step the method finds inconsistent): the estimator's state after
        ``k``, the box of ``x[k]`` for the next prediction, ``(P_k, band)`` and the
        estimator's box. The anchors inside the window are replaced by the recomputed ones."""
        a = self._history.start(k)
        assert a is not None  # _isolate ran from it
        anchors = {b.k: b for b in self._history.anchors if b.k > a.k}
        st, prev = a.state, a.prev
        rows = [r for r in self._history.rows if r[0] >= a.k] + [(k, u, y, t)]
        for j, u_j, y_j, t_j in rows:
            why: list[str] = []  # what the replay finds is not reported again
            pred = self._prediction(j, prev, st, u_j, t_j, why)
            if j in anchors:
                anchors[j].state, anchors[j].prev, anchors[j].pred = st, prev, pred
            band = self._band(j, t_j, pred, u_j, y_j)
            y_use = y_j.copy()
            y_use[list(hold)] = np.nan
            y_use[(y_j < band[0]) | (y_j > band[1])] = np.nan
            u_e = u_j if self.sys.nu else None
            new, box = self._use(st, u_e, y_use, y_j, t_j, why)
            if new.inconsistent:
                new, box = self._use(st, u_e, np.full_like(y_j, np.nan), y_j, t_j, why)
            cur = self._current(pred, box.lo, box.hi, why)
            prev = None if cur is None else {"lo": cur[0], "hi": cur[1], "u": u_j, "y": y_j}
            st = new
        return st, prev, (pred, band), box

    @property
    def isolation(self) -> Isolation | None:
        """The open fault's isolation (None without an open fault, or where none was run)."""
        return self._isolation

    def _bias_step(
        self,
        k: int,
        ref: tuple[Any, tuple[np.ndarray, np.ndarray]],
        u: np.ndarray,
        u_e: np.ndarray | None,
        y: np.ndarray,
        t: float | None,
        reasons: list[str],
    ) -> bool:
        """Advance the open fault's bias estimate (:mod:`ivobs.monitor.bias`) with all the
        outputs of step ``k``; True when its interval excludes 0 (the data since its start
        prove the fault). A bias that no longer fits (the fault ended or jumped) restarts the
        estimate at this step, from the reference's prediction ``ref`` met with the old
        estimate's own."""
        est = self._bias
        if est is None:
            return False
        if est.step(u_e, y, t):
            return est.excludes_zero
        reasons.append(
            f"{output_names(est.outputs)}: the bias estimated since step {est.start} changed "
            "(the fault is no constant bias): re-estimated"
        )
        carry = est.predict(u_e, t) if est.outputs == self.latch.outputs else None
        self._begin_bias(k, ref, carry, u, u_e, y, t)
        return self._bias is not None and self._bias.excludes_zero

    def _begin_bias(
        self,
        k: int,
        ref: tuple[Any, tuple[np.ndarray, np.ndarray]],
        carry: tuple[np.ndarray, np.ndarray] | None,
        u: np.ndarray,
        u_e: np.ndarray | None,
        y: np.ndarray,
        t: float | None,
    ) -> None:
        """A bias estimate of the held outputs from step ``k`` (:meth:`BiasEstimate.begin`):
        from the reference's prediction, met with ``carry`` when given; after a drift that
        prediction contradicts the data, and the reference's alone is used."""
        pred, band = ref
        starts = [(pred, band)]
        if carry is not None and pred is not None:
            met = self._meet(carry, pred, [], "")  # pred when disjoint
            starts.insert(0, (met, self._band(k, t, met, u, y)))
        for p, b in starts:
            self._bias = BiasEstimate.begin(self.sys, self.latch.outputs, k, p, b, y)
            if self._bias is None or self._bias.step(u_e, y, t):
                return
            self._bias = None  # not even one step: a fault that is no constant bias

    def _bias_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The bias of each output as estimated at this step (NaN where none is)."""
        lo, hi = np.full(self.sys.ny, np.nan), np.full(self.sys.ny, np.nan)
        if self._bias is not None:
            idx = list(self._bias.outputs)
            lo[idx], hi[idx] = self._bias.lower, self._bias.upper
        return lo, hi

    @property
    def bias(self) -> BiasEstimate | None:
        """The open fault's bias estimate (None without an open fault, or where the model
        cannot be augmented)."""
        return self._bias

    def _prediction(
        self,
        k: int,
        prev: dict[str, Any] | None,
        st: Any,
        u: np.ndarray,
        t: float | None,
        reasons: list[str],
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """``P_k``: Lemma 1 from ``prev`` met with the estimator's prediction from ``st``."""
        pred = self._predict(k, prev)
        probe = self._probe(st, u, t) if self.tight else None
        if probe is not None:
            pred = (
                probe
                if pred is None
                else self._meet(pred, probe, reasons, "the estimator's prediction")
            )
        return pred

    def _current(
        self,
        pred: tuple[np.ndarray, np.ndarray] | None,
        lo: np.ndarray,
        hi: np.ndarray,
        reasons: list[str],
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """``X_k``: the estimator's box met with the prediction."""
        cur = None if np.isnan(lo).any() else (lo.copy(), hi.copy())
        if cur is not None and pred is not None:
            return self._meet(pred, cur, reasons, "estimate")
        return pred if cur is None else cur

    def _trial_step(
        self,
        k: int,
        trial: tuple[Any, dict[str, Any] | None],
        ref: tuple[tuple[np.ndarray, np.ndarray] | None, tuple[np.ndarray, np.ndarray] | None],
        u: np.ndarray,
        y_use: np.ndarray,
        y: np.ndarray,
        t: float | None,
        why: list[str],
    ) -> tuple[Any, dict[str, Any] | None]:
        """One step of the trial estimate that uses the held outputs again (the same test as
        the reference's: band, the method's own check, disjoint boxes); ``why`` collects
        what contradicts."""
        st, prev = trial
        held = list(self.latch.outputs)
        y_all = y_use.copy()
        y_all[held] = y[held]
        pred = self._prediction(k, prev, st, u, t, why)
        if pred is not None and ref[0] is not None:  # both hold x[k] if the data are fault-free
            pred = self._meet(ref[0], pred, why, "the trial's prediction", "the reference's")
        b_lo, b_hi = self._band(k, t, pred, u, y_all)
        for i in np.flatnonzero((y_all < b_lo) | (y_all > b_hi))[:3]:
            why.append(f"y{i + 1} = {y_all[i]:.6g} outside [{b_lo[i]:.6g}, {b_hi[i]:.6g}]")
        new, box = self.estimator.advance(st, u if self.sys.nu else None, y_all, t)
        if new.inconsistent:
            why.append(f"{self.method}: inconsistent with the model and bounds")
        cur = self._current(pred, box.lo, box.hi, why)
        if cur is not None and ref[1] is not None:
            cur = self._meet(ref[1], cur, why, "the trial's estimate", "the reference's")
        return new, None if cur is None else {"lo": cur[0], "hi": cur[1], "u": u, "y": y}

    def _use(
        self,
        st: Any,
        u: np.ndarray | None,
        y_use: np.ndarray,
        y: np.ndarray,
        t: float | None,
        reasons: list[str],
    ) -> tuple[Any, Box]:
        """The estimator's step without the excluded outputs; with them when the model cannot
        predict without them (bounds computed from ``y[k]``), said in the reasons."""
        try:
            return self.estimator.advance(st, u, y_use, t)
        except IvobsError:
            if np.array_equal(np.isnan(y_use), np.isnan(y)):
                raise
            reasons.append("the model's bounds need the measurement: used although inconsistent")
            return self.estimator.advance(st, u, y, t)

    def _trace(
        self, st: Any, u: np.ndarray | None, y: np.ndarray, t: float | None
    ) -> tuple[int, ...]:
        """The measured outputs the method finds inconsistent on their own (look-ahead steps
        from the same state); all of them when only their combination is."""
        measured = np.flatnonzero(~np.isnan(y)).tolist()
        alone = []
        for i in measured:
            yi = np.full_like(y, np.nan)
            yi[i] = y[i]
            if self.estimator.advance(st, u, yi, t, keep=False)[0].inconsistent:
                alone.append(i)
        return tuple(alone or measured)

    def run(self, u: Any = None, y: Any = None, *, t: Any = None) -> MonitorRecord:
        """:meth:`update` over a record, continuing from the current state (exactly what a
        stream of the same rows gives)."""
        u, y, tt = self._record(u, y, t)
        return stack_steps(
            [self.update(u[k], y[k], None if tt is None else float(tt[k])) for k in range(len(y))],
            self.sys,
        )

    def check(
        self, u: Any = None, y: Any = None, *, t: Any = None, estimate: Estimate | None = None
    ) -> MonitorRecord:
        """The alarms of a whole record, offline and vectorised over time (long logs).

        Uses the estimator's ``run()`` (or ``estimate``, a result of that run already at hand)
        and, at every step, the band of the one-step prediction ([Efimov2013, Lemma 1]) from
        the estimator's box of the step before (at step 0, the prior box). This band contains
        the online monitor's (which also intersects with its own previous prediction and, with
        ``tight=True``, with the estimator's prediction), so ``check`` may see fewer alarms than
        :meth:`update`; every alarm it raises carries the same guarantee. Leaves the online
        state alone.

        The estimator's run uses every sample, the faulty ones too, so a fault shows here only
        where it contradicts that estimate (often its onset alone); the record's ``faults`` are
        the runs of consecutive alarmed steps, without latch or bias estimate. :meth:`run` is
        the monitor proper: the faulty output left out, latched, its bias estimated
        (``ivobs run`` reports a log's faults that way).

        ``u`` may be a :class:`~ivobs.io.Log` (from :func:`~ivobs.io.read_log`): its rows are
        steps, a gap in its step column a run of missing samples (:mod:`ivobs.io.steps`), as for
        ``ivobs run`` and ``ivobs monitor`` (also for :meth:`run`).
        """
        if not isinstance(self.sys, LinearSystem):
            raise IvobsError(
                "check: the vectorised offline test needs a LinearSystem; for a nonlinear "
                "model use run() (the same alarms step by step)"
            )
        refuse_uncertain(self.sys)
        u, y, tt = self._record(u, y, t)
        res = estimate
        if res is None:
            res = self.estimator.run(u, y, t=tt)
        elif res.lower.shape != (y.shape[0], self.sys.nx):
            raise IvobsError(
                f"estimate: expected bounds of shape {(y.shape[0], self.sys.nx)}, got "
                f"{res.lower.shape}"
            )
        return check_record(self.sys, self.x0, self.margin, self.method, u, y, tt, res)

    def _record(self, u: Any, y: Any, t: Any) -> tuple[np.ndarray, np.ndarray, Any]:
        from ..io.logs import Log

        if isinstance(u, Log):  # the rows of a log, on their steps
            if y is not None or t is not None:
                raise IvobsError("u: a Log holds the measurements and times; give it alone")
            u, y, t = u.u, u.y, u.t if self.sys.is_continuous else None
        y = as_signal("y", y, self.sys.ny, allow_nan=True, allow_batch=False)
        u = as_signal("u", u, self.sys.nu, y.shape[0], allow_batch=False)
        tt = None if t is None else as_float_array("t", t).ravel()
        if self.sys.is_continuous and tt is None:
            raise IvobsError("t: a continuous-time system needs the sample times t (T,)")
        return u, y, tt

    # -- the consistency test ------------------------------------------------------------
    def _predict(self, k: int, prev: dict[str, Any] | None) -> tuple[np.ndarray, np.ndarray] | None:
        """The model's one-step prediction of ``x[k]`` from the box of ``x[k-1]``
        (:mod:`ivobs.monitor.bands`), or the prior box at ``k = 0``."""
        if k == 0:
            return None if self.x0 is None else (self.x0.lo.copy(), self.x0.hi.copy())
        if prev is None:
            return None
        return self._bands.predict(k, prev)

    def _probe(
        self, st: Any, u: np.ndarray, t: float | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The estimator's own box of ``x[k]`` without ``y[k]`` (:meth:`Estimator.predict`)."""
        try:
            box = self.estimator.advance(st, u if self.sys.nu else None, None, t, keep=False)[1]
        except IvobsError:
            return None  # bounds computed from y[k] ([Efimov2013, Remark 1]): no prediction
        return None if box.is_unknown else (box.lo, box.hi)

    def _meet(
        self,
        a: tuple[np.ndarray, np.ndarray],
        b: tuple[np.ndarray, np.ndarray],
        reasons: list[str],
        what: str,
        other: str = "the model's prediction",
    ) -> tuple[np.ndarray, np.ndarray]:
        """``a ∩ b``; when they do not meet (beyond rounding), an alarm and ``b``."""
        lo, hi = np.maximum(a[0], b[0]), np.minimum(a[1], b[1])
        bad = lo - hi > self.margin * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
        if bad.any():
            i = int(np.argmax(bad))
            reasons.append(
                f"{what} disjoint from {other} in x{i + 1} "
                f"([{b[0][i]:.6g}, {b[1][i]:.6g}] vs [{a[0][i]:.6g}, {a[1][i]:.6g}])"
            )
            return b[0].copy(), b[1].copy()
        return np.minimum(lo, hi), np.maximum(lo, hi)

    def _band(
        self,
        k: int,
        t: float | None,
        pred: tuple[np.ndarray, np.ndarray] | None,
        u: np.ndarray,
        y: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The output band of ``P_k`` (:mod:`ivobs.monitor.bands`), widened by the rounding
        margin."""
        ny = self.sys.ny
        if pred is None:
            return np.full(ny, -np.inf), np.full(ny, np.inf)
        key = t if self.sys.is_continuous else k
        lo, hi = self._bands.band(k, key, pred, u, y)
        return lo - self.margin * (1.0 + np.abs(lo)), hi + self.margin * (1.0 + np.abs(hi))

    # -- persistence ---------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The monitor's state (estimator state, previous box, counters, the open fault, the
        fingerprint of the model, prior and settings): JSON-serialisable
        (:mod:`ivobs.monitor.persist`)."""
        return monitor_state(self)

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state`: the same model (matrices, bounds), prior box, settings,
        method and design, or the state is refused naming what differs."""
        restore_monitor(self, state)

    @property
    def estimator_state(self) -> Any:
        """The estimator's online state the monitor continues from (the estimator's own
        ``step()`` state is not used)."""
        return self._est

    def __repr__(self) -> str:
        return f"<Monitor {self.method!r} k={self._k} alarms={self.alarms}>"
