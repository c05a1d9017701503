"""The estimator protocol shared by every method (scikit-learn's idea: one interface).

Subclasses implement the method; the base class owns validation, the online state, the
offline loop, missing samples bookkeeping, inconsistency reporting and outward rounding.

A subclass provides

* ``__init__(sys, x0=None, *, <its design options>, **base_options)``: validate, design offline
  (no time loop), set ``self.design`` (a :class:`Design` dataclass with the papers' symbols) and
  ``self.valid_from``; then call nothing else.
* ``_initial_state() -> dict``: the online state at step 0 (numpy arrays / numbers only).
* ``_step(state, k, u_k, y_k, t_k) -> (lo, hi)``: advance one step in place and return the
  bounds of ``x[k]`` from ``u[0..k]``, ``y[0..k]``. ``y_k`` may contain NaN (missing components:
  predict without them). On a measurement that contradicts the model, set
  ``state["_inconsistent"] = True`` and predict without it.
* optionally ``_run(u, y, t) -> (lo, hi) | (lo, hi, inconsistent) | None``: the whole record
  at once (vectorised; batch ``(B, T, n)`` inputs allowed), as *fresh* arrays the base class may
  modify in place; ``inconsistent`` is a ``(..., T)`` bool array of steps whose measurement was
  found inconsistent (and not used). Return ``None`` to fall back to the loop (e.g. missing
  samples).

Soundness under floating point: every returned bound of ``x[k]`` is widened outwards by
``ROUNDING * (1 + |bound| + s_k)`` (:data:`ROUNDING` ``= 1e-10``, about ``4.5e5`` units of
rounding ``eps``), where ``s_k`` is the *data scale*: the largest magnitude of a data term seen up
to step ``k`` (``|y_j|``, ``|B| |u_j|``, ``|D| |u_j|``, ``|E| |d_j|``, ``|F| |d_j|``, ``j <= k``).
A recursion that combines terms of size ``s`` loses about ``eps s`` per operation, amplified by
the gain of the error dynamics; the margin covers amplifications up to ``~1e5`` relative to the
largest quantity involved, the bounds *and* the data (a measurement ``y = 1e8`` carrying a state
of size 1 is only known to ``eps 1e8``). This is a documented safety margin, not interval
arithmetic with directed rounding.
"""

from __future__ import annotations

import copy
import hashlib
import inspect
import time
import warnings
from dataclasses import dataclass, fields
from typing import Any, ClassVar

import numpy as np

from .._validate import _shape_str, as_bool, as_float_array, as_signal, as_vector
from ..errors import DesignError, InconsistentDataError, IvobsError
from ..model import LinearSystem
from ..result import Estimate
from ..sets import Box

__all__ = [
    "MAX_DENSE_STATES",
    "ROUNDING",
    "VECTOR_MIN_STEPS",
    "Design",
    "Estimator",
    "check_size",
    "check_x0",
]

ROUNDING = 1e-10
"""Relative outward widening of every bound (covers floating-point rounding)."""

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


def outward(
    lo: np.ndarray, hi: np.ndarray, scale: np.ndarray | float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Widen bounds by the rounding margin ``ROUNDING (1 + max(|lo|, |hi|) + scale)`` (NaN
    stays NaN), in place: pass arrays you own. ``scale``: the data scale per step, shaped like
    the bounds without their last axis (see the module docstring).

    Works through cache-sized slabs of rows with two reused buffers: on a long record of a
    large system, whole-array temporaries cost more in page faults than the arithmetic."""
    n = lo.shape[-1] if lo.ndim else 1
    flat = lo.ndim == 2 or (lo.flags.c_contiguous and hi.flags.c_contiguous)  # rows: views
    if lo.size <= _SLAB or not flat or n == 0 or lo.shape != hi.shape:
        with np.errstate(invalid="ignore"):
            m = np.maximum(np.abs(lo), np.abs(hi))
            if scale is not None:
                m += np.asarray(scale)[..., None] if np.ndim(scale) else scale
            m *= ROUNDING
            m += ROUNDING
            lo -= m
            hi += m
        return lo, hi
    L, H = lo.reshape(-1, n), hi.reshape(-1, n)
    rows = L.shape[0]
    # the part of the margin that does not depend on the bound: ROUNDING (1 + s) per row
    base = ROUNDING * (1.0 + (0.0 if scale is None else np.asarray(scale, dtype=float)))
    S = np.broadcast_to(base, lo.shape[:-1]).reshape(-1, 1)
    step = max(1, _SLAB // n)
    m = np.empty((min(step, rows), n))
    t = np.empty_like(m)
    with np.errstate(invalid="ignore"):
        for r0 in range(0, rows, step):
            r1 = min(rows, r0 + step)
            mm, tt = m[: r1 - r0], t[: r1 - r0]
            np.abs(L[r0:r1], out=mm)
            np.abs(H[r0:r1], out=tt)
            np.maximum(mm, tt, out=mm)
            mm *= ROUNDING
            mm += S[r0:r1]
            L[r0:r1] -= mm
            H[r0:r1] += mm
    return lo, hi


_SLAB = 1 << 15
"""Elements per slab of :func:`outward`."""


def _owned(a: Any) -> np.ndarray:
    """A float array safe to modify in place: ``_run`` returns fresh arrays (or views of
    fresh arrays), so only read-only or foreign-typed results are copied."""
    if isinstance(a, np.ndarray) and a.dtype == float and a.flags.writeable:
        return a
    return np.array(a, dtype=float)


class Estimator:
    """Base class of all guaranteed estimators (see the module docstring for the contract)."""

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    reference: ClassVar[str] = ""
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
        self._state: dict[str, Any] | None = None

    # -- to implement ---------------------------------------------------------------------
    def _initial_state(self) -> dict[str, Any]:
        raise NotImplementedError

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        return None

    # -- online ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Return to step 0 (before the first measurement)."""
        self._state = self._initial_state()
        self._state["k"] = 0

    @property
    def k(self) -> int:
        """Number of steps processed online so far."""
        return 0 if self._state is None else int(self._state["k"])

    def step(self, u_k: Any = None, y_k: Any = None, t: float | None = None) -> Box:
        """Process ``u[k]``, ``y[k]`` and return the box of ``x[k]`` (NaN box before
        ``valid_from``). ``y_k`` may hold NaN for missing components; ``None`` means the whole
        measurement is missing. Continuous-time methods need the sample time ``t``."""
        if self._state is None:
            self.reset()
        assert self._state is not None
        u_k = self._check_u_k(u_k)
        y_k = self._check_y_k(y_k)
        t_k = self._check_t_k(t)
        k = int(self._state["k"])
        scale = max(float(self._state.get("_scale", 0.0)), self._step_scale(k, u_k, y_k, t_k))
        self._state["_scale"] = scale
        lo, hi = self._step(self._state, k, u_k, y_k, t_k)
        self._state["k"] = k + 1
        self.last_inconsistent = bool(self._state.pop("_inconsistent", False))
        if self.last_inconsistent:
            self._report_inconsistent([k])
        if k < self.valid_from:
            return Box.unknown(self.sys.nx)
        lo, hi = np.array(lo, dtype=float), np.array(hi, dtype=float)
        if not self.rounds_itself:
            outward(lo, hi, scale)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            state_arrays = [v for v in self._state.values() if isinstance(v, np.ndarray)]
            what = "NaN" if np.isnan(lo).any() or np.isnan(hi).any() else "infinite"
            raise self._non_finite_error(k, _overflowed(lo, hi, *state_arrays), what)
        return Box._trusted(lo, hi)

    def predict(self, u_k: Any = None, t: float | None = None) -> Box:
        """The box the next :meth:`step` would return for ``x[k]`` if ``y[k]`` were missing,
        without changing the online state (a step on a copy of the state)."""
        if self._state is None:
            self.reset()
        saved = _copy_state(self._state)
        flag = self.last_inconsistent
        try:
            return self.step(u_k, None, t)
        finally:
            self._state = saved
            self.last_inconsistent = flag

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
                "u and y: expected the same number of samples (rows), got "
                f"u: {u.shape[-2]}, y: {T}"
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
                    lo[sl], hi[sl], inconsistent[sl] = self._block(u[sl], y[sl], t_arr,
                                                                   vectorize, bar)
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

    def _finalize(
        self, lo: np.ndarray, hi: np.ndarray, scale: np.ndarray | None = None
    ) -> None:
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
                k, _overflowed(lo[row][k], hi[row][k], lo[row][prev], hi[row][prev])
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
        T = y.shape[0]
        state = self._initial_state()
        state["k"] = 0
        lo = np.empty((T, self.sys.nx))
        hi = np.empty((T, self.sys.nx))
        inc = np.zeros(T, dtype=bool)
        for k in range(T):
            if self.rounds_itself:
                t_k = None if t is None else float(t[k])
                state["_scale"] = max(state.get("_scale", 0.0),
                                      self._step_scale(k, u[k], y[k], t_k))
            lo[k], hi[k] = self._step(state, k, u[k], y[k], None if t is None else float(t[k]))
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
        """The online state as a JSON-serialisable dict (see :meth:`restore`)."""
        st = self._state if self._state is not None else {**self._initial_state(), "k": 0}
        data = {}
        for key, val in st.items():
            if isinstance(val, np.ndarray):
                if val.dtype.kind == "f" and np.isnan(val).any():
                    # NaN (a missing sample) as null: strict JSON; restore() reads it back
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
        """Continue from a state saved by :meth:`state` (same method and design)."""
        if not isinstance(state, dict) or "state" not in state:
            raise IvobsError("state: expected the dict returned by Estimator.state()")
        if state.get("method") != self.name or state.get("fingerprint") != self._fingerprint():
            raise IvobsError(
                f"state: saved by method {state.get('method')!r} with another design; it can only "
                f"be restored into the same method ({self.name!r}) with the same design"
            )
        saved = state["state"]
        if not isinstance(saved, dict):
            raise IvobsError(
                "state: expected entry 'state' to be the dict of saved values from "
                f"Estimator.state(), got {type(saved).__name__}"
            )
        ref = self._initial_state()
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
        missing = set(ref) - set(st)
        if missing:
            raise IvobsError(f"state: missing entries {sorted(missing)}")
        _check_restored(st, ref)
        self._state = st

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


_TAMPERED = "; the state was altered or is not from Estimator.state() of this estimator"


def _check_restored(st: dict[str, Any], ref: dict[str, Any]) -> None:
    """Check a restored online state against a fresh one (``ref``, from ``_initial_state()``):
    the step counter, the data scale, and every entry of ``ref`` (arrays: dimensions, fixed
    axes, finite values, ``lo <= hi``; scalars: their type). Axes that grow while running
    (generators: the last axis of a matrix; histories: an axis empty at step 0) may differ."""
    k = st.get("k")
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 0:
        raise IvobsError(f"state: entry 'k': expected the step count (an integer >= 0), got {k!r}"
                         + _TAMPERED)
    scale = st.get("_scale", 0.0)
    if (isinstance(scale, bool) or not isinstance(scale, (int, float, np.number))
            or not np.isfinite(scale) or scale < 0):
        raise IvobsError(
            f"state: entry '_scale': expected the data scale (a finite number >= 0), got "
            f"{scale!r}" + _TAMPERED
        )
    for key, fresh in ref.items():
        val = st[key]
        if isinstance(fresh, np.ndarray):
            _check_restored_array(key, val, fresh)
        elif isinstance(fresh, (bool, np.bool_)):
            if not isinstance(val, (bool, np.bool_)):
                raise IvobsError(f"state: entry {key!r}: expected True or False, got {val!r}"
                                 + _TAMPERED)
        elif isinstance(fresh, (int, np.integer)):
            if isinstance(val, bool) or not isinstance(val, (int, np.integer)):
                raise IvobsError(f"state: entry {key!r}: expected an integer, got {val!r}"
                                 + _TAMPERED)
        elif isinstance(fresh, (float, np.floating)) or fresh is None:  # None: not yet known
            number = not isinstance(val, bool) and isinstance(val, (int, float, np.number))
            finite_ok = number and (
                bool(np.isfinite(val)) or (fresh is not None and not np.isfinite(fresh))
            )
            if not (finite_ok or (fresh is None and val is None)):
                raise IvobsError(
                    f"state: entry {key!r}: expected a finite number"
                    f"{' or None' if fresh is None else ''}, got {val!r}" + _TAMPERED
                )
    for key in ref:  # bounds kept in pairs: <name>lo <= <name>hi
        if key.endswith("lo") and key[:-2] + "hi" in ref:
            lo, hi = st[key], st[key[:-2] + "hi"]
            if lo.shape != hi.shape:
                raise IvobsError(
                    f"state: entries {key!r} and {key[:-2] + 'hi'!r}: expected bounds of the same "
                    f"shape, got {_shape_str(lo.shape)} and {_shape_str(hi.shape)}" + _TAMPERED
                )
            if np.any(lo > hi):
                idx = tuple(int(i) for i in np.argwhere(lo > hi)[0])
                raise IvobsError(
                    f"state: entries {key!r} and {key[:-2] + 'hi'!r}: expected lower <= upper "
                    f"bounds, got {lo[idx]} > {hi[idx]} at index {idx}" + _TAMPERED
                )


def _check_restored_array(key: str, val: Any, fresh: np.ndarray) -> None:
    """One array entry of a restored state against its fresh counterpart (see
    :func:`_check_restored`)."""
    if not isinstance(val, np.ndarray):
        raise IvobsError(
            f"state: entry {key!r}: expected a saved array, got {type(val).__name__} "
            f"{val!r:.60}" + _TAMPERED
        )
    pattern = tuple(
        "any" if (i == 0 and n == 0) or (i == fresh.ndim - 1 and fresh.ndim >= 2) else n
        for i, n in enumerate(fresh.shape)
    )
    if val.ndim != fresh.ndim or any(
        p != "any" and p != n for p, n in zip(pattern, val.shape)
    ):
        raise IvobsError(
            f"state: entry {key!r}: expected an array of shape {_shape_str(pattern)}, got "
            f"{_shape_str(val.shape)}" + _TAMPERED
        )
    # non-finite values only in an entry that has them in a fresh state, and NaN in a kept
    # measurement record "y" (a missing sample, as in step())
    bad = np.isinf(val) if key == "y" else ~np.isfinite(val)
    if np.all(np.isfinite(fresh)) and np.any(bad):
        idx = tuple(int(i) for i in np.argwhere(bad)[0])
        raise IvobsError(
            f"state: entry {key!r}: expected finite numbers, got {val[idx]} at index {idx}"
            + _TAMPERED
        )


_HUGE = 1e300
"""A bound this large is one step of growth away from the end of the float range."""


def _overflowed(*arrays: np.ndarray) -> bool:
    """Whether any array holds an infinity or a finite value beyond :data:`_HUGE` (the bounds
    ran out of the float range; NaN then comes from ``inf - inf``)."""
    with np.errstate(invalid="ignore"):
        return any(bool(np.any(np.abs(a) > _HUGE)) for a in arrays if a.dtype.kind == "f")


def _copy_state(state: Any) -> Any:
    """A deep copy of an online state (fast path for the usual dict of arrays and numbers)."""
    if isinstance(state, dict):
        return {k: _copy_state(v) for k, v in state.items()}
    if isinstance(state, list):
        return [_copy_state(v) for v in state]
    if isinstance(state, np.ndarray):
        return state.copy()
    if isinstance(state, (int, float, str, bool, type(None), np.generic)):
        return state
    try:
        return copy.deepcopy(state)
    except TypeError as exc:
        raise IvobsError(f"predict: this method's online state cannot be copied ({exc})") from None

