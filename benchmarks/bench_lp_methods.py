"""Tightness and speed of the LP-based methods on their benchmark records, one case per call.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_lp_methods.py CASE [CASE ...]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_lp_methods.py --list

Each case prints one JSON line: the mean width of the boxes over the record (every step from
``valid_from``, every state), the steps run and their CPU time (``time.process_time``; the
``exact`` method solves its two chains in two threads, whose CPU time both count). Only the
public API is used, so the same script measures any checkout (``PYTHONPATH=<checkout>/src``):
run two checkouts interleaved, several rounds, and compare (BENCHMARKS.md).

Cases: ``servo-cz`` (servo motor, 400 ``step()`` calls, vertex disturbances seed 0),
``tank30-cz`` (CORA tank30, the whole recorded record, ``run()``), ``<cora>-cz`` and
``<cora>-dw`` for the other CORA records (``run()``), ``henon-nlcz`` (the Hénon map, 500
``step()`` calls), ``quadtank-dw`` (quadruple tank, 2,000 steps, ``run()``), ``servo-exact-w20``
(servo, 400 ``step()`` calls of ``exact`` with ``window=20``), ``<cora>-exact`` (the full-horizon
hull of the small CORA records).
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from typing import Any

import numpy as np

import ivobs

CORA = ["cora-vehicle6", "cora-pedestrian4", "cora-slip4", "cora-2dim"]


def _henon() -> tuple[Any, Any, np.ndarray, np.ndarray]:
    sys_ = ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=["x1 + v1"],
        states=["x1", "x2"],
        params={"a": (1.39, 1.41), "b": 0.3},
        d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )
    rng = np.random.default_rng(0)
    x = np.array([0.3, 0.1])
    T = 500
    y = np.empty((T, 1))
    for k in range(T):
        a = rng.choice([1.39, 1.41])
        y[k, 0] = x[0] + rng.choice([-0.02, 0.02])
        x = np.array([1 - a * x[0] ** 2 + x[1] + rng.choice([-0.005, 0.005]), 0.3 * x[0]])
    return sys_, ivobs.Box([0.2, 0.0], [0.4, 0.2]), np.zeros((T, 0)), y


def _case(name: str) -> tuple[str, Any, Any, np.ndarray, np.ndarray, dict[str, Any], bool]:
    """(method, system, x0, u, y, options, online) of a case."""
    if name == "servo-cz" or name == "servo-exact-w20":
        sc = ivobs.scenarios.get("servo-motor", horizon=400)
        tr = sc.simulate("vertex", seed=0)
        if name == "servo-cz":
            return "constrained-zonotope", sc.system, sc.x0, tr.u, tr.y, {}, True
        return "exact", sc.system, sc.x0, tr.u, tr.y, {"window": 20, "progress": False}, True
    if name == "henon-nlcz":
        s, x0, u, y = _henon()
        return "nl-constrained-zonotope", s, x0, u, y, {}, True
    if name == "quadtank-dw":
        sc = ivobs.scenarios.get("quadruple-tank", horizon=2000)
        tr = sc.simulate("vertex", 0)
        return "dual-window", sc.system, sc.x0, tr.u, tr.y, {}, False
    bench, _, tag = name.rpartition("-")
    sc = ivobs.scenarios.get(bench)
    tr = sc.simulate("recorded")
    method = {"cz": "constrained-zonotope", "dw": "dual-window", "exact": "exact"}[tag]
    opts: dict[str, Any] = {"progress": False} if tag == "exact" else {}
    return method, sc.system, sc.x0, tr.u, tr.y, opts, False


def measure(name: str) -> dict[str, Any]:
    method, system, x0, u, y, opts, online = _case(name)
    est = ivobs.make_estimator(method, system, x0=x0, on_inconsistent="ignore", **opts)
    T = y.shape[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c0 = time.process_time()
        if online:
            lo, hi = np.empty((T, system.nx)), np.empty((T, system.nx))
            for k in range(T):
                box = est.step(u[k], y[k])
                lo[k], hi[k] = box.lo, box.hi
        else:
            res = est.run(u, y)
            lo, hi = res.lower, res.upper
        cpu = time.process_time() - c0
    w = (hi - lo)[est.valid_from :]
    return {"case": name, "width": float(np.mean(w)), "steps": T, "cpu": cpu, "rate": T / cpu}


CASES = ["servo-cz", "tank30-cz", "henon-nlcz", "quadtank-dw", "servo-exact-w20", "cora-tank30-dw"]
CASES += [f"{c}-{t}" for c in CORA for t in ("cz", "dw", "exact")]

if __name__ == "__main__":
    if sys.argv[1:2] == ["--list"]:
        print(" ".join(CASES))
    for case in sys.argv[1:]:
        if case != "--list":
            print(json.dumps(measure("cora-tank30-cz" if case == "tank30-cz" else case)))
