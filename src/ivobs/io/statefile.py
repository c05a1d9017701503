"""Monitor state files (``ivobs monitor --state FILE``): JSON, written atomically, checked
entry by entry when read back, locked while a monitor uses them.

A state file holds the monitor's state (:meth:`ivobs.monitor.Monitor.state`, with the
fingerprint of its model) and where the stream stopped (its first step, the rows consumed, the
last step and time, the columns, digests of the rows), under a checksum: a file edited by hand
is refused, and so is a malformed one, naming the key. While a monitor runs it holds an
exclusive lock on ``FILE.lock`` (``fcntl.flock``). What is checked and why: docs/operating.md,
"One monitor per state file" and "A state belongs to one model and one stream".
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import json
import os
import socket
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..errors import IvobsError
from ..model.protocol import SystemModel
from .atomic import write_text_atomic
from .fingerprint import canonical_json

__all__ = [
    "STATE_FORMAT",
    "STATE_VERSION",
    "StateLock",
    "check_monitor_state",
    "check_stream",
    "lock_path",
    "read_state_file",
    "write_state_file",
]

STATE_FORMAT = "ivobs-monitor-state"
STATE_VERSION = 2
"""2: the stream's first step, columns and row digests, and a checksum of the whole file."""

MAX_STATE_BYTES = 1 << 30
"""Largest state file read (the largest methods' states are a few megabytes)."""


class _StateChecker(Protocol):
    def check_state(self, state: Any) -> Any: ...


def _checksum(data: dict[str, Any]) -> str:
    payload = {k: data.get(k) for k in ("format", "version", "method", "monitor", "stream")}
    return hashlib.sha256(canonical_json(payload).encode()).hexdigest()


def read_state_file(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The JSON of a state file, refused unless it is an intact ivobs monitor state of this
    version (its checksum matches)."""
    name = str(path)
    try:
        if Path(path).stat().st_size > MAX_STATE_BYTES:
            raise IvobsError(f"--state: {name!r} is larger than {MAX_STATE_BYTES} bytes")
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:  # ValueError: not UTF-8 or not JSON
        if isinstance(exc, IvobsError):
            raise
        why = exc.strerror if isinstance(exc, OSError) else f"not JSON ({type(exc).__name__})"
        raise IvobsError(f"--state: cannot read {name!r}: {why}") from None
    except RecursionError:
        raise IvobsError(f"--state: {name!r} is not a monitor state (nested too deeply)") from None
    if not isinstance(data, dict) or data.get("format") != STATE_FORMAT:
        raise IvobsError(f"--state: {name!r} is not an ivobs monitor state")
    if data.get("version") != STATE_VERSION:
        raise IvobsError(
            f"--state: {name!r} was written by another ivobs version (state file version "
            f"{data.get('version', 1)!r}; this one writes {STATE_VERSION}): it cannot be checked "
            "against this monitor; delete it to start afresh"
        )
    if data.get("checksum") != _checksum(data):
        raise malformed(name, "checksum", "does not match the content")
    return data


def write_state_file(
    path: str | os.PathLike[str], method: str, monitor: dict[str, Any], stream: dict[str, Any]
) -> None:
    """Write a state file atomically: a crash never leaves half a state behind."""
    data: dict[str, Any] = {
        "format": STATE_FORMAT,
        "version": STATE_VERSION,
        "method": method,
        "monitor": monitor,
        "stream": stream,
    }
    data = json.loads(json.dumps(data))  # the values as read back: what the checksum covers
    data["checksum"] = _checksum(data)
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
    if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v <= 2**53:
        raise malformed(name, key, f"expected an integer in 0..2**53, got {v!r}"[:200])
    return v


def check_monitor_state(
    data: dict[str, Any], sys: SystemModel, estimator: _StateChecker, name: str, start: int
) -> None:
    """Check the entries of a state file read by :func:`read_state_file` for a monitor of the
    system ``sys`` running ``estimator`` on a stream that starts at step ``start`` (the prior
    box's); ``name`` is the file's name in the errors."""
    m = data.get("monitor")
    if not isinstance(m, dict):
        raise malformed(name, "monitor", f"expected a table, got {m!r}"[:200])
    k = _count(name, "monitor.k", m.get("k"))
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
    check_stream(data.get("stream"), k, name, start)


def check_stream(stream: Any, k: int, name: str, start: int) -> None:
    """The ``stream`` entry of a state file ``name``: where the stream stopped, consistent with
    the ``k`` steps of the restored monitor from ``start``, the prior box's step (the monitor's
    own entries are checked by :meth:`Monitor.restore <ivobs.monitor.Monitor.restore>`)."""
    keys = {"start", "rows", "step", "t", "columns", "digest", "last"}
    if not isinstance(stream, dict) or set(stream) != keys:
        raise malformed(name, "stream", f"expected the entries {', '.join(sorted(keys))}")
    if _count(name, "stream.start", stream["start"]) != start:
        raise IvobsError(
            f"--state: {name!r}: the stream of this state starts at step {stream['start']}, "
            f"the system file's prior box is at step {start} ([x0] step): another system file "
            "or another stream; delete the state to start afresh"
        )
    if _count(name, "stream.rows", stream["rows"]) > k:
        raise malformed(name, "stream.rows", f"{stream['rows']} rows for {k} steps")
    step = stream["step"]  # None: no step column, or no row yet
    if step is not None and _count(name, "stream.step", step) != start + k - 1:
        raise malformed(
            name, "stream.step", f"{step}, but {k} steps from step {start} end at {start + k - 1}"
        )
    t = stream["t"]
    if t is not None and (
        isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t)
    ):
        raise malformed(name, "stream.t", f"expected a finite number, got {t!r}"[:200])
    cols = stream["columns"]
    if not isinstance(cols, list) or not all(isinstance(c, str) for c in cols):
        raise malformed(name, "stream.columns", "expected the list of the log's columns")
    for key in ("digest", "last"):
        if stream[key] is not None and not isinstance(stream[key], str):
            raise malformed(name, f"stream.{key}", "expected a digest (text)")


def _check_prev(prev: Any, sys: SystemModel, name: str) -> None:
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


# -- the lock ----------------------------------------------------------------------------
def lock_path(path: str | os.PathLike[str]) -> Path:
    """The lock file of the state file ``path``: ``path`` with ``.lock`` appended."""
    p = Path(path)
    return p.with_name(p.name + ".lock")


class StateLock:
    """An exclusive lock on a state file, held while a monitor runs (``with StateLock(path):``);
    a second monitor is refused, naming the process that holds it. The lock file is removed
    when the lock is released (a killed monitor leaves it behind, unlocked: harmless)."""

    def __init__(self, path: str | os.PathLike[str]):
        self.state = Path(path)
        self.path = lock_path(path)
        self.fh: Any = None

    def __enter__(self) -> StateLock:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - Windows: no lock (docs/operating.md)
            return self
        while self.fh is None:
            try:
                fh = open(self.path, "a+", encoding="utf-8")
            except OSError as exc:
                raise IvobsError(
                    f"--state: cannot create the lock file {str(self.path)!r}: {exc.strerror}"
                ) from None
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError:  # held by another process
                fh.seek(0)
                holder = _holder(fh.read(1000))
                fh.close()
                raise IvobsError(
                    f"--state: {str(self.state)!r} is in use by another monitor ({holder}); "
                    "two monitors on one state file would overwrite each other's state: stop "
                    "that one, or give this one another state file"
                ) from None
            if _same_inode(fh, self.path):
                self.fh = fh
            else:  # the holder removed it as we opened it: lock the file now at that path
                fh.close()
        with contextlib.suppress(OSError):  # who holds it, for the error of the next one
            self.fh.seek(0)
            self.fh.truncate()
            since = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
            info = {"pid": os.getpid(), "host": socket.gethostname(), "since": since}
            self.fh.write(json.dumps(info))
            self.fh.flush()
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.fh is not None:
            with contextlib.suppress(OSError):
                os.unlink(self.path)  # removed while still held: see _same_inode
            self.fh.close()  # releases the lock
            self.fh = None


def _same_inode(fh: Any, path: Path) -> bool:
    """Whether the open file ``fh`` is still the file at ``path`` (a lock taken on a file that
    its holder removed meanwhile locks nothing anyone else sees)."""
    try:
        return os.path.samestat(os.fstat(fh.fileno()), os.stat(path))
    except OSError:
        return False


def _holder(text: str) -> str:
    """``pid N on HOST since T`` from a lock file's content."""
    try:
        info = json.loads(text)
        return f"process {int(info['pid'])} on {str(info['host'])[:100]} since {info['since']}"
    except (ValueError, TypeError, KeyError):
        return "a process that is starting"
