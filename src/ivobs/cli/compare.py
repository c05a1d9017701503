"""``ivobs compare SCENARIO``: several methods on one record, a table and an overlay figure."""

from __future__ import annotations

import argparse
from typing import Any

from ..errors import IvobsError
from ..report.baseline import BASELINES
from ..report.comparison import applicable_methods
from ..scenarios import DISTURBANCES
from . import (
    add_option_argument,
    add_trust_option,
    check_disturbance,
    check_outputs,
    check_seed,
    parse_options,
    parse_states,
)
from ._plant import add_plant_options, add_truth_option, plant_inputs, plant_scenario

#: Methods whose cost grows fast with the state dimension (LPs over the horizon, generators):
#: left out of the default set for systems with more than ``LARGE_NX`` states (on heat-1d,
#: nx = 50, 500 steps: ``exact`` takes over an hour, ``zonotope`` and ``reachability`` over a
#: minute each; the others a few seconds to half a minute).
SLOW_METHODS = ("exact", "constrained-zonotope", "strip", "zonotope", "reachability")
LARGE_NX = 20


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "compare",
        help="compare methods on a scenario (table + overlay figure)",
        description="Simulate a scenario once, run several methods on the same record and print "
        "their mean widths (and ratio to the exact hull when 'exact' is among them), "
        "containment and timings; optionally write an overlay figure like the papers'.",
    )
    p.add_argument("scenario", nargs="?", help="scenario name (see `ivobs scenarios`)")
    add_plant_options(p)
    add_truth_option(p)
    add_trust_option(p)
    p.add_argument(
        "--methods",
        help="comma-separated method names (default: all but intersect; "
        f"for more than {LARGE_NX} states also without "
        f"{', '.join(SLOW_METHODS)})",
    )
    p.add_argument(
        "--disturbance",
        default=None,
        help=f"{' | '.join(DISTURBANCES)} (recorded: cora-* scenarios and --log; default: "
        "paper, or vertex for --system --horizon)",
    )
    p.add_argument(
        "--baseline",
        choices=list(BASELINES),
        help="add a row that is NOT guaranteed, to see what the guarantee costs: kalman, a "
        "Kalman filter's mean ± 3σ (bounded signals taken as uniform, variance r²/3; linear "
        "models with exact matrices); its misses of the true state are counted, not failures",
    )
    add_option_argument(p, per_method=True)
    p.add_argument("--seed", type=int, default=0, help="random seed for vertex/uniform (>= 0)")
    p.add_argument(
        "--burn-in",
        type=int,
        default=None,
        help="steps excluded from mean widths (default: a tenth of the horizon)",
    )
    p.add_argument(
        "--plot",
        metavar="FILE",
        help="write an overlay figure (format from the extension; none: .png is added)",
    )
    p.add_argument("--states", help="comma-separated state numbers to plot (1..nx)")
    p.add_argument(
        "--html",
        metavar="FILE",
        help="write a self-contained interactive HTML report (zoomable bands per state, the "
        "method table; needs plotly: ivobs[html])",
    )
    p.add_argument(
        "--json",
        metavar="FILE",
        help="also write the table as JSON (one object per method; '-' for standard output)",
    )
    return p


def _scenario(args: argparse.Namespace, outputs: dict[str, Any]) -> Any:
    """The scenario, or the plant of ``--system`` (its log as the recorded trajectory); the
    outputs are checked against every file read first."""
    from .. import scenarios
    from ..io.atomic import check_distinct

    if args.system:
        from ..io.systemfile import load_system

        if args.scenario:
            raise IvobsError(f"give either a scenario ({args.scenario!r}) or --system, not both")
        if args.log and args.disturbance not in (None, "recorded"):
            raise IvobsError("--disturbance: with --log the measurements are the log's")
        args.disturbance = "recorded" if args.log else args.disturbance or "vertex"
        check_disturbance(args.disturbance)
        spec = load_system(args.system, allow_code=args.allow_code)
        args._spec = spec
        check_distinct(outputs, plant_inputs(args, spec))
        return plant_scenario(args, spec)
    check_distinct(outputs)
    if args.truth:
        raise IvobsError(
            "--truth: the true state of a measurement log; give --system FILE --log FILE (a "
            "scenario's simulated record has its own true state)"
        )
    if args.log or args.horizon is not None or args.discretize is not None:
        raise IvobsError("--log/--horizon/--discretize: need --system FILE")
    if args.held_disturbances:
        raise IvobsError("--held-disturbances: needs --system FILE and --discretize TS")
    if not args.scenario:
        raise IvobsError("give a scenario name (see `ivobs scenarios`) or --system FILE")
    args.disturbance = check_disturbance(args.disturbance or "paper")
    return scenarios.get(args.scenario)


def default_methods(sc: Any) -> tuple[list[str], list[str]]:
    """The default methods for scenario ``sc`` (those that accept its model) and those left out
    for its size."""
    names = [m for m in applicable_methods(sc.system)[0] if m != "intersect"]
    if sc.system.nx <= LARGE_NX:
        return names, []
    return [m for m in names if m not in SLOW_METHODS], [m for m in names if m in SLOW_METHODS]


def _model_kind(system: Any) -> str:
    """A few words on what makes methods refuse ``system``."""
    from ..model import NonlinearSystem

    kinds = ["nonlinear" if isinstance(system, NonlinearSystem) else "linear"]
    if system.is_continuous:
        kinds.append("continuous-time")
    if getattr(system, "is_time_varying", False):
        kinds.append("time-varying")
    if getattr(system, "is_uncertain", False):
        kinds.append("interval matrices")
    return ", ".join(kinds)


def main(args: argparse.Namespace) -> int:
    from ..report import compare

    check_seed(args.seed)
    sc = _scenario(args, check_outputs(args, ("json", "html", "plot")))
    states = parse_states(args.states, sc.system.nx) if args.states else None
    if args.states and not args.plot:
        raise IvobsError("--states: selects the states of the figure; give --plot FILE too")
    if args.burn_in is not None and not 0 <= args.burn_in < sc.horizon:
        raise IvobsError(
            f"--burn-in: expected a number of steps in 0..{sc.horizon - 1} "
            f"({sc.name} has {sc.horizon} steps), got {args.burn_in}"
        )
    left_out: list[str] = []
    if args.methods:
        names = [m.strip() for m in args.methods.split(",") if m.strip()]
        if not names:
            raise IvobsError(
                f"--methods: expected comma-separated method names, got {args.methods!r}"
            )
    else:
        names, left_out = default_methods(sc)
    refused = [] if args.methods else applicable_methods(sc.system)[1]
    options = _options(args, names)
    traj, results = compare(
        sc,
        names,
        disturbance=args.disturbance,
        seed=args.seed,
        burn_in=args.burn_in,
        options=options,
        baselines=[args.baseline] if args.baseline else [],
    )
    burn = sc.horizon // 10 if args.burn_in is None else args.burn_in
    print(f"# {sc.name}: {sc.source}")
    print(f"# {sc.horizon} steps, {args.disturbance} disturbances, burn-in {burn} steps")
    if left_out:
        print(
            f"# {sc.system.nx} states: {', '.join(left_out)} left out (slow at this size); "
            f"include them with --methods {','.join(names + left_out)}"
        )
    if refused:
        print(f"# not for this model ({_model_kind(sc.system)}): {', '.join(refused)}")
    print_table(results, sc.state_names)
    if args.json:
        from ._summary import summary_document, write_json

        spec = getattr(args, "_spec", None)
        doc = summary_document(sc.name, sc.source, results, horizon=sc.horizon, burn_in=burn,
                               state_names=sc.state_names,
                               first_step=0 if spec is None else spec.x0_step)  # fmt: skip
        write_json(args.json, doc)
    if args.html:
        _write_html(args.html, sc, traj, results)
    if args.plot is not None:
        from . import use_agg

        use_agg()
        from ..report.compare_figure import comparison_figure
        from ..report.plot import save_figure

        truth = traj.x if traj.has_truth else None
        fig = comparison_figure(
            _estimates(results, "--plot"),
            truth=truth,
            states=states,
            t=traj.t if sc.system.sampling_period != 1 or sc.t is not None else None,
            state_names=sc.state_names,
            title=sc.name,
        )
        print(f"\nfigure: {save_figure(fig, args.plot)}")
    return 1 if any(r.ok and r.guaranteed and r.contains is False for r in results) else 0


def _estimates(results: Any, what: str) -> dict[str, Any]:
    """The estimates to draw, by label (a baseline's says it is not guaranteed); none at all
    is an error of the option ``what``."""
    good = {
        r.method if r.guaranteed else f"{r.method} (NOT guaranteed)": r.estimate
        for r in results
        if r.estimate is not None
    }
    if not good:
        raise IvobsError(f"{what}: no method gave an estimate; nothing to draw")
    return good


def _options(args: argparse.Namespace, names: list[str]) -> dict[str, dict[str, Any]]:
    """The design options per method: a system file's ``[method.options]`` for its method (as
    ``ivobs run`` and ``load_system(...).make_estimator()`` use them), then ``--option``."""
    from ..io.options import same_method

    out: dict[str, dict[str, Any]] = {}
    spec = getattr(args, "_spec", None)
    if spec is not None and spec.method and spec.options:
        for name in names:
            if same_method(name, spec.method):
                out[name] = dict(spec.options)
    for name, opts in parse_options(args.option, names).items():
        out.setdefault(name, {}).update(opts)
    return out


def _write_html(path: str, sc: Any, traj: Any, results: Any) -> None:
    from ..report.html import html_report, results_table

    page = html_report(
        path,
        _estimates(results, "--html"),
        title=f"ivobs compare: {sc.name}",
        truth=traj.x if traj.has_truth else None,
        t=traj.t,
        state_names=sc.state_names,
        table=results_table(results, sc.state_names),
        notes=[f"{sc.source}; {sc.horizon} steps"],
    )
    print(f"\nreport: {page}")


def print_table(results: Any, state_names: Any) -> None:
    """The methods' table (ratios to ``exact`` when it gave a result), after a blank line, and
    the full reason of every method without a result (the table's cell is cut short)."""
    from ..report import markdown_table

    print()
    ref = "exact" if any(r.method == "exact" and r.ok for r in results) else None
    print(markdown_table(results, state_names, reference=ref))
    failed = [r for r in results if not r.ok and r.error]
    if failed:
        print()
        for r in failed:
            print(f"{r.method}: {r.error}")
