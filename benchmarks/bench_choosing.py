"""The measurements behind docs/choosing.md ("Which method?") that BENCHMARKS.md had no row for.

Three small experiments, every linear method with its default options, vertex disturbances
(``ivobs.testing.adversarial_run``), CPU time per step of ``run()`` (design excluded):

* ``stable`` / ``unstable``: random observable plants, 4 states, 2 outputs, 1 input, ``A``
  rescaled to spectral radius 0.8 or 1.05 (``ivobs.testing.random_system``), 300 steps, with
  complete data and with 10 % of the output components missing at random; the mean summed width
  over steps 150-299 divided by the moving-window exact hull's (``exact`` with ``window=20``);
* ``sampling``: the DC servo motor of the gallery (continuous time, load torque
  ``|tau| <= 0.05``, sensor noise ``0.01``) sampled every 0.01 s and every 0.1 s (``discretize``:
  the torque varies between samples), the same 10 s of plant time, ``u = 2``, uniform
  disturbances; the mean summed width over the second half divided by ``exact``'s.

Usage: ``OPENBLAS_NUM_THREADS=1 python benchmarks/bench_choosing.py [stable|unstable|sampling]``
(all three by default; about 3 minutes on one core).
"""

from __future__ import annotations

import sys
import time
import warnings

import numpy as np

import ivobs
from ivobs.testing import adversarial_run, random_system

LINEAR = [m for m in ivobs.methods() if not m.startswith("nl-") and m != "exact"]


def _one(method, sys, x0, u, y, x, late, options=None):
    """(summed mean width over ``late``, all contained, CPU µs per step) or the error."""
    try:
        est = ivobs.make_estimator(method, sys, x0=x0, **(options or {}))
    except ivobs.IvobsError as exc:
        return type(exc).__name__
    t0 = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = est.run(u, y)
    cpu = time.process_time() - t0
    ok = bool(res.contains(x)[res.valid_from :].all())
    width = float(np.sum(np.mean(res.upper[late] - res.lower[late], axis=0)))
    return width, ok, 1e6 * cpu / len(y)


def _table(rows, ref):
    for method, out in rows:
        if isinstance(out, str):
            print(f"| {method} | {out} | | |")
        else:
            w, ok, us = out
            print(f"| {method} | {w / ref:.3g} | {'yes' if ok else 'NO'} | {us:,.0f} |")


def random_plants(rho: float, seeds=(0, 1, 2), T=300) -> None:
    late = slice(T // 2, T)
    for missing in (0.0, 0.1):
        ratios: dict[str, list] = {m: [] for m in LINEAR}
        for seed in seeds:
            sys = random_system(np.random.default_rng(seed), nx=4, ny=2, nu=1, rho=rho)
            x0 = ivobs.Box(-np.ones(4), np.ones(4))
            traj = adversarial_run(sys, x0, T, seed=seed)
            y = traj.y.copy()
            if missing:
                rng = np.random.default_rng(100 + seed)
                y[rng.random(y.shape) < missing] = np.nan
            ref = _one("exact", sys, x0, traj.u, y, traj.x, late, {"window": 20})
            for m in LINEAR:
                out = _one(m, sys, x0, traj.u, y, traj.x, late)
                ratios[m].append(out if isinstance(out, str) else (out[0] / ref[0], *out[1:]))
            ratios.setdefault("exact (window 20)", []).append((1.0, ref[1], ref[2]))
        print(f"\nrho(A) = {rho}, missing {missing:.0%}, seeds {list(seeds)}, {T} steps")
        print("| method | width / exact (per seed) | contains | CPU µs/step |")
        print("|---|---|---|---|")
        for m, outs in ratios.items():
            errs = [o for o in outs if isinstance(o, str)]
            good = [o for o in outs if not isinstance(o, str)]
            r = ", ".join(f"{o[0]:.3g}" for o in good) + (
                f" ({len(errs)}× {errs[0]})" if errs else ""
            )
            ok = "yes" if all(o[1] for o in good) else "NO"
            us = np.median([o[2] for o in good]) if good else float("nan")
            print(f"| {m} | {r} | {ok} | {us:,.0f} |")


def sampling(t_final=10.0) -> None:
    A = np.array([[0.0, 1.0, 0.0], [0.0, -1.6, 5.0], [0.0, -0.4, -0.05]])
    B = np.array([[0.0], [0.0], [0.75]])
    E = np.array([[0.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    F = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    d = ivobs.Box([-0.05, -0.01, -0.01], [0.05, 0.01, 0.01])  # torque; sensor noise
    plant = ivobs.LinearSystem(A, B, C, E=E, F=F, d=d, dt=0)
    x0 = ivobs.Box([-0.2] * 3, [0.2] * 3)
    for Ts in (0.01, 0.1):
        sys = plant.discretize(Ts)
        T = round(t_final / Ts)
        late = slice(T // 2, T)
        # uniform, not vertex, disturbances: noise on its bounds at every sample would tell the
        # set methods the state to 1e-5 when sampled fast, which no real sensor does
        u = np.full((T, 1), 2.0)
        d = ivobs.uniform_disturbance(sys.d, T, seed=0)
        traj = ivobs.simulate(sys, x0=[0.05, -0.1, 0.0], u=u, d=d)
        ref = _one("exact", sys, x0, traj.u, traj.y, traj.x, late, {"window": 20})
        print(f"\nservo sampled every {Ts} s ({T} steps, {sys.sampling}, nd = {sys.nd})")
        print("| method | width / exact | contains | CPU µs/step |")
        print("|---|---|---|---|")
        rows = [(m, _one(m, sys, x0, traj.u, traj.y, traj.x, late)) for m in LINEAR]
        _table([*rows, ("exact (window 20)", ref)], ref[0])


if __name__ == "__main__":
    which = sys.argv[1:] or ["stable", "unstable", "sampling"]
    if "stable" in which:
        random_plants(0.8)
    if "unstable" in which:
        random_plants(1.05)
    if "sampling" in which:
        sampling()
