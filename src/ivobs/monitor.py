"""Streaming fault detection: a guaranteed estimator plus a consistency test at every step.

At step ``k`` the :class:`Monitor` predicts, *from the data before k only*, a box ``P_k`` that
contains ``x[k]``:

* the model's one-step prediction from the previous box (Lemma 1 of papers 003/004,
  :func:`ivobs.image_bounds`)::

      x[k] ∈ A_{k-1} [X_{k-1}] + B_{k-1} u[k-1] + E_{k-1} [d[k-1]]

  where ``X_{k-1}`` is the tightest box of ``x[k-1]`` known after step ``k - 1`` (the
  estimator's box intersected with the previous prediction); at ``k = 0``, the prior box ``x0``;
* intersected (``tight=True``) with the estimator's own prediction of ``x[k]``: the box the
  estimator returns when ``y[k]`` is missing (every method predicts through missing samples).
  For prediction-form observers this is their box itself; for zonotope or exact methods it is
  tighter than a box-wise prediction.

It then checks the measurement against the output band this predicts::

      y[k] ∈ C_k [P_k] + D_k u[k] + F_k [d[k]]

(``d[k-1]`` and ``d[k]`` are different samples with independent bounds, so using both boxes is
sound even though one disturbance enters both equations). An **alarm** is raised when a measured
component lies outside the band, when the estimator reports the measurement as inconsistent
(empty intersections in the exact, strip and constrained-zonotope methods), or when the
estimator's box and the prediction do not meet.

**Guarantee.** Under the model's assumptions (the matrices are right, ``d[k]`` stays in its
bounds, ``x[0]`` in its prior box) ``x[k] ∈ P_k`` and ``y[k]`` lies in the band at every step, so
an alarm is never false. Floating-point rounding is covered by widening the band by
``margin * (1 + |bound|)`` (``margin = 1e-9`` by default). An alarm therefore proves that the
data contradict the model: a sensor or actuator fault, a wrong model or wrong bounds.

The monitor uses the estimator protocol only (``step``, ``state``/``restore``), so it works with
every method; its state (``state()`` / ``restore()``) is JSON-serialisable, so a restarted
monitor continues with the same boxes and the same alarms as one that never stopped.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._validate import as_float_array, as_signal, as_vector
from .errors import IvobsError
from .estimators import Estimator, make_estimator
from .io import equal_systems
from .model import LinearSystem
from .result import Estimate
from .sets import Box, image_bounds, neg, pos

__all__ = ["Monitor", "MonitorRecord", "MonitorStep"]

STATE_VERSION = 1


@dataclass(frozen=True)
class MonitorStep:
    """The outcome of one step.

    ``lower``/``upper``: the estimator's box of ``x[k]`` (NaN before its ``valid_from``);
    ``alarm``: the measurement contradicts the model (never false under its assumptions);
    ``reason``: why (empty without alarm); ``band_lower``/``band_upper``: the output band the
    data before ``k`` predict for ``y[k]`` (infinite where nothing is known yet).
    """

    step: int
    lower: np.ndarray
    upper: np.ndarray
    alarm: bool
    reason: str = ""
    band_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    band_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def box(self) -> Box:
        return Box._trusted(self.lower, self.upper)


@dataclass
class MonitorRecord:
    """:meth:`Monitor.run` over a record: arrays over the steps."""

    lower: np.ndarray
    upper: np.ndarray
    alarm: np.ndarray
    reasons: list[str]
    band_lower: np.ndarray
    band_upper: np.ndarray

    @property
    def first_alarm(self) -> int | None:
        """The first step with an alarm (None without one)."""
        idx = np.flatnonzero(self.alarm)
        return int(idx[0]) if idx.size else None


class Monitor:
    """A guaranteed estimator with an alarm at every step (see the module docstring).

    Parameters
    ----------
    sys : the model.
    method : a method name (``ivobs.methods()``) or an :class:`~ivobs.Estimator` already built
        for ``sys``.
    x0 : prior box on ``x[0]`` (passed to the method, and the first prediction).
    tight : also intersect the prediction with the estimator's own prediction (one extra
        estimator step per step, with ``y[k]`` missing, on a copy of its state; switched off by
        itself when the state cannot be copied, as the ``exact`` method's LP solver).
    margin : relative widening of the band against floating-point rounding.
    **options : the method's design options (an explicit gain ``L``, ...).

    The monitor takes over the estimator's reports of inconsistent measurements: they become
    alarms instead of warnings.

    >>> import ivobs
    >>> from ivobs.monitor import Monitor
    >>> sc = ivobs.scenarios.get("servo-motor")
    >>> mon = Monitor(sc.system, "interval-split", x0=sc.x0)          # doctest: +SKIP
    >>> out = mon.update(u_k=[2.0], y_k=[0.01, 0.02])                  # doctest: +SKIP
    >>> out.alarm, out.lower, out.upper                                # doctest: +SKIP
    """

    def __init__(
        self,
        sys: LinearSystem,
        method: str | Estimator = "reachability",
        x0: Box | None = None,
        *,
        tight: bool = True,
        margin: float = 1e-9,
        **options: Any,
    ):
        if not isinstance(sys, LinearSystem):
            raise IvobsError(f"sys: expected an ivobs.LinearSystem, got {type(sys).__name__}")
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
        self._split: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._dimg: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        # The estimator's own inconsistency reports become alarms (est.last_inconsistent), not
        # warnings.
        est.on_inconsistent = "ignore"
        self.reset()

    # -- online ---------------------------------------------------------------------------
    def reset(self) -> None:
        """Back to step 0."""
        self.estimator.reset()
        self._k = 0
        self._prev: dict[str, Any] | None = None  # box of x[k-1], u[k-1], y[k-1]
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
        y = self._check_y(y_k)
        probe = self._probe(u, t) if self.tight else None
        box = self.estimator.step(u if sys.nu else None, y, t)
        flagged = self.estimator.last_inconsistent
        return self._advance(u, y, t, box.lo, box.hi, probe, flagged)

    def _advance(
        self,
        u: np.ndarray,
        y: np.ndarray,
        t: float | None,
        lo: np.ndarray,
        hi: np.ndarray,
        probe: tuple[np.ndarray, np.ndarray] | None,
        flagged: bool,
    ) -> MonitorStep:
        """The consistency test of step ``k`` given the estimator's box and flag."""
        k = self._k
        reasons: list[str] = []
        pred = self._predict(k)
        if probe is not None:
            pred = (
                probe
                if pred is None
                else self._meet(pred, probe, reasons, "the estimator's prediction")
            )
        band_lo, band_hi = self._band(k, t, pred, u, y)
        out = (y < band_lo) | (y > band_hi)  # False where y is NaN (missing)
        for i in np.flatnonzero(out)[:3]:
            reasons.append(
                f"y{i + 1} = {y[i]:.6g} outside the predicted band "
                f"[{band_lo[i]:.6g}, {band_hi[i]:.6g}]"
            )
        if flagged:
            reasons.append(f"{self.method}: measurement inconsistent with the model and bounds")
        cur = None if np.isnan(lo).any() else (lo.copy(), hi.copy())
        if cur is not None and pred is not None:
            cur = self._meet(pred, cur, reasons, "estimate")
        elif cur is None:
            cur = pred
        alarm = bool(reasons)
        self.alarms += alarm
        self._prev = None if cur is None else {"lo": cur[0], "hi": cur[1], "u": u, "y": y}
        self._k = k + 1
        return MonitorStep(k, lo, hi, alarm, "; ".join(reasons), band_lo, band_hi)

    def run(self, u: Any = None, y: Any = None, *, t: Any = None) -> MonitorRecord:
        """:meth:`update` over a record, continuing from the current state (exactly what a
        stream of the same rows gives)."""
        u, y, tt = self._record(u, y, t)
        return _record(
            [self.update(u[k], y[k], None if tt is None else float(tt[k])) for k in range(len(y))],
            self.sys,
        )

    def check(
        self, u: Any = None, y: Any = None, *, t: Any = None, estimate: Estimate | None = None
    ) -> MonitorRecord:
        """The alarms of a whole record, offline and vectorised over time (long logs).

        Uses the estimator's ``run()`` (or ``estimate``, a result of that run already at hand)
        and, at every step, the band of the Lemma 1 prediction from the estimator's box of the
        step before (at step 0, the prior box). This band contains the online monitor's (which
        also intersects with its own previous prediction and, with ``tight=True``, with the
        estimator's prediction), so ``check`` may see fewer alarms than :meth:`update`; every
        alarm it raises carries the same guarantee. Leaves the online state alone.
        """
        u, y, tt = self._record(u, y, t)
        res = estimate
        if res is None:
            res = self.estimator.run(u, y, t=tt)
        elif res.lower.shape != (y.shape[0], self.sys.nx):
            raise IvobsError(
                f"estimate: expected bounds of shape {(y.shape[0], self.sys.nx)}, got "
                f"{res.lower.shape}"
            )
        sys, T = self.sys, y.shape[0]
        X_lo, X_hi = res.lower, res.upper
        known = ~np.isnan(X_lo).any(axis=1)
        P_lo, P_hi = np.full((T, sys.nx), -np.inf), np.full((T, sys.nx), np.inf)
        if self.x0 is not None:
            P_lo[0], P_hi[0] = self.x0.lo, self.x0.hi
        steps = np.arange(T)
        if T > 1 and sys.is_discrete:
            prev_lo = np.where(known[:-1, None], X_lo[:-1], -np.inf)
            prev_hi = np.where(known[:-1, None], X_hi[:-1], np.inf)
            a_lo, a_hi = self._images("A", steps[:-1], prev_lo, prev_hi)
            e_lo, e_hi = self._disturbance_images("E", steps[:-1], y[:-1])
            bu = self._products("B", steps[:-1], u[:-1])
            P_lo[1:], P_hi[1:] = a_lo + bu + e_lo, a_hi + bu + e_hi
        keys = tt if (sys.is_continuous and tt is not None) else steps
        c_lo, c_hi = self._images("C", keys, P_lo, P_hi)
        f_lo, f_hi = self._disturbance_images("F", steps, y)
        du = self._products("D", keys, u)
        b_lo, b_hi = c_lo + du + f_lo, c_hi + du + f_hi
        b_lo, b_hi = (
            b_lo - self.margin * (1 + np.abs(b_lo)),
            b_hi + self.margin * (1 + np.abs(b_hi)),
        )
        b_lo, b_hi = np.nan_to_num(b_lo, nan=-np.inf), np.nan_to_num(b_hi, nan=np.inf)
        out = (y < b_lo) | (y > b_hi)
        with np.errstate(invalid="ignore"):
            lo, hi = np.maximum(P_lo, X_lo), np.minimum(P_hi, X_hi)
            gap = lo - hi > self.margin * (1 + np.maximum(np.abs(lo), np.abs(hi)))
        disjoint = known & gap.any(axis=1)
        inconsistent = np.asarray(res.inconsistent, dtype=bool)
        alarm = out.any(axis=1) | disjoint | inconsistent
        reasons = [""] * T
        for k in np.flatnonzero(alarm):
            why = [
                f"y{i + 1} = {y[k, i]:.6g} outside the predicted band "
                f"[{b_lo[k, i]:.6g}, {b_hi[k, i]:.6g}]"
                for i in np.flatnonzero(out[k])[:3]
            ]
            if inconsistent[k]:
                why.append(f"{self.method}: measurement inconsistent with the model and bounds")
            if disjoint[k]:
                i = int(np.argmax(gap[k]))
                why.append(
                    f"estimate disjoint from the model's prediction in x{i + 1} "
                    f"([{X_lo[k, i]:.6g}, {X_hi[k, i]:.6g}] vs "
                    f"[{P_lo[k, i]:.6g}, {P_hi[k, i]:.6g}])"
                )
            reasons[int(k)] = "; ".join(why)
        return MonitorRecord(X_lo.copy(), X_hi.copy(), alarm, reasons, b_lo, b_hi)

    def _images(
        self, name: str, keys: np.ndarray, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Lemma 1 for ``A`` or ``C`` over rows of boxes (one matrix per row when the system is
        time-varying)."""
        get = self.sys.A_at if name == "A" else self.sys.C_at
        if not self.sys.is_time_varying:
            return image_bounds(get(0), lo, hi)
        pairs = [image_bounds(get(k), lo[i], hi[i]) for i, k in enumerate(keys)]
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    def _products(self, name: str, keys: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``B u`` or ``D u`` over rows."""
        get = self.sys.B_at if name == "B" else self.sys.D_at
        if not self.sys.is_time_varying:
            return u @ get(0).T
        return np.array([get(k) @ u[i] for i, k in enumerate(keys)])

    def _disturbance_images(
        self, name: str, steps: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``E[d[k]]`` or ``F[d[k]]`` over the steps (bounds from ``y[k]`` when callable)."""
        sys = self.sys
        get = sys.E_at if name == "E" else sys.F_at
        n = sys.nx if name == "E" else sys.ny
        if sys.is_time_varying or callable(sys.d):
            pairs = [image_bounds(get(k), *_bounds(sys.d_at(k, y[i]))) for i, k in enumerate(steps)]
            return (
                np.array([p[0] for p in pairs]).reshape(-1, n),
                np.array([p[1] for p in pairs]).reshape(-1, n),
            )
        d = sys.d_at(0) if sys.has_constant_bounds else sys.d
        assert isinstance(d, Box)
        if d.is_time_varying:
            if steps.size:
                d.at(int(steps[-1]))  # raises when the record is longer than the bounds
            return image_bounds(get(0), d.lo[steps], d.hi[steps])
        lo, hi = image_bounds(get(0), d.lo, d.hi)
        return np.broadcast_to(lo, (steps.size, n)), np.broadcast_to(hi, (steps.size, n))

    def _record(self, u: Any, y: Any, t: Any) -> tuple[np.ndarray, np.ndarray, Any]:
        y = as_signal("y", y, self.sys.ny, allow_nan=True, allow_batch=False)
        u = as_signal("u", u, self.sys.nu, y.shape[0], allow_batch=False)
        tt = None if t is None else as_float_array("t", t).ravel()
        if self.sys.is_continuous and tt is None:
            raise IvobsError("t: a continuous-time system needs the sample times t (T,)")
        return u, y, tt

    # -- the consistency test ------------------------------------------------------------
    def _check_y(self, y_k: Any) -> np.ndarray:
        if y_k is None:
            return np.full(self.sys.ny, np.nan)
        y = as_float_array("y_k", y_k).ravel().copy()
        if y.shape[0] != self.sys.ny:
            raise IvobsError(f"y_k: expected {self.sys.ny} measurement value(s), got {y.shape[0]}")
        if np.any(np.isinf(y)):
            raise IvobsError("y_k: infinite measurement; use NaN for a missing sample")
        return y

    def _predict(self, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        """``A[X_{k-1}] + B u[k-1] + E[d[k-1]]`` (Lemma 1), or the prior box at ``k = 0``."""
        if k == 0:
            return None if self.x0 is None else (self.x0.lo.copy(), self.x0.hi.copy())
        if self._prev is None or self.sys.is_continuous:
            return None
        p = self._prev
        lo, hi = self._image("A", k - 1, p["lo"], p["hi"])
        e_lo, e_hi = self._disturbance_image("E", k - 1, p["y"])
        bu = self.sys.B_at(k - 1) @ p["u"]
        return lo + bu + e_lo, hi + bu + e_hi

    def _image(
        self, name: str, k: Any, lo: np.ndarray, hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Lemma 1 for ``M = A`` or ``C`` at step ``k`` (``M⁺``, ``M⁻`` cached when constant)."""
        if name in self._split:
            Mp, Mn = self._split[name]
        else:
            M = self.sys.A_at(k) if name == "A" else self.sys.C_at(k)
            Mp, Mn = pos(M), neg(M)
            if not self.sys.is_time_varying:
                self._split[name] = (Mp, Mn)
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return image_bounds(Mp - Mn, lo, hi)
        return Mp @ lo - Mn @ hi, Mp @ hi - Mn @ lo

    def _disturbance_image(self, name: str, k: Any, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``E[d[k]]`` or ``F[d[k]]`` (cached for constant matrices and bounds)."""
        if name in self._dimg:
            return self._dimg[name]
        M = self.sys.E_at(k) if name == "E" else self.sys.F_at(k)
        d = self.sys.d_at(k, y)
        out = image_bounds(M, d.lo, d.hi)
        if not self.sys.is_time_varying and self.sys.has_constant_bounds:
            self._dimg[name] = out
        return out

    def _probe(self, u: np.ndarray, t: float | None) -> tuple[np.ndarray, np.ndarray] | None:
        """The estimator's own box of ``x[k]`` without ``y[k]`` (:meth:`Estimator.predict`)."""
        try:
            box = self.estimator.predict(u if self.sys.nu else None, t)
        except IvobsError as exc:
            if "cannot be copied" in str(exc):  # e.g. a live LP solver: Lemma 1 only from now
                self.tight = False
            return None  # also bounds computed from y[k] (003 Remark 1): no prediction
        return None if box.is_unknown else (box.lo, box.hi)

    def _meet(
        self,
        a: tuple[np.ndarray, np.ndarray],
        b: tuple[np.ndarray, np.ndarray],
        reasons: list[str],
        what: str,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``a ∩ b``; when they do not meet (beyond rounding), an alarm and ``b``."""
        lo, hi = np.maximum(a[0], b[0]), np.minimum(a[1], b[1])
        bad = lo - hi > self.margin * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
        if bad.any():
            i = int(np.argmax(bad))
            reasons.append(
                f"{what} disjoint from the model's prediction in x{i + 1} "
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
        """``C[P_k] + D u[k] + F[d[k]]``, widened by the rounding margin."""
        ny = self.sys.ny
        if pred is None:
            return np.full(ny, -np.inf), np.full(ny, np.inf)
        key = t if self.sys.is_continuous else k
        lo, hi = self._image("C", key, pred[0], pred[1])
        f_lo, f_hi = self._disturbance_image("F", k, y)
        du = self.sys.D_at(key) @ u
        lo, hi = lo + du + f_lo, hi + du + f_hi
        return lo - self.margin * (1.0 + np.abs(lo)), hi + self.margin * (1.0 + np.abs(hi))

    # -- persistence ---------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The monitor's state (estimator state, previous box, counters): JSON-serialisable."""
        prev = None
        if self._prev is not None:
            prev = {key: _encode(val) for key, val in self._prev.items()}
        return {
            "version": STATE_VERSION,
            "method": self.method,
            "k": self._k,
            "alarms": self.alarms,
            "prev": prev,
            "estimator": self.estimator.state(),
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from :meth:`state` (same system, method and design)."""
        if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
            raise IvobsError("state: expected the dict returned by Monitor.state()")
        try:
            self.estimator.restore(state["estimator"])
            prev = state["prev"]
            self._prev = None if prev is None else {k: _decode(v) for k, v in prev.items()}
            self._k = int(state["k"])
            self.alarms = int(state["alarms"])
        except (KeyError, TypeError, ValueError) as exc:
            if isinstance(exc, IvobsError):
                raise
            raise IvobsError(f"state: malformed monitor state ({exc!r})") from None
        if self.estimator.k != self._k:
            raise IvobsError(
                f"state: the estimator is at step {self.estimator.k}, the monitor at {self._k}"
            )

    def __repr__(self) -> str:
        return f"<Monitor {self.method!r} k={self._k} alarms={self.alarms}>"


def _bounds(box: Box) -> tuple[np.ndarray, np.ndarray]:
    return box.lo, box.hi


def _record(steps: list[MonitorStep], sys: LinearSystem) -> MonitorRecord:
    T = len(steps)
    return MonitorRecord(
        lower=np.array([s.lower for s in steps]).reshape(T, sys.nx),
        upper=np.array([s.upper for s in steps]).reshape(T, sys.nx),
        alarm=np.array([s.alarm for s in steps], dtype=bool),
        reasons=[s.reason for s in steps],
        band_lower=np.array([s.band_lower for s in steps]).reshape(T, sys.ny),
        band_upper=np.array([s.band_upper for s in steps]).reshape(T, sys.ny),
    )


def _vector(name: str, v: Any, n: int) -> np.ndarray:
    if isinstance(v, np.ndarray) and v.shape == (n,) and v.dtype == float:
        if not np.all(np.isfinite(v)):
            raise IvobsError(f"{name}: expected finite numbers, got {v}")
        return v.copy()
    return as_vector(name, v, n)


def _encode(v: np.ndarray) -> list[Any]:
    """Arrays as lists, with non-finite values spelled out (strict JSON has no NaN/inf)."""
    return [x if np.isfinite(x) else str(x) for x in np.asarray(v, dtype=float).tolist()]


def _decode(v: list[Any]) -> np.ndarray:
    return np.array([float(x) for x in v], dtype=float)
