"""nl-interval on plants whose boxes wrap, and what its window-centred form costs elsewhere.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_nl_interval_wrap.py [--cache DIR] [--skip-exact]

1. Random stable linear plants whose boxes wrap (``ρ(A) = 0.95 < 1 < ρ(|A|)``, 4-6 states, one
   output, every disturbance ``±0.1``: tests/vertexsim.py ``wrapping_plant``), 400 exact steps
   with every disturbance on a vertex (``exact_linear``), prior ``[-1, 1]``: the ratio of each
   method's mean width over steps 50..400 (all states) to the exact hull's (method ``exact``;
   ``--cache DIR`` keeps its bounds, which take minutes).
2. The nonlinear scenarios over a vertex record (``simulate("vertex", 0)``): nl-interval's mean
   width per state and its CPU steps per second (``run()``, best of 3).

Run it against another checkout (``PYTHONPATH=<other>/src``) for the figures before a change.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
from timing import cpu_best

import ivobs

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from vertexsim import exact_linear, wrapping_plant

SEEDS = range(8)
T = 400
METHODS = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"]
SCENARIOS = ["henon-nl", "pendulum-nl", "cora-tank6-nl", "cstr"]


def exact_hull(
    seed: int, sys_: ivobs.LinearSystem, U: np.ndarray, Y: np.ndarray, cache: Path | None
):
    path = None if cache is None else cache / f"exact_wrap_{seed}.npz"
    if path is not None and path.exists():
        z = np.load(path)
        return z["lo"], z["hi"]
    n = sys_.nx
    res = ivobs.make_estimator("exact", sys_, x0=ivobs.Box(-np.ones(n), np.ones(n))).run(U, Y)
    if path is not None:
        np.savez(path, lo=res.lower, hi=res.upper)
    return res.lower, res.upper


def linear_table(cache: Path | None) -> None:
    print("| plant | n | ρ(\\|A\\|) | " + " | ".join(METHODS) + " |")
    print("|---|---|---|" + "---|" * len(METHODS))
    ratios: dict[str, list[float]] = {m: [] for m in METHODS}
    for seed in SEEDS:
        n = 4 + seed % 3
        sys_, _ = wrapping_plant(seed, n)
        U, X, Y = exact_linear(sys_, np.zeros(n), T, seed)
        elo, ehi = exact_hull(seed, sys_, U, Y, cache)
        we = (ehi - elo)[50:].mean()
        cells = []
        for m in METHODS:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                res = ivobs.make_estimator(m, sys_, x0=ivobs.Box(-np.ones(n), np.ones(n))).run(U, Y)
            if np.any(res.lower > X) or np.any(X > res.upper):
                raise SystemExit(f"{m} on plant {seed}: a box misses the true state")
            r = float((res.upper - res.lower)[50:].mean() / we)
            ratios[m].append(r)
            cells.append(f"{r:.3g}")
        rho = max(abs(np.linalg.eigvals(abs(sys_.A))))
        print(f"| {seed} | {n} | {rho:.2f} | " + " | ".join(cells) + " |", flush=True)
    print("| **max** | | | " + " | ".join(f"**{max(v):.3g}**" for v in ratios.values()) + " |")


def nonlinear_table() -> None:
    print("\n| scenario | steps | nl-interval mean width per state | steps/s (CPU) |")
    print("|---|---|---|---|")
    for name in SCENARIOS:
        sc = ivobs.scenarios.get(name)
        tr = sc.simulate("vertex", 0)
        est = ivobs.make_estimator("nl-interval", sc.system, x0=sc.x0)
        res = est.run(tr.u, tr.y)
        steps = tr.y.shape[0]
        cpu = cpu_best(lambda est=est, tr=tr: est.run(tr.u, tr.y))
        w = np.array2string((res.upper - res.lower).mean(axis=0), precision=4, separator=", ")
        print(f"| `{name}` | {steps} | {w} | {steps / cpu:.0f} |", flush=True)


def main(argv: list[str]) -> None:
    cache = Path(argv[argv.index("--cache") + 1]) if "--cache" in argv else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    if "--skip-exact" not in argv:
        linear_table(cache)
    nonlinear_table()


if __name__ == "__main__":
    main(sys.argv[1:])
