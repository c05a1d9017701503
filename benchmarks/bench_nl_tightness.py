"""Nonlinear tightness: each nonlinear method's width at step k over an inner bound of the true
hull (``ivobs.report.inner.inner_hull``: local optimisation over x0, parameters and signals
consistent with every measurement; every point found is a real admissible state).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_tightness.py [starts]

For each nonlinear scenario: ``paper`` (uniform) signals, seed 0, the hull at step ``k``; the
ratio is the mean over states of ``method width / inner width`` (states whose inner width is
below 1e-9 left out) and its maximum. A ratio is an upper bound on the method's distance to the
tightest box (the inner hull may be smaller than the true one where the optimiser found too few
points). Every method's box must contain every point found (checked up to 1e-6: the points
satisfy the measurement equations to 1e-8, so one may sit 1e-8 outside a measurement's bound).
"""

from __future__ import annotations

import sys
import time

import numpy as np

import ivobs
from ivobs.report.inner import inner_hull

METHODS = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"]
STEPS = {"henon-nl": 10, "pendulum-nl": 10, "cora-tank6-nl": 8, "cstr": 10,
         "unicycle-range": 8, "chain10-nl": 6}  # fmt: skip


def main(starts: int = 2) -> None:
    head = "| scenario | k | points | " + " | ".join(f"{m} mean (max)" for m in METHODS) + " |"
    print(head)
    print("|" + "---|" * (3 + len(METHODS)))
    for name, k in STEPS.items():
        sc = ivobs.scenarios.get(name, horizon=k + 1)
        tr = sc.simulate("paper", 0)
        t0 = time.perf_counter()
        lo, hi, n = inner_hull(sc.system, sc.x0, tr.u, tr.y, k, truth=tr, starts=starts)
        inner = hi - lo
        keep = inner > 1e-9
        cells = []
        for m in METHODS:
            res = ivobs.make_estimator(m, sc.system, x0=sc.x0).run(tr.u, tr.y)
            slack = 1e-6 * (1 + np.abs(inner))  # points are feasible to 1e-8 in y
            if not (np.all(res.lower[k] <= lo + slack) and np.all(hi - slack <= res.upper[k])):
                raise SystemExit(f"{m} on {name}: a feasible point outside the box")
            r = (res.upper[k] - res.lower[k])[keep] / inner[keep]
            cells.append(f"{r.mean():.2f} ({r.max():.2f})" if r.size else "point")
        dt = time.perf_counter() - t0
        print(f"| `{name}` | {k} | {n} | " + " | ".join(cells) + f" |  <!-- {dt:.0f} s -->")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 2)
