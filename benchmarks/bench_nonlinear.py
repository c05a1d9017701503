"""Nonlinear models: the inclusion-engine comparison behind docs/nonlinear.md, and ``nl-interval``
on the Hénon map (speed, soundness over >= 10^5 steps, widths).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nonlinear.py [engines|speed|sound] [steps]

* ``engines``: per-call time of one Hénon step (natural and mean-value forms) for the generated
  code, ``mpmath.iv`` and ``codac`` (when installed), and the share of ``tanh``/``sinh``
  enclosures of each engine that miss the 40-digit value (2,000 thin arguments in [-20, 20]);
* ``speed``: ``nl-interval`` ``run()`` and ``step()`` on the Hénon map (y = x1 and y = x2),
  best of 3;
* ``sound``: ``nl-interval`` on ``steps`` (default 100,000) Hénon steps simulated in 40 digits
  with ``a``, ``w1`` and ``v1`` on random vertices at every step (tests/nlsystems.py): the
  number of steps whose exact state leaves the box (must be 0) and the widths.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

import ivobs

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))


def _best(fn, n: int) -> float:  # type: ignore[no-untyped-def]
    """Best time per call (µs) of 3 repeats of ``n`` calls."""
    best = math.inf
    for _ in range(3):
        start = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - start) / n)
    return best * 1e6


def engines() -> None:
    import mpmath as mp

    from nlsystems import henon

    mp.mp.dps = 40
    s = henon()
    xl, xh, wl, wh = [0.2, 0.0], [0.4, 0.2], s.w_box.lo.tolist(), s.w_box.hi.tolist()
    print("Hénon step, one evaluation of f over the box (µs, best of 3):")
    print(
        f"  generated code  natural {_best(lambda: s._f.natural(xl, xh, [], wl, wh), 20000):6.1f}"
        f"   natural ∩ mean-value {_best(lambda: s._f.tight(xl, xh, [], wl, wh), 20000):6.1f}"
    )
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

    print(f"  mpmath.iv       natural {_best(mp_step, 5000):6.1f}")
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

    print(
        f"  codac {codac.__version__ if hasattr(codac, '__version__') else ''}"
        f"     natural {_best(codac_step, 20000):6.1f}"
    )
    tanh, sinh = codac.TanhOp.fwd, codac.SinhOp.fwd  # codac.sinh(Interval) builds an expression
    for name, fn, truth in (("tanh", tanh, mp.tanh), ("sinh", sinh, mp.sinh)):
        miss = 0
        for x in args:
            r = fn(I(x))
            if not (mp.mpf(r.lb()) <= truth(mp.mpf(x)) <= mp.mpf(r.ub())):
                miss += 1
        print(f"  {name}: codac misses {miss} of {len(args)}")


def speed() -> None:
    from nlsystems import HENON_X0, henon, henon_mp, simulate

    for out in ("x1", "x2"):
        f, g = henon_mp(out)
        _, Y = simulate(
            f,
            g,
            [0.3, 0.1],
            20000,
            params={"a": (1.39, 1.41)},
            process={"w1": (-0.005, 0.005)},
            noise=[(-0.02, 0.02)],
            seed=3,
        )
        est = ivobs.make_estimator("nl-interval", henon(out), x0=HENON_X0)
        best_run = min(_timed(lambda e=est, y=Y: e.run(None, y)) for _ in range(3))
        n = 5000

        def steps(est: ivobs.Estimator = est, Y: np.ndarray = Y, n: int = n) -> None:
            est.reset()
            for k in range(n):
                est.step(None, Y[k])

        best_step = min(_timed(steps) for _ in range(3))
        print(
            f"nl-interval Hénon y = {out}+v: run() {len(Y) / best_run:9,.0f} steps/s, "
            f"step() {n / best_step:9,.0f} steps/s"
        )


def _timed(fn) -> float:  # type: ignore[no-untyped-def]
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def sound(steps: int) -> None:
    from nlsystems import HENON_X0, henon, henon_mp, simulate, violations

    for out in ("x1", "x2"):
        f, g = henon_mp(out)
        X, Y = simulate(
            f,
            g,
            [0.3, 0.1],
            steps,
            params={"a": (1.39, 1.41)},
            process={"w1": (-0.005, 0.005)},
            noise=[(-0.02, 0.02)],
            seed=7,
        )
        res = ivobs.make_estimator("nl-interval", henon(out), x0=HENON_X0).run(None, Y)
        bad = violations(X, res.lower, res.upper)
        w = res.upper - res.lower
        print(
            f"nl-interval Hénon y = {out}+v, {steps:,} steps: {len(bad)} violations; "
            f"mean widths after step 100 {np.round(w[100:].mean(axis=0), 4).tolist()}, "
            f"max {np.round(w[100:].max(axis=0), 4).tolist()}"
        )


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "all"
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 100_000
    if what in ("engines", "all"):
        engines()
    if what in ("speed", "all"):
        speed()
    if what in ("sound", "all"):
        sound(n)
