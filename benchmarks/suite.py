"""Benchmark suite: every scenario x every method.

For each scenario and method: mean width after a burn-in, its ratio to the exact hull (``exact``,
full horizon where affordable, else a moving window — the table says which), containment of the
true state (and of CORA's own recorded trajectories), design time and run time.

    python benchmarks/suite.py                      # everything -> BENCHMARKS.md + results CSV
    python benchmarks/suite.py --scenarios servo-motor,dinh2019 --methods reachability,exact

Writes ``benchmarks/results/suite.csv`` and replaces the section between
``<!-- suite:start -->`` and ``<!-- suite:end -->`` in ``BENCHMARKS.md`` (``--out`` elsewhere).
"""

from __future__ import annotations

import argparse
import csv
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

import ivobs
from ivobs import scenarios
from ivobs.report import compare, markdown_table

ROOT = Path(__file__).resolve().parent.parent
EXACT_FULL_MAX_STEPS = 400  # full-horizon exact above this is too slow for a routine run
EXACT_WINDOW = 40

DEFAULT_SCENARIOS = [
    "dinh2019",
    "servo-motor",
    "tang-example2",
    "efimov-planar",
    "henon",
    "kkl-random8",
    "kkl-ltv-dt",
    "cora-2dim",
    "cora-vehicle6",
    "cora-pedestrian4",
    "cora-slip4",
]


def _exact_options(sc: scenarios.Scenario) -> dict:
    return {} if sc.horizon <= EXACT_FULL_MAX_STEPS else {"window": EXACT_WINDOW}


def run(scenario_names, method_names, disturbance, seed):
    rows, sections = [], []
    for name in scenario_names:
        sc = scenarios.get(name)
        names = list(method_names)
        options = {"exact": _exact_options(sc)} if "exact" in names else {}
        kinds = [disturbance] + (["recorded"] if sc.recorded is not None else [])
        for kind in kinds:
            t0 = time.perf_counter()
            _traj, results = compare(sc, names, disturbance=kind, seed=seed, options=options)
            ref = "exact" if any(r.method == "exact" and r.ok for r in results) else None
            exact = next((r for r in results if r.method == "exact" and r.ok), None)
            head = (
                f"### {name} ({kind} disturbances, {sc.horizon} steps, burn-in "
                f"{sc.horizon // 10})\n\n{sc.source}. "
            )
            if exact is not None and options.get("exact"):
                head += f"Exact reference: moving window of {EXACT_WINDOW} steps. "
            sections.append(head + "\n\n" + markdown_table(results, sc.state_names, ref))
            for r in results:
                ratio = ""
                if r.ok and exact is not None and r.mean_width is not None:
                    ratio = float(np.mean(r.mean_width / exact.mean_width))
                rows.append(
                    {
                        "scenario": name,
                        "disturbance": kind,
                        "method": r.method,
                        "mean_width": "" if r.mean_width is None else float(np.mean(r.mean_width)),
                        "ratio_to_exact": ratio,
                        "contains": "" if r.contains is None else r.contains,
                        "design_s": r.design_time,
                        "run_s": r.run_time,
                        "error": r.error or "",
                    }
                )
            print(f"{name} [{kind}]: {time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return rows, sections


def write(rows, sections, out_md: Path, out_csv: Path, command: str) -> None:
    out_csv.parent.mkdir(parents=True, exist_ok=True)
    fields = [
        "scenario",
        "disturbance",
        "method",
        "mean_width",
        "ratio_to_exact",
        "contains",
        "design_s",
        "run_s",
        "error",
    ]
    with open(out_csv, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    body = (
        f"<!-- suite:start -->\n## Accuracy and cost per scenario\n\nCommand: `{command}`  \n"
        f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python "
        f"{platform.python_version()}, ivobs {ivobs.__version__}.  \nMean widths after the "
        "burn-in; 'ratio to exact' is the mean over states of width / exact width (1 is the "
        "best any guaranteed method can do with the same data).\n\n"
        + "\n\n".join(sections)
        + "\n<!-- suite:end -->"
    )
    text = out_md.read_text() if out_md.exists() else "# Benchmarks\n"
    if "<!-- suite:start -->" in text:
        pre, rest = text.split("<!-- suite:start -->", 1)
        post = rest.split("<!-- suite:end -->", 1)[1] if "<!-- suite:end -->" in rest else ""
        text = pre + body + post
    else:
        text = text.rstrip() + "\n\n" + body + "\n"
    out_md.write_text(text)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", default=",".join(DEFAULT_SCENARIOS))
    p.add_argument("--methods", default=None, help="default: every registered method")
    p.add_argument("--disturbance", default="vertex")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(ROOT / "BENCHMARKS.md"))
    p.add_argument("--csv", default=str(ROOT / "benchmarks" / "results" / "suite.csv"))
    args = p.parse_args(argv)
    names = [s for s in args.scenarios.split(",") if s]
    methods = args.methods.split(",") if args.methods else ivobs.methods()
    rows, sections = run(names, methods, args.disturbance, args.seed)
    cmd = "python benchmarks/suite.py" + ("" if argv is None else " " + " ".join(argv))
    write(rows, sections, Path(args.out), Path(args.csv), cmd)
    print(f"wrote {args.out} and {args.csv}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
