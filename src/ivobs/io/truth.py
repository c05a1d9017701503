"""The true state of a logged record (CSV), for containment checks and figures.

A truth file is read like a measurement log (:mod:`ivobs.io.logs`, the same parser and step
clock): an optional step (``k`` / ``step``) or time (``t`` / ``time``) column, then one column
per state, named by the system's state names or ``x1..xn`` (also ``x_1``, ``x[1]``; matched by
name or number, in any order). Its rows are placed on their steps as the log's are, and it must
give the true state at every step of the log it goes with, no more and no fewer: a truth that
skips or adds a step would be compared with the boxes of other steps.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import IvobsError
from ..model import SystemModel
from .logs import Log, LogParser, LogRow, column_number, read_rows
from .steps import StepClock

__all__ = ["read_truth"]


class _TruthParser(LogParser):
    """A log parser whose value columns are the states (held in the rows' ``y``)."""

    def __init__(self, names: tuple[str, ...] | None, nx: int, source: str):
        super().__init__(0, nx, source)
        self.names = names

    def _signal_column(self, i: int, column: str, line: int) -> None:
        self._y.append(i)  # which state it is: once every column is known

    def _check_signals(self, line: int) -> None:
        """Each state once: every column numbered ``x1..xn`` (or ``x0..``), or every column
        named by a state."""
        cols = [self.columns[i] for i in self._y]
        n = self.ny
        nums = [column_number(c, "x") for c in cols]
        schemes = [[None if k is None else k - base for k in nums] for base in (1, 0)]
        if self.names is not None:
            where = {name.lower(): j for j, name in enumerate(self.names)}
            schemes.append([where.get(c.lower()) for c in cols])
        for states in schemes:
            order = [s for s in states if s is not None]
            if len(order) == len(cols) == n and sorted(order) == list(range(n)):
                self._y[:] = [i for _, i in sorted(zip(order, self._y))]
                return
        named = f"{', '.join(self.names)} or " if self.names else ""
        raise self.fail(
            line,
            f"expected {n} state columns named {named}x1..x{n} (and an optional step k or time "
            f"t column), got {cols}",
        )


class _EveryStep(StepClock):
    """The log's step clock, without gaps: the truth is needed at every step."""

    def _check_gap(self, row: LogRow, gap: int) -> None:
        steps = f"steps {self.next}..{self.next + gap - 1}" if gap > 1 else f"step {self.next}"
        raise self.fail(
            row.line,
            f"{steps} missing (k jumps to {row.step}): give the true state at every step of "
            "the log",
        )


def read_truth(
    path: str | os.PathLike[str], system: SystemModel, log: Log, *, what: str = "truth"
) -> np.ndarray:
    """The true states ``(T, nx)`` in the CSV file ``path``, one row per step of ``log`` (the
    measurement log of ``system`` they go with, from :func:`~ivobs.io.read_log`).

    The rows start at the log's first step and cover each of its steps once; with a time
    column in both files, the times agree. ``what`` names the file in errors (``"--truth"`` on
    the command line); they say the line and the column, or the steps that differ.
    """
    model = getattr(system, "system", system)  # a loaded system file: its model
    path = Path(path)
    source = f"{what} {path}"
    names = getattr(model, "names", None)  # SignalNames; None: a model without names
    parser = _TruthParser(None if names is None else names.states, int(model.nx), source)
    clock = _EveryStep(model, source, log.start)
    rows = read_rows(path, parser, clock, what, "k,x1,x2")
    first = log.start
    if len(rows) != log.T:
        raise IvobsError(
            f"{source}: {len(rows)} rows (steps {first}..{first + len(rows) - 1}), but the log "
            f"has {log.T} steps ({first}..{first + log.T - 1}): give the true state at every "
            "step of the log"
        )
    x = np.array([r.y for r in rows], dtype=float).reshape(log.T, model.nx)
    gaps = np.flatnonzero(np.isnan(x).any(axis=1))
    if gaps.size:
        row = rows[int(gaps[0])]
        raise IvobsError(
            f"{source}, line {row.line}: the true state at step {first + int(gaps[0])} has an "
            "empty or NaN cell; give every state at every step"
        )
    if parser.has_time and log.t is not None:
        t = np.array([r.t for r in rows], dtype=float)
        off = np.flatnonzero(~np.isclose(t, log.t, rtol=1e-9, atol=1e-12))
        if off.size:
            j = int(off[0])
            raise IvobsError(
                f"{source}, line {rows[j].line}: time {t[j]:g}, but the log's step "
                f"{first + j} is at time {float(log.t[j]):g}: the rows must be the log's steps"
            )
    return x
