"""What the LPs alone cost in a constrained-zonotope step (servo and tank30), CPU time.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_cz_floor.py [servo|tank30]

The step's box is the exact interval hull of the filtered set: ``2 nx`` LPs, plus ``2 nx`` for
the hull of the prediction whose multipliers choose what the reduction eliminates
(constrained_zonotope.py's docstring). This measures, on the programs the estimator actually
solves (recorded by wrapping the solver calls), the time of

* servo: the warm-started chains as the estimator runs them; HiGHS' fixed cost of one
  ``Highs.run()`` on an already solved program (0 iterations); the same 12 programs as one block
  program (one run from scratch);
* tank30 (first 40 steps): the chains, the per-program fallbacks (``linprog_duals``) when a
  chain fails, the simplex iterations and runs per step, and the whole step,

so that a speed goal can be set against the floor these leave. The recorded programs are solved
again with the same calls: the multipliers, hence the boxes, are those of the estimator.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import ivobs
from ivobs.sets.czonotope import _highs

clock = time.process_time


def servo() -> None:
    programs: list[tuple[Any, ...]] = []
    chain = _highs.chain_duals

    def spy(*args: Any) -> Any:
        programs.append(args)
        return chain(*args)

    _highs.chain_duals = spy
    sc = ivobs.scenarios.get("servo-motor", horizon=200)
    tr = sc.simulate("vertex", seed=0)
    est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0)
    for k in range(200):
        est.step(tr.u[k], tr.y[k])
    _highs.chain_duals = chain
    sel = programs[50:150]
    Gs, A, b, radius, _ = sel[0]
    print(f"servo: {len(programs) / 200:.1f} chain calls per step, {Gs.shape[0]} programs of "
          f"{A.shape[0]} x {A.shape[1]}")  # fmt: skip
    start = clock()
    for args in sel:
        chain(*args)
    print(f"  chains as the estimator runs them: {1e6 * (clock() - start) / len(sel):.0f} µs/step")
    h = _highs._solver(0)
    _highs._pass(h, Gs[0], _highs._csc(A), A.shape, b, radius)
    _highs._solve(h)
    start = clock()
    for _ in range(2000):
        h.run()
    fixed = 1e6 * (clock() - start) / 2000
    print(f"  Highs.run() of a solved program (0 iterations): {fixed:.1f} µs")
    start = clock()
    for Gs, A, b, radius, _ in sel:
        _highs.block_duals(Gs, A, b, radius)
    block = 1e6 * (clock() - start) / len(sel)
    print(f"  the {Gs.shape[0]} programs as one block program: {block:.0f} µs/step")


def tank30(steps: int = 40) -> None:
    acc = {"chains": 0.0, "fallbacks": 0.0, "step": 0.0, "iterations": 0.0, "runs": 0.0}
    chain, fallback, solve = _highs.chain_duals, _highs.linprog_duals, _highs._solve

    def timed(key: str, f: Any) -> Any:
        def g(*args: Any) -> Any:
            start = clock()
            out = f(*args)
            acc[key] += clock() - start
            return out

        return g

    def counted(h: Any) -> Any:
        out = solve(h)
        acc["iterations"] += h.getInfo().simplex_iteration_count
        acc["runs"] += 1
        return out

    _highs.chain_duals = timed("chains", chain)
    _highs.linprog_duals = timed("fallbacks", fallback)
    _highs._solve = counted
    sc = ivobs.scenarios.get("cora-tank30")
    est = ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0)
    for k in range(steps):
        start = clock()
        est.step(sc.recorded.u[k], sc.recorded.y[k])
        acc["step"] += clock() - start
    _highs.chain_duals, _highs.linprog_duals, _highs._solve = chain, fallback, solve
    per = {key: value / steps for key, value in acc.items()}
    print(f"tank30, first {steps} steps, per step: chains {1e3 * per['chains']:.0f} ms "
          f"({per['runs']:.0f} runs, {per['iterations']:.0f} simplex iterations), fallbacks "
          f"{1e3 * per['fallbacks']:.0f} ms, whole step {1e3 * per['step']:.0f} ms")  # fmt: skip


if __name__ == "__main__":
    what = sys.argv[1:] or ["servo", "tank30"]
    if "servo" in what:
        servo()
    if "tank30" in what:
        tank30()
