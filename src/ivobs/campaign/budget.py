"""The work a campaign spec may ask for: a stated budget, checked before anything is built.

A few characters of a spec can ask for more than a machine has (``seeds = { stop = 10**12 }``,
``horizon = 10**9``, ``scenario_options.heat-1d.nx = 10**8``, an options grid of millions of
combinations). Each limit of :data:`BUDGET` is checked as soon as the spec gives the numbers it
depends on, before a seed list, a scenario or a job is built; a spec beyond one is refused
naming it, unless the user says it is meant (``--allow-large``, ``allow_large=True``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["BUDGET", "Budget", "seed_count"]


@dataclass(frozen=True)
class Budget:
    """The largest campaign run without ``allow_large``.

    ``jobs``: scenarios × disturbances × method settings (options grids) × seeds;
    ``steps``: steps simulated and estimated over all jobs (each job: its record's length);
    ``record``: numbers in one record, steps × states (one array of the bounds: 80 MB);
    ``states``: the state dimension a scenario option may ask for (``nx``)."""

    jobs: int = 100_000
    steps: int = 1_000_000_000
    record: int = 10_000_000
    states: int = 100_000

    def refusal(self, what: str, value: int, limit: int, unit: str) -> str | None:
        """The message when ``value`` exceeds ``limit``, else None."""
        if value <= limit:
            return None
        return (
            f"{what}: {value} {unit}, beyond the campaign budget of {limit} {unit} "
            "(docs/campaign.md); pass --allow-large (CLI) or allow_large=True (API) to run it "
            "anyway"
        )

    def scenario_sizes(self, options: dict[str, Any]) -> str | None:
        """A scenario's options that set its size (``horizon``, ``nx``, ``t_final / dt``),
        checked before the scenario is built."""
        sizes = [("horizon", options.get("horizon"), self.record, "steps"),
                 ("nx", options.get("nx"), self.states, "states")]  # fmt: skip
        t_final, dt = options.get("t_final"), options.get("dt")
        if isinstance(t_final, (int, float)) and isinstance(dt, (int, float)) and _number(dt):
            if dt > 0 and _number(t_final):
                steps = math.ceil(min(abs(t_final / dt), 2.0**63))  # t_final / dt overflows
                sizes.append(("t_final / dt", steps, self.record, "steps"))
        for what, value, limit, unit in sizes:
            if isinstance(value, int) and not isinstance(value, bool):
                msg = self.refusal(what, value, limit, unit)
                if msg is not None:
                    return msg
        return None


BUDGET = Budget()
"""The budget of every campaign (docs/campaign.md states it)."""


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def seed_count(start: int, stop: int, step: int) -> int:
    """``len(range(start, stop, step))`` (``step >= 1``) without building the range."""
    return max(0, -(-(stop - start) // step))
