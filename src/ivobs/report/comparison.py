"""Run several methods on one scenario and tabulate widths, containment and timings.

Used by ``ivobs demo``, ``ivobs compare`` and the benchmark suite.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..estimators import get as get_method
from ..estimators import make_estimator
from ..estimators import methods as all_methods
from ..result import Estimate
from ..scenarios import Scenario
from ..simulate import Trajectory

__all__ = ["POINT_TOL", "MethodResult", "applicable_methods", "compare", "markdown_table"]


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
    misses: int | None = None
    """Steps whose box misses the true state (None: no true state)."""
    cpu_time: float = float("nan")
    """Processor seconds of the design and the run together."""
    guaranteed: bool = True
    """False for a baseline (:mod:`~ivobs.report.baseline`): its misses are expected."""
    options: dict[str, Any] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        return self.estimate is not None

    def timed(self, design: Any, run: Any) -> Any:
        """``design()`` and ``run(design())``, whose result is the :attr:`estimate`, with their
        wall-clock times and their processor time together; returns the design."""
        c0, t0 = time.process_time(), time.perf_counter()
        est = design()
        self.design_time = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.estimate = run(est)
        self.run_time = time.perf_counter() - t0
        self.cpu_time = time.process_time() - c0
        return est

    def measure(self, truth: np.ndarray | None, burn_in: int) -> None:
        """Containment of ``truth`` (None: unknown) and the mean widths from ``burn_in``."""
        assert self.estimate is not None
        if truth is not None:
            self.misses = int(np.sum(~self.estimate.contains(truth)))
            self.contains = self.misses == 0
        if max(burn_in, self.estimate.valid_from) < self.estimate.T:
            self.mean_width = self.estimate.mean_width(burn_in)


def applicable_methods(system: Any) -> tuple[list[str], list[str]]:
    """The methods that accept ``system`` (model class, time base, time variation, interval
    matrices: :func:`ivobs.estimators.base.check_system`) and those that do not."""
    from ..estimators.base import check_system

    ok, refused = [], []
    for name in all_methods():
        try:
            check_system(get_method(name), system)
        except IvobsError:
            refused.append(name)
        else:
            ok.append(name)
    return ok, refused


def compare(
    scenario: Scenario,
    methods: Sequence[str] | None = None,
    *,
    disturbance: str = "paper",
    seed: Any = 0,
    burn_in: int | None = None,
    options: dict[str, dict[str, Any]] | None = None,
    trajectory: Trajectory | None = None,
    baselines: Sequence[str] = (),
    strips: bool | None = True,
) -> tuple[Trajectory, list[MethodResult]]:
    """Simulate the scenario once and run every method on the same record.

    ``strips``: every box of ``x[k]`` met with the measurement strips of ``y[k]``
    (:mod:`ivobs.estimators.measured`; the prediction-form observers too, so that no measured
    state is wider than its sensor's band); ``None``: each method's default. An option given
    in ``options`` wins.

    A method that cannot be designed for the system (``DesignError``, or unsupported system
    class) is reported with its reason instead of a result. ``baselines`` (``"kalman"``:
    :mod:`~ivobs.report.baseline`) add rows that are **not guaranteed**, after the methods; a
    baseline the system cannot have is an :class:`IvobsError`, before any method runs.
    """
    from .baseline import BASELINES, check_baseline

    for name in baselines:
        check_baseline(name, scenario.system)
    traj = trajectory if trajectory is not None else scenario.simulate(disturbance, seed)
    names = list(all_methods() if methods is None else methods)
    burn = scenario.horizon // 10 if burn_in is None else int(burn_in)
    truth = traj.x if traj.has_truth else None
    t = traj.t if scenario.system.is_continuous else None
    out: list[MethodResult] = []
    for name in names:
        get_method(name)  # unknown names fail loudly, not as a table row
        opts = dict((options or {}).get(name, {}))
        if strips is not None:
            opts = {"strips": strips, **opts}
        res = MethodResult(method=name, options=opts)
        try:
            res.timed(partial(make_estimator, name, scenario.system, x0=scenario.x0, **opts),
                      lambda est: est.run(traj.u, traj.y, t=t))  # fmt: skip
        except IvobsError as exc:
            res.error = f"{type(exc).__name__}: {exc}"
        else:
            res.measure(truth, burn)
        out.append(res)
    for name in baselines:
        c0, t0 = time.process_time(), time.perf_counter()
        band = BASELINES[name](scenario.system, scenario.x0, traj.u, traj.y)
        res = MethodResult(method=band.method, estimate=band, guaranteed=False, design_time=0.0)
        res.run_time, res.cpu_time = time.perf_counter() - t0, time.process_time() - c0
        res.measure(truth, burn)
        out.append(res)
    return traj, out


def markdown_table(
    results: Sequence[MethodResult],
    state_names: Sequence[str] | None = None,
    reference: str | None = None,
) -> str:
    """A Markdown table: mean width per state, containment, design and run time (wall clock),
    and the CPU time of design and run together (the figure to compare methods by on a loaded
    machine).

    With ``reference`` (a method name among the results, e.g. ``"exact"``), a column gives the
    mean over states of each method's width ratio to it.
    """
    ok = [r for r in results if r.ok and r.mean_width is not None]
    first = ok[0].mean_width if ok else None
    nx = first.shape[0] if first is not None else 0
    names = list(state_names) if state_names else [f"x{i + 1}" for i in range(nx)]
    ref = next((r for r in ok if r.method == reference), None) if reference else None
    head = ["method"] + [f"width {n}" for n in names] + ([f"ratio to {reference}"] if ref else [])
    head += ["contains truth", "design (s)", "run (s)", "CPU design + run (s)"]
    point = _point_states(ref) if ref is not None else None
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
        label = r.method if r.guaranteed else f"{r.method} (NOT guaranteed)"
        cells = [label] + [f"{w:.4g}" for w in r.mean_width]
        if ref is not None:
            cells.append(_ratio_cell(r, ref, point))
        seen = {True: "yes", False: "**NO**", None: "n/a"}[r.contains]
        if r.contains is False and r.misses is not None:
            seen += f" ({r.misses} of {r.estimate.T} steps)" if r.estimate is not None else ""
        cells += [seen, f"{r.design_time:.3f}", f"{r.run_time:.4f}", f"{r.cpu_time:.4f}"]
        lines.append("| " + " | ".join(cells) + " |")
    if not all(r.guaranteed for r in results):
        lines.append(
            "\nNOT guaranteed: a Kalman filter's mean ± 3σ, the bounded signals taken as "
            "uniform; its misses are expected (what the guarantee costs is the difference in "
            "width)."
        )
    if point is not None and point.any():
        which = "every state" if point.all() else ", ".join(n for n, p in zip(names, point) if p)
        lines.append(
            f"\nRatios leave out {which}: there the {reference} box is (numerically) a point "
            f"(mean width below {POINT_TOL:g} (1 + |x|)), so a ratio would compare rounding "
            "margins, not methods ('point' when no state is left)."
        )
    return "\n".join(lines)


POINT_TOL = 1e-6
"""A reference box narrower than ``POINT_TOL (1 + |x|)`` on average is a point for the ratios."""


def _point_states(ref: MethodResult) -> np.ndarray:
    """States where the reference's mean width is below ``POINT_TOL (1 + |x|)`` (``|x|``: the
    largest magnitude of its bounds)."""
    assert ref.estimate is not None and ref.mean_width is not None
    est = ref.estimate
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN columns (before valid_from)
        mag = np.nanmax(np.maximum(np.abs(est.lower), np.abs(est.upper)), axis=0)
    mag = np.where(np.isfinite(mag), mag, 0.0)
    return ref.mean_width < POINT_TOL * (1.0 + mag)


def _ratio_cell(r: MethodResult, ref: MethodResult, point: np.ndarray | None) -> str:
    """Mean over states of ``r``'s width over the reference's, states at a point left out."""
    assert r.mean_width is not None and ref.mean_width is not None
    keep = ~point if point is not None else np.ones(ref.mean_width.shape, dtype=bool)
    keep &= ref.mean_width > 0
    if not keep.any():
        return "point"
    return f"{np.mean(r.mean_width[keep] / ref.mean_width[keep]):.3f}"
