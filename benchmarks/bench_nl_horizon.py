"""nl-horizon against nl-constrained-zonotope and the linearised exact hull.

The linearised exact hull is ``exact`` (moving window of the same ``N``) on the time-varying
linear system obtained by linearising the model along the TRUE trajectory:
``A_k = ∂f/∂x``, ``E_k = ∂f/∂w`` at ``(x_k, w_k)``, the affine part ``f(x_k, w_k) - A_k x_k -
E_k w_k`` an input with ``B = I`` (and the same for ``h``), the same bounds on ``w``. It is the
hull a method that knew the linearisation points exactly would give from the same data: the
reference the window's linearisation over proven boxes tends to.

Run: ``python benchmarks/bench_nl_horizon.py [--steps 1000] [--scenarios range-only ...]``.
Prints, per scenario: the mean width per state over the late half, the ratios, the misses
(true state outside the box) and the steps per second.
"""

from __future__ import annotations

import argparse
import time
import warnings
from typing import Any

import numpy as np

import ivobs
from ivobs.scenarios import registry


def truth_w(sys: ivobs.NonlinearSystem, tr: ivobs.Trajectory) -> np.ndarray:
    """The per-step ``w = (params, signals)`` of a simulated trajectory."""
    p = np.zeros((tr.T, 0)) if tr.p is None else np.broadcast_to(tr.p, (tr.T, tr.p.shape[-1]))
    return np.hstack([p, tr.d])


def linearised_along(sys: ivobs.NonlinearSystem, tr: ivobs.Trajectory) -> tuple[Any, np.ndarray]:
    """The LTV model linearised along the true trajectory, and its inputs (the affine parts)."""
    w = truth_w(sys, tr)
    nx, ny, T = sys.nx, sys.ny, tr.T
    A, E, C, F, uf, uh = [], [], [], [], [], []
    for k in range(T):
        x, u, wk = tr.x[k], tr.u[k], w[k]
        ax, bx, aw, bw = sys.f_jac_box(x, x, u, wk, wk)
        Jx, Jw = 0.5 * (ax + bx), 0.5 * (aw + bw)
        flo, fhi = sys.f_box(x, x, u, wk, wk)
        hx_lo, hx_hi, hw_lo, hw_hi = sys.h_jac_box(x, x, u, wk, wk)
        Hx, Hw = 0.5 * (hx_lo + hx_hi), 0.5 * (hw_lo + hw_hi)
        hlo, hhi = sys.h_box(x, x, u, wk, wk)
        A.append(Jx), E.append(Jw), C.append(Hx), F.append(Hw)
        uf.append(0.5 * (flo + fhi) - Jx @ x - Jw @ wk)
        uh.append(0.5 * (hlo + hhi) - Hx @ x - Hw @ wk)
    lin = ivobs.LinearSystem(
        A=lambda k: A[min(k, T - 1)],
        B=np.hstack([np.eye(nx), np.zeros((nx, ny))]),
        C=lambda k: C[min(k, T - 1)],
        D=np.hstack([np.zeros((ny, nx)), np.eye(ny)]),
        E=lambda k: E[min(k, T - 1)],
        F=lambda k: F[min(k, T - 1)],
        d=sys.w_box,
    )
    return lin, np.hstack([np.array(uf), np.array(uh)])


def run(name: str, sys: Any, x0: ivobs.Box, u: np.ndarray, y: np.ndarray, x: np.ndarray,
        **opts: Any) -> tuple[np.ndarray, int, float]:  # fmt: skip
    est = ivobs.make_estimator(name, sys, x0, **opts)
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = est.run(u, y)
    dt = time.perf_counter() - t0
    misses = int(np.sum((x < res.lower) | (x > res.upper)))
    return res.upper - res.lower, misses, y.shape[0] / dt


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--scenarios", nargs="+", default=["range-only", "unicycle-range"])
    ap.add_argument("--kinds", nargs="+", default=["vertex", "uniform"])
    ap.add_argument("--window", type=int, default=None)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    for scen in args.scenarios:
        for kind in args.kinds:
            sc = registry.get(scen, horizon=args.steps)
            tr = sc.simulate(kind, seed=args.seed)
            sys = sc.system
            win = {} if args.window is None else {"window": args.window}
            N = args.window or 20
            rows = {}
            rows["nl-horizon"] = run("nl-horizon", sys, sc.x0, tr.u, tr.y, tr.x, **win)
            rows["nl-constrained-zonotope"] = run(
                "nl-constrained-zonotope", sys, sc.x0, tr.u, tr.y, tr.x
            )
            lin, ulin = linearised_along(sys, tr)
            rows["linearised exact"] = run("exact", lin, sc.x0, ulin, tr.y, tr.x, window=N)
            late = slice(args.steps // 2, None)
            ref = rows["linearised exact"][0][late].mean(axis=0)
            cz = rows["nl-constrained-zonotope"][0][late].mean(axis=0)
            print(f"\n{scen} ({kind}, {args.steps} steps, window {N}); late half mean widths")
            print(f"{'method':26s} {'widths':44s} {'/lin':>6s} {'/nlCZ':>6s} miss steps/s")
            for name, (W, miss, sps) in rows.items():
                m = W[late].mean(axis=0)
                r_lin, r_cz = np.max(m / ref), np.max(m / cz)
                ws = " ".join(f"{v:.4g}" for v in m)
                print(f"{name:26s} {ws:44s} {r_lin:6.2f} {r_cz:6.2f} {miss:4d} {sps:7.1f}")


if __name__ == "__main__":
    main()
