"""``ivobs figures``: regenerate the papers' figures, and one per nonlinear or uncertain scenario,
into a folder (``--paper`` takes reference keys: Wang2020, Tang2019, Efimov2013, Dinh2024, in any
case; ``--scenario`` scenario names; ``--list`` prints what each selection draws)."""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

from . import check_out_dir


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "figures",
        help="regenerate the papers' figures (and the scenarios') as PNG files",
        description="Redraw the figures of the papers ivobs implements (Wang2020: fixed-time; "
        "Tang2019: reachability, zonotope, interval observers; Efimov2013: interval observers, "
        "Hénon map; Dinh2024: KKL observers) with ivobs' methods, one PNG per figure, and one "
        "figure per nonlinear or uncertain scenario (the true state and the bounds of every "
        "method that accepts the system). Each figure checks that its bounds contain the true "
        "state. With neither --paper nor --scenario: every figure. What differs from the "
        "papers: docs/figures.md.",
    )
    p.add_argument("--out", metavar="DIR", help="output folder (created); required unless --list")
    p.add_argument(
        "--paper",
        default=None,
        metavar="LIST",
        help="comma-separated reference keys, any case, e.g. Wang2020,Dinh2024 "
        "(Wang2020,Tang2019,Efimov2013,Dinh2024)",
    )
    p.add_argument(
        "--scenario",
        default=None,
        metavar="LIST",
        help="comma-separated scenario names, e.g. henon-nl,cstr (henon-nl, pendulum-nl, "
        "cora-tank6-nl, cstr, unicycle-range, chain10-nl, servo-uncertain; henon: its "
        "Remark-1 observer against the nonlinear methods)",
    )
    p.add_argument("--list", action="store_true", help="print the selected figures' files and stop")
    return p


def main(args: argparse.Namespace) -> int:
    from ..errors import IvobsError

    papers = None if args.paper is None else [p for p in args.paper.split(",") if p.strip()]
    chosen = None if args.scenario is None else [s for s in args.scenario.split(",") if s.strip()]
    from ..report.figures import figure_specs  # validates both lists before any work

    specs = figure_specs(papers, name="--paper", scenarios=chosen, scenarios_name="--scenario")
    if args.list:
        for s in specs:
            print(f"{s.stem}.png  ({s.paper or 'scenario ' + s.scenario})")
        return 0
    if args.out is None:
        raise IvobsError("--out: give the output folder (or --list to see the figures)")
    from . import use_agg

    use_agg()
    from ..io.atomic import check_distinct
    from ..report.figures import generate

    check_out_dir(args.out, "--out")
    # the figures' files through the one output guard: no two of them one file (links)
    check_distinct({f"--out's {s.stem}.png": Path(args.out) / f"{s.stem}.png" for s in specs})
    t0 = time.perf_counter()
    try:
        paths = generate(args.out, papers, scenarios=chosen, verbose=True)
    except OSError as exc:  # e.g. a full disk
        where = exc.filename or args.out
        raise IvobsError(f"--out: cannot write {str(where)!r}: {exc.strerror or exc}") from None
    print(f"{len(paths)} figure(s) in {time.perf_counter() - t0:.1f} s")
    return 0
