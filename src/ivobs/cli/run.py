"""``ivobs run SCENARIO --method M``: one method on one scenario."""

from __future__ import annotations

import argparse
from typing import Any

import numpy as np


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "run",
        help="run one method on a scenario",
        description="Simulate a scenario, run one method, print a summary; optionally write the "
        "bounds as CSV and a figure.",
    )
    p.add_argument("scenario", help="scenario name (see `ivobs scenarios`)")
    p.add_argument("--method", "-m", required=True, help="method name (see `ivobs methods`)")
    p.add_argument(
        "--disturbance",
        default="paper",
        help="paper | vertex | uniform | sinusoidal | zero (default: paper)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed for vertex/uniform")
    p.add_argument("--csv", metavar="FILE", help="write the bounds to this CSV file")
    p.add_argument("--plot", metavar="FILE", help="write a figure (PNG) of the bounds")
    return p


def main(args: argparse.Namespace) -> int:
    from .. import scenarios
    from ..estimators import make_estimator

    sc = scenarios.get(args.scenario)
    traj = sc.simulate(args.disturbance, args.seed)
    est = make_estimator(args.method, sc.system, x0=sc.x0)
    res = est.run(traj.u, traj.y, t=traj.t if sc.system.is_continuous else None)
    ok = res.contains(traj.x)
    burn = sc.horizon // 10
    mw = res.mean_width(max(burn, res.valid_from))
    print(f"{args.method} on {sc.name} ({sc.source})")
    print(f"steps: {res.T}, valid from step {res.valid_from}")
    print("mean width per state: " + ", ".join(f"{w:.4g}" for w in mw))
    print(f"contains the true state at every step: {'yes' if np.all(ok) else 'NO'}")
    if args.csv:
        res.to_csv(args.csv)
        print(f"bounds written to {args.csv}")
    if args.plot:
        from . import use_agg

        use_agg()
        from ..plot import plot_estimates, save_figure

        fig = plot_estimates(
            {args.method: res},
            truth=traj.x,
            t=traj.t,
            state_names=sc.state_names,
            title=f"{args.method} on {sc.name}",
        )
        save_figure(fig, args.plot)
        print(f"figure written to {args.plot}")
    return 0 if np.all(ok) else 1
