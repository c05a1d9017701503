"""Measurement logs (CSV): an optional step (``k`` / ``step``) or time (``t`` / ``time``)
column, the inputs ``u1, u2, ...`` and the measurements ``y1, y2, ...``.

An empty cell or ``NaN`` in a ``y`` column is a missing sample. :func:`read_log` reads a log,
:class:`LogParser` parses rows one at a time (the streaming monitor), :func:`write_log` writes
one (atomically).
"""

from __future__ import annotations

import csv
import math
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import SystemModel
from .atomic import write_text_atomic

__all__ = ["Log", "LogParser", "LogRow", "log_from_frame", "not_utf8", "read_log", "write_log"]

_STEP_COLS = ("k", "step")
_TIME_COLS = ("t", "time")
_SIGNAL = re.compile(r"^(?P<kind>[uy])(?:\d+|[_\[(.].*)?$", re.IGNORECASE)
_NUMBERED = re.compile(r"^[uy](?:(\d+)|_(\d+)|\[(\d+)\]|\((\d+)\)|\.(\d+))$", re.IGNORECASE)


def _signal_number(column: str) -> int | None:
    """The number of a signal column (``y2``, ``y_2``, ``y[2]``, ``y(2)``), else None."""
    m = _NUMBERED.match(column)
    return None if m is None else int(next(g for g in m.groups() if g is not None))


@dataclass
class LogRow:
    """One parsed row: the step and/or time value when the log has them, ``u`` and ``y``."""

    line: int
    u: np.ndarray
    y: np.ndarray
    step: int | None = None
    t: float | None = None


class LogParser:
    """Parse a log row by row (used by :func:`read_log` and the streaming monitor).

    Call :meth:`header` with the first non-comment line, then :meth:`row` with each further
    line. Errors name the source, the line and the column.
    """

    def __init__(self, nu: int, ny: int, source: str = "<log>"):
        self.nu, self.ny, self.source = nu, ny, source
        self.columns: list[str] = []
        self._step: int | None = None
        self._time: int | None = None
        self._u: list[int] = []
        self._y: list[int] = []
        self._last: LogRow | None = None

    @property
    def has_step(self) -> bool:
        return self._step is not None

    @property
    def has_time(self) -> bool:
        return self._time is not None

    def fail(self, line: int, msg: str) -> IvobsError:
        return IvobsError(f"{self.source}, line {line}: {msg}")

    @staticmethod
    def _cells(text: str) -> list[str]:
        return next(csv.reader([text]))

    def header(self, text: str, line: int = 1) -> None:
        """Read the header: signal columns numbered ``u1, u2, ...`` (also ``y[2]``, ``y_2``)
        are mapped by their number, whatever their order; unnumbered ones (``u_speed``) are
        taken in header order. A UTF-8 byte-order mark (Excel) is ignored."""
        cols = [c.strip() for c in self._cells(text.lstrip("\ufeff"))]
        self.columns = cols
        seen: set[str] = set()
        for i, c in enumerate(cols):
            low = c.lower()
            if low in seen:
                raise self.fail(line, f"duplicate column {c!r}")
            seen.add(low)
            m = _SIGNAL.match(c)
            if low in _STEP_COLS:
                if self._step is not None:
                    raise self.fail(line, "two step columns (k, step): keep one")
                self._step = i
            elif low in _TIME_COLS:
                if self._time is not None:
                    raise self.fail(line, "two time columns (t, time): keep one")
                self._time = i
            elif m:
                (self._u if m.group("kind").lower() == "u" else self._y).append(i)
            else:
                raise self.fail(
                    line,
                    f"unexpected column {c!r}: a log has an optional step "
                    "(k or step) or time (t or time) column, input columns u1, u2, "
                    "... and measurement columns y1, y2, ...",
                )
        for kind, idx, n in (("u", self._u, self.nu), ("y", self._y, self.ny)):
            if len(idx) != n:
                names = [cols[i] for i in idx]
                what = "inputs" if kind == "u" else "measurements"
                raise self.fail(
                    line,
                    f"the system has {n} {what}, so the log needs {n} "
                    f"{kind}-columns ({kind}1, ...); found {len(idx)}: {names}",
                )
            self._by_number(kind, idx, line)

    def _by_number(self, kind: str, idx: list[int], line: int) -> None:
        """Order the ``kind`` columns ``idx`` (in place) by their number when all have one."""
        nums = [_signal_number(self.columns[i]) for i in idx]
        if not idx or any(n is None for n in nums):
            return
        n = len(idx)
        for base in (1, 0):
            if sorted(nums) == list(range(base, base + n)):  # type: ignore[type-var]
                idx[:] = [i for _, i in sorted(zip(nums, idx))]
                return
        names = ", ".join(self.columns[i] for i in idx)
        raise self.fail(
            line,
            f"{kind}-columns {names}: expected the numbers {kind}1..{kind}{n} (each once; "
            "columns are matched by their number)",
        )

    def row(self, text: str, line: int) -> LogRow:
        if not self.columns:
            raise self.fail(line, "no header line before the data")
        cells = self._cells(text)
        if len(cells) != len(self.columns):
            raise self.fail(
                line,
                f"expected {len(self.columns)} fields ({','.join(self.columns)}), got {len(cells)}",
            )
        vals = np.empty(len(cells))
        for i, cell in enumerate(cells):
            s = cell.strip()
            if s == "" or s.lower() == "nan":
                vals[i] = np.nan
                continue
            try:
                if "_" in s:  # float() accepts 1_000; a CSV number does not
                    raise ValueError(s)
                vals[i] = float(s)
            except ValueError:
                raise self.fail(
                    line, f"column {self.columns[i]!r}: expected a number, got {s!r}"
                ) from None
            if not math.isfinite(vals[i]):
                raise self.fail(
                    line,
                    f"column {self.columns[i]!r}: infinite value {s!r} (use "
                    "an empty cell or NaN for a missing measurement)",
                )
        for i in [
            *self._u,
            *([] if self._step is None else [self._step]),
            *([] if self._time is None else [self._time]),
        ]:
            if np.isnan(vals[i]):
                what = "inputs must be known at every step" if i in self._u else "required"
                raise self.fail(line, f"column {self.columns[i]!r} is missing ({what})")
        out = LogRow(line=line, u=vals[self._u], y=vals[self._y])
        if self._step is not None:
            v = vals[self._step]
            if v != int(v):
                raise self.fail(
                    line, f"column {self.columns[self._step]!r}: expected an integer step, got {v}"
                )
            out.step = int(v)
            if (
                self._last is not None
                and self._last.step is not None
                and out.step <= self._last.step
            ):
                raise self.fail(
                    line,
                    f"step {out.step} does not increase (previous "
                    f"{self._last.step}, line {self._last.line})",
                )
        if self._time is not None:
            out.t = float(vals[self._time])
            if self._last is not None and self._last.t is not None and out.t <= self._last.t:
                raise self.fail(
                    line,
                    f"time {out.t} does not increase (previous "
                    f"{self._last.t}, line {self._last.line})",
                )
        self._last = out
        return out


def not_utf8(source: str, exc: UnicodeDecodeError) -> IvobsError:
    """The error for a log that is not UTF-8 text."""
    return IvobsError(
        f"{source}: not valid UTF-8 ({exc.reason}, byte "
        f"{exc.object[exc.start : exc.start + 1]!r}); a log must be UTF-8 text (CSV)"
    )


def _is_skipped(text: str) -> bool:
    s = text.strip()
    return not s or s.startswith("#")


@dataclass
class Log:
    """A measurement record: ``u`` ``(T, nu)``, ``y`` ``(T, ny)`` (NaN = missing), the step and
    time columns when present."""

    u: np.ndarray
    y: np.ndarray
    t: np.ndarray | None = None
    steps: np.ndarray | None = None
    columns: list[str] = field(default_factory=list)

    @property
    def T(self) -> int:
        return int(self.y.shape[0])

    @property
    def missing(self) -> np.ndarray:
        """``(T,)`` bool: rows with at least one missing measurement."""
        rows: np.ndarray = np.any(np.isnan(self.y), axis=1)
        return rows


def read_log(path: str | os.PathLike[str], system: SystemModel) -> Log:
    """Read a CSV log for ``system`` (its ``nu`` inputs and ``ny`` measurements).

    Lines starting with ``#`` and blank lines are skipped. Errors name the line and the column:
    a wrong number of fields, text where a number belongs, a missing input, a step or time that
    does not increase.
    """
    system = getattr(system, "system", system)  # a loaded system file: its model
    if not hasattr(system, "nu"):
        raise IvobsError(f"system: expected an ivobs system, got {type(system).__name__}")
    path = Path(path)
    if path.is_dir():
        raise IvobsError(f"log file {str(path)!r} is a directory; expected a CSV file")
    if not path.is_file():
        raise IvobsError(f"log file {str(path)!r} not found")
    parser = LogParser(system.nu, system.ny, str(path))
    rows: list[LogRow] = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            for i, text in enumerate(fh, start=1):
                if _is_skipped(text):
                    continue
                if not parser.columns:
                    parser.header(text, i)
                else:
                    rows.append(parser.row(text, i))
    except UnicodeDecodeError as exc:
        raise not_utf8(str(path), exc) from None
    if not parser.columns:
        raise IvobsError(f"{path}: empty log (expected a header line such as k,u1,y1,y2)")
    if not rows:
        raise IvobsError(f"{path}: the log has a header but no data rows")
    return Log(
        u=np.array([r.u for r in rows]).reshape(len(rows), system.nu),
        y=np.array([r.y for r in rows]).reshape(len(rows), system.ny),
        t=np.array([r.t for r in rows]) if parser.has_time else None,
        steps=np.array([r.step for r in rows]) if parser.has_step else None,
        columns=parser.columns,
    )


def log_from_frame(frame: Any, system: SystemModel) -> Log:
    """A :class:`Log` from a ``pandas.DataFrame`` with the columns of a CSV log (``k``/``step``
    or ``t``/``time``, ``u1..``, ``y1..``; NaN = missing sample). The rows go through the same
    parser as a file (the same checks and messages; "line" counts the header as line 1). A
    non-default index (e.g. a time index) is kept as a column only if it is named ``k``,
    ``step``, ``t`` or ``time``."""
    cols = getattr(frame, "columns", None)
    if cols is None or not hasattr(frame, "itertuples"):
        raise IvobsError(f"frame: expected a pandas DataFrame, got {type(frame).__name__}")
    index_name = getattr(frame.index, "name", None)
    if isinstance(index_name, str) and index_name.lower() in _STEP_COLS + _TIME_COLS:
        frame = frame.reset_index()
    parser = LogParser(system.nu, system.ny, "<DataFrame>")
    parser.header(",".join(str(c) for c in frame.columns))
    rows = [
        parser.row(",".join("" if _blank(v) else repr(float(v)) for v in values), i)
        for i, values in enumerate(frame.itertuples(index=False, name=None), start=2)
    ]
    if not rows:
        raise IvobsError("<DataFrame>: no data rows")
    return Log(
        u=np.array([r.u for r in rows]).reshape(len(rows), system.nu),
        y=np.array([r.y for r in rows]).reshape(len(rows), system.ny),
        t=np.array([r.t for r in rows]) if parser.has_time else None,
        steps=np.array([r.step for r in rows]) if parser.has_step else None,
        columns=parser.columns,
    )


def _blank(v: Any) -> bool:
    try:
        return bool(math.isnan(float(v)))
    except (TypeError, ValueError):
        raise IvobsError(f"<DataFrame>: expected numbers in the log's cells, got {v!r}") from None


def write_log(
    path: str | os.PathLike[str], u: Any, y: Any, *, t: Any = None, steps: bool = True
) -> None:
    """Write a log (``k[,t],u1..,y1..``) atomically; NaN measurements become empty cells."""
    y = np.atleast_2d(np.asarray(y, dtype=float))
    T = y.shape[0]
    u = np.zeros((T, 0)) if u is None else np.asarray(u, dtype=float).reshape(T, -1)
    cols = (["k"] if steps else []) + (["t"] if t is not None else [])
    cols += [f"u{i + 1}" for i in range(u.shape[1])] + [f"y{i + 1}" for i in range(y.shape[1])]
    tt = None if t is None else np.asarray(t, dtype=float).ravel()

    def cell(v: float) -> str:
        return "" if np.isnan(v) else repr(float(v))

    lines = [",".join(cols)]
    for k in range(T):
        parts = ([str(k)] if steps else []) + ([repr(float(tt[k]))] if tt is not None else [])
        parts += [cell(v) for v in u[k]] + [cell(v) for v in y[k]]
        lines.append(",".join(parts))
    write_text_atomic(path, "\n".join(lines) + "\n")
