"""``ivobs figures``: regenerate the papers' figures into a folder (``--paper`` takes reference
keys: Wang2020, Tang2019, Efimov2013, Dinh2024, in any case)."""

from __future__ import annotations

import argparse
import time
from typing import Any

from . import check_out_dir


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "figures",
        help="regenerate the papers' figures as PNG files",
        description="Redraw the figures of the papers ivobs implements (Wang2020: fixed-time; "
        "Tang2019: reachability, zonotope, interval observers; Efimov2013: interval observers, "
        "Hénon map; Dinh2024: KKL observers) with ivobs' methods, one PNG per figure. Each "
        "figure checks that its bounds contain the true state. What differs from the papers: "
        "docs/figures.md.",
    )
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created)")
    p.add_argument(
        "--paper",
        default=None,
        metavar="LIST",
        help="comma-separated reference keys, any case, e.g. Wang2020,Dinh2024 "
        "(default: all of Wang2020,Tang2019,Efimov2013,Dinh2024)",
    )
    return p


def main(args: argparse.Namespace) -> int:
    from . import use_agg

    use_agg()
    from ..report.figures import figure_specs, generate

    papers = None
    if args.paper is not None:
        papers = [p for p in args.paper.split(",") if p.strip()]
    figure_specs(papers, name="--paper")  # validates the list before any work
    check_out_dir(args.out, "--out")
    t0 = time.perf_counter()
    paths = generate(args.out, papers, verbose=True)
    print(f"{len(paths)} figure(s) in {time.perf_counter() - t0:.1f} s")
    return 0
