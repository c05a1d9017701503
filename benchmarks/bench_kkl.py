"""Speed of the KKL / Sylvester observers (method ``kkl``, [Dinh2024]), in CPU time.

Prints steps per second (best of a few repeats, ``time.process_time``) for

* DT LTI ``run()`` on a 200,000-step servo-motor record (floor: 1e6 steps/s);
* a batch of 10,000 servo-motor streams x 1,000 steps;
* DT LTI online ``step()`` (floor: 20,000 steps/s);
* DT LTV ``run()`` (Example 3, the loop);
* CT LTI (Example 1, 8 states) and CT LTV (pendulum) ``run()`` on a dt = 0.01 grid;
* the offline design time (default target with gradient refinement).

``--widths``: the mean width over whole records of every scenario of ``suite.py`` that ``kkl``
runs (vertex disturbances); ``--ct-widths``: the same for the continuous-time records (Example 1
in continuous time, the pendulum with its input between samples, plants with slow targets and
missing samples); ``--missing``: the width ratio with 10 % of the output components
missing on random 4-state plants (``rho = 0.8``, 3,000 steps).

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_kkl.py [--quick | --widths | --ct-widths |
--missing]``.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from suite import DEFAULT_SCENARIOS  # benchmarks/ is on the path of a script run from it

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


SCENARIOS = DEFAULT_SCENARIOS  # the scenarios of benchmarks/suite.py


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


def _pendulum_u(t: object) -> list[object]:
    """The pendulum's input ``0.15 sin 3t`` ([Dinh2024, Example 2]) between samples too."""
    from ivobs import nlmath

    return [0.15 * nlmath.sin(3 * t)]


def ct_widths() -> None:
    """Mean width (sum over the states) over whole continuous-time records."""
    from ivobs import Box, LinearSystem

    cases: list[tuple[str, object, object, dict[str, object], object]] = []
    for kind in ("vertex", "paper"):
        sc = ivobs.scenarios.get("kkl-random8", continuous=True, t_final=10.0)
        cases.append((f"kkl-random8 CT {kind}", sc, sc.simulate(kind, seed=0), {}, None))
        pend = ivobs.scenarios.get("pendulum", t_final=15.0)
        opts = {"input_hold": _pendulum_u}
        cases.append((f"pendulum {kind}", pend, pend.simulate(kind, seed=0), opts, None))
    plant = LinearSystem(
        [[0.2, 1.0], [0.0, -6.0]], None, [[1.0, 0.3]], E=0.05 * np.eye(2), F=[[0.0, 0.02]],
        d=ivobs.Box.symmetric([1.0, 1.0]), dt=0,
    )  # fmt: skip
    t = np.arange(400) * 0.05
    x0 = Box(-np.ones(2), np.ones(2))
    tr = ivobs.simulate(
        plant, [1.0, -1.0], None, ivobs.vertex_disturbance(plant.d, 400, seed=0), t=t
    )
    y = tr.y.copy()
    y[np.random.default_rng(0).random(y.shape) < 0.1] = np.nan
    slow = {"A_z": np.diag([-1.0, -2.0]), "B_z": np.ones((2, 1))}
    for name, yy, opts in (
        ("slow target", tr.y, slow),
        ("slow target, 10 % missing", y, slow),
        ("default target, 10 % missing", y, {}),
    ):
        cases.append((name, (plant, x0, t), tr, opts, yy))
    for name, sc, trj, opts, yy in cases:
        if isinstance(sc, tuple):
            system, x0_, tt = sc
        else:
            system, x0_, tt = sc.system, sc.x0, sc.t  # type: ignore[attr-defined]
        est = ivobs.make_estimator("kkl", system, x0=x0_, **opts)
        y_ = trj.y if yy is None else yy  # type: ignore[attr-defined]
        t0 = clock()
        res = est.run(trj.u, y_, t=tt)  # type: ignore[attr-defined]
        dt = clock() - t0
        w = res.width.sum(axis=1).mean()
        ok = bool(res.contains(trj.x).all())  # type: ignore[attr-defined]
        print(f"{name:30s} T={len(y_):5d} mean_width={w:.10g} contains={ok} cpu={dt:.2f}s")


def missing() -> None:
    """Mean width with 10 % of the output components missing / with complete data."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    from test_kkl_missing_samples import missing_run

    for ny in (1, 2):
        for seed in range(6):
            full, miss, x = missing_run(seed, ny)
            ratio = miss.width[100:].sum(1).mean() / full.width[100:].sum(1).mean()
            print(f"ny={ny} seed={seed} ratio={ratio:.3g} contains={miss.contains(x).all()}")


if __name__ == "__main__":
    if "--widths" in sys.argv:
        widths()
    elif "--ct-widths" in sys.argv:
        ct_widths()
    elif "--missing" in sys.argv:
        missing()
    else:
        main(quick="--quick" in sys.argv)
