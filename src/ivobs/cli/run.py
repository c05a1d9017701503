"""``ivobs run``: one method on a scenario, or on your own system and measurement log.

* ``ivobs run SCENARIO --method M [--csv R.csv] [--plot P.png]``: simulate a paper example.
* ``ivobs run --system F.toml --log L.csv [--method M] --out R.csv [--plot P.png]``: your plant
  (system file) and your data (log); missing samples are predicted through, alarms reported.

Output files are written to a temporary file and renamed: an error never leaves a half-written
file behind.
"""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..io.plant import check_log_times, discretized
from ..scenarios import DISTURBANCES
from . import (
    add_option_argument,
    add_trust_option,
    check_disturbance,
    check_outputs,
    check_seed,
    parse_options,
)
from ._plant import add_plant_options, add_truth_option, plant_inputs


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "run",
        help="run one method on a scenario, or on a system file and a log",
        description="Simulate a scenario (or read a system file and a measurement log), run one "
        "method, print a summary; optionally write the bounds as CSV and a figure.",
    )
    p.add_argument("scenario", nargs="?", help="scenario name (see `ivobs scenarios`)")
    add_plant_options(p, horizon=False)
    add_truth_option(p)
    p.add_argument(
        "--method",
        "-m",
        help="method name (see `ivobs methods`; with --system, default: the file's [method])",
    )
    add_option_argument(p, per_method=False)
    p.add_argument(
        "--disturbance",
        default=None,
        help=f"scenario only: {' | '.join(DISTURBANCES)} (recorded: the stored record of the "
        "cora-* scenarios; default: paper)",
    )
    p.add_argument(
        "--seed", type=int, default=None, help="scenario only: random seed for vertex/uniform"
    )
    p.add_argument(
        "--csv", "--out", "-o", dest="csv", metavar="FILE", help="write the bounds to this CSV file"
    )
    p.add_argument(
        "--plot",
        metavar="FILE",
        help="write a figure of the bounds (format from the extension; none: .png is added)",
    )
    p.add_argument(
        "--html",
        metavar="FILE",
        help="write a self-contained interactive HTML report (zoomable bands, alarms; needs "
        "plotly: ivobs[html])",
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        help="also write a summary as JSON, as `ivobs compare --json` does (the method, its "
        "options, mean widths per state, steps, inconsistent steps, containment or null, "
        "timings; '-' for standard output)",
    )
    add_trust_option(p)
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress bar (default: on a terminal only)",
    )
    return p


def main(args: argparse.Namespace) -> int:
    from ..io.atomic import check_distinct

    outputs = check_outputs(args, ("csv", "plot", "html", "json"))
    check_distinct(outputs, plant_inputs(args))
    if args.system:
        if args.scenario:
            raise IvobsError(f"give either a scenario ({args.scenario!r}) or --system, not both")
        if args.disturbance is not None or args.seed is not None:
            raise IvobsError(
                "--disturbance/--seed: only with a scenario (a log gives the measurements)"
            )
        return _run_system(args, outputs)
    if args.log or args.truth or args.discretize is not None or args.held_disturbances:
        raise IvobsError(
            "--log/--truth/--discretize: need --system FILE (the model of the logged plant; a "
            "scenario's simulated record has its own true state)"
        )
    if not args.scenario:
        raise IvobsError("give a scenario name (see `ivobs scenarios`) or --system FILE --log FILE")
    if not args.method:
        raise IvobsError("--method: required with a scenario (see `ivobs methods`)")
    args.disturbance = check_disturbance(args.disturbance or "paper")
    args.seed = check_seed(0 if args.seed is None else args.seed)
    return _run_scenario(args)


def _check_time_base(system: Any, method: str, where: str) -> None:
    """A continuous-time file with a discrete-time method: point to ``--discretize``."""
    from ..estimators import get, methods

    if system.is_continuous and not get(method).supports_continuous:
        continuous = [m for m in methods() if get(m).supports_continuous]
        raise IvobsError(
            f"--method: {method} is for discrete-time systems and {where} is continuous-time "
            f"(dt = 0): give --discretize TS (the log's sampling period) or a continuous-time "
            f"method ({', '.join(continuous)})"
        )


def _run(design: Any, u: Any, y: Any, t: Any, args: argparse.Namespace, opts: Any) -> Any:
    """The estimator ``design()`` and its run (:func:`_estimate`) as a row of ``ivobs
    compare``'s table: the estimate, the times and the options."""
    from ..report import MethodResult

    r = MethodResult("", options=opts)
    est = r.timed(design, lambda est: _estimate(est, u, y, t, args))
    r.method = est.name
    return est, r


def _summary(
    args: argparse.Namespace, r: Any, name: str, source: str, burn: int, **kw: Any
) -> None:
    """``--json``: the summary ``ivobs compare --json`` writes, with this one method."""
    if args.json:
        from ._summary import summary_document, write_json

        doc = summary_document(name, source, [r], horizon=r.estimate.T, burn_in=burn, **kw)
        write_json(args.json, doc)


def _contained(r: Any) -> str:
    """The summary's line on containment."""
    if r.contains is None:
        return "n/a (no recorded true state)"
    return "yes" if r.contains else f"NO ({r.misses} of {r.estimate.T} steps)"


def _run_scenario(args: argparse.Namespace) -> int:
    from .. import scenarios
    from ..estimators import make_estimator

    sc = scenarios.get(args.scenario)
    traj = sc.simulate(args.disturbance, args.seed)
    opts = parse_options(args.option, [args.method]).get(args.method, {})
    _, r = _run(
        lambda: make_estimator(args.method, sc.system, x0=sc.x0, **opts),
        traj.u, traj.y, traj.t if sc.system.is_continuous else None, args, opts,
    )  # fmt: skip
    res, truth, burn = r.estimate, traj.x if traj.has_truth else None, sc.horizon // 10
    r.measure(truth, burn)
    print(f"{args.method} on {sc.name} ({sc.source})")
    print(f"steps: {res.T}, valid from step {res.valid_from}")
    if r.mean_width is not None:
        print("mean width per state: " + ", ".join(f"{w:.4g}" for w in r.mean_width))
    print(f"contains the true state at every step: {_contained(r)}")
    _summary(args, r, sc.name, sc.source, burn, state_names=sc.state_names)
    title = f"{args.method} on {sc.name}"
    _write(res, args, truth=truth, t=traj.t, state_names=sc.state_names, title=title)
    return 1 if r.contains is False else 0


def _run_system(args: argparse.Namespace, outputs: dict[str, Any]) -> int:
    from ..io.atomic import check_distinct
    from ..io.logs import read_log
    from ..io.systemfile import load_system
    from ..model import NonlinearSystem
    from ..monitor import Monitor

    if not args.log:
        raise IvobsError("--system: needs --log FILE (a CSV log with k, u1.., y1.. columns)")
    spec = load_system(args.system, allow_code=args.allow_code)
    spec.system = discretized(
        spec.system, args.discretize, args.system, held=args.held_disturbances
    )
    check_distinct(outputs, plant_inputs(args, spec))
    log = read_log(args.log, spec.system, start=spec.x0_step)
    if args.discretize is not None:
        check_log_times(log.t, args.discretize, args.log)
    truth = None
    if args.truth:
        from ..io.truth import read_truth

        truth = read_truth(args.truth, spec.system, log, what="--truth")
    method = args.method or spec.method
    if method is None:
        raise IvobsError(
            f"--method: {args.system} names no method ([method] name = ...); give --method"
        )
    _check_time_base(spec.system, method, args.system)
    if spec.system.is_continuous and log.t is None:
        raise IvobsError(
            f"{args.log}: the system is continuous-time (dt = 0): the log needs a time column t"
        )
    opts = parse_options(args.option, [method]).get(method, {})

    def design() -> Any:
        est = spec.make_estimator(method, **opts)
        est.on_inconsistent = "ignore"  # reported below, once, as ALARMS (from the Monitor)
        return est

    # a discrete-time system counts steps: a time column only labels the rows of the output
    t = log.t if spec.system.is_continuous else None
    est, r = _run(design, log.u, log.y, t, args, opts)
    res = r.estimate
    if isinstance(spec.system, NonlinearSystem) or spec.system.is_uncertain:
        # the monitor's bands need a linear model with exact matrices: the method's own
        # inconsistency reports are the alarms
        alarms = np.flatnonzero(res.inconsistent)
        reasons = {int(k): f"{est.name}: no state in the box is consistent with y" for k in alarms}
    else:
        record = Monitor(spec.system, est, x0=spec.x0).check(log.u, log.y, t=t, estimate=res)
        alarms = np.flatnonzero(record.alarm)
        reasons = {int(k): record.reasons[int(k)] for k in alarms[:1]}
    res.t = log.t
    res.info["first_step"] = log.start  # the output's k: the log's steps
    name = spec.name or args.system
    print(f"{est.name} on {name} ({args.log})")
    print(f"steps: {res.T}, valid from step {res.valid_from}")
    skipped = 0 if log.filled is None else int(np.sum(log.filled))
    gaps = f" ({skipped} skipped by the log)" if skipped else ""
    print(f"missing samples: {int(np.sum(log.missing))} step(s) with a missing measurement{gaps}")
    r.measure(truth, 0)
    if r.mean_width is not None:
        print("mean width per state: " + ", ".join(f"{w:.4g}" for w in r.mean_width))
    if truth is not None:
        print(f"contains the true state at every step: {_contained(r)}")
    if alarms.size:
        k0 = log.start  # rows are steps from the prior's
        shown = ", ".join(str(int(k) + k0) for k in alarms[:10])
        shown += " ..." if alarms.size > 10 else ""
        print(f"ALARMS: {alarms.size} step(s) inconsistent with the model: {shown}")
        print(f"first: step {int(alarms[0]) + k0}: {reasons[int(alarms[0])]}")
        episodes = _print_episodes(spec, est, log, t, k0)
    else:
        episodes = []
        print("alarms: none (every measurement is consistent with the model and bounds)")
    labels = spec.system.names.state_labels()
    _summary(args, r, name, f"{args.system} + {args.log}", 0, state_names=labels,
             first_step=log.start, inconsistent={r.method: alarms})  # fmt: skip
    _write(
        res,
        args,
        truth=truth,
        t=log.t,
        alarms=alarms,
        episodes=episodes,
        title=f"{est.name} on {name}",
        state_names=labels,
    )
    return 1 if alarms.size or r.contains is False else 0


def _print_episodes(spec: Any, est: Any, log: Any, t: Any, k0: int) -> list[str]:
    """The log's fault episodes as the online monitor sees them (the faulty outputs left
    out of the estimate, the alarm latched, each sensor fault isolated and its bias
    estimated): a persistent fault is one episode, not the few steps where it contradicts the
    method's estimate. Returns the lines (for the HTML report)."""
    from ..monitor import Monitor

    record = Monitor(spec.system, est, x0=spec.x0).run(log.u, log.y, t=t)
    print(f"fault episodes (ivobs monitor, the faulty outputs left out): {len(record.faults)}")
    lines = []
    for f in record.faults[:10]:
        end = "open at the end of the log" if f.end is None else f"cleared at step {f.end + k0}"
        line = f"from step {f.start + k0}, {f.duration} step(s), {end}: {f.names or '-'}"
        line += f"; isolated: {f.isolation}" if f.isolation else ""
        lines.append(line + (f"; bias {f.bias_text}" if f.bias_text else ""))
        print(f"  {lines[-1]}")
    return lines


def _estimate(est: Any, u: Any, y: Any, t: Any, args: argparse.Namespace) -> Any:
    """``est.run`` with a progress bar on a terminal for the step-by-step path (the ``exact``
    method draws its own)."""
    if "progress" in type(est).options():
        if args.progress is not None:
            est.progress = args.progress
        return est.run(u, y, t=t)
    return est.run(u, y, t=t, progress=args.progress)


def _write(
    res: Any,
    args: argparse.Namespace,
    truth: Any = None,
    alarms: Any = None,
    episodes: Any = (),
    **plot_kw: Any,
) -> None:
    if args.csv:
        res.to_csv(args.csv)
        print(f"bounds written to {args.csv}")
    if args.plot:
        from . import use_agg

        use_agg()
        from ..report.plot import plot_estimates, save_figure

        fig = plot_estimates({res.method: res}, truth=truth, **plot_kw)
        path = save_figure(fig, args.plot)
        print(f"figure written to {path}")
    if args.html:
        from ..report.html import html_report

        if alarms is None:
            alarms = np.flatnonzero(res.inconsistent)
        page = html_report(
            args.html,
            {res.method: res},
            title=plot_kw.get("title") or res.method,
            truth=truth,
            t=plot_kw.get("t"),
            state_names=plot_kw.get("state_names"),
            alarms=[int(k) for k in alarms],
            episodes=list(episodes),
        )
        print(f"report written to {page}")
