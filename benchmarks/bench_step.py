"""Online ``step()`` speed of every method on the servo motor ([Tang2019, Example 1]).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_step.py [method,method,...]

Best of 3 repeats of 2,000 online steps (``est.step(u[k], y[k])`` after ``est.reset()``),
vertex disturbances. Prints steps per second per method.
"""

from __future__ import annotations

import sys
import time

import ivobs

STEPS = 2000


def main(methods: list[str]) -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=STEPS)
    tr = sc.simulate("vertex", seed=0)
    for name in methods:
        est = ivobs.make_estimator(name, sc.system, x0=sc.x0)
        best = 0.0
        for _ in range(3):
            est.reset()
            start = time.perf_counter()
            for k in range(STEPS):
                est.step(tr.u[k], tr.y[k])
            best = max(best, STEPS / (time.perf_counter() - start))
        print(f"{name:22s} step() {best:9,.0f} steps/s")


if __name__ == "__main__":
    default = [m for m in ivobs.methods() if m not in ("exact", "intersect")]
    main(sys.argv[1].split(",") if len(sys.argv) > 1 else default)
