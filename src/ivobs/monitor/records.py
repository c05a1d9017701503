"""What the monitor returns: one :class:`MonitorStep` per step, a :class:`MonitorRecord` over a
record."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..model import LinearSystem
from ..sets import Box

__all__ = ["MonitorRecord", "MonitorStep", "stack_steps"]


@dataclass(frozen=True)
class MonitorStep:
    """The outcome of one step.

    ``lower``/``upper``: the estimator's box of ``x[k]`` (NaN before its ``valid_from``);
    ``alarm``: the measurement contradicts the model (never false under its assumptions);
    ``reason``: why (empty without alarm); ``band_lower``/``band_upper``: the output band the
    data before ``k`` predict for ``y[k]`` (infinite where nothing is known yet).
    """

    step: int
    lower: np.ndarray
    upper: np.ndarray
    alarm: bool
    reason: str = ""
    band_lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    band_upper: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def box(self) -> Box:
        return Box._trusted(self.lower, self.upper)


@dataclass
class MonitorRecord:
    """:meth:`Monitor.run` over a record: arrays over the steps."""

    lower: np.ndarray
    upper: np.ndarray
    alarm: np.ndarray
    reasons: list[str]
    band_lower: np.ndarray
    band_upper: np.ndarray

    @property
    def first_alarm(self) -> int | None:
        """The first step with an alarm (None without one)."""
        idx = np.flatnonzero(self.alarm)
        return int(idx[0]) if idx.size else None


def stack_steps(steps: list[MonitorStep], sys: LinearSystem) -> MonitorRecord:
    T = len(steps)
    return MonitorRecord(
        lower=np.array([s.lower for s in steps]).reshape(T, sys.nx),
        upper=np.array([s.upper for s in steps]).reshape(T, sys.nx),
        alarm=np.array([s.alarm for s in steps], dtype=bool),
        reasons=[s.reason for s in steps],
        band_lower=np.array([s.band_lower for s in steps]).reshape(T, sys.ny),
        band_upper=np.array([s.band_upper for s in steps]).reshape(T, sys.ny),
    )
