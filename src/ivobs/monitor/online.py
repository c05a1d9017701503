"""The online monitor: a guaranteed estimator and a consistency test at every step (the
method is described in :mod:`ivobs.monitor`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_float_array, as_signal, as_vector
from ..errors import IvobsError
from ..estimators import Estimator, make_estimator
from ..io.systemwrite import equal_systems
from ..model import LinearSystem
from ..result import Estimate
from ..sets import Box, image_bounds, neg, pos
from .offline import check_record
from .records import MonitorRecord, MonitorStep, stack_steps

__all__ = ["Monitor"]

STATE_VERSION = 1


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
        return check_record(self.sys, self.x0, self.margin, self.method, u, y, tt, res)

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
        """``A[X_{k-1}] + B u[k-1] + E[d[k-1]]`` ([Efimov2013, Lemma 1]), or the prior box at
        ``k = 0``."""
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
        """[Efimov2013, Lemma 1] for ``M = A`` or ``C`` at step ``k`` (``M⁺``, ``M⁻`` cached
        when constant)."""
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
            return None  # also bounds computed from y[k] ([Efimov2013, Remark 1]): no prediction
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
