"""What the monitor returns: one :class:`MonitorStep` per step, a :class:`MonitorRecord` over a
record, and the :class:`Fault` episodes they report."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from ..model.protocol import SystemModel
from ..sets import Box

__all__ = [
    "Fault",
    "MonitorRecord",
    "MonitorStep",
    "bias_intervals",
    "output_names",
    "stack_steps",
]


def output_names(outputs: tuple[int, ...]) -> str:
    """``(0, 2)`` -> ``"y1;y3"`` (empty: the contradiction names no output)."""
    return ";".join(f"y{i + 1}" for i in outputs)


def bias_intervals(bounds: Iterable[tuple[int, float, float]]) -> str:
    """``[(0, 0.4, 0.56)]`` -> ``"y1 in [0.4, 0.56]"``: estimated biases, output by output."""
    return ", ".join(f"{output_names((i,))} in [{lo:.4g}, {hi:.4g}]" for i, lo, hi in bounds)


@dataclass(frozen=True)
class Fault:
    """A fault episode: from ``start``, the first step whose data contradicted the model, to
    ``end``, the step at which the alarm cleared (``None``: still raised at the last step seen).

    ``outputs``: the outputs found inconsistent during the episode (0-based; ``y1`` is 0),
    excluded from the estimate until it clears (empty when the contradiction could not be
    traced to outputs: the estimate disjoint from the model's prediction); ``last``: the last
    step of the record the episode was seen in; ``bias_lower``/``bias_upper``: the bias of
    each output (NaN for the others) as estimated at the episode's last alarmed step
    (:mod:`ivobs.monitor.bias`; None where the model cannot be augmented); ``isolated``: the
    output sets whose removal makes the recent data consistent with the model
    (:mod:`ivobs.monitor.isolate`; one set: isolated, several: the data cannot tell them
    apart, none: not isolated), ``isolation`` the same as text (``"y2"``, ``"y1 or y2 (cannot
    be told apart)"``, ``"not isolated: ..."``; empty where no isolation was run).
    """

    start: int
    outputs: tuple[int, ...]
    end: int | None
    last: int
    bias_lower: np.ndarray | None = None
    bias_upper: np.ndarray | None = None
    isolated: tuple[tuple[int, ...], ...] = ()
    isolation: str = ""

    @property
    def duration(self) -> int:
        """Steps with the alarm raised: ``end - start``, or up to the last step seen when the
        episode is still open."""
        return (self.end if self.end is not None else self.last + 1) - self.start

    @property
    def names(self) -> str:
        return output_names(self.outputs)

    @property
    def bias_text(self) -> str:
        """The estimated biases of the episode's outputs (empty without an estimate)."""
        if self.bias_lower is None or self.bias_upper is None:
            return ""
        lo, hi = self.bias_lower, self.bias_upper
        return bias_intervals((i, lo[i], hi[i]) for i in self.outputs if not np.isnan(lo[i]))


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
    ``fault_start``/``outputs``: the open episode's first step and inconsistent outputs;
    ``bias_lower``/``bias_upper``: the episode's estimate of a constant bias on each faulty
    output (NaN elsewhere and without an estimate; :mod:`ivobs.monitor.bias`);
    ``isolated``/``isolation``: the open episode's isolation (:class:`Fault`).
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
    bias_lower: np.ndarray | None = None
    bias_upper: np.ndarray | None = None
    isolated: tuple[tuple[int, ...], ...] = ()
    isolation: str = ""

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
    ``faults``: the episodes, in order; ``bias_lower``/``bias_upper``: ``(T, ny)``, the
    estimated bias of each faulty output (NaN elsewhere; None from :meth:`Monitor.check`).
    """

    lower: np.ndarray
    upper: np.ndarray
    alarm: np.ndarray
    reasons: list[str]
    band_lower: np.ndarray
    band_upper: np.ndarray
    evidence: np.ndarray | None = None
    faults: list[Fault] = field(default_factory=list)
    bias_lower: np.ndarray | None = None
    bias_upper: np.ndarray | None = None

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
    nan = np.full(sys.ny, np.nan)
    for s in steps:
        if s.alarm and s.fault_start is not None:
            f = Fault(s.fault_start, s.outputs, None, s.step, s.bias_lower, s.bias_upper,
                      s.isolated, s.isolation)  # fmt: skip
            if faults and faults[-1].start == s.fault_start and faults[-1].end is None:
                faults[-1] = f
            else:
                faults.append(f)
        elif faults and faults[-1].end is None:
            faults[-1] = dataclasses.replace(faults[-1], end=s.step, last=s.step)
    bias = [(nan, nan) if s.bias_lower is None else (s.bias_lower, s.bias_upper) for s in steps]
    return MonitorRecord(
        lower=np.array([s.lower for s in steps]).reshape(T, sys.nx),
        upper=np.array([s.upper for s in steps]).reshape(T, sys.nx),
        alarm=np.array([s.alarm for s in steps], dtype=bool),
        reasons=[s.reason for s in steps],
        band_lower=np.array([s.band_lower for s in steps]).reshape(T, sys.ny),
        band_upper=np.array([s.band_upper for s in steps]).reshape(T, sys.ny),
        evidence=np.array([s.evidence for s in steps], dtype=bool),
        faults=faults,
        bias_lower=np.array([b[0] for b in bias]).reshape(T, sys.ny),
        bias_upper=np.array([b[1] for b in bias]).reshape(T, sys.ny),
    )
