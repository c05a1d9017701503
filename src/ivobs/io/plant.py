"""Your own plant as a :class:`~ivobs.scenarios.Scenario`: a system file with its log (the
measurements) or simulated from the file's prior box. This is how ``ivobs compare --system``
and campaign specs (a scenario entry ending in ``.toml``) run on a user's plant."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..scenarios import Scenario
from ..simulate import Trajectory
from .loaded import SystemFile

__all__ = ["DEFAULT_HORIZON", "check_log_times", "discretized", "file_scenario"]

DEFAULT_HORIZON = 200
"""Steps simulated from a system file when neither a log nor a horizon is given (campaigns)."""


def discretized(system: Any, ts: float | None, where: str, held: bool = False) -> Any:
    """``system`` discretised with period ``ts`` (``--discretize``; disturbances that vary
    between samples, or ``held``: ``--held-disturbances``), or unchanged."""
    if ts is None:
        if held:
            raise IvobsError("--held-disturbances: only with --discretize TS")
        return system
    if not (isinstance(ts, (int, float)) and math.isfinite(ts) and ts > 0):
        raise IvobsError(f"--discretize: expected a sampling period > 0, got {ts!r}")
    if not system.is_continuous:
        raise IvobsError(f"--discretize: {where} is already discrete-time (dt = {system.dt})")
    return system.discretize(float(ts), disturbances="held" if held else "varying")


def check_log_times(t: np.ndarray | None, ts: float, where: str) -> None:
    """A log of a discretised plant must be sampled every ``ts``."""
    if t is None or t.size < 2:
        return
    steps = np.diff(t)
    if not np.allclose(steps, ts, rtol=1e-9, atol=1e-12 * max(1.0, abs(ts))):
        worst = float(steps[np.argmax(np.abs(steps - ts))])
        raise IvobsError(
            f"{where}: the log's time column is not sampled every --discretize {ts:g} "
            f"(a step of {worst:g}); discretise with the log's period"
        )


def file_scenario(
    path: str | os.PathLike[str] | SystemFile,
    *,
    log: str | os.PathLike[str] | None = None,
    horizon: int | None = None,
    discretize: float | None = None,
    allow_code: bool = False,
    held_disturbances: bool = False,
    truth: str | os.PathLike[str] | None = None,
) -> Scenario:
    """The plant of the system file ``path`` as a scenario: with ``log``, the log is its
    ``recorded`` trajectory (its true state from the CSV file ``truth``, read by
    :func:`~ivobs.io.truth.read_truth`, named ``--truth`` in errors; else none); otherwise it
    is simulated for ``horizon`` steps (true initial state: the centre of the prior box
    ``[x0]``, inputs zero). ``path`` may be a system file already loaded."""
    from .logs import read_log
    from .systemfile import load_system

    spec = path if isinstance(path, SystemFile) else load_system(path, allow_code=allow_code)
    path = spec.source or "<system file>"
    system = discretized(spec.system, discretize, str(path), held=held_disturbances)
    if spec.x0 is None:
        raise IvobsError(f"{path}: the system file needs a prior box [x0] for this command")
    name = spec.name or Path(path).stem
    labels = system.names.state_labels()
    if log is not None:
        if horizon is not None:
            raise IvobsError("horizon: only without a log (the log sets the horizon)")
        rec = read_log(log, system, start=spec.x0_step)
        if system.is_continuous and rec.t is None:
            raise IvobsError(
                f"{log}: the system is continuous-time (dt = 0): the log needs a time "
                "column t (or give --discretize TS)"
            )
        if discretize is not None:
            check_log_times(rec.t, discretize, str(log))
        T = rec.T
        t = rec.t if rec.t is not None else np.arange(T) * system.sampling_period
        if truth is not None:
            from .truth import read_truth

            x = read_truth(truth, system, rec, what="--truth")
        else:
            x = np.full((T, system.nx), np.nan)
        recorded = Trajectory(x=x, y=rec.y, u=rec.u, d=np.full((T, system.nd), np.nan), t=t)
        return Scenario(
            name=name, system=system, x0=spec.x0, x_true0=spec.x0.center, u=rec.u, horizon=T,
            source=f"{path} + {log}", t=rec.t if system.is_continuous else None,
            state_names=labels, recorded=recorded,
        )  # fmt: skip
    if truth is not None:
        raise IvobsError(
            "--truth: the true state of a measurement log; give the log too (a simulated "
            "record has its own true state)"
        )
    if horizon is None or isinstance(horizon, bool) or not isinstance(horizon, int) or horizon < 1:
        raise IvobsError(
            "horizon: give a log (measurements) or a number of steps >= 1 to simulate from "
            f"the file's prior box, got {horizon!r}"
        )
    if system.is_continuous:
        raise IvobsError(
            f"{path}: a continuous-time system is simulated from a scenario or a log; "
            "discretise it (--discretize TS)"
        )
    return Scenario(
        name=name, system=system, x0=spec.x0, x_true0=spec.x0.center,
        u=np.zeros((horizon, system.nu)), horizon=horizon, source=str(path), state_names=labels,
    )  # fmt: skip
