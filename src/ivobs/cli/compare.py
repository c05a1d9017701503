"""``ivobs compare SCENARIO``: several methods on one record, a table and an overlay figure."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "compare", help="compare methods on a scenario (table + overlay figure)",
        description="Simulate a scenario once, run several methods on the same record and print "
                    "their mean widths (and ratio to the exact hull when 'exact' is among them), "
                    "containment and timings; optionally write an overlay figure like the papers'.",
    )
    p.add_argument("scenario", help="scenario name (see `ivobs scenarios`)")
    p.add_argument("--methods", help="comma-separated method names (default: all but intersect)")
    p.add_argument("--disturbance", default="paper",
                   help="paper | vertex | uniform | sinusoidal | zero | recorded (CORA)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--burn-in", type=int, default=None, help="steps excluded from mean widths")
    p.add_argument("--plot", metavar="FILE", help="write an overlay figure (PNG)")
    p.add_argument("--states", help="comma-separated state indices to plot (1-based)")
    return p


def main(args: argparse.Namespace) -> int:
    from .. import scenarios
    from ..estimators import methods as all_methods
    from ..report import compare, markdown_table

    sc = scenarios.get(args.scenario)
    names = ([m.strip() for m in args.methods.split(",") if m.strip()] if args.methods
             else [m for m in all_methods() if m != "intersect"])
    traj, results = compare(sc, names, disturbance=args.disturbance, seed=args.seed,
                            burn_in=args.burn_in)
    burn = sc.horizon // 10 if args.burn_in is None else args.burn_in
    print(f"# {sc.name}: {sc.source}")
    print(f"# {sc.horizon} steps, {args.disturbance} disturbances, burn-in {burn} steps\n")
    ref = "exact" if any(r.method == "exact" and r.ok for r in results) else None
    print(markdown_table(results, sc.state_names, reference=ref))
    if args.plot:
        from . import use_agg

        use_agg()
        from ..plot import plot_estimates, save_figure

        states = ([int(s) - 1 for s in args.states.split(",")] if args.states else None)
        good = {r.method: r.estimate for r in results if r.ok}
        truth = None if np.isnan(traj.x).all() else traj.x
        fig = plot_estimates(good, truth=truth, states=states, t=traj.t,
                             state_names=sc.state_names, title=f"{sc.name}")
        save_figure(fig, args.plot)
        print(f"\nfigure: {args.plot}")
    return 1 if any(r.ok and r.contains is False for r in results) else 0
