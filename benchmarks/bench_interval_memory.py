"""The interval family with and without the finite-memory bound (option ``finite_memory``).

Servo motor of [Tang2019], vertex disturbances: the summed width (mean over the record after a
burn-in) with complete data and with 10 % of the samples missing at random, and the CPU speed
of ``run()`` on the complete record (vectorised path); then every other scenario the family
designs on: soundness and the summed width with and without the bound.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_interval_memory.py [T] [--scenarios]``
(``T``: servo record length, default 10⁶).
"""

from __future__ import annotations

import os
import sys

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np
from timing import cpu_best  # benchmarks/timing.py

import ivobs

METHODS = ("interval", "interval-split", "interval-transformed")
BURN = 1000


def servo(T: int) -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    tr = sc.simulate("vertex", seed=0)
    y_miss = tr.y.copy()
    y_miss[np.random.default_rng(1).random(T) < 0.1] = np.nan
    print(f"servo-motor, {T:,} steps, burn-in {BURN}: summed width (mean), run() CPU steps/s")
    print("| method | finite_memory | complete | 10 % missing | run() steps/s | sound |")
    print("|---|---|---:|---:|---:|---|")
    for method in METHODS:
        for memory in (False, True):
            est = ivobs.make_estimator(method, sc.system, x0=sc.x0, finite_memory=memory)
            full = est.run(tr.u, tr.y)
            t = cpu_best(lambda est=est: est.run(tr.u, tr.y))
            miss = est.run(tr.u, y_miss)
            sound = bool(full.contains(tr.x).all() and miss.contains(tr.x).all())
            w_full = full.width.sum(axis=-1)[BURN:].mean()
            w_miss = miss.width.sum(axis=-1)[BURN:].mean()
            print(
                f"| {method} | {memory} | {w_full:.4g} | {w_miss:.4g} | {T / t:,.0f} | {sound} |",
                flush=True,
            )


def scenarios() -> None:
    print("\nother scenarios (default horizon, vertex disturbances, burn-in 10 %):")
    print("| scenario | method | without | with | sound | window N |")
    print("|---|---|---:|---:|---|---|")
    for name in ivobs.scenarios.names():
        sc = ivobs.scenarios.get(name)
        if name == "servo-motor" or not isinstance(sc.system, ivobs.LinearSystem):
            continue
        try:
            tr = sc.simulate("vertex", seed=0)
        except ivobs.IvobsError:
            continue
        for method in METHODS:
            try:
                off = ivobs.make_estimator(method, sc.system, x0=sc.x0, finite_memory=False)
                on = ivobs.make_estimator(method, sc.system, x0=sc.x0)
            except ivobs.IvobsError:
                continue
            a, b = off.run(tr.u, tr.y), on.run(tr.u, tr.y)
            burn = a.width.shape[0] // 10
            wa = np.nanmean(a.width.sum(axis=-1)[burn:])
            wb = np.nanmean(b.width.sum(axis=-1)[burn:])
            sound = bool(a.contains(tr.x).all() and b.contains(tr.x).all())
            win = on.operators.window
            print(
                f"| {name} | {method} | {wa:.4g} | {wb:.4g} | {sound} | "
                f"{win.N if win is not None else '-'} |",
                flush=True,
            )


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if "--scenarios" in sys.argv:
        scenarios()
    else:
        servo(int(args[0]) if args else 1_000_000)
