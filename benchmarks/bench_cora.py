"""The comparison of [Althoff2021] on CORA's benchmarks: every ivobs method, the exact hull and
CORA's saved values, in the same time convention.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_cora.py
        [--methods m1,m2] [--benchmarks cora-tank30,cora-vehicle6,...] [--budget 120]
        [--out benchmarks/results] [--figure docs/img/cora_tank30_radius.png | --no-figure]
        [--recompute-exact] [--merge]

For every CORA benchmark (scenarios ``cora-tank30``, ``cora-vehicle6``, ``cora-pedestrian4``,
``cora-slip4``, ``cora-2dim``; CORA's recorded data, ``scenario.simulate("recorded")``) and every
ivobs method with its default options, the metric of [Althoff2021]: the interval-hull radius of
each state (half the width of the box) as the root mean square over all time points, the mean of
those over the states (``rms``), the mean radius at time point 20 and at the final point, the
time per step (``step()``, ms) and the design time (``make_estimator``, s). Beside them: the exact
hull (``exact``, full horizon: slow, so cached in ``<out>/cora_exact_<benchmark>.npz``) and, on
tank30, CORA's saved hulls (ivobs/data/cora_tank30_results.npz).

**Time convention** (ivobs/data/CORA_README.md): time point ``k`` (1-based) is the box of
``x[k-1]``, row ``k-1`` of every estimate. Methods in filter form (``data_used = "filter"``)
have used ``y[0..k-1]`` there, those in prediction form (and CORA's gain observers FRad-C,
Nom-G, Hinf-G) ``y[0..k-2]``; the ``form`` column says which. The exact hull is in filter form.

Each run happens in a child process with a time budget (``--budget`` seconds, design included):
a run over budget stops between steps and reports the steps done (its ``rms`` over those only,
marked); a design that does not return within the budget is stopped. A method that refuses a
system is listed with its reason. ``misses``: steps whose box does not contain CORA's recorded
state (pedestrian4's record leaves its own bounds at 3 samples: CORA_README).

Writes ``<out>/cora_table.md`` and ``<out>/cora_table.json`` (and prints the table; ``--merge``
keeps the saved rows of the method/benchmark pairs not run this time), and the
figure (radius over time per method on tank30, log scale, exact hull as the floor, CORA's
values as markers).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import multiprocessing as mp
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np

import ivobs

BENCHMARKS = ["cora-tank30", "cora-vehicle6", "cora-pedestrian4", "cora-slip4", "cora-2dim"]
CORA_ALGS = {  # key in cora_tank30_results.npz -> (CORA's name, form)
    "FRadA": ("CORA FRad-A", "filter"),
    "FRadB": ("CORA FRad-B", "filter"),
    "FRadC": ("CORA FRad-C", "prediction"),
    "NomG": ("CORA Nom-G", "prediction"),
    "HinfG": ("CORA Hinf-G", "prediction"),
    "ESOA": ("CORA ESO-A", "filter"),
    "ESOB": ("CORA ESO-B", "filter"),
}
K_EARLY = 20
"""The early time point CORA's saved tank30 results have (1-based)."""

ROOT = Path(__file__).resolve().parents[1]


# -- the metric -----------------------------------------------------------------------------
def radii(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Interval-hull radius per time point and state, ``(T, n)``."""
    return np.asarray(0.5 * (hi - lo))


def metric(r: np.ndarray, start: int = 0) -> dict[str, Any]:
    """[Althoff2021]'s table entry from the radii ``(T, n)``: per-state RMS over the time
    points from ``start`` on, their mean, the mean radius at point 20 and at the last point."""
    rr = r[start:]
    rms = np.sqrt(np.mean(rr**2, axis=0))
    T = r.shape[0]
    return {
        "rms": float(rms.mean()),
        "rms_per_state": rms.tolist(),
        "r_early": float(r[K_EARLY - 1].mean()) if T >= K_EARLY and K_EARLY > start else None,
        "r_final": float(r[-1].mean()),
        "steps": int(T),
    }


# -- the exact hull, cached -----------------------------------------------------------------
def _fingerprint(sc: Any, tr: Any) -> str:
    h = hashlib.sha256()
    s = sc.system
    for a in (s.A, s.B, s.C, s.D, s.E, s.F, s.d.lo, s.d.hi, sc.x0.lo, sc.x0.hi, tr.u, tr.y):
        h.update(np.ascontiguousarray(np.asarray(a, dtype=float)).tobytes())
    return h.hexdigest()[:16]


def exact_hull(
    bench: str,
    out: Path,
    recompute: bool = False,
    *,
    disturbance: str = "recorded",
    seed: int | None = None,
    window: int | None = None,
    horizon: int | None = None,
) -> dict[str, Any]:
    """The exact interval hull of ``bench``'s recorded data (or of ``scenario.simulate(
    disturbance, seed)``; ``window``: the moving window of ``exact``, None for the full
    horizon), from the cache when its data fingerprint matches, else computed (minutes on
    tank30) and cached."""
    sc = ivobs.scenarios.get(bench, **({} if horizon is None else {"horizon": horizon}))
    tr = sc.simulate(disturbance, seed)
    fp = _fingerprint(sc, tr)
    stem = f"cora_exact_{bench}"
    if disturbance != "recorded" or window is not None:
        stem = f"exact_{bench}_{disturbance}_seed{seed}_T{tr.y.shape[0]}_window{window}"
    path = out / f"{stem}.npz"
    if path.exists() and not recompute:
        z = np.load(path)
        if str(z["fingerprint"]) == fp:
            return {"lo": z["lo"], "hi": z["hi"], "seconds": float(z["seconds"]), "cached": True}
    est = ivobs.make_estimator("exact", sc.system, x0=sc.x0, window=window, progress=False)
    start = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = est.run(tr.u, tr.y)
    seconds = time.perf_counter() - start
    out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path, lo=res.lower, hi=res.upper, seconds=seconds, fingerprint=fp, ivobs=ivobs.__version__
    )
    return {"lo": res.lower, "hi": res.upper, "seconds": seconds, "cached": False}


# -- one method on one benchmark, in a child process ------------------------------------------
def _run(bench: str, method: str, budget: float, conn: Any) -> None:
    """Design, then ``step()`` through the record until done or over budget; sends a dict."""
    sc = ivobs.scenarios.get(bench)
    tr = sc.simulate("recorded")
    out: dict[str, Any] = {"benchmark": bench, "method": method}
    warnings.simplefilter("ignore")
    start = time.perf_counter()
    try:
        est = ivobs.make_estimator(method, sc.system, x0=sc.x0, on_inconsistent="ignore")
    except ivobs.IvobsError as exc:
        out.update(status="refused", reason=str(exc), design_s=time.perf_counter() - start)
        conn.send(out)
        return
    design = time.perf_counter() - start
    cls = type(est)
    T = tr.y.shape[0]
    lo, hi = np.full((T, sc.system.nx), np.nan), np.full((T, sc.system.nx), np.nan)
    n_inc, k = 0, 0
    t0 = time.perf_counter()
    try:
        for k in range(T):
            box = est.step(tr.u[k], tr.y[k])
            lo[k], hi[k] = box.lo, box.hi
            n_inc += est.last_inconsistent
            if time.perf_counter() - start > budget and k + 1 < T:
                k += 1
                break
        else:
            k = T
    except ivobs.IvobsError as exc:
        out.update(status="failed", reason=f"step {k}: {exc}", design_s=design)
        conn.send(out)
        return
    steps_s = time.perf_counter() - t0
    out.update(
        status="ok" if k == T else "over budget",
        form=cls.data_used,
        design_s=design,
        ms_per_step=1e3 * steps_s / max(k, 1),
        steps_done=k,
        valid_from=est.valid_from,
        inconsistent=n_inc,
        lo=lo[:k],
        hi=hi[:k],
    )
    conn.send(out)


def run_one(bench: str, method: str, budget: float) -> dict[str, Any]:
    """:func:`_run` in a forked child, stopped if it does not answer within the budget (plus a
    grace period for the step in progress)."""
    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_run, args=(bench, method, budget, child))
    proc.start()
    child.close()
    res: dict[str, Any] | None = None
    if parent.poll(budget * 1.5 + 30.0):
        try:
            res = parent.recv()
        except EOFError:
            res = None
    if proc.is_alive():
        proc.terminate()
    proc.join()
    if res is None:
        res = {
            "benchmark": bench,
            "method": method,
            "status": "over budget",
            "reason": f"no answer within {budget * 1.5 + 30:.0f} s (design or one step)",
        }
    return res


# -- the table --------------------------------------------------------------------------------
def score(res: dict[str, Any], x: np.ndarray | None, exact: dict[str, Any]) -> dict[str, Any]:
    """The metric of a run, its ratios to the exact hull over the same steps, and its misses
    of the recorded state."""
    row = {k: v for k, v in res.items() if k not in ("lo", "hi")}
    if "lo" not in res or not res["steps_done"]:
        return row
    lo, hi, k, vf = res["lo"], res["hi"], res["steps_done"], res["valid_from"]
    r = radii(lo, hi)
    m = metric(r, vf)
    ex = metric(radii(exact["lo"][:k], exact["hi"][:k]), vf)
    row.update(m)
    row["rms_ratio"] = m["rms"] / ex["rms"]
    row["final_ratio"] = m["r_final"] / ex["r_final"]
    if m["r_early"] is not None and ex["r_early"]:
        row["early_ratio"] = m["r_early"] / ex["r_early"]
    if x is not None and np.isfinite(x).all():
        xs = x[vf:k]
        miss = ~((lo[vf:] <= xs) & (xs <= hi[vf:])).all(axis=1)
        row["misses"] = (np.flatnonzero(miss) + vf).tolist()
    row["radius_mean"] = r.mean(axis=1).tolist()
    return row


def cora_rows() -> list[dict[str, Any]]:
    """CORA's saved tank30 hulls (time points 20 and 235) as rows."""
    z = np.load(ROOT / "src/ivobs/data/cora_tank30_results.npz")
    ex20 = radii(z["exact_k20_lo"], z["exact_k20_hi"]).mean()
    ex235 = radii(z["exact_k235_lo"], z["exact_k235_hi"]).mean()
    rows = []
    for key, (name, form) in CORA_ALGS.items():
        row: dict[str, Any] = {"benchmark": "cora-tank30", "method": name, "form": form}
        if f"cora_k20_{key}_lo" in z:
            row["r_early"] = float(radii(z[f"cora_k20_{key}_lo"], z[f"cora_k20_{key}_hi"]).mean())
            row["early_ratio"] = row["r_early"] / ex20
        row["r_final"] = float(radii(z[f"cora_k235_{key}_lo"], z[f"cora_k235_{key}_hi"]).mean())
        row["final_ratio"] = row["r_final"] / ex235
        row["status"] = "CORA (saved)"
        rows.append(row)
    return rows


def _f(v: Any, fmt: str) -> str:
    return "–" if v is None else format(v, fmt)


def markdown(rows: list[dict[str, Any]], exacts: dict[str, dict[str, Any]]) -> str:
    lines = []
    for bench in dict.fromkeys(r["benchmark"] for r in rows):
        ex = exacts[bench]
        em = metric(radii(ex["lo"], ex["hi"]))
        T = ex["lo"].shape[0]
        lines += [
            f"### {bench} ({T} time points; point 20 and the final point {T})",
            "",
            "| method | form | rms radius | / exact | r(20) | / exact | r(final) | / exact "
            "| ms/step | design s | misses | status |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|",
            f"| exact hull (full horizon) | filter | {em['rms']:.4g} | 1.00 "
            f"| {_f(em['r_early'], '.4g')} | 1.00 | {em['r_final']:.4g} | 1.00 "
            f"| {1e3 * ex['seconds'] / T:.0f} | – | – | reference |",
        ]
        for r in rows:
            if r["benchmark"] != bench:
                continue
            status = r["status"]
            if r.get("reason"):
                status += ": " + r["reason"].replace("|", "\\|").replace("\n", " ")[:160]
            elif r["status"] == "over budget":
                status += f" (stopped after {r['steps_done']} steps)"
            if r.get("valid_from"):  # NaN boxes before: the metric (and exact's) from there on
                status += f" (boxes from point {r['valid_from'] + 1} on)"
            misses = r.get("misses")
            lines.append(
                f"| {r['method']} | {r.get('form', '–')} | {_f(r.get('rms'), '.4g')} "
                f"| {_f(r.get('rms_ratio'), '.2f')} | {_f(r.get('r_early'), '.4g')} "
                f"| {_f(r.get('early_ratio'), '.2f')} | {_f(r.get('r_final'), '.4g')} "
                f"| {_f(r.get('final_ratio'), '.2f')} | {_f(r.get('ms_per_step'), '.3g')} "
                f"| {_f(r.get('design_s'), '.3g')} "
                f"| {'–' if misses is None else (len(misses) if len(misses) > 3 else misses)} "
                f"| {status} |"
            )
        lines.append("")
    return "\n".join(lines)


def figure(rows: list[dict[str, Any]], exact: dict[str, Any], path: Path) -> None:
    """Mean radius over time per method on tank30 (log scale), the exact hull as the floor,
    CORA's saved values as markers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10, 5.5))
    T = exact["lo"].shape[0]
    kk = np.arange(1, T + 1)
    for r in rows:
        if r["benchmark"] == "cora-tank30" and "radius_mean" in r:
            y = np.asarray(r["radius_mean"])
            ax.plot(kk[: y.size], y, lw=1.2, label=f"{r['method']} ({r['form']})")
    ax.plot(kk, radii(exact["lo"], exact["hi"]).mean(axis=1), "k-", lw=2.5, label="exact hull")
    markers = iter("osD^v<>")
    for r in rows:
        if r["benchmark"] == "cora-tank30" and r["status"] == "CORA (saved)":
            pts = [(T, r["r_final"])] + ([(K_EARLY, r["r_early"])] if "r_early" in r else [])
            ax.plot(*zip(*pts, strict=True), next(markers), ms=7, mfc="none", label=r["method"])
    ax.set_yscale("log")
    ax.set_xlabel("time point k (1-based: the box of x[k-1])")
    ax.set_ylabel("mean interval-hull radius over the 30 states")
    ax.set_title(
        "CORA tank30 [Althoff2021]: ivobs methods, exact hull, CORA's saved values", fontsize=10
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--methods", default=None, help="comma-separated (default: all but exact)")
    p.add_argument("--benchmarks", default=",".join(BENCHMARKS))
    p.add_argument("--budget", type=float, default=120.0, help="seconds per run (design incl.)")
    p.add_argument("--out", default=str(ROOT / "benchmarks/results"))
    p.add_argument("--figure", default=str(ROOT / "docs/img/cora_tank30_radius.png"))
    p.add_argument("--no-figure", action="store_true")
    p.add_argument("--recompute-exact", action="store_true")
    p.add_argument(
        "--merge",
        action="store_true",
        help="keep the rows of <out>/cora_table.json not run this time",
    )
    a = p.parse_args(argv)
    methods = a.methods.split(",") if a.methods else [m for m in ivobs.methods() if m != "exact"]
    benches = a.benchmarks.split(",")
    out = Path(a.out)
    try:
        import cvxpy  # noqa: F401  (imported once here, not in every design time)
    except ImportError:
        pass
    rows: list[dict[str, Any]] = []
    exacts: dict[str, dict[str, Any]] = {}
    for bench in benches:
        x = ivobs.scenarios.get(bench).simulate("recorded").x
        runs = []
        for method in methods:
            runs.append(run_one(bench, method, a.budget))
            r = runs[-1]
            print(
                f"{bench:17s} {method:22s} {r['status']:12s} "
                f"ms/step {_f(r.get('ms_per_step'), '.3g'):>6s}",
                flush=True,
            )
        exacts[bench] = exact_hull(bench, out, a.recompute_exact)  # (cached: after the runs)
        rows += [score(res, x, exacts[bench]) for res in runs]
        if bench == "cora-tank30":
            rows += cora_rows()
    saved = out / "cora_table.json"
    if a.merge and saved.exists():
        done = {(r["benchmark"], r["method"]) for r in rows}
        kept = [
            r
            for r in json.loads(saved.read_text())
            if (r["benchmark"], r["method"]) not in done
            and not (r["status"] == "CORA (saved)" and r["benchmark"] in benches)
        ]
        for bench in dict.fromkeys(r["benchmark"] for r in kept):
            exacts[bench] = exact_hull(bench, out)
        rows = kept + rows
        order = {m: i for i, m in enumerate(ivobs.methods())}
        rows.sort(key=lambda r: (BENCHMARKS.index(r["benchmark"]), order.get(r["method"], 999)))
    table = markdown(rows, exacts)
    print(table)
    out.mkdir(parents=True, exist_ok=True)
    (out / "cora_table.md").write_text(table + "\n", encoding="utf-8")
    (out / "cora_table.json").write_text(json.dumps(rows) + "\n", encoding="utf-8")
    if not a.no_figure and "cora-tank30" in exacts:
        figure(rows, exacts["cora-tank30"], Path(a.figure))


if __name__ == "__main__":
    main()
