"""Fault estimation by the streaming monitor (``ivobs.monitor``, :mod:`ivobs.monitor.bias`):
how long a persistent sensor bias stays flagged, whether the boxes keep the true state, and the
estimated bias.

DC servo motor ([Tang2019, Example 1]), constant input 2 V, vertex (bang-bang) disturbances
and noise, a bias added to one sensor from step ``--onset`` (300) on:

* ``angle``: +0.5 on the angle sensor ``y1`` (9 noise bounds). The angle integrates the speed,
  so after the onset a constant offset is itself a model trajectory;
* ``angle-transient``: the same, removed at step ``--onset + 100``;
* ``speed``: +0.5 on the speed sensor ``y2``;
* ``speed-0.3``: +0.3 on the speed sensor (5 noise bounds), which the loose band of
  ``interval-split`` lets into its estimate for a few steps.

Prints, per method and fault: the share of the faulty steps with the alarm raised, whether it
stays raised from the first alarm to the end of the fault (``kept``), the steps after the onset
whose box missed the true state (and those of them from the first alarm on), the episodes
(start, end, outputs held, isolation: :mod:`ivobs.monitor.isolate`), the bias interval at the
last step, and the CPU time.

Run: ``python benchmarks/bench_fault_estimation.py [--methods strip,reachability] [--steps 600]``
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from ivobs.monitor import Monitor

# the servo record of the tests (every disturbance on a vertex), one simulator for both
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from vertexsim import servo_vertex as servo_record

METHODS = "strip,reachability,interval-split,zonotope,constrained-zonotope"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--methods", default=METHODS)
    ap.add_argument("--steps", type=int, default=600)
    ap.add_argument("--onset", type=int, default=300)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    T, s0 = args.steps, args.onset
    faults = {
        "angle": (0, s0, T, 0.5),
        "angle-transient": (0, s0, min(T, s0 + 100), 0.5),
        "speed": (1, s0, T, 0.5),
        "speed-0.3": (1, s0, T, 0.3),
    }
    print(f"servo motor, {T} steps, bias +0.5 from step {s0}, seed {args.seed}")
    print(
        "fault            method                alarm  kept  missed (after 1st alarm)  "
        "episodes                       bias"
    )
    for fault, (out, a, b, size) in faults.items():
        sc, u, x, y = servo_record(T, args.seed)
        y[a:b, out] += size
        for m in args.methods.split(","):
            t0 = time.process_time()
            rec = Monitor(sc.system, m, x0=sc.x0).run(u, y)
            cpu = time.process_time() - t0
            share = rec.alarm[a:b].mean()
            first = rec.first_alarm
            kept = "yes" if first is not None and rec.alarm[first:b].all() else "no"
            miss = ((x < rec.lower - 1e-9) | (x > rec.upper + 1e-9)).any(axis=1)
            after = int(miss[first:].sum()) if first is not None else int(miss[a:].sum())
            missed = f"{int(miss[a:].sum())} ({after})"
            eps = ", ".join(
                f"{f.start}-{'' if f.end is None else f.end} {f.names} [{f.isolation or '-'}]"
                for f in rec.faults
            )
            lo, hi = rec.bias_lower[b - 1, out], rec.bias_upper[b - 1, out]
            bias = "-" if np.isnan(lo) else f"[{lo:.3f}, {hi:.3f}]"
            print(
                f"{fault:16s} {m:20s} {share:6.1%} {kept:4s}  {missed:22s}  {eps:30s} {bias:16s} "
                f"{cpu:5.1f} s",
                flush=True,
            )


if __name__ == "__main__":
    main()
