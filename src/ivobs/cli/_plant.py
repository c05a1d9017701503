"""Your own plant on the commands that take a scenario: ``--system FILE`` (a system file), with
``--log FILE`` (its measurements) or a simulation from the file's prior box, and
``--discretize TS`` for a continuous-time file."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import IvobsError

__all__ = ["add_plant_options", "add_truth_option", "plant_inputs", "plant_scenario"]


def add_plant_options(p: argparse.ArgumentParser, *, horizon: bool = True) -> None:
    """``--system``, ``--log``, ``--horizon`` (a simulation when there is no log; ``horizon``
    False: the command needs the log), ``--discretize`` and ``--held-disturbances``."""
    p.add_argument(
        "--system", "-s", metavar="FILE", help="system file (TOML) instead of a scenario"
    )
    p.add_argument("--log", "-l", metavar="FILE", help="measurement log (CSV) for --system")
    if horizon:
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
        help="--system: discretise a continuous-time system (inputs held over each period "
        "TS; disturbances vary between samples unless --held-disturbances); the log's time "
        "column must then be sampled every TS",
    )
    p.add_argument(
        "--held-disturbances",
        action="store_true",
        help="--discretize: the disturbances are held over each period (default: any signal "
        "in their bounds between samples, which the estimates then cover)",
    )


def add_truth_option(p: argparse.ArgumentParser) -> None:
    """``--truth FILE``: the true state of the logged record."""
    p.add_argument(
        "--truth",
        metavar="FILE",
        help="--log: the true state of the logged record (CSV: an optional step k or time t "
        "column, one column per state named by the system's states or x1..xn, one row per "
        "step of the log); containment and the figure's truth line come from it",
    )


def plant_inputs(args: argparse.Namespace, spec: Any = None) -> dict[str, Any]:
    """The files a command on ``--system`` reads, by option: the system file, the log (or the
    monitor's ``--input``), its true state and the bounds files the system file names
    (``spec``: the loaded system file)."""
    inputs = {
        "--system": args.system,
        "--input": getattr(args, "input", None),
        "--log": getattr(args, "log", None),
        "--truth": getattr(args, "truth", None),
    }
    for i, path in enumerate(() if spec is None else spec.files):
        inputs["--system's [disturbance] csv" + (f" {i + 1}" if i else "")] = path
    return inputs


def plant_scenario(args: argparse.Namespace, spec: Any = None) -> Any:
    """The :class:`~ivobs.scenarios.Scenario` of ``--system`` (and ``--log`` or
    ``--horizon``): :func:`ivobs.io.plant.file_scenario` (``spec``: the system file, already
    loaded)."""
    from ..io.plant import file_scenario

    if not getattr(args, "log", None) and getattr(args, "horizon", None) is None:
        raise IvobsError(
            "--system: give --log FILE (measurements) or --horizon N (simulate N steps from "
            "the file's prior box)"
        )
    return file_scenario(
        spec if spec is not None else args.system,
        log=getattr(args, "log", None),
        horizon=getattr(args, "horizon", None),
        discretize=args.discretize,
        held_disturbances=getattr(args, "held_disturbances", False),
        allow_code=getattr(args, "allow_code", False),
        truth=getattr(args, "truth", None),
    )
