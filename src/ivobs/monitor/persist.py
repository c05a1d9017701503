"""The monitor's state (:meth:`Monitor.state <ivobs.monitor.Monitor.state>` /
:meth:`~ivobs.monitor.Monitor.restore`): JSON-serialisable, with the fingerprint of what it
belongs to.

A state holds the estimator's saved state, the box of the previous step, the counters, the
open fault, its bias estimate (:mod:`ivobs.monitor.bias`) and isolation, and the recent data
with the monitor's state at the anchors an isolation starts from (:mod:`ivobs.monitor.isolate`;
a state without them, written before isolation, continues with an empty history). It continues
only the monitor that wrote it: the estimator's state carries the fingerprint of its design
(method and gains), and the monitor's the fingerprint of the model (matrices, disturbance
bounds, prior box) and of its settings (:mod:`ivobs.io.fingerprint`).
Two plants with the same gains but other bounds or another prior give other boxes: a state of
one is refused by the other, naming what differs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import IvobsError
from ..io.fingerprint import PARTS, model_fingerprint
from ._codec import _decode, _encode_prev
from .bias import BiasEstimate
from .isolate import DEFAULT_WINDOW, Isolation

if TYPE_CHECKING:
    from .online import Monitor

__all__ = ["STATE_VERSION", "monitor_state", "restore_monitor"]

STATE_VERSION = 2
"""Version of the monitor's state: 2 adds the model's fingerprint (version 1 had none, so a
state of another plant with the same gains was taken)."""

MAX_STEPS = 2**53
"""Largest step count a state may hold (the estimators' bound)."""


def fingerprint(mon: Monitor) -> dict[str, str]:
    """The fingerprint of ``mon``'s model, prior box and settings."""
    settings: dict[str, Any] = {
        "tight": mon.tight,
        "margin": mon.margin,
        "clear_after": mon.latch.clear_after,
    }
    if mon.window != DEFAULT_WINDOW:  # named only when set: the states of before still match
        settings["window"] = mon.window
    return model_fingerprint(mon.sys, mon.x0, settings)


def monitor_state(mon: Monitor) -> dict[str, Any]:
    """The state of ``mon`` as a JSON-serialisable dict."""
    trial = mon._trial
    return {
        "version": STATE_VERSION,
        "method": mon.method,
        "model": fingerprint(mon),
        "k": mon._k,
        "alarms": mon.alarms,
        "prev": _encode_prev(mon._prev),
        "fault": mon.latch.state(),
        "trial": None
        if trial is None
        else {
            "estimator": mon.estimator.save_state(trial[0]),
            "prev": _encode_prev(trial[1]),
        },
        "estimator": mon.estimator.save_state(mon._est),
        "bias": None if mon._bias is None else mon._bias.save(),
        "isolation": None if mon._isolation is None else mon._isolation.save(),
        "history": mon._history.save(mon.estimator.save_state),
    }


def check_model(mon: Monitor, saved: Any) -> None:
    """Refuse a state written for another model, prior box or settings, naming what differs."""
    if not isinstance(saved, dict):
        raise IvobsError("state: model: expected the fingerprint of the monitor's model")
    ours = fingerprint(mon)
    for part, what in PARTS.items():
        if saved.get(part) != ours[part]:
            raise IvobsError(
                f"state: written for another model: {what} differ from this monitor's. A state "
                "continues only the monitor that wrote it (same system file, prior box and "
                "settings); start afresh for this one"
            )


def _prev(saved: Any, mon: Monitor, key: str) -> dict[str, np.ndarray] | None:
    """A saved box of the previous step (``lo``, ``hi``, ``u``, ``y``), checked."""
    if saved is None:
        return None
    sys = mon.sys
    sizes = {"lo": sys.nx, "hi": sys.nx, "u": sys.nu, "y": sys.ny}
    if not isinstance(saved, dict) or set(saved) != set(sizes):
        raise IvobsError(f"state: {key}: expected the entries lo, hi, u, y")
    out = {}
    for name, n in sizes.items():
        v = saved[name]
        if not isinstance(v, list) or len(v) != n:
            raise IvobsError(f"state: {key}.{name}: expected {n} numbers")
        out[name] = _decode(v)
    if np.isnan(out["lo"]).any() or np.isnan(out["hi"]).any() or np.any(out["lo"] > out["hi"]):
        raise IvobsError(f"state: {key}: expected a box with lo <= hi (no NaN)")
    if not np.all(np.isfinite(out["u"])):
        raise IvobsError(f"state: {key}.u: expected finite inputs")
    return out


def _count(state: dict[str, Any], key: str, most: int) -> int:
    v = state.get(key)
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= most:
        raise IvobsError(f"state: {key}: expected an integer in 0..{most}, got {v!r}"[:200])
    return v


def restore_monitor(mon: Monitor, state: Any) -> None:
    """Continue ``mon`` from a state of :func:`monitor_state` (same model, prior, settings,
    method and design), every entry checked."""
    if not isinstance(state, dict) or state.get("version") != STATE_VERSION:
        if isinstance(state, dict) and state.get("version") == 1:
            raise IvobsError(
                "state: saved by an older ivobs (monitor state version 1), without the "
                "fingerprint of its model: it cannot be checked against this monitor; start "
                "afresh"
            )
        raise IvobsError("state: expected the dict returned by Monitor.state()")
    check_model(mon, state.get("model"))
    k = _count(state, "k", MAX_STEPS)
    alarms = _count(state, "alarms", k)
    try:
        est = mon.estimator.check_state(state.get("estimator"))
        prev = _prev(state.get("prev"), mon, "prev")
        trial = state.get("trial")
        if trial is not None:
            if not isinstance(trial, dict):
                raise IvobsError("state: trial: expected a table or null")
            trial = (
                mon.estimator.check_state(trial.get("estimator")),
                _prev(trial.get("prev"), mon, "trial.prev"),
            )
    except (KeyError, TypeError, ValueError, RecursionError) as exc:
        if isinstance(exc, IvobsError):
            raise
        raise IvobsError(f"state: malformed monitor state ({type(exc).__name__})") from None
    if est.k != k:
        raise IvobsError(f"state: the estimator is at step {est.k}, the monitor at {k}")
    mon.latch.restore(state.get("fault"), mon.sys.ny, k)
    if trial is not None and (mon.latch.start is None or trial[0].k != k):
        raise IvobsError("state: trial: a trial estimate needs an open fault at the same step")
    bias = BiasEstimate.restore(mon.sys, state.get("bias"), k)
    if bias is not None and (mon.latch.start is None or bias.state.k != k - bias.start):
        raise IvobsError("state: bias: a bias estimate needs an open fault, up to the same step")
    isolation = Isolation.restore(state.get("isolation"), mon.sys.ny, k)
    if isolation is not None and mon.latch.start is None:
        raise IvobsError("state: isolation: an isolation needs an open fault")
    mon._history.restore(
        state.get("history"),
        mon.estimator.check_state,
        lambda p: _prev(p, mon, "history.prev"),
        mon.sys,
        k,
    )
    mon._est, mon._prev, mon._k, mon.alarms = est, prev, k, alarms
    mon._trial, mon._bias, mon._isolation = trial, bias, isolation
