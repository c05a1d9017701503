"""Measurement logs (CSV): an optional step (``k`` / ``step``) or time (``t`` / ``time``)
column, the inputs ``u1, u2, ...`` and the measurements ``y1, y2, ...``.

An empty cell or ``NaN`` (any spelling: ``nan``, ``-nan``) in a ``y`` column is a missing
sample. The step column is honoured (:class:`~ivobs.io.steps.StepClock`): a row's ``k`` is its
step, a gap is a run of missing samples, and the first row must be the step of the prior box.
:func:`read_log` reads a log, :class:`LogParser` parses rows one at a time (the streaming
monitor), :func:`write_log` writes one (atomically).
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
from .steps import LogRow, StepClock

__all__ = [
    "Log",
    "LogParser",
    "LogRow",
    "csv_cell",
    "log_from_frame",
    "not_utf8",
    "read_log",
    "read_number",
    "write_log",
]

_STEP_COLS = ("k", "step")
_TIME_COLS = ("t", "time")
_SIGNAL = re.compile(r"^(?P<kind>[uy])(?:\d+|[_\[(.].*)?$", re.IGNORECASE | re.ASCII)
_INTEGER = re.compile(r"^[+-]?[0-9]+$")

MAX_STEP = 2**53
"""Largest step number a log may give (beyond it a float cannot count steps one by one)."""


def column_number(column: str, letters: str = "uy") -> int | None:
    """The number of a column ``y2``, ``y_2``, ``y[2]``, ``y(2)``, ``y.2`` whose letter is one
    of ``letters`` (any case), else None."""
    pattern = rf"^[{letters}](?:(\d+)|_(\d+)|\[(\d+)\]|\((\d+)\)|\.(\d+))$"
    m = re.match(pattern, column, re.IGNORECASE | re.ASCII)
    return None if m is None else int(next(g for g in m.groups() if g is not None))


def _shown(text: str) -> str:
    """A cell quoted in an error, cut short (a field may be 128 KiB long)."""
    return repr(text) if len(text) <= 40 else repr(text[:37] + "...")


def csv_cell(v: float, nan: str = "") -> str:
    """A number as a CSV cell, with full precision (``repr``); NaN as ``nan`` (a missing
    sample: an empty cell)."""
    return nan if np.isnan(v) else repr(float(v))


def read_number(cell: str) -> float:
    """One CSV cell as a number: NaN for an empty cell and for every spelling of NaN (``nan``,
    ``-nan``, ``NaN``); ``ValueError`` naming what is wrong for anything else that is not a
    finite number written in ASCII (``float`` also reads ``1_000`` and other scripts' digits,
    which a CSV number is not)."""
    s = cell.strip()
    if s == "":
        return math.nan
    if not s.isascii():
        raise ValueError("expected a number written with the digits 0-9")
    if "_" in s:  # float() reads 1_000; a CSV number does not
        raise ValueError("expected a number")
    try:
        v = float(s)
    except ValueError:
        raise ValueError("expected a number") from None
    if math.isinf(v):
        raise ValueError("infinite value (use an empty cell or NaN for a missing measurement)")
    return v


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

    def _cells(self, text: str, line: int) -> list[str]:
        try:
            return next(csv.reader([text]), [])
        except csv.Error as exc:  # a field over csv's 128 KiB limit, a NUL byte
            raise self.fail(line, f"not a CSV row ({exc})") from None

    def header(self, text: str, line: int = 1) -> None:
        """Read the header: signal columns numbered ``u1, u2, ...`` (also ``y[2]``, ``y_2``)
        are mapped by their number, whatever their order; unnumbered ones (``u_speed``) are
        taken in header order. A UTF-8 byte-order mark (Excel) is ignored."""
        cols = [c.strip() for c in self._cells(text.lstrip("\ufeff"), line)]
        self.columns = cols
        seen: set[str] = set()
        for i, c in enumerate(cols):
            low = c.lower()
            if low in seen:
                raise self.fail(line, f"duplicate column {c!r}")
            seen.add(low)
            if low in _STEP_COLS:
                if self._step is not None:
                    raise self.fail(line, "two step columns (k, step): keep one")
                self._step = i
            elif low in _TIME_COLS:
                if self._time is not None:
                    raise self.fail(line, "two time columns (t, time): keep one")
                self._time = i
            else:
                self._signal_column(i, c, line)
        self._check_signals(line)

    def _signal_column(self, i: int, column: str, line: int) -> None:
        """Column ``i``, neither a step nor a time column: an input or a measurement (a reader
        of other files, :func:`~ivobs.io.truth.read_truth`, takes its own columns here)."""
        m = _SIGNAL.match(column)
        if m:
            (self._u if m.group("kind").lower() == "u" else self._y).append(i)
            return
        raise self.fail(
            line,
            f"unexpected column {column!r}: a log has an optional step "
            "(k or step) or time (t or time) column, input columns u1, u2, "
            "... and measurement columns y1, y2, ...",
        )

    def _check_signals(self, line: int) -> None:
        """As many ``u`` and ``y`` columns as the system has inputs and outputs, by number."""
        cols = self.columns
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
        nums = [column_number(self.columns[i]) for i in idx]
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
        cells = self._cells(text, line)
        if len(cells) != len(self.columns):
            raise self.fail(
                line,
                f"expected {len(self.columns)} fields ({','.join(self.columns)}), got {len(cells)}",
            )
        vals = np.empty(len(cells))
        for i, cell in enumerate(cells):
            try:
                vals[i] = read_number(cell)
            except ValueError as exc:
                raise self.fail(
                    line, f"column {self.columns[i]!r}: {exc}, got {_shown(cell.strip())}"
                ) from None
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
            out.step = self._step_of(cells[self._step].strip(), vals[self._step], line)
            if (
                self._last is not None
                and self._last.step is not None
                and out.step <= self._last.step
            ):
                raise self.fail(
                    line,
                    f"step {out.step} does not increase (previous "
                    f"{self._last.step}, line {self._last.line}): each step once, in order",
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

    def _step_of(self, text: str, value: float, line: int) -> int:
        """The step of a row: an integer in ``0..MAX_STEP`` (read exactly when written as one:
        a float cannot tell 2**53 + 1 from 2**53)."""
        col = self.columns[self._step or 0]
        step = int(text) if _INTEGER.match(text) and len(text) <= 20 else value
        if step != int(step):
            raise self.fail(line, f"column {col!r}: expected an integer step, got {value}")
        if not 0 <= step <= MAX_STEP:
            raise self.fail(
                line, f"column {col!r}: expected a step in 0..2**53, got {_shown(text)}"
            )
        return int(step)


def not_utf8(source: str, exc: UnicodeDecodeError) -> IvobsError:
    """The error for a log that is not UTF-8 text."""
    return IvobsError(
        f"{source}: not valid UTF-8 ({exc.reason}, byte "
        f"{exc.object[exc.start : exc.start + 1]!r}); a log must be UTF-8 text (CSV)"
    )


@dataclass
class Log:
    """A measurement record: ``u`` ``(T, nu)``, ``y`` ``(T, ny)`` (NaN = missing), one row per
    step from ``start`` (the step of the prior box), the step and time columns when present.

    ``filled``: ``(T,)`` bool, the steps the file skipped (a gap in its step column: their
    measurements are missing, their times interpolated between the rows around them)."""

    u: np.ndarray
    y: np.ndarray
    t: np.ndarray | None = None
    steps: np.ndarray | None = None
    columns: list[str] = field(default_factory=list)
    start: int = 0
    filled: np.ndarray | None = None

    @property
    def T(self) -> int:
        return int(self.y.shape[0])

    @property
    def missing(self) -> np.ndarray:
        """``(T,)`` bool: rows with at least one missing measurement."""
        rows: np.ndarray = np.any(np.isnan(self.y), axis=1)
        return rows


def _model_and_start(system: Any, start: int | None) -> tuple[Any, int]:
    """The model of ``system`` (a model or a loaded system file) and the step of the prior box:
    ``start``, else the system file's ``[x0] step``, else 0."""
    if start is None:
        start = int(getattr(system, "x0_step", 0))
    model = getattr(system, "system", system)  # a loaded system file: its model
    if not hasattr(model, "nu"):
        raise IvobsError(f"system: expected an ivobs system, got {type(model).__name__}")
    return model, start


def _stack(rows: list[LogRow], parser: LogParser, clock: StepClock, model: Any) -> Log:
    T = len(rows)
    return Log(
        u=np.array([r.u for r in rows]).reshape(T, model.nu),
        y=np.array([r.y for r in rows]).reshape(T, model.ny),
        t=np.array([r.t for r in rows], dtype=float) if parser.has_time else None,
        steps=np.arange(clock.start, clock.start + T) if parser.has_step else None,
        columns=parser.columns,
        start=clock.start,
        filled=np.array([r.filled for r in rows], dtype=bool),
    )


def read_log(path: str | os.PathLike[str], system: SystemModel, *, start: int | None = None) -> Log:
    """Read a CSV log for ``system`` (a model, or a loaded system file: its ``nu`` inputs and
    ``ny`` measurements).

    Lines starting with ``#`` and blank lines are skipped. The step column is honoured
    (:mod:`ivobs.io.steps`): the first row must be at ``start``, the step of the prior box
    (default: the system file's ``[x0] step``, else 0), and a gap in ``k`` is a run of missing
    samples. Errors name the line and the column: a wrong number of fields, text where a
    number belongs, a missing input, a step or time that does not increase, a log that starts
    at another step than the prior's.
    """
    model, start = _model_and_start(system, start)
    path = Path(path)
    parser = LogParser(model.nu, model.ny, str(path))
    clock = StepClock(model, str(path), start)
    rows = read_rows(path, parser, clock, "log file", "k,u1,y1,y2")
    return _stack(rows, parser, clock, model)


def read_rows(
    path: Path, parser: LogParser, clock: StepClock, what: str, example: str
) -> list[LogRow]:
    """The rows of the CSV file ``path`` read by ``parser`` and placed on their steps by
    ``clock`` (``what`` names the file in errors, ``example`` is a header line it could have)."""
    if path.is_dir():
        raise IvobsError(f"{what} {str(path)!r} is a directory; expected a CSV file")
    if not path.is_file():
        raise IvobsError(f"{what} {str(path)!r} not found")
    rows: list[LogRow] = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            for i, text in enumerate(fh, start=1):
                if not text.strip() or text.lstrip().startswith("#"):
                    continue
                if not parser.columns:
                    parser.header(text, i)
                else:
                    rows.extend(clock.place(parser.row(text, i)))
    except UnicodeDecodeError as exc:
        raise not_utf8(parser.source, exc) from None
    except OSError as exc:
        raise IvobsError(f"{what} {str(path)!r}: cannot read it ({exc.strerror})") from None
    if not parser.columns:
        raise IvobsError(f"{parser.source}: empty file (expected a header line such as {example})")
    if not rows:
        raise IvobsError(f"{parser.source}: the file has a header but no data rows")
    return rows


def log_from_frame(frame: Any, system: SystemModel, *, start: int | None = None) -> Log:
    """A :class:`Log` from a ``pandas.DataFrame`` with the columns of a CSV log (``k``/``step``
    or ``t``/``time``, ``u1..``, ``y1..``; NaN = missing sample). The rows go through the same
    parser and step clock as a file (the same checks and messages; "line" counts the header as
    line 1). A non-default index (e.g. a time index) is kept as a column only if it is named
    ``k``, ``step``, ``t`` or ``time``."""
    model, start = _model_and_start(system, start)
    cols = getattr(frame, "columns", None)
    if cols is None or not hasattr(frame, "itertuples"):
        raise IvobsError(f"frame: expected a pandas DataFrame, got {type(frame).__name__}")
    index_name = getattr(frame.index, "name", None)
    if isinstance(index_name, str) and index_name.lower() in _STEP_COLS + _TIME_COLS:
        frame = frame.reset_index()
    parser = LogParser(model.nu, model.ny, "<DataFrame>")
    parser.header(",".join(str(c) for c in frame.columns))
    clock = StepClock(model, "<DataFrame>", start)
    rows = [
        placed
        for i, values in enumerate(frame.itertuples(index=False, name=None), start=2)
        for placed in clock.place(
            parser.row(",".join("" if _blank(v) else repr(float(v)) for v in values), i)
        )
    ]
    if not rows:
        raise IvobsError("<DataFrame>: no data rows")
    return _stack(rows, parser, clock, model)


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

    lines = [",".join(cols)]
    for k in range(T):
        parts = ([str(k)] if steps else []) + ([repr(float(tt[k]))] if tt is not None else [])
        parts += [csv_cell(v) for v in u[k]] + [csv_cell(v) for v in y[k]]
        lines.append(",".join(parts))
    write_text_atomic(path, "\n".join(lines) + "\n")
