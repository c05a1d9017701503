"""``ivobs demo``: every available method on the servo motor, a table and a figure."""

from __future__ import annotations

import argparse
import os
from typing import Any

from ..scenarios import DISTURBANCES
from . import check_disturbance, check_out_dir, check_seed
from .compare import default_methods, print_table


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "demo",
        help="run every method on the servo motor [Tang2019] and compare",
        description="Run every available method on the DC servo motor of [Tang2019], print a "
        "table of mean widths and containment, and write a figure.",
    )
    p.add_argument("--out", default="ivobs-demo", help="output folder (default: ./ivobs-demo)")
    p.add_argument("--scenario", default="servo-motor", help="scenario (default: servo-motor)")
    p.add_argument(
        "--disturbance",
        default="vertex",
        help=f"{' | '.join(DISTURBANCES)} (default: vertex, the adversarial case)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed for vertex/uniform (>= 0)")
    return p


def main(args: argparse.Namespace) -> int:
    from . import use_agg

    use_agg()
    from .. import scenarios
    from ..report import compare
    from ..report.plot import plot_estimates, save_figure

    check_disturbance(args.disturbance)
    check_seed(args.seed)
    check_out_dir(args.out, "--out")
    sc = scenarios.get(args.scenario)
    names, left_out = default_methods(sc)
    traj, results = compare(sc, names, disturbance=args.disturbance, seed=args.seed)
    print(f"# {sc.name}: {sc.source}")
    print(
        f"# {sc.horizon} steps, {args.disturbance} disturbances (seed {args.seed}); mean widths "
        f"after a burn-in of {sc.horizon // 10} steps"
    )
    if left_out:
        print(f"# {sc.system.nx} states: {', '.join(left_out)} left out (slow at this size)")
    print_table(results, sc.state_names)
    os.makedirs(args.out, exist_ok=True)
    good = {r.method: r.estimate for r in results if r.estimate is not None}
    has_truth = traj.has_truth
    if good:
        fig = plot_estimates(
            good,
            truth=traj.x if has_truth else None,
            t=traj.t,
            state_names=sc.state_names,
            title=f"{sc.name}: guaranteed bounds" + (" minus the true state" if has_truth else ""),
            relative=has_truth,
        )
        path = save_figure(fig, os.path.join(args.out, f"{sc.name}.png"))
        print(f"\nfigure: {path}")
    return 1 if any(r.ok and r.contains is False for r in results) else 0
