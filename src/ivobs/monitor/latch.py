"""The latch of the monitor's alarm: a fault episode stays open until the outputs it excludes
have been consistent with the fault-free estimate for ``clear_after`` consecutive steps."""

from __future__ import annotations

from typing import Any

from ..errors import IvobsError
from .records import output_names

__all__ = ["Latch"]


class Latch:
    """The open fault episode, if any: its first step, the outputs it excludes from the
    estimate, and how many consecutive steps those outputs have been consistent again.

    A step *counts* towards clearing when its data raise no contradiction and every excluded
    output is measured and consistent with the prediction of the estimate that excludes it; a
    step where an excluded output is missing neither counts nor resets the count; a step with a
    contradiction resets it (and adds the outputs it traces to the episode).
    """

    def __init__(self, clear_after: int):
        self.clear_after = clear_after
        self.reset()

    def reset(self) -> None:
        self.start: int | None = None
        self.outputs: tuple[int, ...] = ()
        self.clean = 0

    def observe(
        self,
        k: int,
        bad: tuple[int, ...],
        evidence: bool,
        held_missing: bool,
        proven: bool = False,
    ) -> None:
        """Step ``k``: ``bad``, the outputs its data contradict; ``evidence``, whether they
        contradict the model at all; ``held_missing``, an excluded output is not measured;
        ``proven``, the data of the episode still prove the fault (its bias estimate excludes
        0, :mod:`ivobs.monitor.bias`): the step does not count towards clearing."""
        if evidence:
            if self.start is None:
                self.start, self.outputs = k, bad
            else:
                self.outputs = tuple(sorted(set(self.outputs) | set(bad)))
            self.clean = 0
        elif self.start is not None and proven:
            self.clean = 0
        elif self.start is not None and not held_missing:
            self.clean += 1
            if self.clean >= self.clear_after:
                self.reset()

    def describe(self) -> str:
        """The reason printed on a latched step without a contradiction of its own."""
        what = output_names(self.outputs) or "no output traced"
        return (
            f"fault since step {self.start} ({what}): consistent again for {self.clean} of "
            f"{self.clear_after} steps"
        )

    # -- persistence ------------------------------------------------------------------------
    def state(self) -> dict[str, Any] | None:
        if self.start is None:
            return None
        return {"start": self.start, "outputs": list(self.outputs), "clean": self.clean}

    def restore(self, saved: Any, ny: int, k: int) -> None:
        """From :meth:`state`, checked (``ny`` outputs, the monitor at step ``k``)."""
        self.reset()
        if saved is None:
            return
        if not isinstance(saved, dict):
            raise IvobsError(f"state: fault: expected a table or null, got {saved!r}"[:200])

        def count(key: str, below: int) -> int:
            v = saved.get(key)
            if isinstance(v, bool) or not isinstance(v, int) or not 0 <= v < below:
                raise IvobsError(
                    f"state: fault.{key}: expected an integer in [0, {below}), got {v!r}"
                )
            return v

        start, clean = count("start", max(k, 1)), count("clean", self.clear_after)
        outs = saved.get("outputs")
        if not isinstance(outs, list) or not all(
            isinstance(i, int) and not isinstance(i, bool) and 0 <= i < ny for i in outs
        ):
            raise IvobsError(
                f"state: fault.outputs: expected a list of output indices in [0, {ny}), got "
                f"{outs!r}"[:200]
            )
        self.start, self.outputs, self.clean = start, tuple(sorted(set(outs))), clean
