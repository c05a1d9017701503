"""Design time of the interval family on random detectable systems, and fixed-time over 10⁵ steps.

**Random detectable systems** (``plant(n, seed, kind)``, the same generator as
``tests/test_design_scale.py``): ``ny = max(2, n // 10)`` outputs, ``A`` scaled to spectral radius
``1.02`` (unstable, so only a detectable pair has an observer), process noise ``0.1·I`` and sensor
noise ``0.05·I`` (``d ∈ [−1, 1]^(n + ny)``). Two kinds:

* ``gaussian``: dense ``A``, ``C`` with independent normal entries (generically observable). No
  gain makes ``|A − LC|`` Schur, so ``interval`` and ``interval-split`` must *refuse, with a
  proof*; only ``interval-transformed`` has a design condition with a solution.
* ``positive``: sparse nonnegative ``A`` (about 4 nonzeros per row off the diagonal, diagonal in
  ``[0.2, 1]`` before scaling: a random compartment/tank network) read by ``ny`` point sensors on
  random states; observability is checked, and all three methods have a solution.

For each ``n`` and kind the script prints the time of ``make_estimator`` (design and every
derived matrix) or the first words of the refusal, then fits ``time ∝ n^p`` over the sizes that
succeeded. Each design runs in its own process with a time limit (``--timeout``, default 600 s), so
the script also measures the old code (``PYTHONPATH=<old src>``).

Then: ``fixed-time`` on a random 30-state plant (``ivobs.testing.random_system(1, nx=30,
ny=15)``) over 10⁵ steps with vertex disturbances (containment and the width range), and the
interval family on ``cora-tank30`` (mean interval-hull radius at k = 20 and k = 235).

Run: ``python benchmarks/bench_design_scale.py [--quick] [--sizes 10,30,100,300]``.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np

METHODS = ("interval", "interval-split", "interval-transformed")


def plant(n: int, seed: int, kind: str, rho: float = 1.02):
    """A random detectable system (module docstring)."""
    from ivobs import Box, LinearSystem
    from ivobs.linalg import is_observable

    rng = np.random.default_rng(seed)
    ny = max(2, n // 10)
    for _ in range(100):
        if kind == "gaussian":
            A = rng.normal(size=(n, n))
            C = rng.normal(size=(ny, n))
        else:
            A = rng.uniform(0, 1, (n, n)) * (rng.random((n, n)) < min(1.0, 4.0 / n))
            A += np.diag(rng.uniform(0.2, 1.0, n))
            C = np.zeros((ny, n))
            C[np.arange(ny), rng.choice(n, ny, replace=False)] = 1.0
        A *= rho / np.max(np.abs(np.linalg.eigvals(A)))
        if n > 120 or is_observable(A, C):  # (the rank test itself is ill-posed above ~100)
            break
    E = np.hstack([0.1 * np.eye(n), np.zeros((n, ny))])
    F = np.hstack([np.zeros((ny, n)), 0.05 * np.eye(ny)])
    d = Box(-np.ones(n + ny), np.ones(n + ny))
    return LinearSystem(A, rng.normal(size=(n, 1)), C, E=E, F=F, d=d)


def _design(args, out) -> None:
    method, n, kind = args
    import ivobs

    sys = plant(n, 1, kind)
    x0 = ivobs.Box.symmetric(np.ones(n))
    t0 = time.perf_counter()
    try:
        est = ivobs.make_estimator(method, sys, x0=x0)
        out.put(
            (
                time.perf_counter() - t0,
                f"ok ({est.design.gain}, ρ {est.design.spectral_radius:.3f})",
            )
        )
    except ivobs.IvobsError as exc:
        out.put((time.perf_counter() - t0, "refused: " + str(exc).split(":", 1)[1][:70].strip()))


def timed_design(method: str, n: int, kind: str, timeout: float) -> tuple[float, str]:
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_design, args=((method, n, kind), q))
    p.start()
    p.join(timeout)
    if p.is_alive():
        p.kill()
        p.join()
        return float("nan"), f"> {timeout:.0f} s (stopped)"
    return q.get() if not q.empty() else (float("nan"), f"crashed (exit {p.exitcode})")


def designs(sizes: list[int], timeout: float) -> None:
    print(
        f"{'kind':>9} {'method':>21} " + " ".join(f"{'n=' + str(n):>10}" for n in sizes) + "   fit"
    )
    for kind in ("positive", "gaussian"):
        for method in METHODS:
            times, notes = [], []
            for n in sizes:
                t, what = timed_design(method, n, kind, timeout)
                times.append(t)
                notes.append(what)
            ok = [(n, t) for n, t, w in zip(sizes, times, notes) if w.startswith("ok") and t > 0]
            fit = ""
            if len(ok) >= 2:
                p = np.polyfit(np.log([n for n, _ in ok]), np.log([t for _, t in ok]), 1)[0]
                fit = f"n^{p:.2f}"
            cells = " ".join(f"{t:>9.2f}s" if np.isfinite(t) else f"{'-':>10}" for t in times)
            print(f"{kind:>9} {method:>21} {cells}   {fit}")
            for n, w in zip(sizes, notes):
                print(f"{'':>32} n={n}: {w}")


def fixed_time(T: int) -> None:
    import ivobs
    from ivobs.testing import adversarial_run, random_system

    sys = random_system(1, nx=30, ny=15)
    x0 = ivobs.Box.symmetric(np.ones(30))
    t0 = time.perf_counter()
    try:
        est = ivobs.make_estimator("fixed-time", sys, x0=x0)
    except ivobs.IvobsError as exc:
        print(f"fixed-time, random 30 states: refused: {exc}")
        return
    td = time.perf_counter() - t0
    tr = adversarial_run(sys, x0, T, seed=0)
    t0 = time.perf_counter()
    try:
        res = est.run(tr.u, tr.y)
    except ivobs.IvobsError as exc:
        print(f"fixed-time, random 30 states: design {td:.2f} s, s = {est.s}; run: {exc}")
        return
    tr_ = time.perf_counter() - t0
    k0 = est.s
    w = res.width[k0:].sum(axis=1)
    inside = bool(res.contains(tr.x)[k0:].all())
    print(f"fixed-time, random 30 states / 15 outputs, s = {est.s}: design {td:.2f} s, {T} steps "
          f"in {tr_:.2f} s; contained {inside}; finite {bool(np.isfinite(w).all())}; summed width "
          f"{w.min():.4g} .. {w.max():.4g}")  # fmt: skip


def tank30() -> None:
    import ivobs

    sc = ivobs.scenarios.get("cora-tank30")
    tr = sc.simulate("recorded")
    for method in METHODS:
        t0 = time.perf_counter()
        try:
            est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
        except ivobs.IvobsError as exc:
            print(f"cora-tank30 {method:>21}: refused ({str(exc)[:80]})")
            continue
        td = time.perf_counter() - t0
        res = est.run(tr.u, tr.y)
        r = 0.5 * (res.upper - res.lower)
        steady = getattr(est.design, "steady_width", None)
        bound = "" if steady is None else f", steady-state bound {0.5 * steady.mean():.4f}"
        inside = bool(res.contains(tr.x).all())
        print(f"cora-tank30 {method:>21}: design {td:.2f} s, r(20) = {r[19].mean():.4f}, "
              f"r(235) = {r[234].mean():.4f}{bound}, contained {inside}")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sizes", default=None)
    ap.add_argument("--timeout", type=float, default=600.0)
    ap.add_argument("--steps", type=int, default=100_000)
    args = ap.parse_args()
    sizes = [10, 30, 100] if args.quick else [10, 30, 100, 300]
    if args.sizes:
        sizes = [int(s) for s in args.sizes.split(",")]
    designs(sizes, args.timeout)
    fixed_time(10_000 if args.quick else args.steps)
    tank30()


if __name__ == "__main__":
    main()
