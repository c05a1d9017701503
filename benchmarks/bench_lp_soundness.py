"""Long containment runs of the LP-based methods against the exact simulator.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_lp_soundness.py [--steps 10000]
        [--methods constrained-zonotope,exact,dual-window,nl-constrained-zonotope]
        [--plants servo,random]

For the servo motor and the random 4-state plant of tests/test_set_membership_soundness.py,
one record of ``--steps`` samples from tests/exactsim.py (every state and measurement an exact
value of the model with its disturbances on random vertices of their bounds; 60-digit interval
arithmetic), then every method over it: the steps whose box misses the exact state, the samples
reported inconsistent (all of them are admissible), the mean width and the CPU time. ``exact``
runs with a moving window of 20 steps (the full horizon grows with the record).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import ivobs

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from exactsim import simulate_linear
from test_set_membership_soundness import random_plant

OPTIONS: dict[str, dict[str, object]] = {"exact": {"window": 20, "progress": False}}


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=10_000)
    p.add_argument(
        "--methods", default="constrained-zonotope,exact,dual-window,nl-constrained-zonotope"
    )
    p.add_argument("--plants", default="servo,random")
    args = p.parse_args(argv)
    T = args.steps
    for plant in args.plants.split(","):
        if plant == "servo":
            sc = ivobs.scenarios.get("servo-motor", horizon=T)
            sys_, x0, u = sc.system, sc.x0, sc.simulate("vertex", seed=0).u
            x_true = 0.5 * (x0.lo + x0.hi) + 0.1
        else:
            sys_, x_true, x0 = random_plant(3)
            u = np.sin(0.1 * np.arange(T))[:, None]
        t0 = time.process_time()
        rec = simulate_linear(sys_, x_true, T, u, seed=11)
        print(f"{plant}: {T} exact steps simulated in {time.process_time() - t0:.0f} s CPU")
        for method in args.methods.split(","):
            est = ivobs.make_estimator(method, sys_, x0=x0, **OPTIONS.get(method, {}))
            c0 = time.process_time()
            res = est.run(u, rec.Y)
            cpu = time.process_time() - c0
            misses = rec.misses(res.lower, res.upper).size
            width = float(np.mean(res.upper - res.lower))
            print(
                f"  {method:26s} misses {misses}  inconsistent {int(res.inconsistent.sum())}  "
                f"mean width {width:.6g}  {T / cpu:,.0f} steps/s CPU"
            )


if __name__ == "__main__":
    main()
