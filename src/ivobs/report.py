"""Run several methods on one scenario and tabulate widths, containment and timings.

Used by ``ivobs demo``, ``ivobs compare`` and the benchmark suite.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import IvobsError
from .estimators import get as get_method
from .estimators import make_estimator
from .estimators import methods as all_methods
from .result import Estimate
from .scenarios import Scenario
from .simulate import Trajectory

__all__ = ["MethodResult", "compare", "markdown_table"]


@dataclass
class MethodResult:
    """One method on one record."""

    method: str
    estimate: Estimate | None = None
    error: str | None = None
    design_time: float = float("nan")
    run_time: float = float("nan")
    contains: bool | None = None
    mean_width: np.ndarray | None = None

    @property
    def ok(self) -> bool:
        return self.estimate is not None


def compare(
    scenario: Scenario,
    methods: Sequence[str] | None = None,
    *,
    disturbance: str = "paper",
    seed: Any = 0,
    burn_in: int | None = None,
    options: dict[str, dict[str, Any]] | None = None,
    trajectory: Trajectory | None = None,
) -> tuple[Trajectory, list[MethodResult]]:
    """Simulate the scenario once and run every method on the same record.

    A method that cannot be designed for the system (``DesignError``, or unsupported system
    class) is reported with its reason instead of a result.
    """
    traj = trajectory if trajectory is not None else scenario.simulate(disturbance, seed)
    names = list(all_methods() if methods is None else methods)
    burn = scenario.horizon // 10 if burn_in is None else int(burn_in)
    out: list[MethodResult] = []
    for name in names:
        get_method(name)  # unknown names fail loudly, not as a table row
        res = MethodResult(method=name)
        opts = dict((options or {}).get(name, {}))
        try:
            t0 = time.perf_counter()
            est = make_estimator(name, scenario.system, x0=scenario.x0, **opts)
            res.design_time = time.perf_counter() - t0
            t0 = time.perf_counter()
            res.estimate = est.run(
                traj.u, traj.y, t=traj.t if scenario.system.is_continuous else None
            )
            res.run_time = time.perf_counter() - t0
        except IvobsError as exc:
            res.error = f"{type(exc).__name__}: {exc}"
            out.append(res)
            continue
        if not np.isnan(traj.x).all():  # CORA's 2-D record stores no state
            res.contains = bool(np.all(res.estimate.contains(traj.x)))
        if burn < res.estimate.T:
            res.mean_width = res.estimate.mean_width(burn)
        out.append(res)
    return traj, out


def markdown_table(
    results: Sequence[MethodResult],
    state_names: Sequence[str] | None = None,
    reference: str | None = None,
) -> str:
    """A Markdown table: mean width per state, containment, design and run time.

    With ``reference`` (a method name among the results, e.g. ``"exact"``), a column gives the
    mean over states of each method's width ratio to it.
    """
    ok = [r for r in results if r.ok and r.mean_width is not None]
    nx = ok[0].mean_width.shape[0] if ok else 0
    names = list(state_names) if state_names else [f"x{i + 1}" for i in range(nx)]
    ref = next((r for r in ok if r.method == reference), None) if reference else None
    head = ["method"] + [f"width {n}" for n in names] + (["ratio to " + reference] if ref else [])
    head += ["contains truth", "design (s)", "run (s)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in results:
        if not r.ok or r.mean_width is None:
            reason = (r.error or "no valid step after burn-in").split("\n")[0]
            if len(reason) > 110:
                reason = reason[:107] + "..."
            lines.append(
                f"| {r.method} | " + " | ".join(["—"] * (len(head) - 2)) + f" | {reason} |"
            )
            continue
        cells = [r.method] + [f"{w:.4g}" for w in r.mean_width]
        if ref is not None:
            ratio = np.mean(r.mean_width / np.where(ref.mean_width > 0, ref.mean_width, np.nan))
            cells.append(f"{ratio:.3f}")
        seen = {True: "yes", False: "**NO**", None: "n/a"}[r.contains]
        cells += [seen, f"{r.design_time:.3f}", f"{r.run_time:.4f}"]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
