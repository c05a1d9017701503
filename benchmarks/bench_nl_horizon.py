"""nl-horizon against nl-constrained-zonotope and the linearised exact hull.

The linearised exact hull is ``exact`` (moving window of the same ``N``) on the time-varying
linear system obtained by linearising the model along the TRUE trajectory:
``A_k = ∂f/∂x``, ``E_k = ∂f/∂w`` at ``(x_k, w_k)``, the affine part ``f(x_k, w_k) - A_k x_k -
E_k w_k`` an input with ``B = I`` (and the same for ``h``), the same bounds on ``w``. It is the
hull a method that knew the linearisation points exactly would give from the same data: the
reference the window's linearisation over proven boxes tends to.

Run: ``python benchmarks/bench_nl_horizon.py [--steps 1000] [--scenarios range-only ...]``;
``--one-beacon``: ``range-only`` with its first beacon alone (the weakly observable case where
every method drifts, docs/nonlinear.md).
Prints, per scenario: the mean width per state over the late half, the ratios, the misses
(true state outside the box) and the steps per second.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import ivobs
from ivobs.scenarios import registry
from ivobs.scenarios.nonlinear import RANGE_BEACONS, range_only_system

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from linearised import linearised_along


def run(name: str, sys: Any, x0: ivobs.Box, u: np.ndarray, y: np.ndarray, x: np.ndarray,
        **opts: Any) -> tuple[np.ndarray, int, float]:  # fmt: skip
    est = ivobs.make_estimator(name, sys, x0, **opts)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = est.run(u, y)
    dt = time.perf_counter() - t0
    misses = int(np.sum((x < res.lower) | (x > res.upper)))
    return res.upper - res.lower, misses, y.shape[0] / dt


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--scenarios", nargs="+", default=["range-only", "unicycle-range"])
    ap.add_argument("--kinds", nargs="+", default=["vertex", "uniform"])
    ap.add_argument("--window", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--one-beacon", action="store_true", help="range-only with one beacon")
    args = ap.parse_args()
    for scen in args.scenarios:
        for kind in args.kinds:
            sc = registry.get(scen, horizon=args.steps)
            if args.one_beacon and scen == "range-only":
                one = range_only_system(beacons=RANGE_BEACONS[:1])
                sc = dataclasses.replace(sc, system=one)
            tr = sc.simulate(kind, seed=args.seed)
            sys = sc.system
            win = {} if args.window is None else {"window": args.window}
            N = args.window or 20
            rows = {}
            rows["nl-horizon"] = run("nl-horizon", sys, sc.x0, tr.u, tr.y, tr.x, **win)
            rows["nl-constrained-zonotope"] = run(
                "nl-constrained-zonotope", sys, sc.x0, tr.u, tr.y, tr.x
            )
            lin, ulin = linearised_along(sys, tr)
            rows["linearised exact"] = run("exact", lin, sc.x0, ulin, tr.y, tr.x, window=N)
            late = slice(args.steps // 2, None)
            ref = rows["linearised exact"][0][late].mean(axis=0)
            cz = rows["nl-constrained-zonotope"][0][late].mean(axis=0)
            print(f"\n{scen} ({kind}, {args.steps} steps, window {N}); late half mean widths")
            print(f"{'method':26s} {'widths':44s} {'/lin':>6s} {'/nlCZ':>6s} miss steps/s")
            for name, (W, miss, sps) in rows.items():
                m = W[late].mean(axis=0)
                r_lin, r_cz = np.max(m / ref), np.max(m / cz)
                ws = " ".join(f"{v:.4g}" for v in m)
                print(f"{name:26s} {ws:44s} {r_lin:6.2f} {r_cz:6.2f} {miss:4d} {sps:7.1f}")


if __name__ == "__main__":
    main()
