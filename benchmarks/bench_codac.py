"""``nl-interval`` against a codac contractor network over the last 1 and 3 steps (issue 30
item 4).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_codac.py [--codac-python PATH]
        [--scenarios a,b] [--windows 1,3] [--network joint|split] [--gain 0.01] [--repeats 3]

codac (``pip install codac``, an optional dependency of this benchmark only) is imported in a
process of its own, never in this one: codac 2.1 switches the whole process to upward rounding
on import. That process is ``--codac-python`` (default: ``$IVOBS_CODAC_PYTHON``, else this
interpreter) running this file with ``--worker DIR``; it needs numpy and codac, not ivobs. The
two processes exchange JSON and ``.npz`` files in a temporary folder (no pickled code).

For each scenario (``henon-nl``, ``cora-tank6-nl``, ``pendulum-nl``, ``cstr``: explicit
discrete-time maps, the Euler step written in their expressions, so codac gets the very model
ivobs estimates), on ``sc.simulate("vertex", seed=0)``:

- ivobs: ``nl-interval`` over the record; CPU time per step (best of ``--repeats`` runs);
- codac, for each window ``N`` and each step ``k >= max(windows)``: the unknowns ``x[k-N..k]``
  and ``w[k-N..k]`` (per-step unknown parameters and signals, as ivobs' ``w``), ``x[k-N]`` in
  ``nl-interval``'s box of step ``k-N`` (the information ivobs had then), ``w[j]`` in ``[w]``,
  the equations ``x[j+1] = f(x[j], u[j], w[j])`` and ``h(x[j], u[j], w[j]) ∈ [y_j]`` for
  ``j = k-N..k``, with ``[y_j] = [down(y_j), up(y_j)]`` as in ivobs. The model's expressions
  are exported from ivobs' SymPy trees with every constant enclosed as ivobs encloses it
  (``0.3`` is the hull of the double and 3/10). The network (``--network``): ``joint``, one
  ``CtcInverse`` of the vector of all equations (HC4-revise on the DAG and the centred form),
  or ``split``, one ``CtcInverse`` per equation intersected (``CtcInter``); contracted until a
  sweep narrows no ``x[j]`` component by ``--gain`` of its width (ivobs' rule; at most
  50 sweeps). CPU time per step: the contraction (box building included, the network is built
  once per window).

Printed: per scenario and method, the mean width over the steps ``k >= max(windows)`` (each
state, and the mean over states), the mean over steps and states of ``nl-interval / codac``
widths (and its largest), the CPU ms per step, and the steps whose box misses the true state of
the record (float64 simulation: a miss below 1e-9 relative would be rounding of the simulator,
reported apart).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

SCENARIOS = ["henon-nl", "cora-tank6-nl", "pendulum-nl", "cstr"]
MAX_SWEEPS = 50
VEC_MAX = 10
"""Most components of one codac vector function (codac 2.1.2's Python binding segfaults on a
list of 11 or more scalar expressions): a larger window is split into such blocks."""
FUNCS = {"sin", "cos", "tan", "exp", "log", "sqrt", "tanh", "sinh", "cosh", "atan", "asin", "acos"}


# -- ivobs side (never imports codac) ---------------------------------------------------------
def _tree(e: Any, index: dict[Any, list[Any]]) -> list[Any]:
    """A JSON tree of the SymPy expression ``e``: ``["v", group, i]`` a variable, ``["c", lo,
    hi]`` a constant (ivobs' enclosure), ``[op, *args]`` otherwise."""
    import sympy as sp

    from ivobs.model.nonlinear.codegen import enclose_constant

    if e in index:
        return index[e]
    if not e.free_symbols:
        lo, hi = enclose_constant(e)
        return ["c", lo, hi]
    args = [_tree(a, index) for a in e.args]
    if e.is_Add:
        return ["+", *args]
    if e.is_Mul:
        return ["*", *args]
    if e.is_Pow:
        ex = e.args[1]
        if ex.is_Integer:
            return ["pow", args[0], int(ex)]
        if ex == sp.Rational(1, 2):
            return ["sqrt", args[0]]
        if ex == sp.Rational(-1, 2):
            return ["/", ["c", 1.0, 1.0], ["sqrt", args[0]]]
        return ["exp", ["*", args[1], ["log", args[0]]]]
    name = e.func.__name__.lower()
    if name in FUNCS | {"abs", "min", "max"}:
        return [name, *args]
    raise SystemExit(f"bench_codac: cannot export {e!r} ({type(e).__name__}) to codac")


def export_model(sys_: Any) -> dict[str, Any]:
    """The scenario's f and h as trees over ``x``, ``u``, ``w`` (ivobs' order), known
    parameters replaced by ivobs' enclosure of their value."""
    from ivobs.model.nonlinear.codegen import enclose_float

    index: dict[Any, list[Any]] = {}
    for group, names in (
        ("x", sys_.state_names),
        ("u", sys_.input_names),
        ("w", sys_.param_names + sys_.signal_names),
    ):
        for i, n in enumerate(names):
            index[sys_._sym[n]] = ["v", group, i]
    for n, v in sys_.known_params.items():
        lo, hi = enclose_float(v)
        index[sys_._sym[n]] = ["c", lo, hi]
    return {
        "nx": sys_.nx,
        "nu": sys_.nu,
        "nw": sys_.nw,
        "ny": sys_.ny,
        "f": [_tree(e, index) for e in sys_.f_exprs],
        "h": [_tree(e, index) for e in sys_.h_exprs],
        "w_lo": sys_.w_box.lo.tolist(),
        "w_hi": sys_.w_box.hi.tolist(),
    }


def run_ivobs(name: str, repeats: int, lag: int = 1, window: int | None = None) -> dict[str, Any]:
    import ivobs
    from ivobs.estimators.nonlinear.meanvalue import measurement

    sc = ivobs.scenarios.get(name)
    if not sc.system.is_discrete:
        raise SystemExit(f"bench_codac: {name} is continuous-time (a validated flow): not compared")
    tr = sc.simulate("vertex", seed=0)
    cpu = math.inf
    for _ in range(repeats):
        est = ivobs.make_estimator("nl-interval", sc.system, x0=sc.x0, lag=lag, window=window)
        c0 = time.process_time()
        res = est.run(tr.u, tr.y)
        cpu = min(cpu, time.process_time() - c0)
    ylo, yhi = zip(*(measurement(np.asarray(y, dtype=float)) for y in tr.y), strict=True)
    return {
        "model": export_model(sc.system),
        "u": np.asarray(tr.u, dtype=float).reshape(tr.y.shape[0], -1),
        "ylo": np.array(ylo, dtype=float),
        "yhi": np.array(yhi, dtype=float),
        "lo": np.asarray(res.lower, dtype=float),
        "hi": np.asarray(res.upper, dtype=float),
        "x": np.asarray(tr.x, dtype=float),
        "cpu": cpu / tr.y.shape[0],
    }


def _codac_version(exe: str) -> str:
    """codac's version in the interpreter ``exe``; exits with what to do when it has none."""
    probe = subprocess.run(
        [exe, "-c", "import codac, numpy; print(codac.__version__)"],
        capture_output=True,
        text=True,
        check=False,
    )
    if probe.returncode != 0:
        why = (probe.stderr.strip().splitlines() or ["no message"])[-1]
        raise SystemExit(
            f"bench_codac: codac is not installed for {exe} ({why}). It is an optional "
            "dependency of this benchmark only: install it in a venv of its own (python3.11 -m "
            "venv DIR; DIR/bin/pip install codac numpy) and pass --codac-python DIR/bin/python "
            "or set IVOBS_CODAC_PYTHON."
        )
    return probe.stdout.strip()


def _misses(lo: np.ndarray, hi: np.ndarray, x: np.ndarray) -> tuple[int, int]:
    """Steps whose box misses ``x`` at all, and by more than 1e-9 relative."""
    out = (x < lo) | (x > hi)
    tol = 1e-9 * (1.0 + np.abs(x))
    far = (x < lo - tol) | (x > hi + tol)
    return int(np.any(out, axis=1).sum()), int(np.any(far, axis=1).sum())


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--codac-python", default=None)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--windows", default="1,3")
    ap.add_argument("--network", choices=["joint", "split"], default="joint")
    ap.add_argument("--gain", type=float, default=0.01)
    ap.add_argument("--no-centred", action="store_true", help="CtcInverse without centred form")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--dump", help="save every step's boxes to this .npz")
    ap.add_argument("--lag", type=int, default=1, help="nl-interval's window (steps back)")
    ap.add_argument(
        "--window",
        type=int,
        default=None,
        help="nl-interval's window-centred form (steps; default: the method's)",
    )
    a = ap.parse_args(argv)
    if a.worker:
        worker(Path(a.worker))
        return
    exe = a.codac_python or os.environ.get("IVOBS_CODAC_PYTHON") or sys.executable
    version = _codac_version(exe)
    windows = [int(v) for v in a.windows.split(",")]
    first = max(windows)
    centred = "without" if a.no_centred else "with"
    print(
        f"codac {version} ({exe}), network {a.network} {centred} centred form, gain {a.gain}, "
        f"windows {windows}, nl-interval lag {a.lag}, window {a.window}"
    )
    rows = []
    dump: dict[str, np.ndarray] = {}
    with tempfile.TemporaryDirectory(prefix="bench_codac_") as tmp:
        d = Path(tmp)
        for name in a.scenarios.split(","):
            iv = run_ivobs(name, a.repeats, a.lag, a.window)
            np.savez(
                d / "in.npz",
                **{k: iv[k] for k in ("u", "ylo", "yhi", "lo", "hi")},
            )
            job = {
                "model": iv["model"],
                "windows": windows,
                "first": first,
                "network": a.network,
                "centred": not a.no_centred,
                "gain": a.gain,
                "repeats": a.repeats,
            }
            (d / "job.json").write_text(json.dumps(job))
            subprocess.run([exe, str(Path(__file__).resolve()), "--worker", tmp], check=True)
            out = np.load(d / "out.npz")
            dump.update({f"{name}/{k}": iv[k] for k in ("lo", "hi", "x")})
            dump.update({f"{name}/codac_{k}": out[k] for k in out.files})
            x = iv["x"][first:]
            wi = (iv["hi"] - iv["lo"])[first:]
            mi = _misses(iv["lo"][first:], iv["hi"][first:], x)
            rows.append((name, "nl-interval", wi, None, iv["cpu"], mi, None))
            for n in windows:
                lo, hi = out[f"lo{n}"][first:], out[f"hi{n}"][first:]
                wc = hi - lo
                with np.errstate(divide="ignore", invalid="ignore"):
                    r = wi.mean(axis=0) / wc.mean(axis=0)
                # steps where nl-interval is wider by more than 1 % (and than rounding)
                worse = wi > 1.01 * wc + 1e-12 * (1.0 + np.abs(x))
                sweeps = float(out[f"sweeps{n}"][first:].mean())
                cpu_c = float(out[f"cpu{n}"][first:].mean())
                m = _misses(lo, hi, x)
                rows.append((name, f"codac {n}-step", wc, (r, worse), cpu_c, m, sweeps))
    if a.dump:
        np.savez(a.dump, **dump)
    print()
    print(
        "| scenario | method | steps | mean width per state | mean width | nl-interval / "
        "method, mean width: mean over states (max) | steps nl-interval wider by > 1 % | "
        "CPU ms/step | sweeps | misses (> 1e-9) |"
    )
    print("|---|---|---:|---|---:|---:|---:|---:|---:|---:|")
    for name, meth, w, cmp, cpu, (m0, m1), sweeps in rows:
        per = ", ".join(f"{v:.4g}" for v in w.mean(axis=0))
        ratio = worse = sw = ""
        if cmp is not None:
            ratio = f"{cmp[0].mean():.3f} ({cmp[0].max():.3f})"
            worse = f"{int(np.any(cmp[1], axis=1).sum())}"
            sw = f"{sweeps:.1f}"
        print(
            f"| `{name}` | {meth} | {w.shape[0]} | {per} | {w.mean():.4g} | {ratio} | {worse} | "
            f"{1e3 * cpu:.3f} | {sw} | {m0} ({m1}) |"
        )


# -- codac side (never imports ivobs) ---------------------------------------------------------
def _expr(t: list[Any], env: dict[str, list[Any]], c: Any) -> Any:
    op = t[0]
    if op == "v":
        return env[t[1]][t[2]]
    if op == "c":
        return c.Interval(t[1], t[2])
    args = [_expr(s, env, c) for s in t[1:]] if op != "pow" else [_expr(t[1], env, c)]
    if op == "+":
        out = args[0]
        for s in args[1:]:
            out = out + s
        return out
    if op == "*":
        out = args[0]
        for s in args[1:]:
            out = out * s
        return out
    if op == "/":
        return args[0] / args[1]
    if op == "pow":
        n = t[2]
        p = c.sqr(args[0]) if abs(n) == 2 else args[0] if abs(n) == 1 else c.pow(args[0], abs(n))
        return p if n > 0 else c.Interval(1.0, 1.0) / p
    if op in ("min", "max"):
        out = args[0]
        for s in args[1:]:
            out = getattr(c, op)(out, s)
        return out
    return getattr(c, op)(args[0])


def _network(model: dict[str, Any], n: int, kind: str, centred: bool, c: Any) -> tuple[Any, int]:
    """The contractor of the window of ``n`` steps on ``z = (x_j, w_j, u_j, y_j)_{j=0..n}``
    and the size of one step's block."""
    nx, nu, nw, ny = model["nx"], model["nu"], model["nw"], model["ny"]
    blk = nx + nw + nu + ny
    Z = c.VectorVar((n + 1) * blk)

    def env(j: int) -> dict[str, list[Any]]:
        o = j * blk
        return {
            "x": [Z[o + i] for i in range(nx)],
            "w": [Z[o + nx + i] for i in range(nw)],
            "u": [Z[o + nx + nw + i] for i in range(nu)],
            "y": [Z[o + nx + nw + nu + i] for i in range(ny)],
        }

    eqs = []
    for j in range(n + 1):
        e = env(j)
        if j < n:
            nxt = env(j + 1)
            eqs += [nxt["x"][i] - _expr(t, e, c) for i, t in enumerate(model["f"])]
        eqs += [_expr(t, e, c) - e["y"][i] for i, t in enumerate(model["h"])]
    if kind == "joint":  # codac 2.1.2's binding crashes on a vector of more than 10 terms
        parts = [
            c.CtcInverse(
                c.AnalyticFunction([Z], eqs[i : i + VEC_MAX]),
                c.IntervalVector([[0.0, 0.0]] * len(eqs[i : i + VEC_MAX])),
                centred,
            )
            for i in range(0, len(eqs), VEC_MAX)
        ]
    else:
        zero = c.Interval(0.0, 0.0)
        parts = [c.CtcInverse(c.AnalyticFunction([Z], e), zero, centred) for e in eqs]
    ctc = parts[0]
    for p in parts[1:]:
        ctc = ctc & p
    return ctc, blk


def worker(d: Path) -> None:
    try:
        import codac as c
    except ImportError as exc:  # _codac_version checked it; a clear message all the same
        raise SystemExit(f"bench_codac worker: codac is not installed ({exc})") from exc
    job = json.loads((d / "job.json").read_text())
    data = np.load(d / "in.npz")
    model = job["model"]
    nx, nu, nw, ny = model["nx"], model["nu"], model["nw"], model["ny"]
    u, ylo, yhi, plo, phi = (data[k] for k in ("u", "ylo", "yhi", "lo", "hi"))
    T = ylo.shape[0]
    out: dict[str, np.ndarray] = {}
    for n in job["windows"]:
        ctc, blk = _network(model, n, job["network"], job["centred"], c)
        xs = [j * blk + i for j in range(n + 1) for i in range(nx)]
        lo, hi = np.full((T, nx), np.nan), np.full((T, nx), np.nan)
        cpu, sweeps = np.full(T, np.nan), np.zeros(T)
        for k in range(job["first"], T):
            best = math.inf
            for _ in range(job["repeats"]):
                c0 = time.process_time()
                bounds = []
                for j in range(n + 1):
                    s = k - n + j
                    xb = (
                        [[plo[s, i], phi[s, i]] for i in range(nx)]
                        if j == 0
                        else [[-math.inf, math.inf]] * nx
                    )
                    wb = [[model["w_lo"][i], model["w_hi"][i]] for i in range(nw)]
                    ub = [[u[s, i], u[s, i]] for i in range(nu)]
                    yb = [
                        [ylo[s, i], yhi[s, i]] if ylo[s, i] == ylo[s, i] else [-math.inf, math.inf]
                        for i in range(ny)
                    ]
                    bounds += xb + wb + ub + yb
                box = c.IntervalVector(bounds)
                count = 0
                while count < MAX_SWEEPS:  # until no x[j] narrows by gain of its width
                    before = [box[i].diam() for i in xs]
                    ctc.contract(box)
                    count += 1
                    if box.is_empty() or not any(
                        box[i].diam() < (1.0 - job["gain"]) * w for i, w in zip(xs, before)
                    ):
                        break
                best = min(best, time.process_time() - c0)
            if box.is_empty():
                raise SystemExit(f"bench_codac worker: window {n}, step {k}: empty box")
            o = n * blk
            lo[k] = [box[o + i].lb() for i in range(nx)]
            hi[k] = [box[o + i].ub() for i in range(nx)]
            cpu[k], sweeps[k] = best, count
        out[f"lo{n}"], out[f"hi{n}"], out[f"cpu{n}"], out[f"sweeps{n}"] = lo, hi, cpu, sweeps
    np.savez(d / "out.npz", **out)


if __name__ == "__main__":
    main()
