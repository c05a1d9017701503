"""Continuous-time plants whose disturbances vary between samples: misses, false faults,
widths and cost of every method on the held model and on the default (varying) model.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_continuous.py [linear|nonlinear]

Plants (simulated here, not by ivobs): a lightly damped oscillator ``x'' = −x − 0.04 x' + d``
sampled every quarter period, position measured (noise ±0.01), ``|d| <= 1`` switching sign 8
times per sample to pump energy in (120 samples; linear methods; exact exponentials per
piece), and the same oscillator and a Van der Pol oscillator (``Ts = 0.1``, ``|0.3 d| <= 0.3``)
as ``NonlinearSystem`` (60 and 100 samples; the nonlinear methods; ``solve_ivp`` DOP853 per
piece). Widths: mean over the second half of the record. CPU seconds of the whole run.
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import ivobs

A = np.array([[0.0, 1.0], [-1.0, -0.04]])
TS = np.pi / 2
SWITCHES = 8
X0 = ivobs.Box([0.0, -1.0], [1.0, 1.0])


def oscillator_record(T: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(1)
    Ph = expm(A * TS / SWITCHES)
    gh = np.linalg.solve(A, Ph - np.eye(2)) @ np.array([0.0, 1.0])
    x, xs, ys = np.array([0.5, -0.3]), [], []
    for _ in range(T):
        xs.append(x.copy())
        ys.append([x[0] + 0.01 * rng.choice([-1.0, 1.0])])
        for _ in range(SWITCHES):
            x = Ph @ x + gh * (1.0 if x[1] >= 0 else -1.0)
    return np.array(xs), np.array(ys)


def nl_record(rhs, x0, Ts: float, T: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(3)
    x, xs, ys = np.array(x0, dtype=float), [], []
    for _ in range(T):
        xs.append(x.copy())
        ys.append([x[0] + 0.01 * rng.choice([-1.0, 1.0])])
        for _ in range(SWITCHES):
            d = 1.0 if x[1] >= 0 else -1.0
            x = solve_ivp(
                lambda t, z, d=d: rhs(z, d), (0.0, Ts / SWITCHES), x, method="DOP853",
                rtol=1e-12, atol=1e-13,
            ).y[:, -1]  # fmt: skip
    return np.array(xs), np.array(ys)


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
    ok = np.all(np.isfinite(res.lower), axis=1)
    tol = 1e-9 * (1.0 + np.abs(xs))
    miss = int(np.sum(ok & np.any((xs < res.lower - tol) | (xs > res.upper + tol), axis=1)))
    w = res.mean_width(len(ys) // 2)
    print(
        f"| {label} | {method} | {miss} | {int(np.sum(res.inconsistent))} | "
        f"{w[0]:.3g} / {w[1]:.3g} | {c:.2f} |",
        flush=True,
    )


def linear() -> None:
    plant = ivobs.LinearSystem(
        A, None, [[1.0, 0.0]], E=[[0.0, 0.0], [1.0, 0.0]], F=[[0.0, 1.0]],
        d=ivobs.Box([-1.0, -0.01], [1.0, 0.01]), dt=0,
    )  # fmt: skip
    xs, ys = oscillator_record(120)
    print("| model | method | misses | flagged | width position / velocity | CPU s |")
    print("|---|---|---|---|---|---|")
    methods = [m for m in ivobs.methods() if not m.startswith("nl-") and m != "interval"]
    for label, sys_ in (
        ("held", plant.discretize(TS, disturbances="held")),
        ("varying", plant.discretize(TS)),
        ("varying, 16 pieces", plant.discretize(TS, pieces=16)),
    ):
        for m in methods:
            row(label, m, sys_, X0, xs, ys)


def nonlinear() -> None:
    osc = ivobs.NonlinearSystem(
        states=["p", "v"], outputs=["y"], f=["v", "-p - 0.04*v + d"], h=["p + n"],
        d={"d": (-1.0, 1.0), "n": (-0.01, 0.01)}, dt=0,
    )  # fmt: skip
    vdp = ivobs.NonlinearSystem(
        states=["p", "v"], outputs=["y"], f=["v", "(1 - p**2)*v - p + 0.3*d"], h=["p + n"],
        d={"d": (-1.0, 1.0), "n": (-0.01, 0.01)}, dt=0,
    )  # fmt: skip
    cases = [
        ("oscillator", osc, TS, 60, lambda z, d: np.array([z[1], -z[0] - 0.04 * z[1] + d]),
         [0.5, -0.3], X0),
        ("Van der Pol", vdp, 0.1, 100,
         lambda z, d: np.array([z[1], (1 - z[0] ** 2) * z[1] - z[0] + 0.3 * d]),
         [1.0, 0.5], ivobs.Box([0.9, 0.4], [1.1, 0.6])),
    ]  # fmt: skip
    print("| plant, model | method | misses | flagged | width position / velocity | CPU s |")
    print("|---|---|---|---|---|---|")
    for name, plant, Ts, T, rhs, x0, box in cases:
        xs, ys = nl_record(rhs, x0, Ts, T)
        for mode in ("held", "varying"):
            sys_ = plant.discretize(Ts, disturbances=mode)
            for m in ("nl-interval", "nl-zonotope", "nl-constrained-zonotope"):
                row(f"{name}, {mode}", m, sys_, box, xs, ys)


if __name__ == "__main__":
    which = sys.argv[1:] or ["linear", "nonlinear"]
    for w in which:
        {"linear": linear, "nonlinear": nonlinear}[w]()
