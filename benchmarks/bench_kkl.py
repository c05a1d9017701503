"""Speed of the KKL / Sylvester observers (method ``kkl``, [Dinh2024]), in CPU time.

Prints steps per second (best of a few repeats, ``time.process_time``) for

* DT LTI ``run()`` on a 200,000-step servo-motor record (floor: 1e6 steps/s);
* a batch of 10,000 servo-motor streams x 1,000 steps;
* DT LTI online ``step()`` (floor: 20,000 steps/s);
* DT LTV ``run()`` (Example 3, the loop);
* CT LTI (Example 1, 8 states) and CT LTV (pendulum) ``run()`` on a dt = 0.01 grid;
* the offline design time (default target with gradient refinement).

``--widths``: the mean width over whole records of every scenario of ``suite.py`` that ``kkl``
runs (vertex disturbances); ``--missing``: the width ratio with 10 % of the output components
missing on random 4-state plants (``rho = 0.8``, 3,000 steps).

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_kkl.py [--quick | --widths | --missing]``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

import numpy as np

import ivobs

clock = time.process_time


def _best(fn: Callable[[], object], repeat: int = 3) -> float:
    times = []
    for _ in range(repeat):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return min(times)


def main(quick: bool = False) -> None:
    T = 20_000 if quick else 200_000
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    tr = sc.simulate()
    t0 = clock()
    est = ivobs.make_estimator("kkl", sc.system, x0=sc.x0)
    design = clock() - t0
    est.run(tr.u[:5000], tr.y[:5000])  # warm-up (imports)
    res = est.run(tr.u, tr.y)
    assert res.contains(tr.x).all()
    dt = _best(lambda: est.run(tr.u, tr.y))
    print(f"design (servo, tuned target)            {design * 1e3:8.1f} ms")
    print(f"DT LTI run, servo {T:>7d} steps          {T / dt:12.3e} steps/s  ({dt * 1e3:.1f} ms)")

    B, K = (1000, 1000) if quick else (10_000, 1000)
    rng = np.random.default_rng(0)
    U = np.broadcast_to(tr.u[:K], (B, K, 1))
    Y = tr.y[:K] + 0.01 * rng.uniform(-1, 1, (B, K, 2))
    dt = _best(lambda: est.run(U, Y, vectorize=True), repeat=2)
    print(f"DT LTI batch {B} x {K}                 {B * K / dt:12.3e} steps/s  ({dt:.2f} s)")

    n = 2000

    def online() -> None:
        est.reset()
        for k in range(n):
            est.step(tr.u[k], tr.y[k])

    dt = _best(online)
    print(f"DT LTI step()                           {n / dt:12.3e} steps/s")

    ex3 = ivobs.scenarios.get("kkl-ltv-dt", horizon=200)
    u3 = np.zeros((200, 0))
    y3 = ivobs.simulate(
        ex3.system, ex3.x_true0, u3, ivobs.vertex_disturbance(ex3.system.d, 200, seed=0)
    ).y
    dt = _best(lambda: ivobs.make_estimator("kkl", ex3.system).run(u3, y3))
    print(f"DT LTV run (Example 3, 200 steps)       {200 / dt:12.3e} steps/s")

    ct = ivobs.scenarios.get("kkl-random8", continuous=True, t_final=2.0 if quick else 10.0)
    trc = ct.simulate()
    estc = ivobs.make_estimator("kkl", ct.system, x0=ct.x0)
    dt = _best(lambda: estc.run(trc.u, trc.y, t=trc.t), repeat=1)
    print(f"CT LTI run (Example 1, {trc.T} samples)    {trc.T / dt:12.3e} steps/s")

    pend = ivobs.scenarios.get("pendulum", t_final=2.0 if quick else 15.0)
    trp = pend.simulate()
    estp = ivobs.make_estimator("kkl", pend.system, x0=pend.x0)
    dt = _best(lambda: estp.run(trp.u, trp.y, t=trp.t), repeat=1)
    print(f"CT LTV run (pendulum, {trp.T} samples)     {trp.T / dt:12.3e} steps/s")


SCENARIOS = [
    "dinh2019",
    "servo-motor",
    "tang-example2",
    "efimov-planar",
    "henon",
    "kkl-random8",
    "kkl-ltv-dt",
    "cora-2dim",
    "cora-vehicle6",
    "cora-pedestrian4",
    "cora-slip4",
]


def widths() -> None:
    """Mean width (sum over the states) over each whole record, from ``valid_from``."""
    import warnings

    warnings.simplefilter("ignore")
    for name in SCENARIOS:
        sc = ivobs.scenarios.get(name)
        tr = sc.simulate("vertex", seed=0)
        res = ivobs.make_estimator("kkl", sc.system, x0=sc.x0).run(tr.u, tr.y)
        w = res.width[res.valid_from :].sum(axis=1).mean()
        ok = bool(res.contains(tr.x)[res.valid_from :].all())
        print(f"{name:18s} T={tr.T:5d} mean_width={w:.10g} contains={ok}")


def missing() -> None:
    """Mean width with 10 % of the output components missing / with complete data."""
    from ivobs.testing import adversarial_run, random_system

    for ny in (1, 2):
        for seed in range(6):
            sys_ = random_system(seed, nx=4, ny=ny, nu=1, rho=0.8)
            x0 = ivobs.Box(-np.ones(4), np.ones(4))
            tr = adversarial_run(sys_, x0, 3000, seed=seed)
            y = tr.y.copy()
            y[np.random.default_rng(100 + seed).random(y.shape) < 0.1] = np.nan
            est = ivobs.make_estimator("kkl", sys_, x0=x0)
            full, miss = est.run(tr.u, tr.y), est.run(tr.u, y)
            ratio = miss.width[100:].sum(1).mean() / full.width[100:].sum(1).mean()
            print(f"ny={ny} seed={seed} ratio={ratio:.3g} contains={miss.contains(tr.x).all()}")


if __name__ == "__main__":
    if "--widths" in sys.argv:
        widths()
    elif "--missing" in sys.argv:
        missing()
    else:
        main(quick="--quick" in sys.argv)
