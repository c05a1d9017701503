"""Speed and widths of the `fixed-time` estimator ([Wang2020]), in CPU time.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_fixed_time.py [--quick] [--widths]

Prints steps per CPU-second (best of a few repeats; ``time.process_time``, so a busy shared
machine inflates the figures much less than wall time) for:

* ``run()`` on one 200,000-step record: dinh2019 with ``s = 1, 2, 6`` and the servo motor
  (floor: 1,000,000 steps/s), and dinh2019 with 10 % of the samples missing;
* the online ``step()`` on the servo motor (2,000 steps; floor 20,000 steps/s);
* a batch of 10,000 servo-motor streams of 1,000 steps;
* a time-varying system (``s = 3``, 5,000 steps): the first ``run()`` (one design per step),
  then ``run()`` and ``step()`` with the designs cached.

``--widths``: the mean width over the whole record (every state, from ``valid_from`` on) on the
scenarios of ``benchmarks/suite.py`` that the method runs (vertex disturbances, seed 0).
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np
from suite import DEFAULT_SCENARIOS  # benchmarks/ is on the path of a script run from it
from timing import cpu_best as cpu  # benchmarks/timing.py

import ivobs
from ivobs import Box, LinearSystem

SUITE = DEFAULT_SCENARIOS  # the scenarios of benchmarks/suite.py


def _ltv() -> LinearSystem:
    def A(k):
        return np.array([[0.9, 0.2 * np.sin(0.1 * k)], [0.1, 0.8 + 0.1 * np.cos(0.2 * k)]])

    def C(k):
        return np.array([[1.0, 0.1 * np.sin(0.05 * k)]])

    return LinearSystem(A, [[0.0], [1.0]], C, E=[[0.1], [0.0]], F=[[0.05]], d=Box([-1.0], [1.0]))


def _batch(sys: LinearSystem, x0: np.ndarray, B: int, T: int) -> tuple[np.ndarray, ...]:
    """B streams with independent uniform disturbances (all streams simulated at once)."""
    rng = np.random.default_rng(1)
    A, Bm, C, D, E, F = sys.matrices_at(0)
    box = sys.d_at(0)
    U = np.broadcast_to(2.0, (B, T, sys.nu))
    d = rng.uniform(box.lo, box.hi, size=(B, T, sys.nd))
    X = np.empty((B, T, sys.nx))
    Y = np.empty((B, T, sys.ny))
    x = np.broadcast_to(x0, (B, sys.nx))
    for k in range(T):
        X[:, k] = x
        Y[:, k] = x @ C.T + U[:, k] @ D.T + d[:, k] @ F.T
        x = x @ A.T + U[:, k] @ Bm.T + d[:, k] @ E.T
    return X, U, Y


def speed(quick: bool) -> None:
    T_long = 20_000 if quick else 200_000
    B, T_b = (1_000, 1_000) if quick else (10_000, 1_000)
    sc = ivobs.scenarios.get("dinh2019", horizon=T_long)
    tr = sc.simulate()
    for s in (1, 2, 6):
        est = ivobs.make_estimator("fixed-time", sc.system, s=s)
        assert est.run(tr.u, tr.y).contains(tr.x).all()
        t = cpu(lambda est=est: est.run(tr.u, tr.y))
        print(f"dinh2019 s={s}: run() {T_long} steps: {T_long / t:,.0f} steps/s")
    est = ivobs.make_estimator("fixed-time", sc.system, s=2)
    y_miss = tr.y.copy()
    y_miss[np.random.default_rng(0).random(y_miss.shape) < 0.1] = np.nan
    y_miss[:3] = tr.y[:3]
    assert est.run(tr.u, y_miss).contains(tr.x).all()
    t = cpu(lambda: est.run(tr.u, y_miss))
    print(f"dinh2019 s=2, 10% missing: run() {T_long / t:,.0f} steps/s")

    sv = ivobs.scenarios.get("servo-motor", horizon=T_long)
    trs = sv.simulate("vertex", seed=0)
    est = ivobs.make_estimator("fixed-time", sv.system)
    assert est.run(trs.u, trs.y).contains(trs.x)[est.valid_from :].all()
    t = cpu(lambda: est.run(trs.u, trs.y))
    print(f"servo-motor (s={est.s}): run() {T_long} steps: {T_long / t:,.0f} steps/s (floor 1e6)")

    def online(n: int = 2000) -> None:
        est.reset()
        for k in range(n):
            est.step(trs.u[k], trs.y[k])

    t = cpu(online)
    print(f"servo-motor: step() {2000 / t:,.0f} steps/s (floor 20,000)")

    X, U, Y = _batch(sv.system, sv.x_true0, B, T_b)
    res = est.run(U, Y)
    assert res.contains(X)[:, est.valid_from :].all() and not res.inconsistent.any()
    t = cpu(lambda: est.run(U, Y), repeat=2)
    print(f"servo-motor: batch {B} x {T_b}: {t:.2f} s CPU = {B * T_b / t:,.0f} steps/s")

    ltv = _ltv()
    T_tv = 5_000
    rng = np.random.default_rng(2)
    tr_tv = ivobs.simulate(
        ltv, [0.5, -0.5], rng.normal(size=(T_tv, 1)), rng.uniform(-1, 1, size=(T_tv, 1))
    )
    t0 = time.process_time()
    est = ivobs.make_estimator("fixed-time", ltv, s=3)
    res = est.run(tr_tv.u, tr_tv.y)
    t_first = time.process_time() - t0
    assert res.contains(tr_tv.x)[3:].all()
    t = cpu(lambda: est.run(tr_tv.u, tr_tv.y))

    def online_tv(n: int = 2000) -> None:
        est.reset()
        for k in range(n):
            est.step(tr_tv.u[k], tr_tv.y[k])

    t_step = cpu(online_tv)
    print(
        f"time-varying (s=3): first run() (a design per step) {T_tv / t_first:,.0f} steps/s, "
        f"cached: run() {T_tv / t:,.0f} steps/s, step() {2000 / t_step:,.0f} steps/s"
    )


def widths() -> None:
    warnings.simplefilter("ignore")
    for name in SUITE:
        sc = ivobs.scenarios.get(name)
        tr = sc.simulate("vertex", seed=0)
        est = ivobs.make_estimator("fixed-time", sc.system)
        res = est.run(tr.u, tr.y)
        vf = est.valid_from
        ok = bool(res.contains(tr.x)[vf:].all())
        mean = np.mean(res.width[vf:])
        print(f"{name:18s} T={len(tr.y):5d} mean width {mean:.10g} contains {ok}")


if __name__ == "__main__":
    if "--widths" in sys.argv:
        widths()
    else:
        speed(quick="--quick" in sys.argv)
