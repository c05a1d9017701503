"""Speed of the interval-observer family (`interval`, `interval-split`, `interval-transformed`).

Servo motor of [Tang2019]. Prints the designed gains, then steps/s for one long record
(vectorised `run`), a batch of independent streams, the online `step()` loop and the loop path of
`run` with 10% missing samples. Targets for `interval` and `interval-split`: >= 1,000,000
steps/s on a 200,000-step record; 10,000 streams x 1,000 steps in < 2 s.

Run: ``python benchmarks/bench_interval.py [--quick]``.
"""

from __future__ import annotations

import os
import sys
import time

# The recursions multiply (N, 3) by (3, 3) matrices: BLAS threads only add contention.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import ivobs

METHODS = ("interval", "interval-split", "interval-transformed")


def _best(fn, repeat: int = 3) -> float:
    """Best wall time; the CPU time of that run is kept in ``_best.cpu`` (on a loaded machine
    the wall time includes waiting for a core)."""
    times = []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        times.append((time.perf_counter() - t0, time.process_time() - c0))
    wall, _best.cpu = min(times)
    return wall


def batch_trajectories(sc: ivobs.scenarios.Scenario, B: int, T: int, seed: int = 0):
    """``B`` trajectories of ``T`` steps with vertex disturbances, simulated batch-wise."""
    A, Bm, C, D, E, F = sc.system.matrices_at(0)
    box = sc.system.d
    rng = np.random.default_rng(seed)
    d = np.where(rng.integers(0, 2, (B, T, box.dim)).astype(bool), box.hi, box.lo)
    u = np.broadcast_to(sc.u[:1], (T, sc.system.nu))
    x = np.empty((B, T, sc.system.nx))
    xk = np.broadcast_to(sc.x_true0, (B, sc.system.nx)).copy()
    for k in range(T):
        x[:, k] = xk
        xk = xk @ A.T + u[k] @ Bm.T + d[:, k] @ E.T
    y = x @ C.T + u @ D.T + d @ F.T
    return u, y, x


def main(quick: bool = False) -> None:
    T_long = 20_000 if quick else 200_000
    B, T_b = (1_000, 1_000) if quick else (10_000, 1_000)
    T_step = 2_000
    sc = ivobs.scenarios.get("servo-motor", horizon=T_long)
    tr = sc.simulate("vertex", seed=0)
    U, Y, X = batch_trajectories(sc, B, T_b)
    print(f"servo motor: nx={sc.system.nx}, ny={sc.system.ny}, nd={sc.system.nd}")
    for method in METHODS:
        t0 = time.perf_counter()
        est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
        t_design = time.perf_counter() - t0
        with np.printoptions(precision=4, suppress=True):
            print(f"{method:>20}: design {t_design:.3f} s, L =\n{est.design.L}")
            print(f"{'':>20}  steady-state width {est.design.steady_width}")
        res = est.run(tr.u, tr.y)
        assert res.contains(tr.x).all(), method
        t = _best(lambda est=est: est.run(tr.u, tr.y))
        print(
            f"{'':>20}  {T_long} steps, vectorised run: {t:.3f} s (CPU {_best.cpu:.3f} s) = "
            f"{T_long / t:,.0f} steps/s"
        )
        res_b = est.run(U, Y)
        assert res_b.contains(X).all(), method
        t = _best(lambda est=est: est.run(U, Y), repeat=2)
        print(
            f"{'':>20}  batch {B} x {T_b}: {t:.3f} s (CPU {_best.cpu:.3f} s) = "
            f"{B * T_b / t:,.0f} steps/s ({'OK' if t < 2 else 'SLOW'} vs 2 s target)"
        )

        def online(est=est) -> None:
            est.reset()
            for k in range(T_step):
                est.step(tr.u[k], tr.y[k])

        t = _best(online, repeat=2)
        print(f"{'':>20}  step() loop: {T_step / t:,.0f} steps/s")
        y_miss = tr.y[:T_step].copy()
        y_miss[np.random.default_rng(1).random(T_step) < 0.1] = np.nan
        t = _best(lambda est=est, y_miss=y_miss: est.run(tr.u[:T_step], y_miss), repeat=2)
        print(f"{'':>20}  run() with 10% missing samples (loop): {T_step / t:,.0f} steps/s")


if __name__ == "__main__":
    main(quick="--quick" in sys.argv)
