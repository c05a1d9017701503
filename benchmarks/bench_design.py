"""Design time of the observer gains (``reachability``/``zonotope``) and their widths on tank30.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_design.py [--sizes 10,30,50,100,300] [--lmi]

1. Time of each design (``gain="radius"``, ``"hinf"``; ``"hinf-lmi"`` with ``--lmi``, up to
   n = 50) on random detectable plants (unstable, ``ny = n/10``, disturbances on every state and
   output), the design cache cleared before each; the exponent of ``time ~ n^p`` fitted over
   the sizes from 30 on (CPU time of the process; wall-clock beside it).
2. CORA's 30-tank benchmark [Althoff2021]: design time and the mean interval-hull radius at
   k = 20 and k = 235 (1-based) of ``reachability`` and ``zonotope`` with each gain, beside
   CORA's gain-based observers (Hinf-G 0.4317, Nom-G 0.4483).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import ivobs
from ivobs import Box, LinearSystem
from ivobs.design import cache
from ivobs.design.hinf import designed_gain
from ivobs.linalg import spectral_radius


def plant(n: int, seed: int = 0) -> LinearSystem:
    rng = np.random.default_rng(seed)
    ny = max(2, n // 10)
    A = rng.normal(size=(n, n))
    A *= 1.05 / spectral_radius(A)
    C = rng.normal(size=(ny, n))
    E = np.hstack([0.1 * np.eye(n), np.zeros((n, ny))])
    F = np.hstack([np.zeros((ny, n)), 0.05 * np.eye(ny)])
    return LinearSystem(A, np.ones((n, 1)), C, E=E, F=F, d=Box.symmetric(np.ones(n + ny)))


def timed(sys: LinearSystem, gain: str) -> tuple[float, float]:
    """Wall-clock and CPU seconds of one design (the CPU time of this process: on a shared
    machine the wall-clock time also counts the other processes)."""
    cache.clear()
    start, cpu = time.perf_counter(), time.process_time()
    designed_gain(sys, None, "bench", gain)
    return time.perf_counter() - start, time.process_time() - cpu


def scaling(sizes: list[int], lmi: bool) -> None:
    gains = ["radius", "hinf"] + (["hinf-lmi"] if lmi else [])
    print(f"{'n':>5s} " + " ".join(f"{g:>17s}" for g in gains) + "   (design s: wall / CPU)")
    times: dict[str, list[tuple[int, float]]] = {g: [] for g in gains}
    for n in sizes:
        sys = plant(n)
        row = []
        for g in gains:
            if g == "hinf-lmi" and n > 50:
                row.append(f"{'-':>17s}")
                continue
            t, cpu = timed(sys, g)
            times[g].append((n, cpu))
            row.append(f"{t:8.3f} /{cpu:7.3f}")
        print(f"{n:5d} " + " ".join(row), flush=True)
    for g, pts in times.items():
        pts = [(n, t) for n, t in pts if n >= 30]
        if len(pts) >= 2:
            p = np.polyfit(np.log([n for n, _ in pts]), np.log([t for _, t in pts]), 1)[0]
            print(f"  {g}: CPU time ~ n^{p:.2f} (n >= 30)")


def tank30() -> None:
    sc = ivobs.scenarios.get("cora-tank30")
    tr = sc.recorded
    print("\ncora-tank30 (CORA: Hinf-G r(235) = 0.4317, Nom-G 0.4483)")
    print(f"{'method':14s} {'gain':9s} {'design s':>9s} {'r(20)':>8s} {'r(235)':>8s} contains")
    for method in ("reachability", "zonotope"):
        for gain in ("radius", "hinf", "hinf-lmi"):
            cache.clear()
            start = time.perf_counter()
            est = ivobs.make_estimator(method, sc.system, x0=sc.x0, gain=gain)
            design = time.perf_counter() - start
            res = est.run(tr.u, tr.y)
            rad = (res.upper - res.lower) / 2
            ok = bool(res.contains(tr.x).all())
            print(
                f"{method:14s} {gain:9s} {design:9.3f} {rad[19].mean():8.4f} "
                f"{rad[234].mean():8.4f} {ok}",
                flush=True,
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="10,30,50,100,300")
    ap.add_argument("--lmi", action="store_true", help="also time the LMI (n <= 50)")
    ap.add_argument("--no-tank", action="store_true")
    args = ap.parse_args()
    scaling([int(s) for s in args.sizes.split(",")], args.lmi)
    if not args.no_tank:
        tank30()


if __name__ == "__main__":
    main()
