"""Your own plant on the commands that take a scenario: ``--system FILE`` (a system file), with
``--log FILE`` (its measurements) or a simulation from the file's prior box, and
``--discretize TS`` for a continuous-time file."""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import IvobsError

__all__ = ["add_plant_options", "check_log_times", "discretized", "plant_scenario"]


def add_plant_options(p: argparse.ArgumentParser, *, log: bool = True) -> None:
    """``--system``, ``--log``, ``--horizon``, ``--discretize`` (and ``--allow-code``)."""
    p.add_argument(
        "--system", "-s", metavar="FILE", help="system file (TOML) instead of a scenario"
    )
    if log:
        p.add_argument("--log", "-l", metavar="FILE", help="measurement log (CSV) for --system")
        p.add_argument(
            "--horizon",
            type=int,
            default=None,
            help="--system without --log: simulate this many steps from the file's prior box "
            "(true initial state: its centre; inputs: zero)",
        )
    p.add_argument(
        "--discretize",
        type=float,
        metavar="TS",
        default=None,
        help="--system: discretise a continuous-time system (zero-order hold, period TS)",
    )


def discretized(system: Any, ts: float | None, where: str) -> Any:
    """``system`` discretised with period ``ts`` (``--discretize``), or unchanged."""
    if ts is None:
        return system
    if not (math.isfinite(ts) and ts > 0):
        raise IvobsError(f"--discretize: expected a sampling period > 0, got {ts!r}")
    if not system.is_continuous:
        raise IvobsError(f"--discretize: {where} is already discrete-time (dt = {system.dt})")
    return system.discretize(ts)


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


def plant_scenario(args: argparse.Namespace, disturbance: str = "vertex", seed: int = 0) -> Any:
    """A :class:`~ivobs.scenarios.Scenario` for ``--system`` (and ``--log``): the log is its
    ``recorded`` trajectory (no true state), or it is simulated for ``--horizon`` steps."""
    from ..io.logs import read_log
    from ..io.systemfile import load_system
    from ..scenarios import Scenario
    from ..simulate import Trajectory

    spec = load_system(args.system, allow_code=getattr(args, "allow_code", False))
    system = discretized(spec.system, args.discretize, args.system)
    if spec.x0 is None:
        raise IvobsError(f"{args.system}: the system file needs a prior box [x0] for this command")
    name = spec.name or Path(args.system).stem
    log_path = getattr(args, "log", None)
    if log_path:
        if getattr(args, "horizon", None) is not None:
            raise IvobsError("--horizon: only without --log (the log sets the horizon)")
        log = read_log(log_path, system)
        if system.is_continuous and log.t is None:
            raise IvobsError(
                f"{log_path}: the system is continuous-time (dt = 0): the log needs a time "
                "column t (or give --discretize TS)"
            )
        if args.discretize is not None:
            check_log_times(log.t, args.discretize, log_path)
        T = log.T
        t = log.t if log.t is not None else np.arange(T) * system.sampling_period
        nan = np.full((T, system.nx), np.nan)
        recorded = Trajectory(x=nan, y=log.y, u=log.u, d=np.full((T, system.nd), np.nan), t=t)
        return Scenario(
            name=name,
            system=system,
            x0=spec.x0,
            x_true0=spec.x0.center,
            u=log.u,
            horizon=T,
            source=f"{args.system} + {log_path}",
            t=log.t if system.is_continuous else None,
            state_names=system.names.state_labels(),
            recorded=recorded,
        )
    horizon = getattr(args, "horizon", None)
    if horizon is None or horizon < 1:
        raise IvobsError(
            "--system: give --log FILE (measurements) or --horizon N (simulate N steps from "
            f"the file's prior box), got horizon {horizon!r}"
        )
    if system.is_continuous:
        raise IvobsError(
            f"{args.system}: a continuous-time system is simulated from a scenario or a log; "
            "give --discretize TS"
        )
    return Scenario(
        name=name,
        system=system,
        x0=spec.x0,
        x_true0=spec.x0.center,
        u=np.zeros((horizon, system.nu)),
        horizon=horizon,
        source=str(args.system),
        state_names=system.names.state_labels(),
    )
