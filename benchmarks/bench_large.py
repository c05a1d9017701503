"""Per-step cost of the interval observers on a large sparse system vs one sparse mat-vec.

The ``heat-1d`` scenario with ``nx = 2000`` nodes (tridiagonal ``A``, 3 point sensors) and the
gain :func:`ivobs.scenarios.heat_gain` (``A - LC >= 0``, checked with sparse algebra). For
``interval`` and ``interval-split`` it prints, per step of a ``T``-step record:

* ``A @ x``: one sparse matrix-vector product with SciPy's public operator (the reference);
* ``run()``: the whole ``run()`` of the record (the recursion with its rounding bound, the
  consistency test of every measurement, the base class's checks);
* ``step()``: the online loop, one call per sample.

Each figure is the best of several interleaved repetitions, in CPU time (the machine may be
shared). Only the public API is used, so the same script measures any version of ivobs.

Run: ``python benchmarks/bench_large.py [--nx 2000] [--T 2000]``.
"""

from __future__ import annotations

import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import ivobs


def record(sc: ivobs.scenarios.Scenario, T: int, seed: int = 0):
    """A vertex-disturbance trajectory, simulated with sparse products."""
    s = sc.system
    rng = np.random.default_rng(seed)
    d = np.where(rng.integers(0, 2, (T, s.nd)).astype(bool), s.d.hi, s.d.lo)
    A, C = s.sparse("A"), s.sparse("C")
    B, E, F = s.B_at(0), s.E_at(0), s.F_at(0)
    x = np.empty((T, s.nx))
    xk = sc.x_true0.copy()
    for k in range(T):
        x[k] = xk
        xk = A @ xk + B @ sc.u[k] + E @ d[k]
    return x, (C @ x.T).T + d @ F.T


def cpu_per_call(fn, calls: int) -> float:
    c0 = time.process_time()
    for _ in range(calls):
        fn()
    return (time.process_time() - c0) / calls


def main(nx: int = 2000, T: int = 2000, repeat: int = 5) -> None:
    sc = ivobs.scenarios.get("heat-1d", nx=nx, horizon=T)
    s = sc.system
    A = s.sparse("A")
    x, y = record(sc, T)
    L = sc.reference["L"]
    print(f"heat-1d: nx = {nx}, nnz(A) = {A.nnz}, {s.ny} sensors, T = {T} steps")
    ests = {}
    for name in ("interval", "interval-split"):
        t0 = time.perf_counter()
        ests[name] = ivobs.make_estimator(name, s, x0=sc.x0, L=L)
        res = ests[name].run(sc.u, y)
        assert res.contains(x).all() and not res.inconsistent.any(), name
        rho = ests[name].design.spectral_radius
        print(
            f"{name}: design (sparse checks, spectral radius {rho:.6f}) "
            f"{time.perf_counter() - t0:.2f} s, mean width {np.mean(res.width):.6g}"
        )
    xv = np.random.default_rng(1).random(nx)
    best: dict[str, float] = {}

    def keep(key: str, value: float) -> None:
        best[key] = min(best.get(key, np.inf), value)

    for _ in range(repeat):
        keep("A @ x", cpu_per_call(lambda: A @ xv, 2000))
        for name, est in ests.items():
            keep(f"{name}: run()", cpu_per_call(lambda e=est: e.run(sc.u, y), 1) / T)

            def online(e=est) -> None:
                e.reset()
                for k in range(500):
                    e.step(sc.u[k], y[k])

            keep(f"{name}: step() (online)", cpu_per_call(online, 1) / 500)
    ref = best["A @ x"]
    print(f"\n{'per step':>34} {'us':>8} {'x A@x':>7}")
    for key, val in best.items():
        print(f"{key:>34} {val * 1e6:8.1f} {val / ref:7.2f}")


if __name__ == "__main__":
    args = sys.argv[1:]
    opts = {a.lstrip("-"): int(b) for a, b in zip(args[::2], args[1::2])}
    main(**opts)
