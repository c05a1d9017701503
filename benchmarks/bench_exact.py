"""Speed of the exact LP reference: full horizon and moving window.

Targets (2-core machine): a 6-state system over 200 steps with the full horizon in under 60 s;
the moving window ``N = 20`` at 50 steps per second or more.

The wall time is the number that counts; the CPU time (both solver threads) and the load
average are printed too, so that a run on a busy machine can be read.

Run: ``python benchmarks/bench_exact.py [--steps 200] [--window 20]``.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

import ivobs
from ivobs.testing import adversarial_run, random_system


def bench(window: int | None, steps: int, seed: int = 0) -> tuple[float, float, ivobs.Estimate]:
    sys = random_system(seed, nx=6, ny=2, nu=1)
    x0 = ivobs.Box.symmetric(np.ones(6))
    traj = adversarial_run(sys, x0, steps, seed=seed + 1)
    est = ivobs.make_estimator("exact", sys, x0=x0, window=window, progress=False)
    wall, cpu = time.perf_counter(), time.process_time()
    res = est.run(traj.u, traj.y)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    assert np.all(res.contains(traj.x)), "exact lost the true state"
    return wall, cpu, res


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--window", type=int, default=20)
    args = parser.parse_args()
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")
    wall, cpu, full = bench(None, args.steps)
    print(
        f"exact, full horizon: nx=6, ny=2, nd=8, {args.steps} steps in {wall:.2f} s "
        f"(CPU {cpu:.2f} s; {args.steps / wall:.1f} steps/s; target: under 60 s)"
    )
    wall, cpu, win = bench(args.window, args.steps)
    print(
        f"exact, window N={args.window}: {args.steps} steps in {wall:.2f} s "
        f"(CPU {cpu:.2f} s; {args.steps / wall:.1f} steps/s; target: at least 50 steps/s)"
    )
    ratio = np.mean(win.width[10:] / full.width[10:])
    print(f"mean width ratio window / full horizon (steps >= 10): {ratio:.4f}")
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
