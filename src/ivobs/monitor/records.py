"""What the monitor returns: one :class:`MonitorStep` per step, a :class:`MonitorRecord` over a
record, and the :class:`Fault` episodes they report."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model.protocol import SystemModel
from ..sets import Box

__all__ = ["Fault", "MonitorRecord", "MonitorStep", "output_names", "stack_steps"]


def output_names(outputs: tuple[int, ...]) -> str:
    """``(0, 2)`` -> ``"y1;y3"`` (empty: the contradiction names no output)."""
    return ";".join(f"y{i + 1}" for i in outputs)


@dataclass(frozen=True)
class Fault:
    """A fault episode: from ``start``, the first step whose data contradicted the model, to
    ``end``, the step at which the alarm cleared (``None``: still raised at the last step seen).

    ``outputs``: the outputs found inconsistent during the episode (0-based; ``y1`` is 0),
    excluded from the estimate until it clears (empty when the contradiction could not be
    traced to outputs: the estimate disjoint from the model's prediction); ``last``: the last
    step of the record the episode was seen in.
    """

    start: int
    outputs: tuple[int, ...]
    end: int | None
    last: int

    @property
    def duration(self) -> int:
        """Steps with the alarm raised: ``end - start``, or up to the last step seen when the
        episode is still open."""
        return (self.end if self.end is not None else self.last + 1) - self.start

    @property
    def names(self) -> str:
        return output_names(self.outputs)


@dataclass(frozen=True)
class MonitorStep:
    """The outcome of one step.

    ``lower``/``upper``: the estimator's box of ``x[k]`` (NaN before its ``valid_from``), from
    the outputs not excluded as faulty; ``alarm``: a fault episode is open at this step (raised
    by data that contradict the model, never falsely under its assumptions; latched until the
    excluded outputs are consistent again, see :class:`~ivobs.monitor.Monitor`); ``reason``:
    why (empty without alarm); ``band_lower``/``band_upper``: the output band the data before
    ``k`` predict for ``y[k]`` (infinite where nothing is known yet); ``evidence``: the data of
    this very step contradict the model; ``inconsistent``: the outputs that do so at this step;
    ``fault_start``/``outputs``: the open episode's first step and inconsistent outputs.
    """

    step: int
    lower: np.ndarray
    upper: np.ndarray
    alarm: bool
    reason: str = ""
    band_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    band_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    evidence: bool = False
    inconsistent: tuple[int, ...] = ()
    fault_start: int | None = None
    outputs: tuple[int, ...] = ()

    @property
    def box(self) -> Box:
        return Box._trusted(self.lower, self.upper)

    @property
    def fault_duration(self) -> int:
        """Steps the open episode has lasted, this one included (0 without alarm)."""
        return 0 if self.fault_start is None else self.step - self.fault_start + 1


@dataclass
class MonitorRecord:
    """:meth:`Monitor.run` over a record: arrays over the steps.

    ``alarm``: latched alarms; ``evidence``: the steps whose own data contradict the model
    (:meth:`Monitor.check` reports these only: ``alarm`` equals ``evidence`` there);
    ``faults``: the episodes, in order.
    """

    lower: np.ndarray
    upper: np.ndarray
    alarm: np.ndarray
    reasons: list[str]
    band_lower: np.ndarray
    band_upper: np.ndarray
    evidence: np.ndarray | None = None
    faults: list[Fault] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.evidence is None:
            self.evidence = self.alarm.copy()

    @property
    def first_alarm(self) -> int | None:
        """The first step with an alarm (None without one)."""
        idx = np.flatnonzero(self.alarm)
        return int(idx[0]) if idx.size else None


def stack_steps(steps: list[MonitorStep], sys: SystemModel) -> MonitorRecord:
    T = len(steps)
    faults: list[Fault] = []
    for s in steps:
        if s.alarm and s.fault_start is not None:
            if faults and faults[-1].start == s.fault_start and faults[-1].end is None:
                faults[-1] = Fault(s.fault_start, s.outputs, None, s.step)
            else:
                faults.append(Fault(s.fault_start, s.outputs, None, s.step))
        elif faults and faults[-1].end is None:
            faults[-1] = Fault(faults[-1].start, faults[-1].outputs, s.step, s.step)
    return MonitorRecord(
        lower=np.array([s.lower for s in steps]).reshape(T, sys.nx),
        upper=np.array([s.upper for s in steps]).reshape(T, sys.nx),
        alarm=np.array([s.alarm for s in steps], dtype=bool),
        reasons=[s.reason for s in steps],
        band_lower=np.array([s.band_lower for s in steps]).reshape(T, sys.ny),
        band_upper=np.array([s.band_upper for s in steps]).reshape(T, sys.ny),
        evidence=np.array([s.evidence for s in steps], dtype=bool),
        faults=faults,
    )
