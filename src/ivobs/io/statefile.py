"""Monitor state files (``ivobs monitor --state FILE``): JSON, written atomically, checked
entry by entry when read back.

A state file holds the monitor's state (:meth:`ivobs.monitor.Monitor.state`: its counters, the
previous box and the estimator's saved state) and where the stream stopped (rows consumed, the
last step and time), so that a restarted monitor continues with the same boxes. Reading one
checks what ``Monitor.restore`` takes on trust (lengths, NaN, ``lo <= hi``, types) and the
estimator's entries (:meth:`ivobs.Estimator.check_state`); a malformed file is refused with the
key that is wrong.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..errors import IvobsError
from .atomic import write_text_atomic

__all__ = ["STATE_FORMAT", "check_monitor_state", "read_state_file", "write_state_file"]

STATE_FORMAT = "ivobs-monitor-state"


class _Dims(Protocol):
    @property
    def nx(self) -> int: ...
    @property
    def nu(self) -> int: ...
    @property
    def ny(self) -> int: ...


class _StateChecker(Protocol):
    def check_state(self, state: Any) -> Any: ...


def read_state_file(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The JSON of a state file, refused unless it is an ivobs monitor state."""
    name = str(path)
    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise IvobsError(f"--state: cannot read {name!r}: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != STATE_FORMAT:
        raise IvobsError(f"--state: {name!r} is not an ivobs monitor state")
    return data


def write_state_file(
    path: str | os.PathLike[str], method: str, monitor: dict[str, Any], stream: dict[str, Any]
) -> None:
    """Write a state file atomically: a crash never leaves half a state behind."""
    data = {"format": STATE_FORMAT, "method": method, "monitor": monitor, "stream": stream}
    write_text_atomic(path, json.dumps(data))


def malformed(name: str, key: str, msg: str) -> IvobsError:
    """The error of a state file whose entry ``key`` is wrong."""
    return IvobsError(
        f"--state: {name!r} is a malformed monitor state: {key}: {msg} (the file was altered "
        "or is not from `ivobs monitor --state`; delete it to start afresh)"
    )


def _numbers(name: str, key: str, v: Any, n: int, nan: bool = True) -> np.ndarray:
    """A saved vector of ``n`` numbers (non-finite ones spelled as strings, as saved)."""
    if not isinstance(v, list) or len(v) != n:
        got = f"{len(v)} values" if isinstance(v, list) else repr(v)[:40]
        raise malformed(name, key, f"expected a list of {n} numbers, got {got}")
    try:
        arr = np.array([float(x) for x in v], dtype=float)
    except (TypeError, ValueError):
        raise malformed(name, key, f"expected numbers, got {v!r}"[:200]) from None
    if not nan and np.isnan(arr).any():
        raise malformed(name, key, f"NaN at component {int(np.flatnonzero(np.isnan(arr))[0])}")
    return arr


def _count(name: str, key: str, v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise malformed(name, key, f"expected an integer >= 0, got {v!r}")
    return v


def check_monitor_state(
    data: dict[str, Any], sys: _Dims, estimator: _StateChecker, name: str
) -> None:
    """Check the entries of a state file read by :func:`read_state_file` for a monitor of the
    system ``sys`` running ``estimator``; ``name`` is the file's name in the errors."""
    m = data.get("monitor")
    if not isinstance(m, dict):
        raise malformed(name, "monitor", f"expected a table, got {m!r}"[:200])
    _count(name, "monitor.k", m.get("k"))
    _count(name, "monitor.alarms", m.get("alarms"))
    _check_prev(m.get("prev"), sys, name)
    est = m.get("estimator")
    if not isinstance(est, dict) or not isinstance(est.get("state"), dict):
        got = est.get("state") if isinstance(est, dict) else est
        raise malformed(name, "monitor.estimator.state", f"expected a table, got {got!r}"[:200])
    try:
        estimator.check_state(est)
    except IvobsError as exc:
        raise malformed(name, "monitor.estimator.state", str(exc)) from None
    stream = data.get("stream", {})
    if not isinstance(stream, dict):
        raise malformed(name, "stream", f"expected a table, got {stream!r}"[:200])
    _count(name, "stream.rows", stream.get("rows", 0))
    if stream.get("step") is not None:
        _count(name, "stream.step", stream["step"])
    t = stream.get("t")
    if t is not None and (
        isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t)
    ):
        raise malformed(name, "stream.t", f"expected a finite number, got {t!r}")


def _check_prev(prev: Any, sys: _Dims, name: str) -> None:
    """The monitor's box of the previous step, with its input and measurement."""
    if prev is None:
        return
    if not isinstance(prev, dict) or set(prev) != {"lo", "hi", "u", "y"}:
        raise malformed(name, "monitor.prev", "expected the keys lo, hi, u, y")
    lo = _numbers(name, "monitor.prev.lo", prev["lo"], sys.nx, nan=False)
    hi = _numbers(name, "monitor.prev.hi", prev["hi"], sys.nx, nan=False)
    bad = np.flatnonzero(lo > hi)
    if bad.size:
        i = int(bad[0])
        raise malformed(name, "monitor.prev", f"lo > hi at component {i}: {lo[i]} > {hi[i]}")
    _numbers(name, "monitor.prev.u", prev["u"], sys.nu, nan=False)
    _numbers(name, "monitor.prev.y", prev["y"], sys.ny)
