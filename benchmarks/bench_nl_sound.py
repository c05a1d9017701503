"""Soundness of the nonlinear methods over long runs on every nonlinear scenario.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_sound.py [steps] [method,method,...]

For each scenario of :mod:`ivobs.scenarios.nonlinear` and each method, ``steps`` steps (default
10^5) with the disturbances and the uncertain parameters switching between the vertices of their
bounds at every step (float64 simulation by :func:`ivobs.simulate_nonlinear`; the estimators'
1e-10 margin covers its one-step rounding, see docs/nonlinear.md), the scenario's inputs
repeated. Prints the number of steps whose box misses the simulated state, the widths (mean and
max after the first 100 steps, to show they stay bounded) and the time.
"""

from __future__ import annotations

import sys
import time

import numpy as np

import ivobs

SCENARIOS = ["henon-nl", "pendulum-nl", "cora-tank6-nl", "cstr", "unicycle-range", "chain10-nl"]
METHODS = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"]


def run(name: str, method: str, steps: int) -> None:
    sc = ivobs.scenarios.get(name)
    sys_ = sc.system
    u = np.resize(sc.u, (steps, sys_.nu)) if sys_.nu else None
    tr = ivobs.simulate_nonlinear(sys_, sc.x_true0, u, "vertex", p="vertex", T=steps, seed=3)
    t0 = time.perf_counter()
    est = ivobs.make_estimator(method, sys_, x0=sc.x0).run(tr.u, tr.y)
    dt = time.perf_counter() - t0
    inside = (est.lower <= tr.x) & (tr.x <= est.upper)
    bad = int(np.count_nonzero(~inside.all(axis=1)))
    w = est.width[100:]
    print(
        f"{name:15s} {method:24s} {steps:7,d} steps: {bad} misses; width mean "
        f"{np.round(w.mean(axis=0).mean(), 4)}, max {np.round(w.max(), 4)}; {dt:.1f} s",
        flush=True,
    )


if __name__ == "__main__":
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    methods = sys.argv[2].split(",") if len(sys.argv) > 2 else METHODS
    for m in methods:
        for s in SCENARIOS:
            run(s, m, n)
