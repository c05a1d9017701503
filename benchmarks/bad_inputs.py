"""Re-run the families of bad input of the data-integrity audit and count the outcomes.

Each case runs in a forked process (at most 10 s of CPU time and 6 GB of memory) and ends as
one of: ``error`` (a clear ``IvobsError``, or exit status 2 with ``ivobs: error:``),
``accepted`` (and an oracle written here says the result is right), ``silent`` (accepted, but
the oracle says it is wrong: a box that misses the true state, a false alarm, an input
overwritten, a state of another plant taken, a hang-free bomb that still ran), ``traceback``
(any other exception) or ``hang`` (killed after 10 s of CPU time). The goal: 0 silent, 0
tracebacks, 0 hangs.

The families (issue "data integrity and hostile input"): 1. gaps and offsets in a log's step
column; 2. ``compare`` outputs over its inputs; 3. a campaign's outputs over its plant files;
4. monitor state files (two monitors, another plant, no stream entry, ``stream.step =
10**9``, the exit status after a restart); 5. compute bombs in expressions and campaign specs;
6. ``numpy.ma`` masks; 7. tracebacks (full disk, TOML integers and nesting, JSON nesting, NumPy
option values, ``u = 1e308``, 128 KiB fields, ``dual-window(cache=10**12)``, ``k = 10**30``);
8. smaller (NFKC names, other scripts' digits, ``-nan``, byte-order marks, quoted files).

Run with the sources to test first on the path::

    PYTHONPATH=src python benchmarks/bad_inputs.py            # this tree
    PYTHONPATH=/path/to/old/src python benchmarks/bad_inputs.py   # another version

It works with versions that lack the newer features (a feature missing is an error or a
traceback there, as it would be for a user).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import io
import json
import multiprocessing
import os
import resource
import shutil
import sys
import tempfile
import time
import traceback
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import ivobs
from ivobs import IvobsError

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from signplant import contains, plant, simulate  # the log-integrity tests' plant

CPU_LIMIT = 10  # seconds of CPU time: beyond it, a hang
MEMORY_LIMIT = 6 << 30


class Silent(Exception):
    """An input accepted with a wrong result (what the oracle found)."""


def cli(*argv: Any) -> tuple[int, str, str]:
    """``ivobs ARGV`` in this process: exit status, standard output and error."""
    from ivobs.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, out.getvalue(), err.getvalue()


def expect_refusal(code: int, err: str) -> None:
    """A CLI case that must be refused: exit 2 with a clear error, else it was taken."""
    if code == 2 and "ivobs: error:" in err:
        raise IvobsError(err.strip())
    raise Silent(f"accepted (exit {code})")


# -- the child -----------------------------------------------------------------------------
def _run(conn: Any, case: Callable[[Path], None], folder: str) -> None:
    resource.setrlimit(resource.RLIMIT_CPU, (CPU_LIMIT, CPU_LIMIT + 1))
    with contextlib.suppress(ValueError, OSError):
        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    try:
        case(Path(folder))
        conn.send(("accepted", ""))
    except IvobsError as exc:
        conn.send(("error", str(exc)[:300]))
    except Silent as exc:
        conn.send(("silent", str(exc)[:300]))
    except BaseException as exc:
        tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
        conn.send(("traceback", tb[:300]))


def outcome(case: Callable[[Path], None]) -> tuple[str, str]:
    folder = tempfile.mkdtemp(prefix="ivobs-bad-")
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_run, args=(child, case, folder))
    proc.start()
    child.close()
    try:
        if parent.poll(600):  # wall time: a backstop only (the machine may be loaded)
            with contextlib.suppress(EOFError):
                return parent.recv()
        return "hang", "no answer"
    finally:
        proc.kill()
        proc.join()
        shutil.rmtree(folder, ignore_errors=True)


# -- shared models -------------------------------------------------------------------------
T = 60


def servo_files(folder: Path, horizon: int = 80, seed: int = 3) -> tuple[Any, Any]:
    from ivobs.io import save_system, write_log

    sc = ivobs.scenarios.get("servo-motor", horizon=horizon)
    tr = sc.simulate("vertex", seed=seed)
    save_system(folder / "s.toml", sc, method="interval-split")
    write_log(folder / "log.csv", tr.u, tr.y)
    return sc, tr


# -- 1. the step column -----------------------------------------------------------------------
def log_cases() -> list[tuple[str, Callable[[Path], None]]]:
    cases = []
    for seed in range(5):
        for drop in ([30], [10, 11], [45, 46, 47, 48], [25, 50]):
            for method in ("interval-split", "zonotope", "fixed-time", "reachability"):
                for how in ("run", "check", "cli"):

                    def case(folder: Path, seed=seed, drop=drop, method=method, how=how) -> None:
                        from ivobs.io import read_log, save_system
                        from ivobs.monitor import Monitor

                        sys, x0 = plant(seed)
                        xs, y = simulate(sys, seed, T)
                        keep = [k for k in range(T) if k not in drop]
                        path = folder / "l.csv"
                        lines = ["k,y1", *(f"{k},{float(y[k, 0])!r}" for k in keep)]
                        path.write_text("\n".join(lines) + "\n")
                        if how == "cli":
                            save_system(folder / "p.toml", sys, x0=x0, method=method)
                            code, out, err = cli("monitor", "-s", folder / "p.toml", "-i", path)
                            if code == 2:
                                raise IvobsError(err)
                            rows = [r.split(",") for r in out.splitlines()[1:]]
                            steps = [int(r[0]) for r in rows]
                            lo = np.array([[float(r[1]), float(r[2])] for r in rows])
                            hi = np.array([[float(r[3]), float(r[4])] for r in rows])
                            alarms = sum(r[5] == "1" for r in rows)
                        else:
                            log = read_log(path, sys)
                            est = ivobs.make_estimator(method, sys, x0=x0)
                            res = est.run(log.u, log.y)
                            lo, hi = res.lower, res.upper
                            steps = list(log.steps)
                            alarms = 0
                            if how == "check":
                                alarms = int(
                                    Monitor(sys, est, x0=x0).check(log.u, log.y).alarm.sum()
                                )
                        if not contains(lo, hi, xs, steps, missing_ok=True):
                            raise Silent("a box misses the true state at its step")
                        if alarms:
                            raise Silent(f"{alarms} false alarms")

                    cases.append((f"gap {drop} {method} {how} seed {seed}", case))
    for start in (1, 5, 1000):

        def offset(folder: Path, start=start) -> None:
            from ivobs.io import read_log

            sys, _ = plant(0)
            _xs, y = simulate(sys, 0, T)
            path = folder / "l.csv"
            path.write_text("k,y1\n" + "".join(f"{start + k},{y[k, 0]!r}\n" for k in range(T)))
            read_log(path, sys)
            raise Silent(f"a log starting at step {start} was given the prior of x[0]")

        cases.append((f"offset start {start}", offset))

    def servo_gap(folder: Path) -> None:
        _sc, _tr = servo_files(folder)
        lines = (folder / "log.csv").read_text().splitlines()
        (folder / "gap.csv").write_text("\n".join(lines[:41] + lines[61:]) + "\n")
        code, out, err = cli("run", "-s", folder / "s.toml", "-l", folder / "gap.csv")
        if code == 2:
            raise IvobsError(err)
        if "ALARMS" in out:
            raise Silent("false alarms after the gap")
        raise Silent("the gap's inputs were invented")

    cases.append(("servo rows 40-59 removed", servo_gap))
    return cases


# -- 2, 3. outputs over inputs ------------------------------------------------------------------
def output_cases() -> list[tuple[str, Callable[[Path], None]]]:
    cases = []
    for option, target in (("--json", "log.csv"), ("--html", "s.toml"), ("--plot", "s.png"),
                           ("--json", "link.csv"), ("--html", "hard.toml")):  # fmt: skip

        def compare(folder: Path, option=option, target=target) -> None:
            servo_files(folder, 40)
            os.symlink(folder / "log.csv", folder / "link.csv")
            os.link(folder / "s.toml", folder / "hard.toml")
            (folder / "s.png").write_bytes(b"x")
            before = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
            argv = ["compare", "-s", folder / "s.toml", "-l", folder / "log.csv"]
            if target == "s.png":  # the log named s.png: an input the figure would replace
                argv = ["compare", "-s", folder / "s.toml", "-l", folder / "s.png"]
            code, _, err = cli(*argv, "--methods", "interval-split", option, folder / target)
            after = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
            if code == 2:
                if any(after.get(k) != v for k, v in before.items()):
                    raise Silent("refused, but an input was changed")
                raise IvobsError(err)
            if any(after.get(k) != v for k, v in before.items()):
                raise Silent(f"{option} overwrote {target}")

        cases.append((f"compare {option} {target}", compare))
    for key in ("summary", "output"):
        for target in ("p.toml", "spec.toml"):

            def spec(folder: Path, key=key, target=target) -> None:
                servo_files(folder, 30)
                os.rename(folder / "s.toml", folder / "p.toml")
                text = 'scenarios = ["servo-motor", "p.toml"]\nmethods = ["interval-split"]\n'
                (folder / "spec.toml").write_text(text + f'horizon = 20\n{key} = "{target}"\n')
                before = (folder / target).read_bytes()
                code, _, err = cli("campaign", folder / "spec.toml", "--workers", "0", "-q")
                if (folder / target).read_bytes() != before:
                    raise Silent(f"the campaign's {key} overwrote {target}")
                if code == 2:
                    raise IvobsError(err)

            cases.append((f"campaign {key} = {target}", spec))
    return cases


# -- 4. monitor state files ---------------------------------------------------------------------
def state_cases() -> list[tuple[str, Callable[[Path], None]]]:
    def prepared(folder: Path) -> tuple[Any, list[str]]:
        sc, tr = servo_files(folder, 80, 6)
        y = tr.y.copy()
        y[15:25, 1] += 0.6
        from ivobs.io import write_log

        write_log(folder / "log.csv", tr.u, y)
        lines = (folder / "log.csv").read_text().splitlines(keepends=True)
        (folder / "head.csv").write_text("".join(lines[:41]))
        argv = ["monitor", "-s", folder / "s.toml", "--state", folder / "st.json"]
        cli(*argv, "-i", folder / "head.csv")
        return sc, argv

    cases = []

    def two_monitors(folder: Path) -> None:
        import subprocess

        prepared(folder)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
        cmd = [sys.executable, "-m", "ivobs.cli", "monitor", "-s", str(folder / "s.toml"),
               "--state", str(folder / "st.json")]  # fmt: skip
        first = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                 env=env)  # fmt: skip
        try:
            first.stdin.write("k,u1,y1,y2\n")  # a resumed monitor prints no header: wait
            first.stdin.flush()  # for its lock (or a while, for a version without one)
            lock = folder / "st.json.lock"
            for _ in range(100):
                if lock.exists() and lock.read_text():
                    break
                time.sleep(0.2)
            second = subprocess.run(cmd, input=(folder / "log.csv").read_text(), env=env,
                                    capture_output=True, text=True, timeout=300)  # fmt: skip
        finally:
            first.stdin.close()
            first.wait()
        if second.returncode == 2 and "ivobs: error:" in second.stderr:
            raise IvobsError(second.stderr)
        raise Silent("two monitors ran on one state file")

    cases.append(("two monitors on one state", two_monitors))

    def other_plant(folder: Path) -> None:
        sc, _argv = prepared(folder)
        from ivobs.io import save_system

        wider = ivobs.LinearSystem(sc.system.A, sc.system.B, sc.system.C, D=sc.system.D,
                                   E=sc.system.E, F=sc.system.F,
                                   d=ivobs.Box(2 * sc.system.d.lo, 2 * sc.system.d.hi))  # fmt: skip
        est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0)
        L = est.design.L
        save_system(folder / "s.toml", sc, method="interval-split", options={"L": L})
        cli("monitor", "-s", folder / "s.toml", "--state", folder / "st2.json", "-i",
            folder / "head.csv")  # fmt: skip
        save_system(folder / "w.toml", wider, x0=sc.x0, method="interval-split", options={"L": L})
        code, _, err = cli("monitor", "-s", folder / "w.toml", "--state", folder / "st2.json",
                           "-i", folder / "log.csv")  # fmt: skip
        expect_refusal(code, err)

    cases.append(("a state of another plant with the same gain", other_plant))

    for name, edit in (
        ("no stream entry", lambda d: d.pop("stream")),
        ("stream.step = 10**9", lambda d: d["stream"].update(step=10**9)),
        ("stream.rows = 0", lambda d: d["stream"].update(rows=0)),
        ("monitor.alarms = 0", lambda d: d["monitor"].update(alarms=0)),
        ("monitor.k = 10**30", lambda d: d["monitor"].update(k=10**30)),
    ):

        def edited(folder: Path, edit=edit) -> None:
            _, argv = prepared(folder)
            data = json.loads((folder / "st.json").read_text())
            edit(data)
            (folder / "st.json").write_text(json.dumps(data))
            code, _, err = cli(*argv, "-i", folder / "log.csv")
            expect_refusal(code, err)

        cases.append((f"state: {name}", edited))

    def other_stream(folder: Path) -> None:
        sc, argv = prepared(folder)
        from ivobs.io import write_log

        tr = sc.simulate("vertex", seed=9)
        write_log(folder / "other.csv", tr.u, tr.y)
        code, _, err = cli(*argv, "-i", folder / "other.csv")
        expect_refusal(code, err)

    cases.append(("a state resumed on another stream", other_stream))

    def exit_status(folder: Path) -> None:
        _, argv = prepared(folder)
        code, _, err = cli(*argv, "-i", folder / "log.csv")
        if code == 2:
            raise IvobsError(err)
        if code == 0:
            raise Silent("a resumed monitor exited 0 although alarms were raised before")

    cases.append(("exit status after a restart", exit_status))
    return cases


# -- 5. compute bombs ---------------------------------------------------------------------------
BOMBS = [
    "1e999999999*x1", "x1 + 1e-999999999", "((x1**1000)**1000)**1000", "x1**700*x1**700",
    "((9**999)**999)**999", "exp(999**999)", "2**(10**6/3)*x1", "exp(exp(exp(100)))*x1",
    "exp(1000)*x1", "pi**700 + x1", "1" + "0" * 2000 + "*x1", "(x1**999)**999",
    "sinh(10**300)*x1", "9**9**9*x1",
]  # fmt: skip
SPECS = [
    "seeds = { start = 0, stop = 1000000000000 }", "seeds = { count = 1000000000 }",
    "horizon = 1000000000", "[scenario_options.heat-1d]\nnx = 100000000",
    "[options.interval-split]\ngain = [" + ", ".join(['"width"'] * 1600)
    + "]\nL = [" + ", ".join(["1.0"] * 1600) + "]",
]  # fmt: skip


def bomb_cases() -> list[tuple[str, Callable[[Path], None]]]:
    cases = []
    for f in BOMBS:

        def expression(folder: Path, f=f) -> None:
            sys = ivobs.NonlinearSystem(f=[f], h=["x1"], states=["x1"])
            est = ivobs.make_estimator("nl-interval", sys, x0=ivobs.Box([0.5], [1.0]))
            est.run(None, np.full((3, 1), 0.7))
            raise Silent("a compute bomb was taken (and finished)")

        cases.append((f"expression {f[:30]}", expression))
    for extra in SPECS:

        def spec(folder: Path, extra=extra) -> None:
            from ivobs.campaign import loads_spec

            text = 'scenarios = ["servo-motor", "heat-1d"]\nmethods = ["interval-split"]\n'
            spec = loads_spec(text + extra)
            spec.jobs()
            raise Silent("an oversized campaign was taken")

        cases.append((f"spec {extra[:40]}", spec))
    return cases


# -- 6. numpy.ma ------------------------------------------------------------------------------
def masked_cases() -> list[tuple[str, Callable[[Path], None]]]:
    cases = []
    for method in ("fixed-time", "interval-split", "zonotope", "reachability", "kkl"):
        for seed in range(3):

            def masked(folder: Path, method=method, seed=seed) -> None:
                from ivobs.testing import adversarial_run

                sc = ivobs.scenarios.get("servo-motor", horizon=60)
                tr = adversarial_run(sc.system, sc.x0, 60, seed=seed)
                y = np.ma.masked_array(tr.y.copy(), mask=np.zeros(tr.y.shape, dtype=bool))
                y[20:26, 1] = tr.y[20:26, 1] + 0.4
                y.mask[20:26, 1] = True
                res = ivobs.make_estimator(method, sc.system, x0=sc.x0).run(tr.u, y)
                if not res.contains(tr.x)[res.valid_from :].all():
                    raise Silent("masked samples used: a box misses the truth")
                if not res.missing[20:26].all():
                    raise Silent("masked samples used as measurements")

            cases.append((f"numpy.ma {method} seed {seed}", masked))
    return cases


# -- 7. tracebacks ------------------------------------------------------------------------------
def traceback_cases() -> list[tuple[str, Callable[[Path], None]]]:
    cases = []
    for what in ("run", "monitor", "campaign"):

        def full(folder: Path, what=what) -> None:
            servo_files(folder, 30)

            def replace(src: Any, dst: Any) -> None:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

            def write(*args: Any) -> None:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

            os.replace = replace  # type: ignore[assignment]  # every atomic write fails
            if what == "run":
                argv = ["run", "-s", folder / "s.toml", "-l", folder / "log.csv", "-o",
                        folder / "o.csv"]  # fmt: skip
            elif what == "monitor":
                argv = ["monitor", "-s", folder / "s.toml", "-i", folder / "log.csv", "--state",
                        folder / "st.json"]  # fmt: skip
            else:
                (folder / "spec.toml").write_text(
                    'scenarios = ["servo-motor"]\nmethods = ["interval-split"]\nhorizon = 20\n'
                    'summary = "sum.md"\n'
                )
                argv = ["campaign", folder / "spec.toml", "--workers", "0", "-q"]
            code, _, err = cli(*argv)
            expect_refusal(code, err)

        cases.append((f"full disk: {what}", full))
    big = "1" + "0" * 400
    for old, new in (("[1.0, 0.1, 0.0],", f"[{big}, 0.1, 0.0],"), ("dt = true", f"dt = {big}"),
                     ("lower = [-0.2, -0.2, -0.2]", f"lower = [-{big}, -0.2, -0.2]"),
                     ("dt = true", "dt = 1" + "0" * 5000),
                     ("dt = true", "dt = " + "[" * 2000 + "]" * 2000),
                     ("dt = true", "dt = " + "{a=" * 600 + "1" + "}" * 600)):  # fmt: skip

        def toml(folder: Path, old=old, new=new) -> None:
            from ivobs.io import load_system

            servo_files(folder, 20)
            text = (folder / "s.toml").read_text().replace(old, new, 1)
            (folder / "s.toml").write_text(text)
            load_system(folder / "s.toml").make_estimator()
            raise Silent("an integer beyond 64 bits or a deep value was taken")

        cases.append((f"TOML {new[:25]}", toml))

    def deep_state(folder: Path) -> None:
        servo_files(folder, 20)
        (folder / "st.json").write_text("[" * 100_000 + "]" * 100_000)
        code, _, err = cli("monitor", "-s", folder / "s.toml", "-i", folder / "log.csv",
                           "--state", folder / "st.json")  # fmt: skip
        expect_refusal(code, err)

    cases.append(("JSON state nested deeply", deep_state))
    from ivobs.estimators import get

    values = [np.array([1.0, 2.0]), np.array(["a", "b"]), np.zeros((2, 2)), np.array([True]),
              np.array([])]  # fmt: skip
    for method in ivobs.methods():
        for option in get(method).options():
            for value in values:

                def numpy_option(folder: Path, method=method, option=option, value=value) -> None:
                    sc = ivobs.scenarios.get("servo-motor", horizon=20)
                    extra = {} if method != "intersect" or option == "methods" else {
                        "methods": ["interval-split", "zonotope"]}  # fmt: skip
                    est = ivobs.make_estimator(method, sc.system, x0=sc.x0, **extra,
                                               **{option: value})  # fmt: skip
                    tr = sc.simulate("vertex", seed=1)
                    est.run(tr.u, tr.y)

                cases.append((f"option {method} {option}={value!r}", numpy_option))
    for method in ("interval-split", "reachability", "zonotope", "kkl", "fixed-time", "exact"):

        def huge_u(folder: Path, method=method) -> None:
            from ivobs.io import write_log

            _sc, tr = servo_files(folder, 20)
            u = tr.u.copy()
            u[5] = 1e308
            write_log(folder / "big.csv", u, tr.y)
            code, _, err = cli("run", "-s", folder / "s.toml", "-l", folder / "big.csv", "-m",
                               method)  # fmt: skip
            if code == 2 and "ivobs: error:" not in err:
                raise RuntimeError(err)

        cases.append((f"CSV u = 1e308, {method}", huge_u))

    def long_field(folder: Path) -> None:
        from ivobs.io import read_log

        sc, _ = servo_files(folder, 20)
        text = (folder / "log.csv").read_text().replace("2.0,", "2" + "0" * 140_000 + ",", 1)
        (folder / "long.csv").write_text(text)
        read_log(folder / "long.csv", sc.system)

    cases.append(("CSV field over 128 KiB", long_field))

    def cache(folder: Path) -> None:
        sc = ivobs.scenarios.get("servo-motor")
        ivobs.make_estimator("dual-window", sc.system, x0=sc.x0, cache=10**12)
        raise Silent("a cache of 10**12 multipliers was taken")

    cases.append(("dual-window(cache=10**12)", cache))
    for method in ivobs.methods():

        def restore(folder: Path, method=method) -> None:
            sc = ivobs.scenarios.get("servo-motor", horizon=4)
            tr = sc.simulate("vertex", seed=1)
            extra = {"methods": ["interval-split", "zonotope"]} if method == "intersect" else {}
            try:
                est = ivobs.make_estimator(method, sc.system, x0=sc.x0, **extra)
            except IvobsError:
                return  # the method declines the servo: nothing to restore
            est.step(tr.u[0], tr.y[0])
            saved = json.loads(json.dumps(est.state()))
            saved["state"]["k"] = 10**30
            est.restore(saved)
            est.step(tr.u[1], tr.y[1])
            raise Silent("a step count of 10**30 was taken")

        cases.append((f"restore k = 10**30, {method}", restore))
    return cases


# -- 8. smaller ----------------------------------------------------------------------------------
def small_cases() -> list[tuple[str, Callable[[Path], None]]]:
    cases = []

    def nfkc(folder: Path) -> None:
        ivobs.NonlinearSystem(f=["\uff58" + "1 + 1"], h=["x1"], states=["x1"])
        raise Silent("'ｘ1' was read as x1")

    def nfkc_name(folder: Path) -> None:
        ivobs.NonlinearSystem(f=["1"], h=["1"], states=["\uff58" + "1"])
        raise Silent("a state named 'ｘ1' was taken")

    cases += [("NFKC name in an expression", nfkc), ("NFKC state name", nfkc_name)]
    for cell in ("\u0661\u0662", "\uff11", "1\u0663"):

        def digits(folder: Path, cell=cell) -> None:
            from ivobs.io import read_log

            sc, _ = servo_files(folder, 5)
            lines = (folder / "log.csv").read_text().splitlines()
            lines[2] = lines[2].rsplit(",", 1)[0] + "," + cell
            (folder / "d.csv").write_text("\n".join(lines) + "\n")
            read_log(folder / "d.csv", sc.system)
            raise Silent(f"{cell!r} was read as a number")

        cases.append((f"digits {cell!r}", digits))

    def minus_nan(folder: Path) -> None:
        from ivobs.io import read_log

        sc, _ = servo_files(folder, 5)
        lines = (folder / "log.csv").read_text().splitlines()
        lines[2] = lines[2].rsplit(",", 1)[0] + ",-nan"
        (folder / "n.csv").write_text("\n".join(lines) + "\n")
        if not np.isnan(read_log(folder / "n.csv", sc.system).y[1, 1]):
            raise Silent("-nan read as a number")

    def bom(folder: Path) -> None:
        from ivobs.io import load_system

        servo_files(folder, 5)
        (folder / "s.toml").write_bytes(b"\xef\xbb\xbf" + (folder / "s.toml").read_bytes())
        load_system(folder / "s.toml")

    def shadow(folder: Path) -> None:
        from ivobs.io import load_system

        servo_files(folder, 5)
        (folder / "secret").write_text("root:$6$SECRETHASH:19000::::\n")
        text = (folder / "s.toml").read_text()
        text = text.replace("upper = [0.0225", f'csv = "{folder / "secret"}"\nupper = ["h"] #', 1)
        (folder / "s.toml").write_text(text)
        try:
            load_system(folder / "s.toml")
        except IvobsError as exc:
            if "SECRETHASH" in str(exc):
                raise Silent("the error quotes the file the system file names") from None
            raise

    cases += [("-nan", minus_nan), ("BOM in TOML", bom), ("[disturbance] csv = secret", shadow)]
    return cases


FAMILIES = {
    "1 log steps": log_cases,
    "2-3 outputs over inputs": output_cases,
    "4 monitor state files": state_cases,
    "5 compute bombs": bomb_cases,
    "6 numpy.ma": masked_cases,
    "7 tracebacks": traceback_cases,
    "8 smaller": small_cases,
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--family", action="append", help="run only these families (by number)")
    ap.add_argument("--verbose", "-v", action="store_true", help="print every case")
    args = ap.parse_args()
    ivobs.scenarios.get("servo-motor").simulate("vertex", seed=0)  # warm the imports once
    ivobs.NonlinearSystem(f=["x1**2"], h=["x1"], states=["x1"])
    totals: Counter[str] = Counter()
    print(f"ivobs {ivobs.__version__} from {Path(ivobs.__file__).parent}")
    for family, make in FAMILIES.items():
        if args.family and not any(family.startswith(f) for f in args.family):
            continue
        counts: Counter[str] = Counter()
        t0 = time.perf_counter()
        for name, case in make():
            kind, msg = outcome(case)
            counts[kind] += 1
            if args.verbose or kind in ("silent", "traceback", "hang"):
                print(f"  {kind:9s} {name}: {msg[:160]}")
        totals.update(counts)
        what = ", ".join(f"{counts[k]} {k}" for k in ("error", "accepted", "silent", "traceback",
                                                        "hang"))  # fmt: skip
        print(f"{family}: {sum(counts.values())} cases: {what} ({time.perf_counter() - t0:.0f} s)")
    what = ", ".join(f"{totals[k]} {k}" for k in ("error", "accepted", "silent", "traceback",
                                                   "hang"))  # fmt: skip
    print(f"total: {sum(totals.values())} cases: {what}")
    return 1 if totals["silent"] or totals["traceback"] or totals["hang"] else 0


if __name__ == "__main__":
    sys.exit(main())
