"""Soundness of the guaranteed methods over long runs with vertex-switching unknowns.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_sound.py [steps] [method,method,...]
        [--scenarios a,b]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_sound.py --random N [steps] [methods]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_sound.py --linear N [steps] [methods]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_sound.py --servo STEPS [-] [methods]
    (--linear and --servo with --nominal: the same systems with exact matrices)

Default: for each scenario of :mod:`ivobs.scenarios.nonlinear` and each nonlinear method,
``steps`` steps (default 10^5) with the disturbances and the uncertain parameters switching
between the vertices of their bounds at every step, the scenario's inputs repeated. Every record
comes from the rigorous simulator of tests/exactsim.py (60-digit intervals, each state and
measurement an exact value of the model): the estimators add no margin, so a float64 run, which
is not a trajectory of the model, would not be a fair test.

``--random N``: ``N`` random nonlinear systems of tests/randsys.py (seeds 0..N-1), ``steps``
each (default 10^4), exact simulator. ``--linear N``: ``N`` random interval-matrix linear
systems (seeds 0..N-1; the ``interval`` method gets the cooperative variant); ``--servo``: the
``servo-uncertain`` scenario (its inputs repeated); both with the matrices on vertices (half of
the steps the vertex that makes ``ΔA x`` extreme), exact simulator; the methods default to
those with ``supports_uncertain``.

Prints the steps whose box misses the true state, the widths (mean over the states and steps
after step 100, and the largest, to show they stay bounded), and the CPU and wall time of the
estimator.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

import ivobs

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

SCENARIOS = ["henon-nl", "pendulum-nl", "cora-tank6-nl", "cstr", "unicycle-range", "range-only",
             "chain10-nl"]  # fmt: skip
METHODS = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"]


def _uncertain_methods() -> list[str]:
    return [m for m in ivobs.methods() if ivobs.estimators.get(m).supports_uncertain]


def _estimate(
    method: str, sys_: Any, x0: ivobs.Box, u: Any, y: np.ndarray
) -> tuple[Any, float, float]:
    c0, t0 = time.process_time(), time.perf_counter()
    est = ivobs.make_estimator(method, sys_, x0=x0).run(u, y)
    return est, time.process_time() - c0, time.perf_counter() - t0


def _line(
    label: str, method: str, steps: int, bad: int, w: np.ndarray, cpu: float, wall: float
) -> None:
    """One result; ``w``: the widths after step 100."""
    print(
        f"{label:18s} {method:24s} {steps:7,d} steps: {bad} misses; width mean "
        f"{w.mean():.4g}, max {w.max():.4g}; cpu {cpu:.1f} s, wall {wall:.1f} s",
        flush=True,
    )


def run(name: str, method: str, steps: int) -> None:
    import exactsim

    sc = ivobs.scenarios.get(name)
    sys_ = sc.system
    u = np.resize(sc.u, (steps, sys_.nu)) if sys_.nu else None
    rec = exactsim.simulate(sys_, sc.x_true0, steps, u, seed=3)
    est, cpu, wall = _estimate(method, sys_, sc.x0, u, rec.Y)
    bad = len(rec.misses(est.lower, est.upper))
    _line(name, method, steps, bad, est.width[100:], cpu, wall)


def run_cases(cases: list[tuple[str, Any, Any]], methods: list[str], steps: int) -> None:
    """``cases``: (label, builder(cooperative) -> randsys.Case, simulator). Per method: each
    case, then the total over the cases."""
    records: dict[tuple[str, bool], Any] = {}
    for m in methods:
        bad, cpu, wall, widths, steps_total = 0, 0.0, 0.0, [], 0
        for label, build, simulate in cases:
            coop = m == "interval"
            case = build(coop)
            if (label, coop) not in records:
                records[label, coop] = simulate(case)
            rec = records[label, coop]
            try:
                est, c, t = _estimate(m, case.system, case.x0, case.u, rec.Y)
            except ivobs.DesignError as exc:  # refused at make_estimator: no bounds to check
                print(f"{label:18s} {m:24s} refused by the design: {str(exc)[:120]}", flush=True)
                continue
            miss = len(rec.misses(est.lower, est.upper))
            _line(label, m, len(rec.Y), miss, est.width[100:], c, t)
            bad, cpu, wall = bad + miss, cpu + c, wall + t
            widths.append(est.width[100:].ravel())
            steps_total += len(rec.Y)
        if len(cases) > 1:
            w = np.concatenate(widths)
            _line(f"total ({len(cases)})", m, steps_total, bad, w, cpu, wall)


def random_cases(n: int, steps: int) -> list[tuple[str, Any, Any]]:
    import exactsim
    import randsys

    def case(seed: int) -> tuple[str, Any, Any]:
        def sim(c: Any) -> Any:
            return exactsim.simulate(c.system, c.x_true0, steps, c.u, seed=seed)

        return f"random-nl {seed}", lambda coop: randsys.random_nonlinear(seed, steps), sim

    return [case(s) for s in range(n)]


def _nominal(c: Any) -> Any:
    """``c`` with the nominal (exact) matrices of its interval-matrix system."""
    s = c.system
    sys_ = ivobs.LinearSystem(s.A, s.B, s.C, D=s.D, E=s.E, F=s.F, d=s.d)
    return type(c)(sys_, c.x_true0, c.x0, c.u, c.text + " (nominal)")


def linear_cases(
    n: int, steps: int, servo_steps: int, nominal: bool = False
) -> list[tuple[str, Any, Any]]:
    """``nominal``: the exact-matrix systems (the servo motor's ``servo-motor``) instead."""
    import exactsim
    import randsys

    def build(seed: int, coop: bool) -> Any:
        c = randsys.random_interval_linear(seed, steps, cooperative=coop)
        return _nominal(c) if nominal else c

    def case(seed: int) -> tuple[str, Any, Any]:
        def sim(c: Any) -> Any:
            return exactsim.simulate_linear(c.system, c.x_true0, steps, c.u, seed=seed)

        return (
            f"random-lin {seed}" + (" nominal" if nominal else ""),
            lambda coop: build(seed, coop),
            sim,
        )

    def servo(coop: bool) -> Any:
        sc = ivobs.scenarios.get("servo-motor" if nominal else "servo-uncertain")
        u = np.resize(sc.u, (servo_steps, sc.system.nu))
        return randsys.Case(sc.system, sc.x_true0, sc.x0, u, sc.name)

    def servo_sim(c: Any) -> Any:
        return exactsim.simulate_linear(c.system, c.x_true0, servo_steps, c.u, seed=3)

    label = "servo-motor" if nominal else "servo-uncertain"
    return [case(s) for s in range(n)] + [(label, servo, servo_sim)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("steps", nargs="?", type=int)
    ap.add_argument("methods", nargs="?")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--random", type=int, metavar="N")
    ap.add_argument("--linear", type=int, metavar="N")
    ap.add_argument("--servo", type=int, metavar="STEPS")
    ap.add_argument("--nominal", action="store_true", help="--linear/--servo: exact matrices")
    a = ap.parse_args()
    methods = a.methods.split(",") if a.methods else None
    if a.random or a.linear or a.servo:
        steps = a.steps or 10_000
        if a.random:
            run_cases(random_cases(a.random, steps), methods or METHODS, steps)
        linear = linear_cases(a.linear or 0, steps, a.servo or 0, a.nominal)
        default = ivobs.methods() if a.nominal else _uncertain_methods()
        if a.linear:
            run_cases(linear[:-1], methods or default, steps)
        if a.servo:
            run_cases(linear[-1:], methods or default, a.servo)
        return
    for m in methods or METHODS:
        for s in a.scenarios.split(","):
            run(s, m, a.steps or 100_000)


if __name__ == "__main__":
    main()
