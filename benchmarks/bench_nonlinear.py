"""Nonlinear methods: the inclusion engine, speed on the Hénon map, mean widths on the nonlinear
scenarios, CORA's six-tank test.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nonlinear.py [engines|speed|widths|tank|all]

* ``engines``: per-call time of one Hénon step (natural and mean-value forms) for the generated
  code, ``mpmath.iv`` and ``codac`` (when installed), and the share of ``tanh``/``sinh``
  enclosures of each engine that miss the 40-digit value (2,000 thin arguments in [-20, 20]);
* ``speed``: on the Hénon map (``a ∈ [1.39, 1.41]``, ``|w1| <= 0.005``, ``y = x1 + v1`` or
  ``x2 + v1``, ``|v1| <= 0.02``, vertex values switching at random): ``nl-interval`` ``run()``
  on 20,000 steps and ``step()`` on 5,000, ``nl-zonotope`` ``step()`` on 2,000 and
  ``nl-constrained-zonotope`` ``step()`` on 500; CPU time (``process_time``, less sensitive to
  a shared machine than wall time), best of 3;
* ``widths``: the mean width over whole records (every state, every step) of ``nl-interval`` and
  ``nl-zonotope`` on the nonlinear scenarios at their default horizons, ``paper`` and
  ``vertex`` signals, seeds 0 and 1, and whether any box missed the simulated state;
* ``tank``: CORA's ``test_nonlinearSysDT_observe_01_tank`` (src/ivobs/data/cora_tank6_nl.npz):
  the final box widths of each method beside CORA's saved FRad-A/B/C boxes.

Soundness over long runs is benchmarks/bench_nl_sound.py.
"""

from __future__ import annotations

import math
import platform
import sys
import time
from importlib import resources
from typing import Any

import numpy as np

import ivobs
from ivobs.scenarios.nonlinear import henon_nl_system, tank6_system

SCENARIOS = ["henon-nl", "pendulum-nl", "cora-tank6-nl", "cstr", "unicycle-range"]
HENON_X0 = ivobs.Box([0.2, 0.0], [0.4, 0.2])


def henon(output: str = "x1") -> ivobs.NonlinearSystem:
    if output == "x1":
        return henon_nl_system()
    return ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=["x2 + v1"],
        states=["x1", "x2"],
        params={"a": (1.39, 1.41), "b": 0.3},
        d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )


def henon_record(T: int, output: str = "x1", seed: int = 0) -> np.ndarray:
    """Measurements of a float64 Hénon run with vertex values (for speed only: soundness is
    checked on exact records, tests/exactsim.py)."""
    rng = np.random.default_rng(seed)
    x = np.array([0.3, 0.1])
    y = np.empty((T, 1))
    i = 0 if output == "x1" else 1
    for k in range(T):
        a = rng.choice([1.39, 1.41])
        y[k, 0] = x[i] + rng.choice([-0.02, 0.02])
        x = np.array([1 - a * x[0] ** 2 + x[1] + rng.choice([-0.005, 0.005]), 0.3 * x[0]])
    return y


def _best(fn: Any, repeats: int = 3) -> float:
    """Best CPU time of ``repeats`` calls."""
    best = math.inf
    for _ in range(repeats):
        start = time.process_time()
        fn()
        best = min(best, time.process_time() - start)
    return best


def engines() -> None:
    import mpmath as mp

    mp.mp.dps = 40
    s = henon()
    xl, xh, wl, wh = [0.2, 0.0], [0.4, 0.2], s.w_box.lo.tolist(), s.w_box.hi.tolist()

    def per_call(fn: Any, n: int) -> float:
        return _best(lambda: [fn() for _ in range(n)]) / n * 1e6

    natural = per_call(lambda: s._f.natural(xl, xh, [], wl, wh), 20000)
    tight = per_call(lambda: s._f.tight(xl, xh, [], wl, wh), 20000)
    print("Hénon step, one evaluation of f over the box (µs CPU, best of 3):")
    print(f"  generated code  natural {natural:6.1f}   natural ∩ mean-value {tight:6.1f}")
    iv = mp.iv
    X1, X2, A, W = (
        iv.mpf([0.2, 0.4]),
        iv.mpf([0.0, 0.2]),
        iv.mpf([1.39, 1.41]),
        iv.mpf([-0.005, 0.005]),
    )
    B = iv.mpf("0.3")

    def mp_step() -> None:
        _ = (1 - A * X1**2 + X2 + W, B * X1)

    print(f"  mpmath.iv       natural {per_call(mp_step, 5000):6.1f}")
    rng = np.random.default_rng(0)
    args = rng.uniform(-20, 20, 2000).tolist()
    from ivobs.model.nonlinear import _runtime as rt

    for name, ours, truth in (("tanh", rt.tanh, mp.tanh), ("sinh", rt.sinh, mp.sinh)):
        miss = sum(
            not (mp.mpf(ours(x, x)[0]) <= truth(mp.mpf(x)) <= mp.mpf(ours(x, x)[1])) for x in args
        )
        print(f"  {name}: generated code misses {miss} of {len(args)}")
    try:
        import codac
    except ImportError:
        print("  codac: not installed (pip install codac)")
        return
    I = codac.Interval
    x1, x2, a, w, b = I(0.2, 0.4), I(0.0, 0.2), I(1.39, 1.41), I(-0.005, 0.005), I(0.3)

    def codac_step() -> None:
        _ = (1 - a * codac.sqr(x1) + x2 + w, b * x1)

    print(f"  codac           natural {per_call(codac_step, 20000):6.1f}")
    tanh, sinh = codac.TanhOp.fwd, codac.SinhOp.fwd  # codac.sinh(Interval) builds an expression
    for name, fn, truth in (("tanh", tanh, mp.tanh), ("sinh", sinh, mp.sinh)):
        miss = sum(
            not (mp.mpf(fn(I(x)).lb()) <= truth(mp.mpf(x)) <= mp.mpf(fn(I(x)).ub())) for x in args
        )
        print(f"  {name}: codac misses {miss} of {len(args)}")


def speed() -> None:
    print(
        f"machine: {platform.processor() or platform.machine()}, Python {platform.python_version()}"
    )
    for out in ("x1", "x2"):
        Y = henon_record(20_000, out)
        est = ivobs.make_estimator("nl-interval", henon(out), x0=HENON_X0)
        run = _best(lambda e=est, y=Y: e.run(None, y))
        rates = [f"nl-interval run() {len(Y) / run:9,.0f}"]
        for name, n in (
            ("nl-interval", 5000),
            ("nl-zonotope", 2000),
            ("nl-constrained-zonotope", 500),
        ):
            est = ivobs.make_estimator(name, henon(out), x0=HENON_X0)

            def steps(est: ivobs.Estimator = est, Y: np.ndarray = Y, n: int = n) -> None:
                est.reset()
                for k in range(n):
                    est.step(None, Y[k])

            rates.append(f"{name} step() {n / _best(steps):8,.0f}")
        print(f"Hénon y = {out} + v, steps/s CPU: " + ", ".join(rates))


def widths() -> None:
    methods = ["nl-interval", "nl-zonotope"]
    print("| scenario | signals | seed | " + " | ".join(methods) + " |")
    print("|---|---|---|" + "---|" * len(methods))
    for name in SCENARIOS:
        sc = ivobs.scenarios.get(name)
        for kind in ("paper", "vertex"):
            for seed in (0, 1):
                tr = sc.simulate(kind, seed)
                cells = []
                for m in methods:
                    res = ivobs.make_estimator(m, sc.system, x0=sc.x0).run(tr.u, tr.y)
                    miss = int(np.count_nonzero(~res.contains(tr.x)))
                    cells.append(
                        f"{np.mean(res.upper - res.lower):.7g}"
                        + (f" ({miss} misses)" if miss else "")
                    )
                print(f"| `{name}` | {kind} | {seed} | " + " | ".join(cells) + " |")


def tank() -> None:
    with resources.files("ivobs.data").joinpath("cora_tank6_nl.npz").open("rb") as fh:
        data = dict(np.load(fh))
    x0 = ivobs.Box(data["R0_c"] - 4.0, data["R0_c"] + 4.0)
    print("CORA six-tank test, final box widths (after y[19]):")
    for i, alg in enumerate(data["saved_methods"]):
        w = data["saved_hi"][i] - data["saved_lo"][i]
        print(f"  CORA {alg:24s} {np.array2string(w, precision=3)}")
    for name in ("nl-interval", "nl-zonotope", "nl-constrained-zonotope"):
        est = ivobs.make_estimator(name, tank6_system(), x0=x0)
        start = time.process_time()
        res = est.run(data["u"], data["y"])
        dt = time.process_time() - start
        w = res.upper[-1] - res.lower[-1]
        print(f"  {name:29s} {np.array2string(w, precision=3)}   {1e3 * dt / 20:.1f} ms/step CPU")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "all"
    for mode in (engines, speed, widths, tank):
        if what in (mode.__name__, "all"):
            mode()
