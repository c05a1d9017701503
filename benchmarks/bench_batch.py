"""Batch throughput of the recursive methods, and the memory of a long record (issue 9).

A batch of ``B`` streams x ``T`` steps of the servo motor ([Tang2019]), vertex disturbances, one
input signal for the whole fleet, run in one call ``est.run(u, Y)`` with ``Y`` of shape
``(B, T, ny)``. Prints, per method, the best wall and CPU time of a few runs, the throughput in
streams x steps per second, and whether the target (10,000 x 1,000 in under 2 s) is met. The
``floor`` line is an estimator whose vectorised path only allocates its output: the cost of the
base class (validation, writing the (B, T, nx) bounds, outward rounding), which every method
pays.

``--memory``: the peak memory (``tracemalloc``) of ``run()`` over one record of 10^6 steps, per
method, in MB and in floats per (step x state). The data (``u``, ``y``) are allocated before the
measurement starts and are not counted.

Run: ``python benchmarks/bench_batch.py [--quick] [--memory] [method ...]`` (``--quick``: 1,000
streams; single-threaded BLAS is set below, as for the targets).
"""

from __future__ import annotations

import os
import sys
import time
import tracemalloc
import warnings

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import ivobs
from ivobs.estimators.base import Estimator

METHODS = (
    "reachability",
    "interval",
    "interval-split",
    "interval-transformed",
    "fixed-time",
    "kkl",
)


class Floor(Estimator):
    """What the base class costs: a vectorised path that only writes its output."""

    name = "floor"

    def _initial_state(self) -> dict:
        return {}

    def _run(self, u, y, t):
        shape = (*y.shape[:-1], self.sys.nx)
        return np.zeros(shape), np.ones(shape)


def fleet(sc: ivobs.scenarios.Scenario, B: int, T: int, seed: int = 0):
    """``B`` trajectories of ``T`` steps (vertex disturbances, random vertices of the prior)."""
    A, Bm, C, D, E, F = sc.system.matrices_at(0)
    box = sc.system.d
    rng = np.random.default_rng(seed)
    d = np.where(rng.integers(0, 2, (B, T, box.dim)).astype(bool), box.hi, box.lo)
    u = sc.u[:T]
    x = np.empty((B, T, sc.system.nx))
    xk = np.where(rng.integers(0, 2, (B, sc.system.nx)).astype(bool), sc.x0.hi, sc.x0.lo)
    for k in range(T):
        x[:, k] = xk
        xk = xk @ A.T + u[k] @ Bm.T + d[:, k] @ E.T
    y = x @ C.T + u @ D.T + d @ F.T
    return u, y, x


def timed(fn, repeat: int) -> tuple[float, float]:
    """Best wall time and the CPU time of that run (on a shared machine the wall time also
    counts waiting for a core)."""
    runs = []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        runs.append((time.perf_counter() - t0, time.process_time() - c0))
    return min(runs)


def throughput(methods: list[str], B: int, T: int) -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    u, Y, X = fleet(sc, B, T)
    print(f"servo motor, batch of {B:,} streams x {T:,} steps (OPENBLAS_NUM_THREADS=1)")
    print(f"{'method':>22} {'wall s':>8} {'CPU s':>8} {'streams*steps/s':>16}  target < 2 s")
    for name in ["floor", *methods]:
        est = (
            Floor(sc.system, sc.x0)
            if name == "floor"
            else ivobs.make_estimator(name, sc.system, x0=sc.x0)
        )
        res = est.run(u, Y)
        vf = res.valid_from
        if name != "floor":  # the floor's box is a placeholder
            assert res.contains(X)[:, vf:].all(), name
            assert not res.inconsistent.any(), name
        del res
        wall, cpu = timed(lambda est=est: est.run(u, Y), repeat=3)
        ok = "" if name == "floor" else ("OK" if wall < 2.0 * B * T / 1e7 else "SLOW")
        print(f"{name:>22} {wall:8.3f} {cpu:8.3f} {B * T / wall:16,.0f}  {ok}")


def memory(methods: list[str], T: int = 1_000_000) -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    tr = sc.simulate("sinusoidal")
    nx = sc.system.nx
    print(f"\npeak memory of run() over one record of {T:,} steps (tracemalloc; data excluded)")
    print(f"{'method':>22} {'peak MB':>9} {'floats/(step*state)':>20} {'output MB':>10}")
    for name in methods:
        est = ivobs.make_estimator(name, sc.system, x0=sc.x0)
        est.run(tr.u[:3000], tr.y[:3000])  # designs and caches outside the measurement
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tracemalloc.start()
            res = est.run(tr.u, tr.y)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
        out = res.lower.nbytes + res.upper.nbytes
        print(f"{name:>22} {peak / 1e6:9.1f} {peak / (8 * T * nx):20.2f} {out / 1e6:10.1f}")
        del res


def main(argv: list[str]) -> None:
    quick = "--quick" in argv
    methods = [a for a in argv if not a.startswith("--")] or list(METHODS)
    throughput(methods, 1_000 if quick else 10_000, 1_000)
    if "--memory" in argv:
        memory(methods, 100_000 if quick else 1_000_000)


if __name__ == "__main__":
    main(sys.argv[1:])
