"""The estimator protocol shared by every method (scikit-learn's idea: one interface).

Subclasses implement the method; the base class owns validation, the online state, the
offline loop, missing samples bookkeeping and inconsistency reporting.

A subclass provides

* ``__init__(sys, x0=None, *, <its design options>, **options)``: validate, design offline (no
  time loop), set ``self.design`` (a :class:`Design` dataclass with the papers' symbols) and
  ``self.valid_from``; then call nothing else. The signature's defaults are the options'
  defaults (:mod:`ivobs.config` lists them; the base class adds the session's changes to the
  arguments of every subclass's ``__init__``, :meth:`Estimator.__init_subclass__`).
* ``_initial_state() -> S``: the online state at step 0, a frozen dataclass derived from
  :class:`~ivobs.estimators.state.OnlineState` (arrays named as in the paper).
* ``_step(state, u_k, y_k, t_k) -> Step[S]``: the method's recursion, written once: from the
  state at step ``k = state.k``, the next state and the bounds of ``x[k]`` from ``u[0..k]``,
  ``y[0..k]``, every rounding error of the step already bounded (below). It never modifies
  ``state``; the state it returns is built in that step (``dataclasses.replace``), and the base
  class sets its counters. ``y_k`` may contain NaN (missing components: predict without
  them). A measurement that contradicts the model is reported by
  ``Step(..., inconsistent=True)`` and not used.
* optionally ``_run(u, y, t) -> (lo, hi) | (lo, hi, inconsistent) | None``: the whole record
  at once (vectorised; batch ``(B, T, n)`` inputs allowed) from a shared kernel, tested equal to
  the loop over ``_step``; fresh arrays the base class may modify in place; ``inconsistent`` a
  ``(..., T)`` bool array of steps whose measurement was found inconsistent (and not used).
  Return ``None`` to fall back to the loop (e.g. missing samples).

Rounding: the base class adds no margin. Each method's ``_step`` and ``_run`` return bounds
that contain the exact sets, every floating-point error bounded by a proven model
([Higham2002] or directed rounding: :mod:`ivobs.sets.rounding`); ``proven_rounding = True``
declares it, and :func:`ivobs.testing.check_estimator` checks it against exact trajectories.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any, ClassVar, cast

import numpy as np

from .._validate import as_bool
from ..errors import DesignError, DivergenceError, InconsistentDataError, IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..result import Estimate
from ..sets import Box
from ..sets.rounding import overflowed
from ._inputs import check_t, check_t_k, check_u_k, check_y_k, keyword_options, lean_u_y
from ._overrides import with_overrides
from .measured import MeasurementStrips
from .persistence import Persistence
from .record import VECTOR_MIN_STEPS, check_record, run_record
from .state import OnlineState, Step, evolve

__all__ = [
    "MAX_DENSE_STATES",
    "VECTOR_MIN_STEPS",
    "Design",
    "Estimator",
    "check_size",
    "check_system",
    "check_x0",
]


@dataclass(frozen=True)
class Design:
    """What an estimator designed offline. Subclasses add fields named as in the papers
    (``L``, ``gamma``, ``T``, ``S``, ``R``, ``s``, ...)."""

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


Bound = np.ndarray | list[float]
"""One step's bounds before rounding, as a method's step returns them (:class:`Step`)."""

MAX_DENSE_STATES = 200
"""Largest ``nx`` for the set-based methods whose every step is dense ``O(nx^3)`` work or
``2 nx`` linear programs (zonotope, strip, constrained-zonotope, exact); docs/scale.md."""


def check_size(who: str, nx: int, work: str) -> None:
    """Refuse ``nx > MAX_DENSE_STATES`` for a method whose every step costs ``work``, with a
    pointer to what scales (a :class:`~ivobs.DesignError`)."""
    if nx > MAX_DENSE_STATES:
        raise DesignError(
            f"{who}: every step {work}; this does not scale to nx = {nx} > {MAX_DENSE_STATES} "
            "states; use 'interval' or 'interval-split' with a gain L=... (sparse A: one sparse "
            "product per step; docs/scale.md)"
        )


def check_x0(x0: Any, nx: int, who: str, required: bool = True) -> Box | None:
    """Validate the prior box on ``x[0]``."""
    if x0 is None:
        if required:
            raise IvobsError(
                f"x0: the {who} method needs a prior box on the initial state, "
                "e.g. x0=ivobs.Box(x0_lo, x0_hi)"
            )
        return None
    if not isinstance(x0, Box):
        raise IvobsError(
            f"x0: expected an ivobs.Box (a prior box on x[0]), got {type(x0).__name__}; "
            "wrap bounds as ivobs.Box(lo, hi)"
        )
    if x0.is_time_varying or x0.dim != nx:
        raise IvobsError(f"x0: expected a constant Box of dimension {nx}, got {x0!r}")
    if not x0.is_bounded:
        raise IvobsError(f"x0: the {who} method needs finite prior bounds, got {x0!r}")
    return x0


def _unset(flag: str) -> list[str]:
    return []


methods_with: Callable[[str], list[str]] = _unset
"""Names of the registered methods whose class flag (``supports_nonlinear``, ...) is true: set
by the registry (:mod:`ivobs.estimators`, imported before this module), which imports every
method first (its imports are lazy)."""


def _arrays(state: OnlineState) -> list[np.ndarray]:
    """The float arrays of a state (to tell an overflow from a bug)."""
    values = (getattr(state, f.name) for f in dataclasses.fields(state))
    return [v for v in values if isinstance(v, np.ndarray) and v.dtype.kind == "f"]


def check_system(method: Any, sys: Any) -> None:
    """Refuse a model the method ``method`` (a class or instance with the ``supports_*``
    flags) cannot handle, with the reason and what can."""
    name = method.name
    if isinstance(sys, NonlinearSystem):
        if not method.supports_nonlinear:  # naming the methods that take one
            can = (
                ", ".join(repr(n) for n in methods_with("supports_nonlinear")) or "(none installed)"
            )
            raise IvobsError(
                f"sys: the {name} method is for linear systems (ivobs.LinearSystem); this one is "
                f"an ivobs.NonlinearSystem. Methods for nonlinear systems: {can}"
            )
    elif not isinstance(sys, LinearSystem):
        raise IvobsError(
            "sys: expected an ivobs.LinearSystem or ivobs.NonlinearSystem, got "
            f"{type(sys).__name__}"
        )
    if sys.is_continuous and not method.supports_continuous:
        if isinstance(sys, NonlinearSystem):
            hint = (
                "Use sys.discretize(Ts): the validated flow over each sampling period, for "
                "every method for nonlinear systems (docs/continuous.md)"
            )
        else:
            ct = ", ".join(repr(n) for n in methods_with("supports_continuous"))
            hint = (
                f"Use sys.discretize(Ts) (docs/continuous.md), or a method that takes the "
                f"continuous-time system itself: {ct}"
            )
        raise IvobsError(
            f"sys: the {name} method is for discrete-time systems; this one is "
            f"continuous-time (dt=0). {hint}"
        )
    if sys.is_time_varying and not method.supports_time_varying:
        raise IvobsError(
            f"sys: the {name} method needs a time-invariant system; this one has "
            "time-varying matrices. Use 'fixed-time', 'kkl' or 'exact'"
        )
    if getattr(sys, "is_uncertain", False) and not method.supports_uncertain:
        raise IvobsError(
            f"sys: the {name} method needs exactly known matrices; this system has interval "
            f"matrices ({', '.join(sys.interval_matrices())}). Methods that accept them: "
            f"{', '.join(methods_with('supports_uncertain'))} "
            "(docs/uncertain.md), or estimate the nominal system sys.nominal() (not guaranteed "
            "for the uncertain plant)"
        )


class Estimator(Persistence):
    """Base class of all guaranteed estimators (see the module docstring for the contract)."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    reference: ClassVar[str] = ""
    """Where the method comes from, as reference keys of docs/references.md
    (``"[Tang2019, Algorithm 1]"``)."""
    order: ClassVar[int] = 1000
    """Position in ``ivobs.methods()``, the README table and the docs (papers' order)."""
    data_used: ClassVar[str] = "filter"
    """Which data the box of ``x[k]`` uses: ``"filter"`` (``u[0..k]``, ``y[0..k]``) or
    ``"prediction"`` (``u[0..k-1]``, ``y[0..k-1]``)."""
    supports_nonlinear: ClassVar[bool] = False
    supports_continuous: ClassVar[bool] = False
    supports_time_varying: ClassVar[bool] = False
    supports_uncertain: ClassVar[bool] = False
    """True for methods that accept interval matrices (``LinearSystem(ivobs.Box(A_lo, A_hi),
    ...)``), each saying why in its docstring; the others refuse such a system."""
    needs_x0: ClassVar[bool] = True
    proven_rounding: ClassVar[bool] = False
    """Declares that ``_step`` (and ``_run``) return bounds that enclose the exact sets, every
    floating-point error of the recursion bounded by a proven model ([Higham2002] or directed
    rounding; :mod:`ivobs.sets.rounding`). The base class adds no margin to any method: every
    built-in method declares it; a method of your own should earn it
    (:func:`ivobs.testing.check_estimator`)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Every method's ``__init__`` takes the session's defaults of its options
        (:mod:`ivobs.config`) for the options not passed: applied here, once for all methods
        (:func:`~ivobs.estimators._overrides.with_overrides`)."""
        super().__init_subclass__(**kwargs)
        init = vars(cls).get("__init__")
        if init is not None:
            cls.__init__ = with_overrides(init)  # type: ignore[method-assign]

    def __init__(
        self,
        sys: Any,
        x0: Box | None = None,
        *,
        on_inconsistent: str = "warn",
        strips: bool | None = None,
    ):
        check_system(self, sys)
        if on_inconsistent not in ("warn", "raise", "ignore"):
            raise IvobsError(
                f"on_inconsistent: expected 'warn', 'raise' or 'ignore', got {on_inconsistent!r}"
            )
        if strips is not None and not isinstance(strips, (bool, np.bool_)):
            raise IvobsError(f"strips: expected True, False or None (the default), got {strips!r}")
        self.strips = self.data_used == "filter" if strips is None else bool(strips)
        """Whether each box of ``x[k]`` is met with the measurement strips of ``y[k]``
        (:mod:`ivobs.estimators.measured`): by default for the filter-form methods."""
        self._strips = MeasurementStrips.of(sys) if self.strips else None
        self.sys = sys
        if self.supports_nonlinear:  # a linear model is converted; self.sys stays as given
            self.model: NonlinearSystem = (
                sys
                if isinstance(sys, NonlinearSystem)
                else NonlinearSystem.from_linear(sys, who=self.name)
            )
        self.x0 = check_x0(x0, sys.nx, self.name, self.needs_x0)
        self.on_inconsistent = on_inconsistent
        self.design: Design = Design()
        self.valid_from: int = 0
        self.last_inconsistent: bool = False
        """Whether the measurement of the last ``step()`` was found inconsistent (not used)."""
        self._state: OnlineState | None = None
        self._branching = False
        """True while a step runs that will not be continued (:meth:`predict`): a method with
        warm-started solver caches (exact) leaves them with the state they belong to."""

    # -- to implement ---------------------------------------------------------------------
    def _initial_state(self) -> OnlineState:
        """The online state at step 0 (an :class:`OnlineState` dataclass)."""
        raise NotImplementedError

    def _step(self, state: Any, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> Step[Any]:
        """The recursion (module docstring)."""
        raise NotImplementedError

    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        return None

    # -- online ---------------------------------------------------------------------------
    def initial_state(self) -> OnlineState:
        """The online state at step 0 (the state after :meth:`reset`)."""
        return self._initial_state()

    def reset(self) -> None:
        """Return to step 0 (before the first measurement)."""
        self._state = self.initial_state()

    @property
    def k(self) -> int:
        """Number of steps processed online so far."""
        return 0 if self._state is None else self._state.k

    def step(self, u_k: Any = None, y_k: Any = None, t: float | None = None) -> Box:
        """Process ``u[k]``, ``y[k]`` and return the box of ``x[k]`` (NaN box before
        ``valid_from``). ``y_k`` may hold NaN for missing components; ``None`` means the whole
        measurement is missing. Continuous-time methods need the sample time ``t``."""
        state = self._state if self._state is not None else self.initial_state()
        self._state, box = self.advance(state, u_k, y_k, t)
        self.last_inconsistent = self._state.inconsistent
        if self.last_inconsistent:
            self._report_inconsistent([state.k])
        return box

    def advance(
        self,
        state: OnlineState,
        u_k: Any = None,
        y_k: Any = None,
        t: float | None = None,
        *,
        finite: bool = True,
        keep: bool = True,
    ) -> tuple[Any, Box]:
        """The pure form of :meth:`step`: from an online ``state`` (from :meth:`initial_state`
        or a previous call), the next state and the box of ``x[k]``; the estimator's own online
        state is not touched (this is how :class:`Intersect` composes its members).
        ``new_state.inconsistent`` says whether ``y_k`` contradicted the model. ``finite=False``
        returns a non-finite box instead of raising the overflow error (a member of a
        composition whose other members still bound the state). ``keep=False``: the new state
        will not be continued (a look-ahead such as :meth:`predict`), so solver caches kept for
        ``state`` stay with it."""
        lean = lean_u_y(self.sys, u_k, y_k) if t is None and self.sys.dt != 0 else None
        if lean is not None:  # the common case, checked cheaply (_inputs.lean_u_y)
            (u_k, y_k), t_k = lean, None
        else:
            u_k, y_k = check_u_k(self.sys, u_k), check_y_k(self.sys, y_k)
            t_k = check_t_k(self.sys, t)
        self._branching, before = not keep, self._branching
        try:
            new, lo, hi, _ = self._advance(state, u_k, y_k, t_k)
        finally:
            self._branching = before
        if self._strips is not None and state.k >= self.valid_from:
            lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)  # (met in place)
            key = state.k if t_k is None else t_k
            if self._strips.meet(lo[None], hi[None], u_k[None], y_k[None], (key,))[0]:
                if not new.inconsistent:  # the strips of y[k] miss the box
                    new = evolve(new, inconsistent=True)
            return new, self._box(state.k, lo, hi, new, finite, owned=True)
        return new, self._box(state.k, lo, hi, new, finite)

    def _advance(
        self, state: OnlineState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[OnlineState, Bound, Bound, bool]:
        """One step: the method's recursion, then the counters."""
        new, lo, hi, flag = self._step(state, u_k, y_k, t_k)
        flag = bool(flag)
        if new is state:  # the method kept its state: a new object for the new counters
            new = evolve(new, k=state.k + 1, inconsistent=flag)
        else:  # a fresh state the method just built and nobody else holds: set its counters
            new.__dict__.update(k=state.k + 1, inconsistent=flag)
        return new, lo, hi, flag

    def _box(
        self,
        k: int,
        lo: Bound,
        hi: Bound,
        state: OnlineState,
        finite: bool = True,
        owned: bool = False,
    ) -> Box:
        """The returned box of step ``k`` (``state``: the state after it), NaN before
        ``valid_from``; ``owned``: ``lo``, ``hi`` are float arrays made for it (else copied)."""
        if k < self.valid_from:
            return Box.unknown(self.sys.nx)
        if owned:
            a, b = cast(np.ndarray, lo), cast(np.ndarray, hi)
        else:
            a, b = np.array(lo, dtype=float), np.array(hi, dtype=float)
        # one product of the bounds is finite only when every bound is (NaN and infinities
        # propagate); an overflow of finite bounds only sends it to the full test
        dot = float(a.dot(b))
        if finite and dot - dot != 0.0 and not (np.isfinite(a).all() and np.isfinite(b).all()):
            what = "NaN" if np.isnan(a).any() or np.isnan(b).any() else "infinite"
            raise self._non_finite_error(k, overflowed(a, b, *_arrays(state)), what)
        return Box._trusted(a, b)

    def predict(self, u_k: Any = None, t: float | None = None) -> Box:
        """The box the next :meth:`step` would return for ``x[k]`` if ``y[k]`` were missing,
        without changing the online state."""
        state = self._state if self._state is not None else self.initial_state()
        return self.advance(state, u_k, None, t, keep=False)[1]

    # -- offline --------------------------------------------------------------------------
    def run(
        self,
        u: Any = None,
        y: Any = None,
        *,
        t: Any = None,
        vectorize: bool | None = None,
        progress: bool | None = False,
    ) -> Estimate:
        """Bounds for a whole record: ``u`` ``(T, nu)``, ``y`` ``(T, ny)`` (NaN = missing), or a
        batch ``(B, T, ·)``. Does not touch the online state. ``vectorize=None`` picks the
        vectorised path for long records and batches (see :data:`VECTOR_MIN_STEPS`).
        ``progress``: draw a progress bar for the step-by-step path (``None``: on a terminal).
        ``t``: the sample times, needed in continuous time; for a sampled system they label the
        result (default ``k dt``) and must step by ``dt``. The result carries the model's state
        names and units."""
        u, y = check_record(self.sys, u, y)
        T = y.shape[-2]
        t_arr, t_labels = check_t(self.sys, t, T)
        start = time.perf_counter()
        if vectorize is None:
            vectorize = T >= VECTOR_MIN_STEPS or y.ndim == 3
        else:
            vectorize = as_bool("vectorize", vectorize)
        from .._progress import Progress

        self._stopped: tuple[int, str] | None = None
        with Progress(int(np.prod(y.shape[:-1])), self.name, enabled=progress) as bar:
            lo, hi, inconsistent = run_record(self, u, y, t_arr, vectorize, bar)
        if np.any(inconsistent):
            self._report_inconsistent(sorted(set(np.argwhere(inconsistent)[:, -1].tolist())))
        names = getattr(self.sys, "names", None)  # the model's labels (SignalNames)
        info: dict[str, Any] = {}
        if self._stopped is not None:
            k, why = self._stopped
            info["stopped"] = {"step": k, "reason": why}
            warnings.warn(
                f"{self.name}: the estimate diverged at step {k} and stops there (the boxes "
                f"of steps 0..{k - 1} stand; NaN after): {why}",
                stacklevel=2,
            )
        return Estimate(
            lower=lo,
            upper=hi,
            valid_from=self.valid_from,
            method=self.name,
            t=t_labels,
            missing=np.any(np.isnan(y), axis=-1),
            inconsistent=inconsistent,
            info={"run_time": time.perf_counter() - start, **info},
            names=names.states if names is not None else None,
            units=names.units if names is not None else None,
        )

    def _loop(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None, bar: Any = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The record step by step through the same recursion as :meth:`step`."""
        T = y.shape[0]
        state = self.initial_state()
        lo = np.empty((T, self.sys.nx))
        hi = np.empty((T, self.sys.nx))
        inc = np.zeros(T, dtype=bool)
        for k in range(T):
            t_k = None if t is None else float(t[k])
            try:
                state, lo[k], hi[k], inc[k] = self._advance(state, u[k], y[k], t_k)
            except DivergenceError as exc:  # the steps before it stand (run() says so)
                if k == 0:
                    raise
                lo[k:], hi[k:] = np.nan, np.nan
                self._stopped = (k, str(exc))
                break
            if bar is not None:
                bar.update()
        return lo, hi, inc

    def _check_overflow(self, k: int, *arrays: np.ndarray) -> None:
        """For estimators that keep a set (strip, constrained-zonotope): the set predicted for
        step ``k`` has run out of the float range (an unstable system the measurements do not
        bound; reducing it is impossible): the overflow error of :meth:`_non_finite_error`."""
        if not all(np.isfinite(a).all() for a in arrays):
            raise self._non_finite_error(k, True)

    def _non_finite_error(self, k: int, overflowed: bool, what: str = "non-finite") -> IvobsError:
        """The error for non-finite bounds at step ``k``: an overflow of the float range (an
        unstable system that the measurements do not bound) or NaN from finite data (a bug)."""
        if overflowed:
            return IvobsError(
                f"{self.name}: the bounds overflowed (exceed 1.8e308) at step "
                f"{k}: the system is unstable and the measurements do not bound the state (e.g. "
                "a long outage); shorten the record, or give measurements that observe the "
                "unstable modes"
            )
        return IvobsError(f"{self.name}: produced {what} bounds at step {k} (a bug; please report)")

    def _report_inconsistent(self, steps: list[int]) -> None:
        if self.on_inconsistent == "ignore" or not steps:
            return
        msg = (
            f"{self.name}: the measurement at step(s) {steps[:10]}"
            f"{' ...' if len(steps) > 10 else ''} "
            "is inconsistent with the model and the bounds (a fault under the model's "
            "assumptions); the estimator predicted without it"
        )
        if self.on_inconsistent == "raise":
            raise InconsistentDataError(msg, step=steps[0])
        warnings.warn(msg, stacklevel=3)

    @classmethod
    def options(cls) -> list[str]:
        """Names of the keyword options this method accepts."""
        return list(cls.option_defaults())

    @classmethod
    def option_defaults(cls) -> dict[str, Any]:
        """The keyword options this method accepts and their defaults, as the ``__init__``
        signatures along the class's bases declare them (the nearest declaration of each; the
        class's own options first). ``None`` usually means "chosen by the design" (the class
        docstring says how). The session's defaults (:func:`ivobs.config.set_defaults`) are not
        included: :func:`ivobs.config.defaults` gives those in effect."""
        return {name: p.default for name, p in keyword_options(cls).items()}

    def __repr__(self) -> str:
        return (
            f"<{type(self).__name__} {self.name!r} nx={self.sys.nx} valid_from={self.valid_from}>"
        )
