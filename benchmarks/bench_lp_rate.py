"""How many linear programs the LP-certified methods solve per reported bound.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_lp_rate.py [scenario,...] [method,...]

For each scenario's benchmark record (CORA's recorded data; otherwise ``simulate("vertex",
seed=0)``) and each method (default ``dual-window`` and ``constrained-zonotope``), with default
options: the number of HiGHS solves (every call of
:meth:`ivobs.sets.lp.LinearProgram.solve`, retries and block programs included; a block program
of ``K`` objectives counts ``K``) divided by the number of bounds reported (``2 nx`` per step),
the CPU time and the mean width. ``exact`` solves every bound at every step (rate 1 or more by
construction) and is not run. A rate below 1 means some bounds came from cached certificates.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np

import ivobs
from ivobs.sets import lp as lp_module
from ivobs.sets.czonotope import hull as hull_module

SCENARIOS = [
    "servo-motor",
    "quadruple-tank",
    "cora-2dim",
    "cora-pedestrian4",
    "cora-vehicle6",
    "cora-slip4",
    "cora-tank30",
]
METHODS = ["dual-window", "constrained-zonotope"]

_COUNT = {"solves": 0}


def _counting_solve() -> Any:
    original = lp_module.LinearProgram.solve

    def solve(self: lp_module.LinearProgram, primal: bool = False, devex: bool = False) -> str:
        # a block program of K copies (the constrained zonotope's small hulls) counts K
        n_obj = max(1, int(getattr(self, "_objectives", 1)))
        _COUNT["solves"] += n_obj
        return original(self, primal, devex)

    return solve


def _counting_load() -> Any:
    original = hull_module._load

    def load(lp: Any, A: Any, b: Any, radius: float, cost: Any, K: int = 1) -> None:
        lp._objectives = K  # read by the counting solve
        original(lp, A, b, radius, cost, K)

    return load


def _record(name: str) -> tuple[Any, Any]:
    sc = ivobs.scenarios.get(name)
    tr = getattr(sc, "recorded", None)
    if tr is None:
        tr = sc.simulate("vertex", seed=0)
    return sc, tr


def main() -> None:
    names = sys.argv[1].split(",") if len(sys.argv) > 1 else SCENARIOS
    methods = sys.argv[2].split(",") if len(sys.argv) > 2 else METHODS
    lp_module.LinearProgram.solve = _counting_solve()  # type: ignore[method-assign]
    hull_module._load = _counting_load()
    print("| scenario | method | steps | solves per bound | CPU s | mean width |")
    print("|---|---|---:|---:|---:|---:|")
    for name in names:
        sc, tr = _record(name)
        for method in methods:
            est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
            _COUNT["solves"] = 0
            t0 = time.process_time()
            res = est.run(tr.u, tr.y)
            dt = time.process_time() - t0
            T = tr.y.shape[0]
            rate = _COUNT["solves"] / (2 * sc.system.nx * T)
            width = float(np.nanmean(res.upper - res.lower))
            print(
                f"| `{name}` | `{method}` | {T} | {rate:.3f} | {dt:.1f} | {width:.5g} |", flush=True
            )


if __name__ == "__main__":
    main()
