"""The set-based nonlinear methods (`nl-zonotope`, `nl-constrained-zonotope`): speed on Hénon,
widths on CORA's six-tank test.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nonlinear_sets.py [speed|tank|all]

* speed: online ``step()`` on the Hénon map with uncertain ``a ∈ [1.39, 1.41]``,
  ``w1 ∈ ±0.005``, ``y = x1 + v1``, ``v1 ∈ ±0.02`` (vertex values switching at random), best of
  3 repeats; goals ``nl-zonotope >= 2,000`` and ``nl-constrained-zonotope >= 500`` steps/s. Both
  wall-clock and CPU time are printed (CPU time is less sensitive to a shared machine); the linear
  ``strip`` on the servo motor is printed beside as a yardstick of the machine's speed.
* tank: CORA's ``test_nonlinearSysDT_observe_01_tank`` (src/ivobs/data/cora_tank6_nl.npz): the
  final box widths of each method beside CORA's saved FRad-A/B/C boxes.
"""

from __future__ import annotations

import platform
import sys
import time
from importlib import resources

import numpy as np

import ivobs
from ivobs.scenarios.nonlinear import tank6_system

METHODS = {"nl-zonotope": 2000, "nl-constrained-zonotope": 500}


def henon() -> ivobs.NonlinearSystem:
    return ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=["x1 + v1"],
        states=["x1", "x2"],
        params={"a": (1.39, 1.41), "b": 0.3},
        d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )


def henon_record(T: int, seed: int = 0) -> np.ndarray:
    """Measurements of a float64 Hénon run (speed only: soundness is tested at 200 bits)."""
    rng = np.random.default_rng(seed)
    x = np.array([0.3, 0.1])
    y = np.empty((T, 1))
    for k in range(T):
        a = rng.choice([1.39, 1.41])
        y[k, 0] = x[0] + rng.choice([-0.02, 0.02])
        x = np.array([1 - a * x[0] ** 2 + x[1] + rng.choice([-0.005, 0.005]), 0.3 * x[0]])
    return y


def _timed(est: ivobs.Estimator, u: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    est.reset()
    w0, c0 = time.perf_counter(), time.process_time()
    for k in range(y.shape[0]):
        est.step(u[k], y[k])
    return time.perf_counter() - w0, time.process_time() - c0


def speed() -> None:
    cpu = platform.processor() or platform.machine()
    print(f"machine: {cpu}, Python {platform.python_version()}")
    sc = ivobs.scenarios.get("servo-motor", horizon=1000)
    tr = sc.simulate("vertex", seed=0)
    ref = ivobs.make_estimator("strip", sc.system, x0=sc.x0)
    best = min(_timed(ref, tr.u, tr.y) for _ in range(3))
    print(
        f"{'strip (servo, yardstick)':32s} {1000 / best[0]:8,.0f} steps/s wall "
        f"{1000 / best[1]:8,.0f} cpu"
    )
    sys_ = henon()
    x0 = ivobs.Box([0.2, 0.0], [0.4, 0.2])
    for name, goal in METHODS.items():
        T = 2000 if goal >= 2000 else 500
        y = henon_record(T)
        u = np.zeros((T, 0))
        est = ivobs.make_estimator(name, sys_, x0=x0)
        best = min(_timed(est, u, y) for _ in range(3))
        print(
            f"{name + ' (Hénon)':32s} {T / best[0]:8,.0f} steps/s wall {T / best[1]:8,.0f} cpu"
            f"   goal {goal:,}"
        )


def tank_system() -> ivobs.NonlinearSystem:
    return tank6_system()  # the cora-tank6-nl scenario's model


def tank() -> None:
    with resources.files("ivobs.data").joinpath("cora_tank6_nl.npz").open("rb") as fh:
        data = dict(np.load(fh))
    x0 = ivobs.Box(data["R0_c"] - 4.0, data["R0_c"] + 4.0)
    print("CORA six-tank test, final box widths (after y[19]):")
    for i, alg in enumerate(data["saved_methods"]):
        w = data["saved_hi"][i] - data["saved_lo"][i]
        print(f"  CORA {alg:24s} {np.array2string(w, precision=3)}")
    for name in METHODS:
        est = ivobs.make_estimator(name, tank_system(), x0=x0)
        start = time.perf_counter()
        res = est.run(data["u"], data["y"])
        dt = time.perf_counter() - start
        w = res.upper[-1] - res.lower[-1]
        print(f"  {name:29s} {np.array2string(w, precision=3)}   {1e3 * dt / 20:.1f} ms/step")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "all"
    if what in ("speed", "all"):
        speed()
    if what in ("tank", "all"):
        tank()
