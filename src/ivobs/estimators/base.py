"""The estimator protocol shared by every method (scikit-learn's idea: one interface).

Subclasses implement the method; the base class owns validation, the online state, the
offline loop, missing samples bookkeeping, inconsistency reporting and outward rounding.

A subclass provides

* ``__init__(sys, x0=None, *, <its design options>, **options)``: validate, design offline (no
  time loop), set ``self.design`` (a :class:`Design` dataclass with the papers' symbols) and
  ``self.valid_from``; then call nothing else.
* ``_initial_state() -> S``: the online state at step 0, a frozen dataclass derived from
  :class:`~ivobs.estimators.state.OnlineState` (arrays named as in the paper).
* ``_step(state, u_k, y_k, t_k) -> Step[S]``: the method's recursion, written once: from the
  state at step ``k = state.k``, the next state and the bounds of ``x[k]`` from ``u[0..k]``,
  ``y[0..k]`` (before outward rounding). It never modifies ``state``. ``y_k`` may contain NaN
  (missing components: predict without them). A measurement that contradicts the model is
  reported by ``Step(..., inconsistent=True)`` and not used.
* optionally ``_run(u, y, t) -> (lo, hi) | (lo, hi, inconsistent) | None``: the whole record
  at once (vectorised; batch ``(B, T, n)`` inputs allowed) from a shared kernel, tested equal to
  the loop over ``_step``; fresh arrays the base class may modify in place; ``inconsistent`` a
  ``(..., T)`` bool array of steps whose measurement was found inconsistent (and not used).
  Return ``None`` to fall back to the loop (e.g. missing samples).

Rounding: every bound is widened outwards by :func:`~ivobs.estimators.rounding.outward`
(see :mod:`ivobs.estimators.rounding`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import time
import warnings
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from .._validate import as_bool, as_float_array, as_signal, as_vector
from ..errors import DesignError, InconsistentDataError, IvobsError
from ..model import LinearSystem
from ..result import Estimate
from ..sets import Box
from ._legacy_state import _check_restored, _copy_state
from .rounding import ROUNDING, outward, overflowed
from .state import STATE_FORMAT, STATE_VERSION, OnlineState, Step, dump_state, load_state

__all__ = [
    "MAX_DENSE_STATES",
    "ROUNDING",
    "VECTOR_MIN_STEPS",
    "Design",
    "Estimator",
    "check_size",
    "check_x0",
]

BATCH_CHUNK = 2_000_000
"""Batches are processed in chunks of about this many floats per signal (cache-sized)."""

VECTOR_MIN_STEPS = 2000
"""``run()`` uses a method's vectorised path from this many steps on (or for batches); shorter
records use the same loop as ``step()``, so ``run()`` and ``step()`` agree bit for bit there."""


@dataclass(frozen=True)
class Design:
    """What an estimator designed offline. Subclasses add fields named as in the papers
    (``L``, ``gamma``, ``T``, ``S``, ``R``, ``s``, ...)."""

    def as_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


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


def _owned(a: Any) -> np.ndarray:
    """A float array safe to modify in place: ``_run`` returns fresh arrays (or views of
    fresh arrays), so only read-only or foreign-typed results are copied."""
    if isinstance(a, np.ndarray) and a.dtype == float and a.flags.writeable:
        return a
    return np.array(a, dtype=float)


def _inconsistent(state: Any) -> bool:
    """Whether the step that produced ``state`` found its measurement inconsistent."""
    if isinstance(state, OnlineState):
        return state.inconsistent
    return bool(state.get("_last_inconsistent", False))


def _arrays(state: OnlineState) -> list[np.ndarray]:
    """The float arrays of a state (to tell an overflow from a bug)."""
    out = []
    for f in dataclasses.fields(state):
        v = getattr(state, f.name)
        if isinstance(v, np.ndarray) and v.dtype.kind == "f":
            out.append(v)
    return out


class Estimator:
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
    needs_x0: ClassVar[bool] = True
    rounds_itself: ClassVar[bool] = False
    """True for methods that apply the rounding margin themselves (``intersect``: its members'
    boxes are rounded before they are intersected, which needs no arithmetic). The online data
    scale ``s_k`` is then in ``state["_scale"]`` when ``_step`` runs."""

    def __init__(self, sys: LinearSystem, x0: Box | None = None, *, on_inconsistent: str = "warn"):
        if not isinstance(sys, LinearSystem):
            raise IvobsError(f"sys: expected an ivobs.LinearSystem, got {type(sys).__name__}")
        if sys.is_continuous and not self.supports_continuous:
            raise IvobsError(
                f"sys: the {self.name} method is for discrete-time systems; this one is "
                "continuous-time (dt=0). Use 'kkl', or sys.discretize(Ts)"
            )
        if sys.is_time_varying and not self.supports_time_varying:
            raise IvobsError(
                f"sys: the {self.name} method needs a time-invariant system; this one has "
                "time-varying matrices. Use 'fixed-time', 'kkl' or 'exact'"
            )
        if on_inconsistent not in ("warn", "raise", "ignore"):
            raise IvobsError(
                f"on_inconsistent: expected 'warn', 'raise' or 'ignore', got {on_inconsistent!r}"
            )
        self.sys = sys
        self.x0 = check_x0(x0, sys.nx, self.name, self.needs_x0)
        self.on_inconsistent = on_inconsistent
        self.design: Design = Design()
        self.valid_from: int = 0
        self.last_inconsistent: bool = False
        """Whether the measurement of the last ``step()`` was found inconsistent (not used)."""
        self._state: Any = None  # an OnlineState (a dict for methods not yet typed)
        self._branching = False
        """True while a step runs that will not be continued (:meth:`predict`): a method with
        warm-started solver caches (exact) leaves them with the state they belong to."""

    # -- to implement ---------------------------------------------------------------------
    def _initial_state(self) -> Any:
        """The online state at step 0 (an :class:`OnlineState` dataclass)."""
        raise NotImplementedError

    def _step(self, state: Any, *args: Any) -> Any:
        """``_step(state, u_k, y_k, t_k) -> Step``: the recursion (module docstring)."""
        raise NotImplementedError

    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        return None

    def initial_state(self) -> Any:
        """The online state at step 0 (the state after :meth:`reset`)."""
        st = self._initial_state()
        if not isinstance(st, OnlineState):
            st["k"] = 0
        return st

    # -- online ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Return to step 0 (before the first measurement)."""
        self._state = self.initial_state()

    @property
    def k(self) -> int:
        """Number of steps processed online so far."""
        if self._state is None:
            return 0
        return self._state.k if isinstance(self._state, OnlineState) else int(self._state["k"])

    def step(self, u_k: Any = None, y_k: Any = None, t: float | None = None) -> Box:
        """Process ``u[k]``, ``y[k]`` and return the box of ``x[k]`` (NaN box before
        ``valid_from``). ``y_k`` may hold NaN for missing components; ``None`` means the whole
        measurement is missing. Continuous-time methods need the sample time ``t``."""
        if self._state is None:
            self.reset()
        k = self.k
        self._state, box = self._advance_any(self._state, u_k, y_k, t, in_place=True)
        self.last_inconsistent = _inconsistent(self._state)
        if self.last_inconsistent:
            self._report_inconsistent([k])
        return box

    def advance(
        self,
        state: Any,
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
        if keep:
            return self._advance_any(state, u_k, y_k, t, finite=finite)
        self._branching, before = True, self._branching
        try:
            return self._advance_any(state, u_k, y_k, t, finite=finite)
        finally:
            self._branching = before

    def _advance_any(
        self,
        state: Any,
        u_k: Any,
        y_k: Any,
        t: Any,
        *,
        in_place: bool = False,
        finite: bool = True,
    ) -> tuple[Any, Box]:
        u_k = self._check_u_k(u_k)
        y_k = self._check_y_k(y_k)
        t_k = self._check_t_k(t)
        if isinstance(state, OnlineState):
            k = state.k
            new, lo, hi, _flag = self._advance(state, u_k, y_k, t_k)
            return new, self._box(k, lo, hi, new.scale, _arrays(new), finite)
        st = state if in_place else _copy_state(state)  # a dict state (not yet typed)
        k = int(st["k"])
        scale = max(float(st.get("_scale", 0.0)), self._step_scale(k, u_k, y_k, t_k))
        st["_scale"] = scale
        lo, hi = self._step(st, k, u_k, y_k, t_k)
        st["k"] = k + 1
        st["_last_inconsistent"] = bool(st.pop("_inconsistent", False))
        arrays = [v for v in st.values() if isinstance(v, np.ndarray)]
        return st, self._box(k, lo, hi, scale, arrays, finite)

    def _advance(
        self, state: OnlineState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[OnlineState, np.ndarray, np.ndarray, bool]:
        """One step of the typed protocol: the data scale, the method's recursion, the counter."""
        scale = max(state.scale, self._step_scale(state.k, u_k, y_k, t_k))
        if self.rounds_itself:  # it needs s_k inside its step
            state = dataclasses.replace(state, scale=scale)
        res: Step[Any] = self._step(state, u_k, y_k, t_k)
        new = dataclasses.replace(
            res.state, k=state.k + 1, scale=scale, inconsistent=bool(res.inconsistent)
        )
        return new, res.lo, res.hi, bool(res.inconsistent)

    def _box(
        self,
        k: int,
        lo: np.ndarray,
        hi: np.ndarray,
        scale: float,
        arrays: list[np.ndarray],
        finite: bool = True,
    ) -> Box:
        """The returned box of step ``k``: rounded outwards, NaN before ``valid_from``."""
        if k < self.valid_from:
            return Box.unknown(self.sys.nx)
        lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
        if not self.rounds_itself:
            outward(lo, hi, scale)
        if finite and not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            what = "NaN" if np.isnan(lo).any() or np.isnan(hi).any() else "infinite"
            raise self._non_finite_error(k, overflowed(lo, hi, *arrays), what)
        return Box._trusted(lo, hi)

    def predict(self, u_k: Any = None, t: float | None = None) -> Box:
        """The box the next :meth:`step` would return for ``x[k]`` if ``y[k]`` were missing,
        without changing the online state."""
        if self._state is None:
            self.reset()
        return self.advance(self._state, u_k, None, t, keep=False)[1]

    def _check_u_k(self, u_k: Any) -> np.ndarray:
        if u_k is None:
            if self.sys.nu:
                raise IvobsError(f"u_k: expected {self.sys.nu} input value(s), got None")
            return np.zeros(0)
        return as_vector("u_k", u_k, self.sys.nu)

    def _check_y_k(self, y_k: Any) -> np.ndarray:
        if y_k is None:
            return np.full(self.sys.ny, np.nan)
        arr = as_float_array("y_k", y_k).ravel()
        if arr.shape[0] != self.sys.ny:
            raise IvobsError(
                f"y_k: expected {self.sys.ny} measurement value(s), got {arr.shape[0]}"
            )
        if np.any(np.isinf(arr)):
            raise IvobsError("y_k: infinite measurement; use NaN for a missing sample")
        return arr

    def _check_t_k(self, t: Any) -> float | None:
        if t is None:
            if self.sys.is_continuous:
                raise IvobsError("t: continuous-time estimation needs the sample time of each step")
            return None
        arr = as_float_array("t", t)
        if arr.size != 1 or not np.isfinite(arr).all():
            raise IvobsError(f"t: expected one finite sample time, got {t!r}")
        return float(arr.reshape(()))

    # -- data scale of the rounding margin (module docstring) ---------------------------
    def _scale_terms(self, k: Any) -> tuple[np.ndarray, float]:
        """``(g, c)`` at step (or time) ``k``: ``g_j |u_j|`` bounds the input terms of input
        ``j`` (``g_j`` the largest entry of column ``j`` of ``|B|`` and ``|D|``), ``c`` the
        disturbance terms ``|E| |d|``, ``|F| |d|`` (0 for bounds computed from ``y``)."""
        cache = self.__dict__.get("_scale_cache")
        if cache is not None:
            return cache
        sys = self.sys
        _A, B, _C, D, E, F = sys.matrices_at(k)
        g = np.max(np.abs(np.vstack([B, D])), axis=0) if sys.nu else np.zeros(0)
        c = 0.0
        dbox = getattr(sys, "_d", None)
        if sys.nd and isinstance(dbox, Box):
            box = sys.d_at(int(k) if sys.is_discrete else 0)
            md = np.maximum(np.abs(box.lo), np.abs(box.hi))
            c = float(max(np.max(np.abs(E) @ md, initial=0.0), np.max(np.abs(F) @ md, initial=0.0)))
        out = (g, c)
        if not sys.is_time_varying and sys.has_constant_bounds:
            self._scale_cache = out
        return out

    def _step_scale(self, k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> float:
        """The magnitude of the data terms of one step (its running maximum is ``s_k``)."""
        g, c = self._scale_terms(k if t_k is None else t_k)
        a = c
        if y_k.size:
            m = np.fmax.reduce(np.abs(y_k))
            if m == m:  # not all missing
                a = max(a, float(m))
        if u_k.size:
            a = max(a, float(np.max(np.abs(u_k) * g)))
        return a

    def _data_scale(self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> np.ndarray:
        """``s_k`` over a record or batch, ``(..., T)``: the running maximum of
        :meth:`_step_scale` (the same numbers as the online path)."""
        T = y.shape[-2]
        a = np.zeros(y.shape[:-1])
        for i in range(y.shape[-1]):  # columns: a reduction over a short last axis is slow
            np.fmax(a, np.abs(y[..., i]), out=a)  # fmax: a missing sample (NaN) counts as 0
        sys = self.sys
        steady = not sys.is_time_varying and sys.has_constant_bounds
        if steady:
            g, c = self._scale_terms(0 if t is None else t[0])
            G, cs = g, np.full(T, c)
        else:
            terms = [self._scale_terms(k if t is None else t[k]) for k in range(T)]
            G = np.array([gc[0] for gc in terms]).reshape(T, sys.nu)
            cs = np.array([gc[1] for gc in terms])
        if sys.nu:
            if u.ndim == 3 and u.strides[0] == 0:
                au = np.max(np.abs(u[0]) * G, axis=-1)  # one input for the whole batch
            else:
                au = np.max(np.abs(u) * G, axis=-1)
            np.maximum(a, au, out=a)
        np.maximum(a, cs, out=a)
        return np.maximum.accumulate(a, axis=-1)

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
        ``progress``: draw a progress bar for the step-by-step path (``None``: on a terminal)."""
        y = as_signal("y", y, self.sys.ny, allow_nan=True)
        T = y.shape[-2]
        u = as_signal("u", u, self.sys.nu, T if u is None else None)
        if u.shape[-2] != T:
            raise IvobsError(
                f"u and y: expected the same number of samples (rows), got u: {u.shape[-2]}, y: {T}"
            )
        if u.ndim == 3 or y.ndim == 3:
            B = (u if u.ndim == 3 else y).shape[0]
            if u.ndim == 3 and y.ndim == 3 and u.shape[0] != y.shape[0]:
                raise IvobsError(f"u, y: batch sizes differ ({u.shape[0]} and {y.shape[0]})")
            u = np.broadcast_to(u, (B, T, self.sys.nu)) if u.ndim == 2 else u
            y = np.broadcast_to(y, (B, T, self.sys.ny)) if y.ndim == 2 else y
        t_arr = self._check_t(t, T)
        start = time.perf_counter()
        if vectorize is None:
            vectorize = T >= VECTOR_MIN_STEPS or y.ndim == 3
        else:
            vectorize = as_bool("vectorize", vectorize)
        from .._progress import Progress

        with Progress(int(np.prod(y.shape[:-1])), self.name, enabled=progress) as bar:
            if y.ndim == 3:
                # streams in cache-sized chunks written into one output: large fresh temporaries
                # cost more in page faults than the arithmetic itself
                B, nx = y.shape[0], self.sys.nx
                lo = np.empty((B, T, nx))
                hi = np.empty((B, T, nx))
                inconsistent = np.zeros((B, T), dtype=bool)
                size = max(1, T) * max(nx, self.sys.ny, self.sys.nu, 1)
                chunk = max(1, BATCH_CHUNK // size)
                for b0 in range(0, B, chunk):
                    sl = slice(b0, min(B, b0 + chunk))
                    lo[sl], hi[sl], inconsistent[sl] = self._block(
                        u[sl], y[sl], t_arr, vectorize, bar
                    )
                    self._finalize(lo[sl], hi[sl], self._data_scale(u[sl], y[sl], t_arr))
            else:
                lo, hi, inconsistent = self._block(u, y, t_arr, vectorize, bar)
                lo, hi = _owned(lo), _owned(hi)
                self._finalize(lo, hi, self._data_scale(u, y, t_arr))
        if np.any(inconsistent):
            self._report_inconsistent(sorted(set(np.argwhere(inconsistent)[:, -1].tolist())))
        return Estimate(
            lower=lo,
            upper=hi,
            valid_from=self.valid_from,
            method=self.name,
            t=t_arr,
            missing=np.any(np.isnan(y), axis=-1),
            inconsistent=inconsistent,
            info={"run_time": time.perf_counter() - start},
        )

    def _block(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None, vectorize: bool, bar: Any
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``_run`` (vectorised) or the loop, for one record or a chunk of streams."""
        out = self._run(u, y, t) if vectorize else None
        if out is not None:
            inc = np.zeros(y.shape[:-1], dtype=bool)
            if len(out) == 3 and out[2] is not None:
                inc = np.asarray(out[2], dtype=bool).reshape(y.shape[:-1])
            if bar is not None:
                bar.update(int(np.prod(y.shape[:-1])))
            return out[0], out[1], inc
        if y.ndim == 2:
            return self._loop(u, y, t, bar)
        parts = [self._loop(u[b], y[b], t, bar) for b in range(y.shape[0])]
        return tuple(np.stack(p) for p in zip(*parts))  # type: ignore[return-value]

    def _finalize(self, lo: np.ndarray, hi: np.ndarray, scale: np.ndarray | None = None) -> None:
        """In place: outward rounding (``scale``: the data scale ``s_k``, ``(..., T)``), NaN
        before ``valid_from``, no non-finite bound after."""
        if not self.rounds_itself:
            outward(lo, hi, scale)
        vf = self.valid_from
        lo[..., :vf, :] = np.nan
        hi[..., :vf, :] = np.nan
        if not np.isfinite(np.sum(lo[..., vf:, :]) + np.sum(hi[..., vf:, :])):
            bad = ~(np.isfinite(lo[..., vf:, :]) & np.isfinite(hi[..., vf:, :]))
            first = np.argwhere(bad)[0]
            k = int(first[-2]) + vf
            row = tuple(int(i) for i in first[:-2])  # the stream of a batch
            prev = max(k - 1, vf)  # finite: k is the first non-finite step
            raise self._non_finite_error(
                k, overflowed(lo[row][k], hi[row][k], lo[row][prev], hi[row][prev])
            )

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

    def _loop(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None, bar: Any = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The record step by step through the same recursion as :meth:`step`."""
        T = y.shape[0]
        state = self.initial_state()
        lo = np.empty((T, self.sys.nx))
        hi = np.empty((T, self.sys.nx))
        inc = np.zeros(T, dtype=bool)
        typed = isinstance(state, OnlineState)
        for k in range(T):
            t_k = None if t is None else float(t[k])
            if typed:
                state, lo[k], hi[k], inc[k] = self._advance(state, u[k], y[k], t_k)
            else:
                if self.rounds_itself:
                    state["_scale"] = max(
                        state.get("_scale", 0.0), self._step_scale(k, u[k], y[k], t_k)
                    )
                lo[k], hi[k] = self._step(state, k, u[k], y[k], t_k)
                state["k"] = k + 1
                inc[k] = bool(state.pop("_inconsistent", False))
            if bar is not None:
                bar.update()
        return lo, hi, inc

    def _check_t(self, t: Any, T: int) -> np.ndarray | None:
        if t is None:
            if self.sys.is_continuous:
                raise IvobsError("t: continuous-time estimation needs the sample times t (T,)")
            return None
        t_arr = as_float_array("t", t).ravel()
        if t_arr.shape[0] != T or np.any(~np.isfinite(t_arr)) or np.any(np.diff(t_arr) <= 0):
            raise IvobsError(f"t: expected {T} finite, strictly increasing sample times")
        return t_arr

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

    # -- persistence ----------------------------------------------------------------------
    def _fingerprint(self) -> str:
        parts = [self.name, str(self.sys.nx), str(self.sys.nu), str(self.sys.ny)]
        for key, val in self.design.as_dict().items():
            # numbers only: provenance strings (how a gain was obtained) do not change the state
            if isinstance(val, np.ndarray) and val.dtype.kind in "fiub":
                parts.append(key + np.array2string(val, precision=12))
            elif isinstance(val, (int, float)):
                parts.append(f"{key}={val}")
        return hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]

    def state(self) -> dict[str, Any]:
        """The online state as a JSON-serialisable dict (see :meth:`restore`): the method, the
        fingerprint of its design, the format version and the state's fields."""
        return self.save_state(self._state if self._state is not None else self.initial_state())

    def save_state(self, st: Any) -> dict[str, Any]:
        """A given online state of this estimator as the JSON-serialisable dict of
        :meth:`state`."""
        if isinstance(st, OnlineState):
            return {
                "format": STATE_FORMAT,
                "version": STATE_VERSION,
                "method": self.name,
                "fingerprint": self._fingerprint(),
                "state": dump_state(st),
            }
        data = {}
        for key, val in st.items():
            if isinstance(val, np.ndarray):
                if val.dtype.kind == "f" and np.isnan(val).any():
                    lst = [None if v != v else v for v in val.ravel().tolist()]
                    data[key] = {"array": lst, "shape": list(val.shape)}
                else:
                    data[key] = {"array": val.tolist(), "shape": list(val.shape)}
            elif isinstance(val, (np.floating, np.integer, np.bool_)):
                data[key] = val.item()
            else:
                data[key] = val
        return {"method": self.name, "fingerprint": self._fingerprint(), "state": data}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a state saved by :meth:`state` (same method and design); the saved
        values are checked against a fresh state of this estimator."""
        self._state = self.check_state(state)

    def check_state(self, state: Any) -> Any:
        """The online state held by ``state`` (a dict from :meth:`state`), checked against this
        estimator (method, design fingerprint, format version, every entry); raises
        :class:`~ivobs.IvobsError` naming what is wrong. Does not change the estimator."""
        if not isinstance(state, dict) or "state" not in state:
            raise IvobsError("state: expected the dict returned by Estimator.state()")
        if state.get("method") != self.name or state.get("fingerprint") != self._fingerprint():
            raise IvobsError(
                f"state: saved by method {state.get('method')!r} with another design; it can only "
                f"be restored into the same method ({self.name!r}) with the same design"
            )
        fresh = self.initial_state()
        if isinstance(fresh, OnlineState):
            version = state.get("version", 1)
            if version != STATE_VERSION:
                raise IvobsError(
                    f"state: saved in state format version {version!r}; this ivobs reads version "
                    f"{STATE_VERSION} (typed states). Re-run from the start of the record, or "
                    "load it with the ivobs version that saved it"
                )
            return load_state(state["state"], fresh)
        return self._restore_dict(state["state"], fresh)

    def _restore_dict(self, saved: Any, ref: dict[str, Any]) -> dict[str, Any]:
        if not isinstance(saved, dict):
            raise IvobsError(
                "state: expected entry 'state' to be the dict of saved values from "
                f"Estimator.state(), got {type(saved).__name__}"
            )
        st: dict[str, Any] = {}
        for key, val in saved.items():
            if isinstance(val, dict) and "array" in val:
                try:
                    st[key] = np.array(val["array"], dtype=float).reshape(val["shape"])
                except (TypeError, ValueError, KeyError) as exc:
                    raise IvobsError(
                        f"state: entry {key!r} is not a valid saved array ({exc}); the state "
                        "was altered or is not from Estimator.state()"
                    ) from None
            else:
                st[key] = val
        ref = {k: v for k, v in ref.items() if k != "k"}
        missing = set(ref) - set(st)
        if missing:
            raise IvobsError(f"state: missing entries {sorted(missing)}")
        _check_restored(st, ref)
        return st

    # -- helpers for subclasses ------------------------------------------------------------
    @classmethod
    def options(cls) -> list[str]:
        """Names of the keyword options this method accepts."""
        names: list[str] = []
        for klass in cls.__mro__:
            if "__init__" in vars(klass):
                sig = inspect.signature(vars(klass)["__init__"])
                for p in sig.parameters.values():
                    if p.kind is p.KEYWORD_ONLY and p.name not in names:
                        names.append(p.name)
        return names

    def __repr__(self) -> str:
        return (
            f"<{type(self).__name__} {self.name!r} nx={self.sys.nx} valid_from={self.valid_from}>"
        )
