"""Speed against tightness on CORA's 30-tank system: which tight method keeps up.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_tank30_tradeoff.py [--quick]

Runs the whole recorded run (235 steps) of ``cora-tank30`` with

* ``constrained-zonotope`` at its default limits (``2 nx`` constraints, ``16 nx`` generators)
  and at smaller ones (fewer constraints and generators: smaller programs, fewer eliminations);
* ``dual-window`` with windows of 20 (its default), 40 and 80 steps;
* ``strip`` for reference.

and prints the CPU steps per second (design included) and the ratio of the mean box width to
that of the exact hull (``benchmarks/results/cora_exact_hull.npz``, made by
``bench_czonotope.py reference``), over all steps and over steps 100-234 (after the transient).
``--quick``: the default constrained zonotope, one smaller limit and ``dual-window`` 80 only.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import ivobs

CACHE = Path(__file__).parent / "results" / "cora_exact_hull.npz"

RUNS: list[tuple[str, dict[str, Any]]] = [
    ("constrained-zonotope", {}),
    ("constrained-zonotope", {"max_constraints": 60, "max_generators": 240}),
    ("constrained-zonotope", {"max_constraints": 30, "max_generators": 480}),
    ("constrained-zonotope", {"max_constraints": 30, "max_generators": 240}),
    ("constrained-zonotope", {"max_constraints": 15, "max_generators": 120}),
    ("dual-window", {}),
    ("dual-window", {"window": 40}),
    ("dual-window", {"window": 80}),
    ("strip", {}),
]
QUICK = [RUNS[0], RUNS[1], RUNS[7]]


def main(runs: list[tuple[str, dict[str, Any]]]) -> None:
    exact = np.load(CACHE)["cora-tank30/width"]
    sc = ivobs.scenarios.get("cora-tank30")
    u, y = sc.recorded.u, sc.recorded.y
    print(f"{'method':22s} {'options':42s} {'steps/s':>8s} {'/exact':>7s} {'k>=100':>7s}")
    for name, options in runs:
        start = time.process_time()
        est = ivobs.make_estimator(name, sc.system, x0=sc.x0, **options)
        res = est.run(u, y)
        rate = len(u) / (time.process_time() - start)
        w = res.upper - res.lower
        whole = w.mean() / exact.mean()
        late = w[100:].mean() / exact[100:].mean()
        text = ", ".join(f"{k}={v}" for k, v in options.items()) or "(defaults)"
        print(f"{name:22s} {text:42s} {rate:8.2f} {whole:7.3f} {late:7.3f}", flush=True)


if __name__ == "__main__":
    main(QUICK if "--quick" in sys.argv[1:] else RUNS)
