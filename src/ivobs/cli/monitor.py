"""``ivobs monitor --system F``: guaranteed bounds and fault alarms, one line per measurement.

Reads log rows (CSV with a header: ``k``/``t``, ``u1..``, ``y1..``) from standard input or from
``--input FILE`` (``--follow`` keeps reading a file that is being appended to, like
``tail -f``), and writes one CSV line per step: ``step, lower_1.., upper_1.., alarm, reason,
fault_start, fault_duration, fault_outputs`` (the alarm is latched while a fault persists:
:class:`ivobs.monitor.Monitor`).
``--state FILE`` keeps the monitor's state on disk (written atomically after every step, or
every ``--save-every N`` steps): a restarted monitor continues with the same boxes.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem
from . import add_trust_option

FAULT_COLUMNS = ("fault_start", "fault_duration", "fault_outputs")
"""After the existing columns: the open fault's first step, its duration so far (steps, this one
included; 0 without alarm) and the outputs it found inconsistent (``y1;y3``)."""


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "monitor",
        help="stream measurements through a guaranteed estimator and raise fault alarms",
        description="Read log rows (header k|t, u1.., y1..) from stdin or --input, print one line "
        "per step: step, lower_1.., upper_1.., alarm, reason, fault_start, fault_duration, "
        "fault_outputs. An alarm means the measurements contradict the model and its bounds: "
        "under the model's assumptions it is never false. It stays raised, with the inconsistent "
        "outputs left out of the bounds, until they are consistent again for --clear-after steps.",
    )
    p.add_argument("--system", "-s", required=True, metavar="FILE", help="system file (TOML)")
    p.add_argument("--method", "-m", help="method (default: the system file's [method])")
    p.add_argument("--input", "-i", metavar="FILE", help="read rows from FILE instead of stdin")
    p.add_argument(
        "--follow", "-f", action="store_true", help="keep reading FILE as it grows (tail -f)"
    )
    p.add_argument(
        "--poll", type=float, default=0.1, metavar="S", help="--follow: seconds between checks"
    )
    p.add_argument(
        "--state",
        metavar="FILE",
        help="load the state from FILE if it exists, and "
        "save it there (atomically) as the stream advances",
    )
    p.add_argument(
        "--save-every", type=int, default=1, metavar="N", help="save the state every N steps"
    )
    add_trust_option(p)
    p.add_argument(
        "--clear-after",
        type=int,
        default=10,
        metavar="M",
        help="clear an alarm after M consecutive steps consistent again (default 10)",
    )
    p.add_argument(
        "--no-tight",
        action="store_true",
        help="band from Lemma 1 predictions only (skip the estimator's own prediction)",
    )
    return p


def _lines(fh: TextIO, follow: bool, poll: float) -> Iterator[str]:
    """Complete lines of ``fh``; with ``follow``, wait for more at EOF (Ctrl-C to stop)."""
    pending = ""
    while True:
        chunk = fh.readline()
        if not chunk:
            if not follow:
                if pending:
                    yield pending
                return
            time.sleep(poll)
            continue
        pending += chunk
        if pending.endswith("\n"):
            yield pending
            pending = ""


def _fmt(v: float) -> str:
    return "nan" if np.isnan(v) else repr(float(v))


class _Session:
    """The monitor plus what is needed to resume the stream where it stopped."""

    def __init__(self, args: argparse.Namespace):
        from ..io.systemfile import load_system
        from ..monitor import Monitor

        self.spec = load_system(args.system, allow_code=args.allow_code)
        method = args.method or self.spec.method
        if method is None:
            raise IvobsError(
                f"--method: {args.system} names no method ([method] name = ...); give --method"
            )
        if not isinstance(self.spec.system, LinearSystem):
            raise IvobsError(
                f"{args.system}: the monitor's predicted bands need a linear model; for a "
                "nonlinear system use 'ivobs run --system FILE --log LOG' (its inconsistent "
                "steps are the alarms)"
            )
        est = self.spec.make_estimator(method)
        self.monitor = Monitor(
            self.spec.system,
            est,
            x0=self.spec.x0,
            tight=not args.no_tight,
            clear_after=args.clear_after,
        )
        self.state_path = None
        if args.state:  # checked before the first row is printed
            from ..io.atomic import check_distinct, check_output_path

            self.state_path = check_output_path(args.state, "--state")
            inputs = {"--system": args.system, "--input": args.input}
            inputs.update({"--system's [disturbance] csv": next(iter(self.spec.files), None)})
            check_distinct({"--state": self.state_path}, inputs)
        self.rows = 0  # data rows consumed (processed or skipped as already done)
        self.last_step: int | None = None
        self.last_t: float | None = None
        self.resumed = False
        if self.state_path is not None and self.state_path.exists():
            self._load()

    def _load(self) -> None:
        from ..io.statefile import check_monitor_state, malformed, read_state_file

        assert self.state_path is not None
        name = str(self.state_path)
        data = read_state_file(self.state_path)
        check_monitor_state(data, self.monitor.sys, self.monitor.estimator, name)
        try:
            self.monitor.restore(data["monitor"])
        except IvobsError as exc:
            raise IvobsError(f"--state: {name!r}: {exc}") from None
        except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
            raise malformed(name, "monitor.estimator.state", f"{exc}") from None
        stream = data.get("stream", {})
        _probe(self.monitor, name, stream.get("t"))
        self.rows = int(stream.get("rows", 0))
        self.last_step = stream.get("step")
        self.last_t = stream.get("t")
        self.resumed = True

    def save(self) -> None:
        if self.state_path is None:
            return
        from ..io.statefile import write_state_file

        stream = {"rows": self.rows, "step": self.last_step, "t": self.last_t}
        write_state_file(self.state_path, self.monitor.method, self.monitor.state(), stream)

    def already_done(self, row: Any, index: int, from_file: bool) -> bool:
        """Whether a row was processed before the restart: by its step or time column when the
        log has one, else by its position (``--input`` only)."""
        if not self.resumed:
            return False
        if row.step is not None and self.last_step is not None:
            return bool(row.step <= self.last_step)
        if row.t is not None and self.last_t is not None:
            return bool(row.t <= self.last_t)
        return from_file and index < self.rows


def _probe(mon: Any, name: str, t: Any) -> None:
    """One prediction from the restored state (``Estimator.predict``: the state is unchanged):
    entries with a wrong shape, NaN or ``lo > hi`` show up here rather than on the next row."""
    from ..io.statefile import malformed

    est, sys_ = mon.estimator, mon.sys
    if mon.k < est.valid_from:
        return
    t_k = None
    if sys_.is_continuous:
        t_k = (0.0 if t is None else float(t)) + 1e-3
    try:
        u0 = np.zeros(sys_.nu) if sys_.nu else None
        box = est.advance(mon.estimator_state, u0, None, t_k, keep=False)[1]
    except IvobsError as exc:
        if "NaN" in str(exc):
            raise malformed(name, "monitor.estimator.state", "gives NaN bounds") from None
        return  # e.g. bounds that need the measurement: nothing to judge
    except (TypeError, ValueError, KeyError, IndexError, AttributeError, ArithmeticError,
            np.linalg.LinAlgError) as exc:  # fmt: skip
        raise malformed(name, "monitor.estimator.state", f"unusable ({exc})") from None
    lo, hi = np.asarray(box.lo, dtype=float), np.asarray(box.hi, dtype=float)
    if np.isnan(lo).any() or np.isnan(hi).any() or np.any(lo > hi):
        raise malformed(name, "monitor.estimator.state", "gives an empty or NaN box")


def main(args: argparse.Namespace) -> int:
    from ..io.logs import LogParser
    from ..monitor.records import output_names

    if not (np.isfinite(args.poll) and args.poll > 0):
        raise IvobsError(
            f"--poll: expected the seconds between checks of --follow, a number > 0, got "
            f"{args.poll!r}"
        )
    if args.clear_after < 1:
        raise IvobsError(f"--clear-after: expected an integer >= 1 (steps), got {args.clear_after}")
    if args.save_every < 1:
        raise IvobsError(f"--save-every: expected an integer >= 1, got {args.save_every}")
    if args.follow and not args.input:
        raise IvobsError("--follow: needs --input FILE (stdin is followed anyway)")
    if args.input:
        if Path(args.input).is_dir():
            raise IvobsError(f"--input: {args.input!r} is a directory; expected a CSV file")
        if not Path(args.input).is_file():
            raise IvobsError(f"--input: no such file {args.input!r}")
    session = _Session(args)
    mon = session.monitor
    sys_ = mon.sys
    source = args.input or "<stdin>"
    parser = LogParser(sys_.nu, sys_.ny, source)
    out = csv.writer(sys.stdout, lineterminator="\n")
    if not session.resumed:
        cols = [f"lower_{i + 1}" for i in range(sys_.nx)] + [
            f"upper_{i + 1}" for i in range(sys_.nx)
        ]
        out.writerow(["k", *cols, "alarm", "reason", *FAULT_COLUMNS])
        sys.stdout.flush()
    fh: TextIO
    if args.input:
        fh = open(args.input, encoding="utf-8-sig", newline="")
    else:
        fh = sys.stdin
    alarms = 0
    index = 0
    unsaved = 0
    in_step = False  # a step interrupted half-way leaves a state that must not be saved
    try:
        for lineno, text in enumerate(_lines(fh, args.follow, args.poll), start=1):
            if not text.strip() or text.lstrip().startswith("#"):
                continue
            if not parser.columns:
                parser.header(text, lineno)
                if sys_.is_continuous and not parser.has_time:
                    raise IvobsError(
                        f"{source}, line {lineno}: the system is continuous-time (dt = 0): "
                        "the rows need a time column t"
                    )
                continue
            row = parser.row(text, lineno)
            index += 1
            if session.already_done(row, index - 1, bool(args.input)):
                continue
            in_step = True
            t_k = row.t if sys_.is_continuous else None  # discrete time counts steps
            step = mon.update(row.u if sys_.nu else None, row.y, t_k)
            alarms += step.alarm
            out.writerow(
                [
                    step.step,
                    *map(_fmt, step.lower),
                    *map(_fmt, step.upper),
                    int(step.alarm),
                    step.reason,
                    "" if step.fault_start is None else step.fault_start,
                    step.fault_duration,
                    output_names(step.outputs),
                ]
            )
            sys.stdout.flush()
            # printed first, saved second: after a crash a step may be printed twice (the same
            # line), never lost
            session.rows = index
            session.last_step, session.last_t = row.step, row.t
            unsaved += 1
            in_step = False
            if unsaved >= args.save_every:
                session.save()
                unsaved = 0
    except UnicodeDecodeError as exc:
        from ..io.logs import not_utf8

        raise not_utf8(source, exc) from None
    finally:
        if unsaved and not in_step:
            session.save()
        if fh is not sys.stdin:
            fh.close()
    return 1 if alarms else 0
