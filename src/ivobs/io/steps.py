"""Which step each row of a log holds: the step column ``k`` honoured.

Every reader of logs places its rows with a :class:`StepClock`, so they all agree: the first
row is the step of the prior box (``x[0]``, or the system file's ``[x0] step``), a gap in ``k``
is a run of missing samples (refused for a system with inputs, whose inputs there are unknown,
and for a continuous-time one, clocked by its time column), and at most
:data:`MAX_MISSING_STEPS` steps may be missing in all; without a step column the rows are
consecutive steps from the prior's. docs/operating.md, "Steps, gaps and where a log starts".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import IvobsError

__all__ = ["MAX_MISSING_STEPS", "LogRow", "StepClock", "check_start"]

MAX_MISSING_STEPS = 1_000_000
"""Most steps a log may skip in all (each becomes a missing sample)."""


@dataclass
class LogRow:
    """One parsed row: the step and/or time value when the log has them, ``u`` and ``y``;
    ``filled``: a step the log skipped (its measurements missing)."""

    line: int
    u: np.ndarray
    y: np.ndarray
    step: int | None = None
    t: float | None = None
    filled: bool = False


def check_start(system: Any, start: int, where: str) -> None:
    """A prior box at step ``start`` > 0 needs a model that does not change with the step: the
    estimators run a model from its step 0."""
    if isinstance(start, bool) or not isinstance(start, int) or start < 0:
        raise IvobsError(f"start: expected the step of the prior box (an integer >= 0), got "
                         f"{start!r}")  # fmt: skip
    if start and (system.is_time_varying or not system.has_constant_bounds):
        raise IvobsError(
            f"{where}: the prior box is given at step {start}, but the model changes with the "
            "step (time-varying matrices or disturbance bounds) and the estimators run it from "
            "step 0: give the prior box and the log from step 0"
        )


class StepClock:
    """Places the rows of one log on its steps (see the module docstring).

    ``start``: the step of the prior box, where the first row must be; :meth:`resume` moves
    the clock to the step after the last one a saved monitor processed."""

    def __init__(self, system: Any, source: str, start: int = 0):
        check_start(system, start, source)
        self.nu, self.ny = int(system.nu), int(system.ny)
        self.continuous = bool(system.is_continuous)
        self.source, self.start = source, start
        self.next = start  # the step of the next row
        self.started = False
        self.missing = 0  # steps filled in for gaps so far
        self._t: float | None = None  # the time of the last row (to label filled rows)

    def resume(self, next_step: int) -> None:
        """Continue a stream whose steps before ``next_step`` were processed already."""
        self.next, self.started = next_step, True

    def fail(self, line: int, msg: str) -> IvobsError:
        return IvobsError(f"{self.source}, line {line}: {msg}")

    def place(self, row: LogRow) -> list[LogRow]:
        """The rows of the steps up to ``row``'s: missing-sample rows for a gap, then ``row``."""
        if row.step is None:  # consecutive rows
            self.next += 1
            self.started = True
            return [row]
        if not self.started and row.step != self.start:
            raise self.fail(
                row.line,
                f"the log starts at step {row.step}, but the prior box bounds x[{self.start}]: "
                f"numbering the rows from {self.start} would start x[{row.step}] from the prior "
                f"of x[{self.start}]. Give the prior box of x[{row.step}] ([x0] step = "
                f"{row.step} in the system file; read_log(..., start={row.step})), or the log "
                f"from step {self.start}",
            )
        if row.step < self.next:
            raise self.fail(row.line, f"step {row.step}: expected step {self.next} or later "
                                      "(each step once, in order)")  # fmt: skip
        gap = row.step - self.next
        filled: list[LogRow] = []
        if gap:
            self._check_gap(row, gap)
            t0, t1 = self._t, row.t
            for j, k in enumerate(range(self.next, row.step), start=1):
                t = None if t0 is None or t1 is None else t0 + (t1 - t0) * j / (gap + 1)
                filled.append(LogRow(row.line, np.zeros(0), np.full(self.ny, np.nan), k, t, True))
        self.next, self.started, self._t = row.step + 1, True, row.t
        return [*filled, row]

    def _check_gap(self, row: LogRow, gap: int) -> None:
        steps = f"steps {self.next}..{self.next + gap - 1}" if gap > 1 else f"step {self.next}"
        if self.nu:
            raise self.fail(
                row.line,
                f"{steps} missing (k jumps to {row.step}): the system has inputs, and theirs "
                "are unknown there; give the rows of those steps with their inputs and empty "
                "measurement cells (missing samples)",
            )
        if self.continuous:
            raise self.fail(
                row.line,
                f"{steps} missing (k jumps to {row.step}): a continuous-time log is clocked by "
                "its time column; give every row, or leave the step column out",
            )
        self.missing += gap
        if self.missing > MAX_MISSING_STEPS:
            raise self.fail(
                row.line,
                f"{steps} missing (k jumps to {row.step}): more than {MAX_MISSING_STEPS} "
                "missing steps in this log, the most a log may skip",
            )
