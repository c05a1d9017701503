"""Every method on the quadruple tank ([Johansson2000]; scenario ``quadruple-tank``): mean width
per state as a ratio to the exact hull, and speed of ``step()`` and ``run()`` (issue 17).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_quadtank.py
        [--methods m1,m2] [--steps 2000] [--burn-in 300] [--window 100] [--seed 0]
        [--budget 30] [--out benchmarks/results]

One record of ``--steps`` samples with vertex disturbances (``simulate("vertex", seed)``). The
reference is the exact interval hull (the ``exact`` method with a moving window of ``--window``
steps, computed and cached by :func:`bench_cora.exact_hull`; the window makes it a slightly
*looser* reference than the full-horizon hull, never a tighter one). For every other method
(default options, ``x0`` the scenario's prior box): the mean width of each state over the steps
from ``--burn-in`` on (from ``run()``), its ratio to the exact one's, whether every box contains
the true state, and the speed in steps per second of CPU time (``time.process_time``; wall time
beside it) of ``run()`` on the whole record and of ``step()`` through it (stopped after
``--budget`` CPU seconds: the rate over the steps done). ``goal``: every state within 1.1x
exact at >= 5,000 ``step()`` steps per CPU second.

Writes ``<out>/quadtank_table.md`` and prints it.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import ivobs

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_cora import exact_hull  # the exact reference, cached

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "quadruple-tank"
GOAL_RATIO, GOAL_RATE = 1.1, 5000.0


def widths(lo: np.ndarray, hi: np.ndarray, burn_in: int) -> np.ndarray:
    """Mean width of each state over the steps from ``burn_in`` on."""
    return np.asarray((hi[burn_in:] - lo[burn_in:]).mean(axis=0))


def step_rate(est: Any, u: np.ndarray, y: np.ndarray, budget: float) -> tuple[float, float, int]:
    """``step()`` through the record: (steps per CPU second, per wall second, steps done)."""
    est.reset()
    c0, w0 = time.process_time(), time.perf_counter()
    k = 0
    for k in range(y.shape[0]):
        est.step(u[k], y[k])
        if (k & 63) == 63 and time.process_time() - c0 > budget:
            break
    n = k + 1
    return n / (time.process_time() - c0), n / (time.perf_counter() - w0), n


def run_method(name: str, sc: Any, tr: Any, burn_in: int, budget: float) -> dict[str, Any]:
    """One method on the record: widths, containment and speeds (or why it did not run)."""
    row: dict[str, Any] = {"method": name}
    try:
        est = ivobs.make_estimator(name, sc.system, x0=sc.x0, on_inconsistent="ignore")
    except ivobs.IvobsError as exc:
        row["error"] = str(exc).split("\n")[0][:120]
        return row
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c0, w0 = time.process_time(), time.perf_counter()
        res = est.run(tr.u, tr.y)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        T = row["steps"] = tr.y.shape[0]
        row["run_cpu"], row["run_wall"] = T / cpu, T / wall
        row["step_cpu"], row["step_wall"], row["step_n"] = step_rate(est, tr.u, tr.y, budget)
    row["width"] = widths(res.lower, res.upper, burn_in)
    row["contains"] = bool(res.contains(tr.x)[res.valid_from :].all())
    return row


def table(rows: list[dict[str, Any]], ex_w: np.ndarray, names: tuple[str, ...], head: str) -> str:
    cols = " | ".join(f"{n} / exact" for n in names)
    lines = [
        head,
        "",
        f"| method | {cols} | worst | step() steps/s CPU (wall) | run() steps/s CPU (wall) "
        "| contains | goal |",
        "|---|" + "---|" * (len(names) + 5),
        f"| exact (width, cm) | {' | '.join(f'{w:.4g}' for w in ex_w)} | 1 | – | – | – | – |",
    ]
    for r in sorted(rows, key=lambda r: float(np.max(r["width"] / ex_w)) if "width" in r else 1e9):
        if "width" not in r:
            lines.append(f"| {r['method']} | refused: {r['error']} |")
            continue
        ratio = r["width"] / ex_w
        goal = ratio.max() <= GOAL_RATIO and r["step_cpu"] >= GOAL_RATE
        partial = "" if r["step_n"] == r["steps"] else f", first {r['step_n']} steps"
        lines.append(
            f"| {r['method']} | {' | '.join(f'{q:.2f}' for q in ratio)} | {ratio.max():.2f} "
            f"| {r['step_cpu']:,.0f} ({r['step_wall']:,.0f}{partial}) "
            f"| {r['run_cpu']:,.0f} ({r['run_wall']:,.0f}) | {'yes' if r['contains'] else 'NO'} "
            f"| {'**yes**' if goal else 'no'} |"
        )
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--methods", default=None, help="comma-separated (default: all but exact)")
    p.add_argument("--steps", type=int, default=2000)
    p.add_argument("--burn-in", type=int, default=300)
    p.add_argument("--window", type=int, default=100, help="exact's moving window")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--budget", type=float, default=30.0, help="CPU seconds of step() per method")
    p.add_argument("--out", default=str(ROOT / "benchmarks/results"))
    args = p.parse_args(argv)
    out = Path(args.out)
    sc = ivobs.scenarios.get(SCENARIO, horizon=args.steps)
    tr = sc.simulate("vertex", args.seed)
    ex = exact_hull(
        SCENARIO, out, disturbance="vertex", seed=args.seed, window=args.window,
        horizon=args.steps,
    )  # fmt: skip
    ex_w = widths(ex["lo"], ex["hi"], args.burn_in)
    names = args.methods.split(",") if args.methods else ivobs.methods()
    rows = []
    for name in names:
        if name == "exact":
            continue
        t0 = time.perf_counter()
        rows.append(run_method(name, sc, tr, args.burn_in, args.budget))
        print(f"{name}: {time.perf_counter() - t0:.1f} s", file=sys.stderr, flush=True)
    head = (
        f"{SCENARIO}, {args.steps} steps, vertex disturbances (seed {args.seed}), mean widths "
        f"from step {args.burn_in} on; exact: moving window of {args.window} steps "
        f"({args.steps / ex['seconds']:.0f} steps/s wall{', cached' if ex['cached'] else ''})"
    )
    text = table(rows, ex_w, sc.state_names or tuple(f"x{i}" for i in range(4)), head)
    out.mkdir(parents=True, exist_ok=True)
    (out / "quadtank_table.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
