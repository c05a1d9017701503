"""Fault detection delay of the streaming monitor (``ivobs.monitor.Monitor``), per method.

DC servo motor ([Tang2019, Example 1]), vertex (bang-bang) disturbances, fault from step
``ONSET`` on:

* a bias of 2, 3, 5 noise bounds (v̄ = 0.0564) on the speed sensor ``y2``;
* a bias of 5 noise bounds on the position sensor ``y1`` (θ integrates the speed: a constant
  position offset is itself a valid trajectory, so only its onset jump can be seen);
* an actuator fault: the motor receives ``u - 1`` V or ``u - 2`` V (dead) instead of ``u = 2`` V.

Prints, per method and fault, the median and the largest detection delay in steps (``-`` when
the fault is not detected within ``WINDOW`` steps) over the seeds, how many seeds detected it,
and the number of false alarms before the onset (must be 0: an alarm is never false under the
model's assumptions).

``--fault-free N`` instead runs ``N`` fault-free steps (vertex disturbances) through the online
monitor of every method and prints the number of alarms (0 expected) and the steps per second.

Run: ``python benchmarks/bench_fault_detection.py [--seeds 20] [--methods reachability,...]``
or ``python benchmarks/bench_fault_detection.py --fault-free 10000``.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import ivobs
from ivobs.monitor import Monitor
from ivobs.simulate import simulate

ONSET = 100
WINDOW = 100
VBAR = 0.0564
SLOW = {"exact", "constrained-zonotope"}

FAULTS = {
    "y2 bias 2v": ("sensor", 1, 2.0),
    "y2 bias 3v": ("sensor", 1, 3.0),
    "y2 bias 5v": ("sensor", 1, 5.0),
    "y1 bias 5v": ("sensor", 0, 5.0),
    "actuator -1V": ("actuator", None, 1.0),
    "actuator -2V": ("actuator", None, 2.0),
}


def faulty_record(sc, fault, seed):
    kind, channel, size = FAULTS[fault]
    d = ivobs.vertex_disturbance(sc.system.d, sc.horizon, seed=seed)
    if kind == "actuator":
        applied = sc.u.copy()
        applied[ONSET:] -= size
        tr = simulate(sc.system, sc.x_true0, applied, d)
        return sc.u, tr.y
    tr = simulate(sc.system, sc.x_true0, sc.u, d)
    y = tr.y.copy()
    y[ONSET:, channel] += size * VBAR
    return sc.u, y


def fault_free(methods: list[str], steps: int) -> None:
    sc = ivobs.scenarios.get("servo-motor")
    print(f"servo motor, {steps} fault-free steps, vertex disturbances, online monitor\n")
    print("| method | steps | alarms | steps/s |")
    print("|---|---|---|---|")
    for method in methods:
        T = min(steps, 1000) if method in SLOW else steps
        tr = simulate(
            sc.system,
            sc.x_true0,
            np.full((T, 1), 2.0),
            ivobs.vertex_disturbance(sc.system.d, T, seed=7),
        )
        try:
            mon = Monitor(sc.system, method, x0=sc.x0)
        except ivobs.IvobsError as exc:
            print(f"| {method} | {str(exc)[:60]} |")
            continue
        t0 = time.perf_counter()
        rec = mon.run(tr.u, tr.y)
        rate = T / (time.perf_counter() - t0)
        print(f"| {method} | {T} | {int(rec.alarm.sum())} | {rate:.0f} |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--slow-seeds", type=int, default=2, help="seeds for exact, constr.-zonotope")
    ap.add_argument("--methods", default=",".join(ivobs.methods()))
    ap.add_argument("--fault-free", type=int, metavar="N", help="N fault-free steps instead")
    args = ap.parse_args()
    if args.fault_free:
        fault_free(args.methods.split(","), args.fault_free)
        return
    sc = ivobs.scenarios.get("servo-motor", horizon=ONSET + WINDOW)
    print(
        f"servo motor, vertex disturbances, fault from step {ONSET}; delay in steps "
        f"(median / max over seeds, detected/seeds); v = {VBAR}\n"
    )
    print(f"| method | {' | '.join(FAULTS)} | false alarms | s/run |")
    print("|---" * (len(FAULTS) + 3) + "|")
    for method in args.methods.split(","):
        seeds = range(args.slow_seeds if method in SLOW else args.seeds)
        cells, false_alarms, t0, runs = [], 0, time.perf_counter(), 0
        try:
            mon = Monitor(sc.system, method, x0=sc.x0)
        except ivobs.IvobsError as exc:
            print(f"| {method} | {str(exc)[:60]} |")
            continue
        for fault in FAULTS:
            delays = []
            for seed in seeds:
                u, y = faulty_record(sc, fault, seed)
                mon.reset()
                rec = mon.run(u, y)
                runs += 1
                false_alarms += int(rec.alarm[:ONSET].sum())
                hit = np.flatnonzero(rec.alarm[ONSET:])
                delays.append(int(hit[0]) if hit.size else None)
            found = [d for d in delays if d is not None]
            if found:
                cells.append(f"{np.median(found):g} / {max(found)} ({len(found)}/{len(delays)})")
            else:
                cells.append(f"- (0/{len(delays)})")
        per_run = (time.perf_counter() - t0) / max(runs, 1)
        print(f"| {method} | {' | '.join(cells)} | {false_alarms} | {per_run:.2f} |", flush=True)


if __name__ == "__main__":
    main()
