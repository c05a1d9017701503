"""Speed and tightness of the strip method ([Alamo2005]).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_strip.py [speed|tank|growth|drift] [key=value]

The step runs compiled when numba is installed; ``IVOBS_NUMBA=0`` in the environment runs the
same source interpreted (what users without numba get).

* ``speed``: online ``step()`` steps/s on the servo motor (2,000 steps, median of 5) and on CORA's
  tank30 (the 235 recorded steps, median of 3), wall and CPU time, with tank30's mean
  interval-hull radius at the 1-based time points k = 20 and k = 235 (row k - 1) beside CORA
  FRad-A's saved values.
* ``tank``: tank30 radii for the options given (``order=``, ``reduction=``).
* ``growth``: CPU seconds per step (median of 3 runs) on random systems n = 5 ... 60 (ny = n / 2,
  default options), the fitted exponent of the per-step cost in n and the one between n = 30
  and 60.
* ``drift``: the ratio of strip's width to the exact hull every 50th step on the CORA
  benchmarks (the exact hull by ``exact``'s LP on the whole record; slow on tank30).
"""

from __future__ import annotations

import sys
import time
from importlib import resources

import numpy as np

import ivobs
from ivobs.testing import adversarial_run, random_system


def _options(argv: list[str]) -> dict[str, object]:
    out: dict[str, object] = {}
    for a in argv:
        k, v = a.split("=")
        out[k] = int(v) if v.isdigit() else v
    return out


def steps_per_second(
    est: ivobs.Estimator, u: np.ndarray, y: np.ndarray, repeats: int
) -> tuple[float, float]:
    """Online steps per second of wall time and of the process's CPU time (the median of
    ``repeats`` runs each: the machine is shared, the CPU figure is the comparable one)."""
    wall, cpu = [], []
    for _ in range(repeats):
        est.reset()
        start, start_cpu = time.perf_counter(), time.process_time()
        for k in range(y.shape[0]):
            est.step(u[k], y[k])
        cpu.append(y.shape[0] / (time.process_time() - start_cpu))
        wall.append(y.shape[0] / (time.perf_counter() - start))
    return float(np.median(wall)), float(np.median(cpu))


def cora_radii() -> dict[str, float]:
    with resources.files("ivobs.data").joinpath("cora_tank30_results.npz").open("rb") as fh:
        z = np.load(fh)
        out = {}
        for k in (20, 235):
            for alg in ("FRadA", "exact"):
                key = f"cora_k{k}_{alg}" if alg != "exact" else f"exact_k{k}"
                out[f"{alg}{k}"] = float(np.mean(0.5 * (z[key + "_hi"] - z[key + "_lo"])))
        return out


def tank(opts: dict[str, object], timed: bool = False) -> None:
    sc = ivobs.scenarios.get("cora-tank30")
    tr = sc.recorded
    est = ivobs.make_estimator("strip", sc.system, x0=sc.x0, **opts)
    start = time.perf_counter()
    res = est.run(tr.u, tr.y)
    elapsed = time.perf_counter() - start
    r = 0.5 * (res.upper - res.lower)
    inside = bool(np.all((res.lower <= tr.x) & (tr.x <= res.upper)))
    ref = cora_radii()
    print(
        f"tank30 strip {opts}: r(20) = {r[19].mean():.4f} (CORA FRad-A {ref['FRadA20']:.4f},"
        f" exact {ref['exact20']:.4f}), r(235) = {r[234].mean():.4f} (CORA {ref['FRadA235']:.4f},"
        f" exact {ref['exact235']:.4f}), max r = {r.max():.3g}, contains x: {inside},"
        f" run {elapsed:.2f} s ({1e3 * elapsed / 235:.2f} ms/step)"
    )
    if timed:
        wall, cpu = steps_per_second(est, tr.u, tr.y, 3)
        print(f"tank30 strip step(): {wall:,.0f} steps/s wall, {cpu:,.0f} steps/s CPU")


def speed(opts: dict[str, object]) -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=2000)
    tr = sc.simulate("vertex", seed=0)
    est = ivobs.make_estimator("strip", sc.system, x0=sc.x0, **opts)
    wall, cpu = steps_per_second(est, tr.u, tr.y, 5)
    print(f"servo strip step(): {wall:,.0f} steps/s wall, {cpu:,.0f} steps/s CPU")
    tank(opts, timed=True)


def growth(opts: dict[str, object]) -> None:
    ns = [5, 10, 20, 30, 40, 60]
    cost = []
    for n in ns:
        sysm = random_system(n, nx=n, ny=max(1, n // 2), nu=1)
        x0 = ivobs.Box(-np.ones(n), np.ones(n))
        T = 60 if n <= 30 else 30
        tr = adversarial_run(sysm, x0, T, seed=n)
        est = ivobs.make_estimator("strip", sysm, x0=x0, **opts)
        est.run(tr.u[:5], tr.y[:5])
        runs = []
        for _ in range(3):
            start, start_cpu = time.perf_counter(), time.process_time()
            est.run(tr.u, tr.y)
            runs.append((time.process_time() - start_cpu, time.perf_counter() - start))
        c, w = np.median(runs, axis=0) / T
        cost.append(c)
        print(f"n = {n:3d}: {1e3 * c:8.2f} ms/step CPU ({1e3 * w:.2f} wall)")
    slope = np.polyfit(np.log(ns), np.log(cost), 1)[0]
    tail = np.log(cost[-1] / cost[-3]) / np.log(ns[-1] / ns[-3])
    print(
        f"fitted exponent of the CPU cost (cost ~ n^a, n = {ns[0]}..{ns[-1]}): a = {slope:.2f};"
        f" between n = {ns[-3]} and {ns[-1]}: {tail:.2f}"
    )


def drift(opts: dict[str, object]) -> None:
    names = ["cora-vehicle6", "cora-pedestrian4", "cora-slip4", "cora-2dim", "cora-tank30"]
    for name in names:
        sc = ivobs.scenarios.get(name)
        tr = sc.recorded
        st = ivobs.make_estimator("strip", sc.system, x0=sc.x0, **opts).run(tr.u, tr.y)
        ex = ivobs.make_estimator("exact", sc.system, x0=sc.x0, progress=False).run(tr.u, tr.y)
        T = tr.y.shape[0]
        pts = sorted({k for k in range(0, T, 50)} | {T - 1}) if T > 50 else [T - 1]
        ratio = [np.mean(st.width[k]) / np.mean(ex.width[k]) for k in pts]
        worst = [np.max(st.width[k] / np.maximum(ex.width[k], 1e-300)) for k in pts]
        print(f"{name}: k, mean-width ratio (worst state) to the exact hull")
        print("   " + "  ".join(f"{k}: {a:.3f} ({b:.2f})" for k, a, b in zip(pts, ratio, worst)))


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "speed"
    options = _options(sys.argv[2:])
    {"speed": speed, "tank": tank, "growth": growth, "drift": drift}[what](options)
