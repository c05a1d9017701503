"""The Hénon map two ways on the same record: [Efimov2013, Remark 1] (linear methods, the
nonlinear term bounded from the measured output) against the full nonlinear model
(``nl-interval``, ``nl-zonotope``, ``nl-constrained-zonotope``, inclusion functions).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_henon_compare.py [horizon] [repeats] [--plot F]

For each setting (``henon-nl``: ``a ∈ [1.39, 1.41]``, ``|w| <= 0.005``, ``|v| <= 0.02``, uniform
signals, seed 0; ``henon``: [Efimov2013]'s ``a ∈ [1, 1.4]``, ``|w| <= 0.015``, ``|v| <= 0.1``,
sinusoidal signals) both models get the scenario's numbers, initial box and ``paper`` record
(``ivobs.report.figures.henon.henon_pair``). Per method: the mean width per state after a
burn-in of a tenth of the horizon, the width at the last step, and the run time (``run()`` on
the record; design excluded, reported apart), median over ``repeats`` of CPU and wall time.
Every run is checked to contain the true state. ``--plot F`` also writes the comparison figure
(``henon_compare_fig``, henon-nl setting, 100 steps).
"""

from __future__ import annotations

import statistics
import sys
import time

from ivobs.estimators import make_estimator
from ivobs.report.figures.common import check_contains
from ivobs.report.figures.henon import NL_METHODS, PAPER_L, REMARK1_METHODS, henon_pair


def _estimator(pair, method):
    if method in NL_METHODS:
        return make_estimator(method, pair.nonlinear, x0=pair.x0)
    if method == "interval (3)":
        return make_estimator("interval", pair.remark1, x0=pair.x0, L=PAPER_L)
    return make_estimator(method, pair.remark1, x0=pair.x0)


def measure(pair, method, repeats):
    """(estimate, design s, run CPU s, run wall s): medians over ``repeats`` fresh estimators."""
    design, cpu, wall, res = [], [], [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        est = _estimator(pair, method)
        design.append(time.perf_counter() - t0)
        c0, w0 = time.process_time(), time.perf_counter()
        res = est.run(pair.traj.u, pair.traj.y)
        cpu.append(time.process_time() - c0)
        wall.append(time.perf_counter() - w0)
    check_contains(f"{pair.setting}: {method}", res, pair.traj.x)
    med = statistics.median
    return res, med(design), med(cpu), med(wall)


def table(setting, horizon, repeats):
    pair = henon_pair(setting, horizon)
    burn = horizon // 10
    print(f"\n{setting}: {horizon} steps, burn-in {burn}, median of {repeats} runs\n")
    print("| model | method | mean width x1 | mean width x2 | final x1 | final x2 "
          "| run CPU ms | run wall ms | µs/step (CPU) | design s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for method in REMARK1_METHODS + NL_METHODS:
        res, design, cpu, wall = measure(pair, method, repeats)
        mean = res.mean_width(burn)
        last = res.width[-1]
        model = "nonlinear" if method in NL_METHODS else "Remark 1"
        name = "interval, L = (−0.1, 0.1)" if method == "interval (3)" else method
        print(f"| {model} | `{name}` | {mean[0]:.4f} | {mean[1]:.4f} | {last[0]:.4f} "
              f"| {last[1]:.4f} | {1e3 * cpu:.1f} | {1e3 * wall:.1f} | {1e6 * cpu / horizon:.0f} "
              f"| {design:.3f} |")  # fmt: skip
    return pair


def main(argv):
    plot = None
    if "--plot" in argv:
        i = argv.index("--plot")
        plot = argv[i + 1]
        argv = argv[:i] + argv[i + 2 :]
    horizon = int(argv[0]) if argv else 200
    repeats = int(argv[1]) if len(argv) > 1 else 5
    for setting in ("henon-nl", "henon"):
        table(setting, horizon, repeats)
    if plot:
        import matplotlib

        matplotlib.use("Agg")
        from ivobs.report.figures.henon import henon_compare_fig

        fig = henon_compare_fig("henon-nl", 100)
        fig.savefig(plot, dpi=100)
        print(f"\nfigure: {plot}")


if __name__ == "__main__":
    main(sys.argv[1:])
