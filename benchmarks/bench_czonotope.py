"""Constrained-zonotope filter: speed and tightness against the exact hull.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_czonotope.py speed      # servo, tank30
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_czonotope.py drift      # CORA benchmarks
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_czonotope.py growth     # n = 5 .. 60
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_czonotope.py reference  # (re)compute cache

``drift``: ratio of the mean box width of ``constrained-zonotope`` (default options) to that of
the exact hull (``exact``, full horizon) at every 50th step (and the last) of each CORA
benchmark, on its recorded data. The exact hull is slow (minutes on tank30): it is computed once
and cached in ``benchmarks/results/cora_exact_hull.npz`` (``reference`` recomputes it).
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

import ivobs

CORA = ["cora-2dim", "cora-vehicle6", "cora-pedestrian4", "cora-slip4", "cora-tank30"]
CACHE = Path(__file__).parent / "results" / "cora_exact_hull.npz"


def _record(name: str) -> tuple[ivobs.scenarios.Scenario, ivobs.Trajectory]:
    sc = ivobs.scenarios.get(name)
    return sc, sc.recorded


def reference(names: list[str]) -> dict[str, np.ndarray]:
    """Exact hull widths ``(T, nx)`` per benchmark, cached."""
    cache = dict(np.load(CACHE)) if CACHE.exists() else {}
    for name in names:
        if f"{name}/width" in cache and "reference" not in sys.argv[1:2]:
            continue
        sc, tr = _record(name)
        t0 = time.perf_counter()
        est = ivobs.make_estimator("exact", sc.system, x0=sc.x0)
        res = est.run(tr.u, tr.y)
        cache[f"{name}/width"] = res.upper - res.lower
        cache[f"{name}/seconds"] = np.array(time.perf_counter() - t0)
        print(f"{name}: exact hull in {float(cache[f'{name}/seconds']):.1f} s", flush=True)
        np.savez(CACHE, **cache)
    return {n: cache[f"{n}/width"] for n in names}


def drift(names: list[str], **options: object) -> None:
    ref = reference(names)
    for name in names:
        sc, tr = _record(name)
        est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0, **options)
        t0 = time.perf_counter()
        res = est.run(tr.u, tr.y)
        dt = time.perf_counter() - t0
        w, wr = res.upper - res.lower, ref[name]
        T = w.shape[0]
        ks = sorted({*range(0, T, 50), T - 1})
        ratio = [float(np.mean(w[k]) / np.mean(wr[k])) for k in ks]
        worst = float(np.max(w.mean(axis=1) / wr.mean(axis=1)))
        inside = bool(np.all(res.contains(tr.x)[~np.isnan(tr.x).any(axis=1)]))
        cells = " ".join(f"{k}:{r:.3f}" for k, r in zip(ks, ratio, strict=True))
        print(
            f"{name:17s} {T / dt:8.1f} steps/s  worst {worst:.3f}  contains {inside}  {cells}",
            flush=True,
        )


def speed() -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=2000)
    tr = sc.simulate("vertex", seed=0)
    est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0)
    best = 0.0
    for _ in range(3):
        est.reset()
        t0 = time.perf_counter()
        for k in range(2000):
            est.step(tr.u[k], tr.y[k])
        best = max(best, 2000 / (time.perf_counter() - t0))
    res = est.run(tr.u, tr.y)
    print(f"servo  step() {best:8.0f} steps/s  mean width {np.nanmean(res.upper - res.lower):.6f}")
    sc, tr = _record("cora-tank30")
    est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0)
    t0 = time.perf_counter()
    res = est.run(tr.u, tr.y)
    dt = time.perf_counter() - t0
    r = 0.5 * (res.upper - res.lower).mean(axis=1)
    print(f"tank30 run  {235 / dt:8.1f} steps/s  r(20) {r[19]:.4f}  r(235) {r[234]:.4f}")


def growth() -> None:
    """Per-step cost on random stable systems (``n/3`` outputs, a disturbance per state and
    output), once the set has reached its limits: steps 20-29 of a 30-step run (CPU time, and
    wall time; ``growth 5,10,20`` for some sizes only; system ``n`` drawn with seed ``n``)."""
    ns = [int(v) for v in sys.argv[2].split(",")] if len(sys.argv) > 2 else [5, 10, 20, 40, 60]
    times: list[float] = []
    for n in ns:
        rng = np.random.default_rng(n)  # the same system whichever sizes are run
        A = rng.normal(size=(n, n))
        A *= 0.9 / max(abs(np.linalg.eigvals(A)))
        ny = max(1, n // 3)
        sys_ = ivobs.LinearSystem(
            A,
            np.zeros((n, 1)),
            rng.normal(size=(ny, n)),
            E=np.hstack([0.1 * np.eye(n), np.zeros((n, ny))]),
            F=np.hstack([np.zeros((ny, n)), 0.05 * np.eye(ny)]),
            d=ivobs.Box(-np.ones(n + ny), np.ones(n + ny)),
        )
        x0 = ivobs.Box(-np.ones(n), np.ones(n))
        d = np.where(rng.integers(0, 2, (30, n + ny)) > 0, 1.0, -1.0)
        tr = ivobs.simulate(sys_, np.zeros(n), np.zeros((30, 1)), d)
        est = ivobs.make_estimator("constrained-zonotope", sys_, x0=x0)
        for k in range(20):
            est.step(tr.u[k], tr.y[k])
        t0, c0 = time.perf_counter(), time.process_time()
        for k in range(20, 30):
            est.step(tr.u[k], tr.y[k])
        wall = (time.perf_counter() - t0) / 10
        times.append((time.process_time() - c0) / 10)
        ms, ms_wall = 1e3 * times[-1], 1e3 * wall
        print(f"n = {n:3d}: {ms:9.2f} ms CPU per step ({ms_wall:9.2f} wall)", flush=True)
    if len(ns) < 2:
        return
    slope = np.polyfit(np.log(ns), np.log(times), 1)[0]
    print(f"fitted exponent of the CPU time (n = {ns[0]}..{ns[-1]}): {slope:.2f}")
    local = np.diff(np.log(times)) / np.diff(np.log(ns))
    pairs = zip(ns, ns[1:], local, strict=False)
    print("local exponents: " + ", ".join(f"{a}-{b}: {e:.2f}" for a, b, e in pairs))


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "speed"
    if what == "speed":
        speed()
    elif what == "growth":
        growth()
    elif what == "reference":
        reference(sys.argv[2].split(",") if len(sys.argv) > 2 else CORA)
    else:
        drift(sys.argv[2].split(",") if len(sys.argv) > 2 else CORA)
