"""Continuous-time plants whose disturbances vary between samples: misses, false faults,
widths and cost of every method on the held model and on the default (varying) model.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_continuous.py [linear|nonlinear]

Plants (simulated by the tests' ``tests/ctsim.py``, not by ivobs): a lightly damped oscillator
``x'' = −x − 0.04 x' + d`` sampled every quarter period, position measured (noise ±0.01), ``|d|
<= 1`` switching sign 8 times per sample to pump energy in (120 samples; linear methods; exact
exponentials per piece), and the same oscillator and a Van der Pol oscillator (``Ts = 0.1``,
``|0.3 d| <= 0.3``) as ``NonlinearSystem`` (60 and 100 samples; the nonlinear methods;
``solve_ivp`` DOP853 per piece). Widths: mean over the second half of the record. CPU seconds of
the whole run.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

import numpy as np

import ivobs

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from ctsim import (
    TS_OSC,
    X0_BOX,
    misses,
    nl_oscillator,
    nl_vdp,
    osc_rhs,
    oscillator,
    simulate_nl,
    simulate_oscillator,
    vdp_rhs,
)


def row(label: str, method: str, sys_: object, x0: ivobs.Box, xs, ys) -> None:
    try:
        est = ivobs.make_estimator(method, sys_, x0=x0)
        c = time.process_time()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = est.run(y=ys)
        c = time.process_time() - c
    except ivobs.IvobsError as exc:
        print(f"| {label} | {method} | error: {str(exc)[:60]} | | | |")
        return
    miss = misses(res, xs, 1e-9 * (1.0 + np.abs(xs)))
    w = res.mean_width(len(ys) // 2)
    print(
        f"| {label} | {method} | {miss} | {int(np.sum(res.inconsistent))} | "
        f"{w[0]:.3g} / {w[1]:.3g} | {c:.2f} |",
        flush=True,
    )


def linear() -> None:
    plant = oscillator()
    xs, ys = simulate_oscillator(T=120)
    print("| model | method | misses | flagged | width position / velocity | CPU s |")
    print("|---|---|---|---|---|---|")
    methods = [m for m in ivobs.methods() if not m.startswith("nl-") and m != "interval"]
    for label, sys_ in (
        ("held", plant.discretize(TS_OSC, disturbances="held")),
        ("varying", plant.discretize(TS_OSC)),
        ("varying, 16 pieces", plant.discretize(TS_OSC, pieces=16)),
    ):
        for m in methods:
            row(label, m, sys_, X0_BOX, xs, ys)


def nonlinear() -> None:
    cases = [
        ("oscillator", nl_oscillator(), TS_OSC, 60, osc_rhs, [0.5, -0.3], X0_BOX),
        ("Van der Pol", nl_vdp(), 0.1, 100, vdp_rhs, [1.0, 0.5], ivobs.Box([0.9, 0.4], [1.1, 0.6])),
    ]
    print("| plant, model | method | misses | flagged | width position / velocity | CPU s |")
    print("|---|---|---|---|---|---|")
    for name, plant, Ts, T, rhs, x0, box in cases:
        xs, ys = simulate_nl(rhs, x0, Ts, T)
        for mode in ("held", "varying"):
            sys_ = plant.discretize(Ts, disturbances=mode)
            for m in ("nl-interval", "nl-zonotope", "nl-constrained-zonotope"):
                row(f"{name}, {mode}", m, sys_, box, xs, ys)


if __name__ == "__main__":
    which = sys.argv[1:] or ["linear", "nonlinear"]
    for w in which:
        {"linear": linear, "nonlinear": nonlinear}[w]()
