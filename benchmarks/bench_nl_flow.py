"""Continuous-time nonlinear plants: cost of the validated flow (``NonlinearSystem(dt=0)
.discretize(Ts, order=..., substeps=...)``) per sampling step.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_flow.py [repeats] [varying|held]
    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_flow.py methods [varying|held]

For a pendulum (Ts = 0.1), a Van der Pol oscillator (Ts = 0.1) and a six-tank cascade with
``sqrt`` outflows (Ts = 0.5), each order and substep count: the time to build the generated
code (SymPy Lie derivatives + compilation), the time of one enclosure of the flow over a box
(``f_box``: what ``nl-interval`` calls per step) and of its Jacobian (``f_jac_box``: the set
methods), the width of the enclosure from a point (the remainder) and from the box, and a
``nl-interval`` run of 200 steps on a noise-free record of the plant (ms per step; ``lag=1``,
the step back through the flow, and ``lag=0``). CPU time (``process_time``) and wall time,
median of ``repeats`` (default 5). ``methods``: ``nl-interval``, ``nl-zonotope`` and
``nl-constrained-zonotope`` on 100 steps of the pendulum (order 4): ms per step and the mean
widths after step 10.
"""

from __future__ import annotations

import statistics
import sys
import time

import numpy as np

import ivobs

PEND = dict(
    f=["w", "-g/L*sin(th) - 0.2*w + u1 + d1"],
    h=["th + v"],
    states=["th", "w"],
    inputs=["u1"],
    params={"g": 9.81, "L": (0.95, 1.05)},
    d={"d1": (-0.1, 0.1), "v": (-0.01, 0.01)},
)
VDP = dict(
    f=["x2", "(1 - x1**2)*x2 - x1 + d1"],
    h=["x1 + v"],
    states=["x1", "x2"],
    d={"d1": (-0.05, 0.05), "v": (-0.02, 0.02)},
)
TANK = dict(
    f=["u1 - k*sqrt(2*g)*sqrt(x1) + w1"]
    + [f"k*sqrt(2*g)*(sqrt(x{i - 1}) - sqrt(x{i})) + w{i}" for i in range(2, 7)],
    h=["x2 + v1", "x4 + v2", "x5 + v3"],
    states=[f"x{i}" for i in range(1, 7)],
    inputs=["u1"],
    params={"k": 0.015, "g": 9.81},
    d={
        **{f"w{i}": (-0.001, 0.001) for i in range(1, 7)},
        **{f"v{i}": (-0.2, 0.2) for i in range(1, 4)},
    },
)
CASES = {
    "pendulum": (PEND, 0.1, [0.4, -0.2], [0.6, 0.2], [0.3]),
    "vdp": (VDP, 0.1, [1.0, -0.5], [1.3, -0.1], []),
    "tank6": (TANK, 0.5, [1.8, 3.8, 3.7, 1.9, 9.5, 3.8], [2.2, 4.2, 4.3, 2.1, 10.5, 4.2], [0.1]),
}


def timed(fn, repeats: int) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    cpu, wall = [], []
    for _ in range(repeats):
        c, w = time.process_time(), time.perf_counter()
        fn()
        cpu.append(time.process_time() - c)
        wall.append(time.perf_counter() - w)
    return statistics.median(cpu), statistics.median(wall)


def record(cont: ivobs.NonlinearSystem, x0: list[float], u: list[float], w, Ts: float, T: int):  # type: ignore[no-untyped-def]
    """Noise-free outputs of the plant from ``x0`` with ``u``, ``w`` constant (solve_ivp)."""
    import sympy as sp
    from scipy.integrate import solve_ivp

    s = cont._sym
    args = [
        s[n] for n in cont.state_names + cont.input_names + cont.param_names + cont.signal_names
    ]
    known = {s[n]: v for n, v in cont.known_params.items()}
    f = sp.lambdify(args, [e.xreplace(known) for e in cont.f_exprs], "math")
    h = sp.lambdify(args, [e.xreplace(known) for e in cont.h_exprs], "math")
    rest = list(u) + list(w)
    x, Y = np.asarray(x0, float), []
    for _ in range(T):
        Y.append(h(*x, *rest))
        sol = solve_ivp(lambda t, z: f(*z, *rest), (0.0, Ts), x, rtol=1e-10, atol=1e-12)
        x = sol.y[:, -1]
    return np.array(Y, dtype=float)


MODE = "varying"


def bench(name: str, order: int, substeps: int, repeats: int) -> None:
    spec, Ts, xl, xh, u = CASES[name]
    cont = ivobs.NonlinearSystem(**spec, dt=0)
    c0 = time.process_time()
    fs = cont.discretize(Ts, order=order, substeps=substeps, disturbances=MODE)
    build = time.process_time() - c0
    wl, wh = fs.w_box.lo, fs.w_box.hi
    xm = [0.5 * (a + b) for a, b in zip(xl, xh)]
    wm = 0.5 * (wl + wh)
    lo, hi = fs.f_box(xm, xm, u, wm, wm)
    point = float(np.max(hi - lo))
    lo, hi = fs.f_box(xl, xh, u, wl, wh)
    box = float(np.max(hi - lo))
    n = 50
    step = timed(lambda: [fs.f_box(xl, xh, u, wl, wh) for _ in range(n)], repeats)
    fs.f_jac_box(xl, xh, u, wl, wh)  # builds the Jacobian's code (first use)
    jac = timed(lambda: fs.f_jac_box(xl, xh, u, wl, wh), repeats)
    T = 200
    U = np.tile(np.asarray(u, float), (T, 1)) if u else None
    Y = record(cont, xm, u, wm, Ts, T)
    x0 = ivobs.Box(xl, xh)
    run = timed(lambda: ivobs.make_estimator("nl-interval", fs, x0=x0).run(U, Y), repeats)
    try:
        r0 = timed(lambda: ivobs.make_estimator("nl-interval", fs, x0=x0, lag=0).run(U, Y), repeats)
        lag0 = f"{r0[0] / T * 1e3:.2f} / {r0[1] / T * 1e3:.2f}"
    except ivobs.IvobsError:
        lag0 = "diverges (no a priori enclosure)"
    print(
        f"| {name} | {order} | {substeps} | {build:.2f} | {step[0] / n * 1e3:.3f} / "
        f"{step[1] / n * 1e3:.3f} | {jac[0] * 1e3:.2f} / {jac[1] * 1e3:.2f} | "
        f"{run[0] / T * 1e3:.2f} / {run[1] / T * 1e3:.2f} | "
        f"{lag0} | {point:.1e} | {box:.3g} |",
        flush=True,
    )


def methods() -> None:
    spec, Ts, xl, xh, u = CASES["pendulum"]
    cont = ivobs.NonlinearSystem(**spec, dt=0)
    fs = cont.discretize(Ts, order=4, disturbances=MODE)
    T = 100
    U = np.tile(np.asarray(u, float), (T, 1))
    xm = [0.5 * (a + b) for a, b in zip(xl, xh)]
    Y = record(cont, xm, u, 0.5 * (fs.w_box.lo + fs.w_box.hi), Ts, T)
    for m in ("nl-interval", "nl-zonotope", "nl-constrained-zonotope"):
        est = ivobs.make_estimator(m, fs, x0=ivobs.Box(xl, xh))
        c, w = time.process_time(), time.perf_counter()
        res = est.run(U, Y)
        c, w = time.process_time() - c, time.perf_counter() - w
        width = np.round((res.upper - res.lower)[10:].mean(axis=0), 4)
        print(f"| {m} | {c / T * 1e3:.2f} / {w / T * 1e3:.2f} | {width} |", flush=True)


if __name__ == "__main__":
    args = sys.argv[1:]
    if args and args[-1] in ("varying", "held"):
        MODE = args.pop()
    if args == ["methods"]:
        methods()
        sys.exit()
    reps = int(args[0]) if args else 5
    print(
        "| plant | order | substeps | build (s, CPU) | f_box ms CPU / wall | f_jac_box ms CPU / "
        "wall | nl-interval ms/step CPU / wall | lag=0 | width from a point | width from the box |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for plant in CASES:
        for order, substeps in ((2, 1), (4, 1), (4, 4), (6, 1)):
            bench(plant, order, substeps, reps)
