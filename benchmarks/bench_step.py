"""Online ``step()`` speed of every method on the servo motor ([Tang2019, Example 1]).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_step.py [method,method,...] [--cpu] [--steps N]
        [--run]

Best of 3 repeats of 2,000 online steps (``est.step(u[k], y[k])`` after ``est.reset()``),
vertex disturbances. Prints steps per second per method. ``--cpu``: per second of the
process's CPU time instead of wall time (comparable across loads on a shared machine).
``--run``: also ``run()`` on one 200,000-step record (best of 3; the floors of the recursive
methods: ``step()`` 20,000 and ``run()`` 1,000,000 steps per CPU-second).
"""

from __future__ import annotations

import sys
import time
from typing import Any

import ivobs

STEPS = 2000
RUN_STEPS = 200_000


def main(methods: list[str], clock: Any = time.perf_counter, run: bool = False) -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=RUN_STEPS if run else STEPS)
    tr = sc.simulate("vertex", seed=0)
    for name in methods:
        est = ivobs.make_estimator(name, sc.system, x0=sc.x0)
        best = 0.0
        for _ in range(3):
            est.reset()
            start = clock()
            for k in range(STEPS):
                est.step(tr.u[k], tr.y[k])
            best = max(best, STEPS / (clock() - start))
        line = f"{name:22s} step() {best:9,.0f} steps/s"
        if run:
            assert est.run(tr.u, tr.y).contains(tr.x)[est.valid_from :].all()
            fastest = 0.0
            for _ in range(3):
                start = clock()
                est.run(tr.u, tr.y)
                fastest = max(fastest, RUN_STEPS / (clock() - start))
            line += f"   run() {fastest:12,.0f} steps/s"
        print(line)


if __name__ == "__main__":
    argv = sys.argv[1:]
    if "--steps" in argv:  # fewer steps (e.g. 400) for the slow methods
        at = argv.index("--steps")
        STEPS = int(argv[at + 1])
        del argv[at : at + 2]
    args = [a for a in argv if a not in ("--cpu", "--run")]
    default = [m for m in ivobs.methods() if m not in ("exact", "intersect")]
    main(
        args[0].split(",") if args else default,
        time.process_time if "--cpu" in sys.argv else time.perf_counter,
        run="--run" in sys.argv,
    )
