"""Speed and widths of the `reachability` and `zonotope` estimators ([Tang2019]) on the servo
motor.

Prints, per method, in CPU time (``time.process_time``, best of the repeats): the vectorised
``run()`` on one long record, a batch of streams, the online ``step()`` loop, and ``run()`` with
10 % of the samples missing (the loop: the window of ``reachability``, the gains of the outputs
present), and the mean width over the long record. Floors: ``run()`` >= 1,000,000 steps/s on a
200,000-step record, ``step()`` >= 20,000 steps/s.

Run: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_reachability.py [--quick]``.
"""

from __future__ import annotations

import os
import sys
import time
import warnings

import numpy as np
from timing import cpu_best as _cpu  # benchmarks/timing.py

import ivobs


def batch_record(sc: ivobs.scenarios.Scenario, B: int, T: int, seed: int = 0):
    """``B`` streams: random x0 in the prior box, vertex disturbances (vectorised simulation)."""
    s = sc.system
    rng = np.random.default_rng(seed)
    x = rng.uniform(sc.x0.lo, sc.x0.hi, size=(B, s.nx))
    d = np.where(rng.integers(0, 2, size=(B, T, s.nd)) == 1, s.d.hi, s.d.lo)
    u = np.broadcast_to(sc.u[:1], (B, T, s.nu))
    X = np.empty((B, T, s.nx))
    for k in range(T):
        X[:, k] = x
        x = x @ s.A.T + u[:, k] @ s.B.T + d[:, k] @ s.E.T
    Y = X @ s.C.T + u @ s.D.T + d @ s.F.T
    return u, Y, X


def main(quick: bool = False) -> None:
    T_long = 20_000 if quick else 200_000
    B, T_b = (1_000, 1_000) if quick else (10_000, 1_000)
    T_step = 2_000
    sc = ivobs.scenarios.get("servo-motor", horizon=max(T_long, T_b))
    tr = sc.simulate("vertex", seed=0)
    U, Y, X = batch_record(sc, B, T_b)
    s = sc.system
    print(f"servo motor ([Tang2019, Example 1]): nx={s.nx}, ny={s.ny}, nd={s.nd}")
    if hasattr(os, "getloadavg"):
        print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (CPU times below)")
    rng = np.random.default_rng(1)
    y_miss = tr.y[:T_step].copy()
    y_miss[rng.random(T_step) < 0.1] = np.nan
    for method in ("reachability", "zonotope"):
        t0 = time.process_time()
        est = ivobs.make_estimator(method, s, x0=sc.x0)
        print(f"{method:>12}: design {time.process_time() - t0:.3f} s")
        res = est.run(tr.u, tr.y)
        assert res.contains(tr.x).all()
        t = _cpu(lambda est=est: est.run(tr.u, tr.y))
        print(f"{method:>12}: {T_long} steps, vectorised run: {T_long / t:>12,.0f} steps/s")
        print(f"{method:>12}: mean width over the record: {np.mean(res.upper - res.lower):.10f}")
        res = est.run(U, Y)
        assert res.contains(X).all() and not res.inconsistent.any()
        t = _cpu(lambda est=est: est.run(U, Y), repeat=2)
        print(f"{method:>12}: batch {B} x {T_b}: {t:.3f} s")

        def online(est=est) -> None:
            est.reset()
            for k in range(T_step):
                est.step(tr.u[k], tr.y[k])

        t = _cpu(online)
        print(f"{method:>12}: step() loop: {T_step / t:>12,.0f} steps/s")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t = _cpu(lambda est=est, y=y_miss: est.run(tr.u[:T_step], y), repeat=2)
        print(f"{method:>12}: run() with 10% missing samples (loop): {T_step / t:>12,.0f} steps/s")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
