"""The ``dual-window`` method's window chosen from the model (``window="auto"``) against the
exact hull.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_dual_window_auto.py [--steps 400]
        [--systems 0-19] [--cora] [--window auto] [--no-exact]

For 20 seeded random detectable systems (2 to 8 states, 1 to 4 outputs, spectral radii 0.6 to
1.05, process disturbances on some states and noise on every output; system 19 badly scaled:
its states 1e-4 to 1e4 apart) a record of ``--steps`` samples with the disturbances on random
vertices of their box (simulated here with NumPy), then ``dual-window`` with ``--window``
(``auto``, the default, or a number) and the full-horizon ``exact`` hull (its mean widths
are kept in ``benchmarks/results/dual_window_auto_exact.npz`` by seed and length: on 8 states
it takes about 5 CPU minutes for 400 steps; ``--no-exact`` skips the systems not kept).
``--refresh`` passes that option too. Printed per system: the window chosen, the ratio of the
mean box width to the exact hull's over the record, the steps whose box misses the simulated
state, and the CPU seconds (design included).

``--cora``: the same on CORA's linear benchmarks (``cora-*`` scenarios, their recorded data);
the exact hull is the one saved in ``benchmarks/results/cora_exact_hull.npz`` (made by
``bench_czonotope.py reference``; the full horizon of tank30 takes hours here).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import ivobs

# the tests' vertex simulator (every disturbance on a vertex): one simulator for both
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from vertexsim import simulate_vertex

CORA = ["cora-2dim", "cora-pedestrian4", "cora-vehicle6", "cora-slip4", "cora-tank30"]
ONLY: list[str] = []  # --only: a subset of CORA
RESULTS = Path(__file__).parent / "results"
HULLS = RESULTS / "cora_exact_hull.npz"
RANDOM_HULLS = RESULTS / "dual_window_auto_exact.npz"
BADLY_SCALED = 19


def random_system(seed: int) -> tuple[ivobs.LinearSystem, ivobs.Box]:
    """A random detectable system (module docstring) and the prior box of its first state."""
    rng = np.random.default_rng(seed)
    nx = 2 + seed % 7
    ny = int(rng.integers(1, max(1, nx // 2) + 1))
    nw = int(rng.integers(1, nx + 1))
    while True:
        A = rng.normal(size=(nx, nx))
        A *= rng.uniform(0.6, 1.05) / max(abs(np.linalg.eigvals(A)))
        C = rng.normal(size=(ny, nx))
        lam = np.linalg.eigvals(A)
        unstable = lam[np.abs(lam) >= 1.0]
        if all(np.linalg.matrix_rank(np.vstack([A - z * np.eye(nx), C])) == nx for z in unstable):
            break
    B = rng.normal(size=(nx, 1))
    D = rng.normal(size=(ny, 1)) * 0.1
    E = np.hstack([rng.normal(size=(nx, nw)), np.zeros((nx, ny))])
    F = np.hstack([np.zeros((ny, nw)), np.eye(ny)])
    r = rng.uniform(0.02, 0.2, nw + ny)
    c = rng.uniform(-0.3, 0.3, nw + ny) * r
    x_true = rng.uniform(-1.0, 1.0, nx)
    if seed == BADLY_SCALED:
        s = 10.0 ** rng.uniform(-4.0, 4.0, nx)
        A, B, C, E = A * s[:, None] / s[None, :], B * s[:, None], C / s[None, :], E * s[:, None]
        x_true = x_true * s
        lo, hi = x_true - s, x_true + s
    else:
        lo, hi = x_true - 1.0, x_true + 1.0
    sys = ivobs.LinearSystem(A, B, C, D=D, E=E, F=F, d=ivobs.Box(c - r, c + r))
    return sys, ivobs.Box(lo, hi)


def _window(text: str) -> int | str:
    return text if text == "auto" else int(text)


def _seeds(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.extend(range(int(a), int(b or a) + 1))
    return out


def _exact_width(
    sys: ivobs.LinearSystem, x0: ivobs.Box, u: np.ndarray, y: np.ndarray, key: str, run: bool
) -> tuple[float, float] | None:
    """The mean width of the full-horizon exact hull and its CPU seconds: kept in
    :data:`RANDOM_HULLS`, computed (if ``run``) and kept when missing."""
    kept = dict(np.load(RANDOM_HULLS)) if RANDOM_HULLS.exists() else {}
    if key in kept:
        return float(kept[key][0]), float(kept[key][1])
    if not run:
        return None
    t = time.process_time()
    ref = ivobs.make_estimator("exact", sys, x0=x0, progress=False).run(u, y)
    kept[key] = np.array([ref.width.mean(), time.process_time() - t])
    np.savez(RANDOM_HULLS, **kept)
    return float(kept[key][0]), float(kept[key][1])


def run_random(seeds: list[int], steps: int, window: int | str, exact: bool, refresh: int) -> None:
    print(f"{'system':>6s} {'nx':>3s} {'ny':>3s} {'window':>6s} {'/exact':>7s} {'misses':>6s} "
          f"{'dw CPU s':>8s} {'exact CPU s':>11s}")  # fmt: skip
    ratios = []
    for seed in seeds:
        sys, x0 = random_system(seed)
        u = np.random.default_rng(seed + 1000).normal(size=(steps, sys.nu))
        x, y = simulate_vertex(sys, x0, u, seed)
        t = time.process_time()
        est = ivobs.make_estimator("dual-window", sys, x0=x0, window=window, refresh=refresh)
        res = est.run(u, y)
        t_dw = time.process_time() - t
        misses = int((~res.contains(x)).sum())
        ratio, t_ex = float("nan"), float("nan")
        ref = _exact_width(sys, x0, u, y, f"{seed}/{steps}", exact)
        if ref is not None:
            ratio, t_ex = float(res.width.mean() / ref[0]), ref[1]
            ratios.append(ratio)
        print(f"{seed:6d} {sys.nx:3d} {sys.ny:3d} {est.design.window:6d} {ratio:7.3f} "
              f"{misses:6d} {t_dw:8.2f} {t_ex:11.1f}", flush=True)  # fmt: skip
    if ratios:
        print(f"max ratio {max(ratios):.3f}, mean {np.mean(ratios):.3f}, "
              f"{sum(r <= 1.1 for r in ratios)} of {len(ratios)} within 1.1x")  # fmt: skip


def run_cora(window: int | str, refresh: int) -> None:
    hulls = np.load(HULLS)
    print(f"{'benchmark':18s} {'window':>6s} {'/exact':>7s} {'k>=100':>7s} {'misses':>6s} "
          f"{'CPU s':>6s}")  # fmt: skip
    for name in [n for n in CORA if n in ONLY] if ONLY else CORA:
        sc = ivobs.scenarios.get(name)
        rec = sc.recorded
        t = time.process_time()
        est = ivobs.make_estimator(
            "dual-window", sc.system, x0=sc.x0, window=window, refresh=refresh
        )
        res = est.run(rec.u, rec.y)
        cpu = time.process_time() - t
        w, ref = res.width, hulls[f"{name}/width"]
        late = w[100:].mean() / ref[100:].mean() if len(w) > 100 else float("nan")
        misses = int((~res.contains(rec.x)).sum()) if rec.has_truth else -1
        print(f"{name:18s} {est.design.window:6d} {w.mean() / ref.mean():7.3f} {late:7.3f} "
              f"{misses:6d} {cpu:6.2f}", flush=True)  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--steps", type=int, default=400)
    p.add_argument("--systems", default="0-19")
    p.add_argument("--cora", action="store_true", help="CORA's benchmarks instead")
    p.add_argument("--window", type=_window, default="auto")
    p.add_argument("--refresh", type=int, default=60)
    p.add_argument("--no-exact", action="store_true", help="skip the exact hull")
    p.add_argument("--only", default="", help="with --cora: these benchmarks only (comma list)")
    args = p.parse_args(argv)
    ONLY[:] = [n for n in args.only.split(",") if n]
    if args.cora:
        run_cora(args.window, args.refresh)
    else:
        run_random(_seeds(args.systems), args.steps, args.window, not args.no_exact, args.refresh)


if __name__ == "__main__":
    main()
