"""Mean box width of every method on every scenario's benchmark record, in two code versions.

Issue 29 asks that on every benchmark record the mean width be within 1 % of 2cc24ba's or
tighter. This script measures it for every scenario of :func:`ivobs.scenarios.names` and every
method of :func:`ivobs.methods`, with each method's default options, on one fixed record per
scenario, in whichever code version ``PYTHONPATH`` selects; a compare mode writes the table.

    # 1. the records, once, with the current code (one .npz per scenario: u, y, x, t)
    PYTHONPATH=src python benchmarks/bench_widths_vs_base.py records --dir /tmp/widths_records
    # 2. every (scenario, method) in each version, one subprocess per run, CPU-capped
    PYTHONPATH=/path/to/2cc24ba/src python benchmarks/bench_widths_vs_base.py run \\
        --records /tmp/widths_records --label 2cc24ba --out benchmarks/results/widths_base.json
    PYTHONPATH=src python benchmarks/bench_widths_vs_base.py run \\
        --records /tmp/widths_records --label head --out benchmarks/results/widths_head.json
    # 3. the Markdown table
    python benchmarks/bench_widths_vs_base.py compare benchmarks/results/widths_base.json \\
        benchmarks/results/widths_head.json

The record of a scenario is its stored data when it has some (the CORA scenarios'
``sc.recorded``), otherwise ``sc.simulate("vertex", seed=0)``; both versions read the same
``.npz`` (its SHA-256 is saved with the results, and compare checks that they agree). Each
version builds the scenario's system and prior box with its own code.

Per (scenario, method): the mean of ``upper - lower`` over every step and state (NaN-safe: the
steps before ``valid_from`` and missing boxes do not count), the number of steps where the true
state is outside the box by more than ``1e-9 * max(1, |x|)``, and the CPU time
(``time.process_time``) of design and run together (numba's compiling of a kernel included
when its on-disk cache is cold; ``run --resume --rerun-skipped`` measures the skipped runs
again with a warm cache). A method that refuses the scenario with an
:class:`~ivobs.IvobsError` is recorded with its reason; a run that exceeds the CPU cap (the
whole subprocess, import included: ``RLIMIT_CPU``) is recorded as "skipped: too slow"; any other
exception is recorded as a crash with the last lines of its traceback.

Only APIs present in both versions are used (``ivobs.scenarios.get/names``, ``ivobs.methods``,
``ivobs.make_estimator``, ``Estimator.run``), so the script runs unchanged against either.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import platform
import subprocess
import sys
import time
import traceback
import warnings
from pathlib import Path
from typing import Any

import numpy as np

SCRIPT = Path(__file__).resolve()
MISS_RTOL = 1e-9
CAP_CPU_S = 120
WALL_FACTOR = 8  # the wall-clock backstop, in CPU caps (a loaded machine runs slower)


# -- the records ---------------------------------------------------------------------------------


def _record_path(directory: Path, scenario: str) -> Path:
    return directory / f"{scenario}.npz"


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def make_records(directory: Path, names: list[str]) -> None:
    """Save each scenario's benchmark record as ``<dir>/<scenario>.npz`` (u, y, x, t, kind)."""
    from ivobs import scenarios

    directory.mkdir(parents=True, exist_ok=True)
    for name in names:
        sc = scenarios.get(name)
        if sc.recorded is not None:
            traj, kind = sc.recorded, "recorded"
        else:
            traj, kind = sc.simulate("vertex", seed=0), "vertex, seed 0"
        path = _record_path(directory, name)
        np.savez(
            path,
            u=np.asarray(traj.u, dtype=float),
            y=np.asarray(traj.y, dtype=float),
            x=np.asarray(traj.x, dtype=float),
            t=np.asarray(traj.t, dtype=float),
            kind=np.array(kind),
        )
        print(f"{name}: {kind}, {np.asarray(traj.y).shape[0]} steps -> {path}", file=sys.stderr)


# -- one run (in its own process) ----------------------------------------------------------------


def _tail(exc: BaseException, lines: int = 6) -> str:
    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__))
    return "\n".join(text.rstrip().splitlines()[-lines:])


def measure(lower: np.ndarray, upper: np.ndarray, x: np.ndarray) -> dict[str, Any]:
    """Mean width (NaN-safe) and the steps whose true state is outside the box."""
    width = upper - lower
    finite = width[~np.isnan(width)]
    mean = float(np.mean(finite)) if finite.size else float("nan")
    out: dict[str, Any] = {"mean_width": mean, "boxed_steps": int(np.sum(~np.isnan(width).all(1)))}
    if np.isnan(x).all():
        out["misses"] = None  # the record stores no true state
        return out
    tol = MISS_RTOL * np.maximum(1.0, np.abs(x))
    out_of_box = (x < lower - tol) | (x > upper + tol)  # NaN bounds or truth: not a miss
    out["misses"] = int(np.sum(out_of_box.any(axis=1)))
    return out


def run_one(scenario: str, method: str, records: Path, warm: bool = False) -> dict[str, Any]:
    """Run ``method`` with default options on ``scenario``'s saved record. ``warm``: also the
    CPU time of the design alone and the mean CPU time of further runs of the same estimator
    (its first-use costs — imports, compiling, caches — paid by the first run)."""
    import ivobs
    from ivobs import scenarios

    sc = scenarios.get(scenario)
    rec = np.load(_record_path(records, scenario))
    u, y, x, t = rec["u"], rec["y"], rec["x"], rec["t"]
    row: dict[str, Any] = {"scenario": scenario, "method": method, "steps": int(y.shape[0])}
    c0 = time.process_time()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        stage = "design"
        try:
            est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
            row["design_cpu_s"] = time.process_time() - c0
            stage = "run"
            tt = t if sc.system.is_continuous else None
            estimate = est.run(u, y, t=tt)
            if warm:  # repeated to at least 0.2 CPU s (at most 50 runs): the mean
                reps, c1 = 0, time.process_time()
                while reps < 50 and (reps == 0 or time.process_time() - c1 < 0.2):
                    est.run(u, y, t=tt)
                    reps += 1
                row["warm_run_cpu_s"] = (time.process_time() - c1) / reps
        except ivobs.IvobsError as exc:
            row["status"] = "refused"
            row["reason"] = f"{type(exc).__name__}: {exc}".splitlines()[0][:300]
            row["stage"] = stage
            row["cpu_s"] = time.process_time() - c0
            return row
    row["cpu_s"] = time.process_time() - c0
    row["status"] = "ok"
    row.update(measure(np.asarray(estimate.lower), np.asarray(estimate.upper), x))
    messages = sorted({str(w.message).splitlines()[0][:200] for w in caught})
    if messages:
        row["warnings"] = messages
    return row


def _child(args: argparse.Namespace) -> int:
    try:
        row = run_one(args.scenario, args.method, Path(args.records), args.warm)
    except Exception as exc:
        row = {
            "scenario": args.scenario,
            "method": args.method,
            "status": "crashed",
            "reason": f"{type(exc).__name__}: {exc}".splitlines()[0][:300],
            "traceback": _tail(exc),
        }
    print("RESULT " + json.dumps(row))
    return 0


# -- every run -----------------------------------------------------------------------------------


def _version(label: str) -> dict[str, Any]:
    import ivobs

    src = Path(ivobs.__file__).resolve().parent
    try:
        commit = subprocess.run(
            ["git", "-C", str(src), "rev-parse", "--short", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(src), "status", "--porcelain", "--", "."],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        commit, dirty = "unknown", ""
    return {
        "label": label,
        "ivobs": str(src),
        "commit": commit + ("+dirty" if dirty else ""),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "date": time.strftime("%Y-%m-%d %H:%M"),
    }


def _limit_cpu(cap: int) -> None:
    import resource

    resource.setrlimit(resource.RLIMIT_CPU, (cap, cap + 5))


def spawn(
    scenario: str, method: str, records: Path, cap: int, warm: bool = False
) -> dict[str, Any]:
    """``run_one`` in a subprocess limited to ``cap`` CPU seconds."""
    cmd = [sys.executable, str(SCRIPT), "one", scenario, method, "--records", str(records)]
    cmd += ["--warm"] if warm else []
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    base = {"scenario": scenario, "method": method}
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(
            cmd,
            capture_output=True,
            text=True,
            env=env,
            timeout=cap * WALL_FACTOR,
            preexec_fn=lambda: _limit_cpu(cap),
        )
    except subprocess.TimeoutExpired:
        return {**base, "status": "skipped", "reason": f"too slow (wall > {cap * WALL_FACTOR} s)"}
    wall = time.perf_counter() - t0
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            row: dict[str, Any] = json.loads(line[len("RESULT ") :])
            row["wall_s"] = wall
            return row
    if proc.returncode in (-24, -9):  # SIGXCPU at the soft limit, SIGKILL at the hard one
        return {**base, "status": "skipped", "reason": f"too slow (CPU > {cap} s)"}
    tail = "\n".join(proc.stderr.rstrip().splitlines()[-6:])
    return {
        **base,
        "status": "crashed",
        "reason": f"exit code {proc.returncode}",
        "traceback": tail,
    }


def _linear_only(scenario: str, method: str) -> dict[str, Any] | None:
    """The refusal ``make_estimator`` gives a linear-only method on a nonlinear scenario, found
    in this process without starting one (the same check, the same message); None otherwise."""
    from ivobs import IvobsError, NonlinearSystem, scenarios
    from ivobs.estimators import base, get

    system = scenarios.get(scenario).system
    if not isinstance(system, NonlinearSystem) or get(method).supports_nonlinear:
        return None
    try:
        base.check_system(get(method), system)  # refuses it first
    except IvobsError as e:
        reason = f"IvobsError: {e}"
    else:
        return None
    return {
        "scenario": scenario,
        "method": method,
        "status": "refused",
        "reason": reason,
        "stage": "design",
    }


def _dump(meta: dict[str, Any], rows: list[dict[str, Any]]) -> str:
    """The result file: JSON, one line per row."""
    body = ",\n".join(json.dumps(r) for r in rows)
    return f'{{"meta": {json.dumps(meta)},\n"rows": [\n{body}\n]}}\n'


def run_all(args: argparse.Namespace) -> int:
    from ivobs import methods, scenarios

    records = Path(args.records).resolve()
    names = args.scenarios.split(",") if args.scenarios else scenarios.names()
    meths = args.methods.split(",") if args.methods else methods()
    out = Path(args.out)
    done: dict[tuple[str, str], dict[str, Any]] = {}
    if args.resume and out.exists():
        again = {"crashed", "skipped"} if args.rerun_skipped else {"crashed"}
        for row in json.loads(out.read_text())["rows"]:
            if row["status"] not in again:
                done[(row["scenario"], row["method"])] = row
    meta = _version(args.label)
    meta["cap_cpu_s"] = args.cap
    meta["records"] = {
        n: _sha256(_record_path(records, n)) for n in names if _record_path(records, n).exists()
    }
    rows: list[dict[str, Any]] = []
    for name in names:
        if not _record_path(records, name).exists():
            sys.exit(f"no record for {name!r} in {records}: run the 'records' mode first")
        for method in meths:
            row = done.get((name, method)) or _linear_only(name, method)
            if row is None:
                row = spawn(name, method, records, args.cap, args.warm)
            rows.append(row)
            done.pop((name, method), None)
            shown = row.get("mean_width", row.get("reason", ""))
            cpu = row.get("cpu_s")
            print(
                f"{name:18s} {method:24s} {row['status']:8s} {shown}"
                + (f"  [{cpu:.1f} CPU s]" if cpu is not None else ""),
                file=sys.stderr,
                flush=True,
            )
            out.parent.mkdir(parents=True, exist_ok=True)
            kept = rows + list(done.values())  # an interrupted resume loses nothing
            out.write_text(_dump(meta, kept))
    return 0


# -- the table -----------------------------------------------------------------------------------

TOL = 0.01  # issue 29: within 1 % of 2cc24ba's mean width, or tighter
SAME = 1e-6  # a relative change below this is rounding: "same", not "tighter"


def _fmt(v: float | None) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "–"
    if math.isinf(v):
        return "inf"
    return f"{v:.6g}"


def verdict(base: dict[str, Any] | None, head: dict[str, Any]) -> tuple[str, float | None]:
    """(verdict, ratio now/base) of one row."""
    hs = head["status"]
    bs = base["status"] if base else "absent"
    if hs == "crashed":
        return "**CRASH now**" + (" (ran at base)" if bs == "ok" else ""), None
    if hs == "refused" and bs == "refused":
        return "refused in both", None
    if hs == "skipped" and bs == "skipped":
        return "skipped in both: too slow", None
    if hs == "skipped":
        return "skipped now: too slow" + (" (ran at base)" if bs == "ok" else ""), None
    if hs == "refused":
        return "refused now" + (" (ran at base)" if bs == "ok" else f" (base: {bs})"), None
    if bs != "ok":
        return f"runs now (base: {bs})", None
    wb, wh = float(base["mean_width"]), float(head["mean_width"])  # type: ignore[index]
    if math.isnan(wb) or math.isnan(wh):
        return "no box in one version", None
    if math.isinf(wb) or math.isinf(wh):
        if wb == wh:
            return "within 1 % (both inf)", None
        return ("tighter (base inf)" if math.isinf(wb) else "**LOOSER** (inf now)"), None
    ratio = wh / wb if wb > 0 else (1.0 if wh == wb else math.inf)
    if abs(ratio - 1) <= SAME:
        return "within 1 % (same)", ratio
    if ratio < 1:
        return "tighter", ratio
    if ratio <= 1 + TOL:
        return "within 1 %", ratio
    return f"**LOOSER by {100 * (ratio - 1):.1f} %**", ratio


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def compare(args: argparse.Namespace) -> int:
    b = json.loads(Path(args.base).read_text())
    h = json.loads(Path(args.head).read_text())
    base_rows = {(r["scenario"], r["method"]): r for r in b["rows"]}
    differ = [
        n
        for n, digest in h["meta"]["records"].items()
        if b["meta"]["records"].get(n, digest) != digest
    ]
    if differ:
        sys.exit(f"the two runs read different records for {', '.join(differ)}")
    lines = [
        f"| scenario | method | mean width at {b['meta']['label']} | now ({h['meta']['label']}) "
        "| now/base | "
        "misses now (base) | CPU s base → now | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    counts: dict[str, int] = {}
    notes: list[str] = []
    scenario_order = {n: i for i, n in enumerate(h["meta"]["records"])}
    method_order: dict[str, int] = {}
    for r in h["rows"]:
        method_order.setdefault(r["method"], len(method_order))
    ordered = sorted(
        h["rows"], key=lambda r: (scenario_order.get(r["scenario"], 999), method_order[r["method"]])
    )
    for hr in ordered:
        key = (hr["scenario"], hr["method"])
        br = base_rows.get(key)
        if hr["status"] == "refused" and br is not None and br["status"] == "refused":
            counts["refused in both"] = counts.get("refused in both", 0) + 1
            if not args.all:
                continue
        text, ratio = verdict(br, hr)
        bucket = text.split(" (")[0].replace("*", "")
        bucket = "LOOSER" if bucket.startswith("LOOSER") else bucket
        counts[bucket] = counts.get(bucket, 0) + 1
        wb = br.get("mean_width") if br and br["status"] == "ok" else None
        wh = hr.get("mean_width") if hr["status"] == "ok" else None
        if wb is None and br is not None and br["status"] != "ok":
            wb_text = br["status"]
        else:
            wb_text = _fmt(wb)
        wh_text = _fmt(wh) if hr["status"] == "ok" else hr["status"]
        miss_now = hr.get("misses")
        miss_base = br.get("misses") if br else None
        misses = "n/a" if hr["status"] == "ok" and miss_now is None else _fmt(miss_now)
        if miss_base is not None:
            misses += f" ({miss_base})"
        cpu_b = br.get("cpu_s") if br else None
        cpu_h = hr.get("cpu_s")
        cpu = " → ".join("–" if c is None else f"{c:.2f}" for c in (cpu_b, cpu_h))
        ratio_text = "–" if ratio is None else f"{ratio:.4f}"
        lines.append(
            f"| {key[0]} | {key[1]} | {wb_text} | {wh_text} | {ratio_text} | {misses} | {cpu} "
            f"| {_cell(text)} |"
        )
        # only what the table's cells cannot say: why a run has no width
        why = {
            when: f"{r['status']}: {_cell(r.get('traceback') or r.get('reason', ''))}"
            for r, when in ((br, "base"), (hr, "now"))
            if r is not None and r["status"] != "ok" and text != "refused in both"
        }
        if len(why) == 2 and why["base"] == why["now"]:
            why = {"both": why["now"]}
        notes += [f"- {key[0]} / {key[1]} ({when}) {detail}" for when, detail in why.items()]
    summary = ", ".join(f"{k}: {v}" for k, v in sorted(counts.items()))
    text = "\n".join(lines) + f"\n\nRows by verdict — {summary}.\n"
    if notes:
        text += "\n" + "\n".join(notes) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    print(text)
    return 0


SPEED_TOL = 1.25  # issue 29: every speed figure within 25 % of 2cc24ba's, or faster


def speed(args: argparse.Namespace) -> int:
    """The Markdown table of the warm runs' speeds (``run --warm``) of two result files: steps
    per CPU-second of the repeated runs (the verdict), and the first design's CPU time."""
    base = {
        (r["scenario"], r["method"]): r for r in json.loads(Path(args.base).read_text())["rows"]
    }
    head = json.loads(Path(args.head).read_text())["rows"]
    lines = [
        "| scenario | method | steps | run steps/s before | now | ratio "
        "| first design s before | now | verdict |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    counts: dict[str, int] = {}
    for h in head:
        b = base.get((h["scenario"], h["method"]))
        if b is None or "warm_run_cpu_s" not in h or "warm_run_cpu_s" not in b:
            continue
        n = h["steps"]
        rb = n / max(b["warm_run_cpu_s"], 1e-9)
        rh = n / max(h["warm_run_cpu_s"], 1e-9)
        # the verdict is the warm run's (steady-state) speed; the first design's CPU time, which
        # also carries the process's first-use imports and compiling, is shown beside it
        if rh * SPEED_TOL < rb:
            verdict = "**SLOWER**"
        else:
            verdict = "faster" if rh > rb * SPEED_TOL else "within 25 %"
        counts[verdict] = counts.get(verdict, 0) + 1
        lines.append(
            f"| {h['scenario']} | {h['method']} | {n} | {rb:,.0f} | {rh:,.0f} | {rb / rh:.2f} | "
            f"{b['design_cpu_s']:.3f} | {h['design_cpu_s']:.3f} | {verdict} |"
        )
    text = "\n".join(lines) + "\n\n" + ", ".join(f"{k}: {v}" for k, v in counts.items()) + "\n"
    if args.out:
        Path(args.out).write_text(text)
    print(text)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="mode", required=True)
    r = sub.add_parser("records", help="save each scenario's record (current code)")
    r.add_argument("--dir", default="/tmp/widths_records")
    r.add_argument("--scenarios", default=None, help="comma-separated (default: every one)")
    a = sub.add_parser("run", help="every (scenario, method), one CPU-capped process each")
    a.add_argument("--records", default="/tmp/widths_records")
    a.add_argument("--label", required=True, help="the version's name in the table")
    a.add_argument("--out", required=True)
    a.add_argument("--scenarios", default=None)
    a.add_argument("--methods", default=None)
    a.add_argument("--cap", type=int, default=CAP_CPU_S, help="CPU seconds per run")
    a.add_argument("--resume", action="store_true", help="keep the rows of --out but crashes")
    a.add_argument("--rerun-skipped", action="store_true", help="with --resume: rerun skips")
    a.add_argument("--warm", action="store_true", help="also time a second run (speed mode)")
    o = sub.add_parser("one", help="one run, printed as a RESULT line (used by 'run')")
    o.add_argument("scenario")
    o.add_argument("method")
    o.add_argument("--records", default="/tmp/widths_records")
    o.add_argument("--warm", action="store_true")
    c = sub.add_parser("compare", help="the Markdown table of two result files")
    c.add_argument("base")
    c.add_argument("head")
    c.add_argument("--out", default=None)
    c.add_argument("--all", action="store_true", help="also the rows refused in both")
    v = sub.add_parser("speed", help="the speed table of two 'run --warm' result files")
    v.add_argument("base")
    v.add_argument("head")
    v.add_argument("--out", default=None)
    args = p.parse_args(argv)
    if args.mode == "speed":
        return speed(args)
    if args.mode == "records":
        from ivobs import scenarios

        names = args.scenarios.split(",") if args.scenarios else scenarios.names()
        make_records(Path(args.dir), names)
        return 0
    if args.mode == "one":
        return _child(args)
    if args.mode == "run":
        return run_all(args)
    return compare(args)


if __name__ == "__main__":
    sys.exit(main())
