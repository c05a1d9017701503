"""``ivobs monitor --system F``: guaranteed bounds and fault alarms, one line per measurement.

Reads log rows (CSV with a header: ``k``/``t``, ``u1..``, ``y1..``) from standard input or from
``--input FILE`` (``--follow`` keeps reading a file that is being appended to, like
``tail -f``), and writes one CSV line per step: ``step, lower_1.., upper_1.., alarm, reason,
fault_start, fault_duration, fault_outputs, bias_..., fault_isolated`` (the alarm is latched
while a fault persists: :class:`ivobs.monitor.Monitor`).
``--state FILE`` keeps the monitor's state on disk (written atomically after every step, or
every ``--save-every N`` steps): a restarted monitor continues with the same boxes. The file is
locked while the monitor runs (a second one is refused), and refused when it was written for
another model or another stream (:mod:`ivobs.io.statefile`).

The rows' step column is honoured (:mod:`ivobs.io.steps`): the first row is at the prior's
step, a gap is a run of missing samples (one line per step). The exit status is 1 when an alarm
was raised anywhere on the stream, the part before a restart included.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import hashlib
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from ..errors import IvobsError
from ..io.fingerprint import canonical_json
from ..io.steps import StepClock
from . import add_trust_option

FAULT_COLUMNS = ("fault_start", "fault_duration", "fault_outputs")
"""After the existing columns: the open fault's first step, its duration so far (steps, this one
included; 0 without alarm) and the outputs it found inconsistent (``y1;y3``); then
``bias_lower_i``, ``bias_upper_i`` per output: the estimated bias of a faulty output (empty
elsewhere, :mod:`ivobs.monitor.bias`); last, ``fault_isolated``: which outputs the recent data
blame (``y2``; ``y1 or y2 (cannot be told apart)``; ``not isolated: ...``;
:mod:`ivobs.monitor.isolate`)."""


def _or_nan(v: np.ndarray | None, n: int) -> np.ndarray:
    return np.full(n, np.nan) if v is None else v


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


class _Stream:
    """Where the stream stands: the step of its first row, the rows consumed, the last step and
    time, the columns, and the digests of all rows and of the last one (what a restarted
    monitor checks the rows it sees again against)."""

    def __init__(self, start: int):
        self.start, self.rows = start, 0
        self.step: int | None = None
        self.t: float | None = None
        self.columns: list[str] = []
        self.digest, self.last = "", ""

    def consume(self, row: Any) -> None:
        y = [None if np.isnan(v) else float(v) for v in row.y]
        values = [row.step, row.t, [float(v) for v in row.u], y]  # the digest of the row's values
        d = hashlib.sha256(canonical_json(values).encode()).hexdigest()[:32]
        self.rows, self.step, self.t = self.rows + 1, row.step, row.t
        self.digest = hashlib.sha256((self.digest + d).encode()).hexdigest()[:32]  # all so far
        self.last = d

    def entries(self) -> dict[str, Any]:
        keys = ("start", "rows", "step", "t", "columns", "digest", "last")
        return {k: getattr(self, k) for k in keys}

    @classmethod
    def saved(cls, entries: dict[str, Any]) -> _Stream:
        out = cls(entries["start"])
        for k, v in entries.items():
            setattr(out, k, v)
        return out


class _Replay:
    """The rows a restarted monitor sees again (processed before the restart: by their step or
    time column, else by position in ``--input``): skipped, and checked to be the rows of the
    stream the state was built from (the digest of them all when all come again, else that of
    the last one)."""

    def __init__(self, saved: _Stream, name: str):
        self.saved, self.name = saved, name
        self.seen = _Stream(saved.start)  # the rows seen again: their count and digests
        self.last_seen = False

    def done(self, row: Any, index: int, from_file: bool) -> bool:
        s = self.saved
        if row.step is not None and s.step is not None:
            return bool(row.step <= s.step)
        if row.t is not None and s.t is not None:
            return bool(row.t <= s.t)
        return from_file and index < s.rows

    def see(self, row: Any) -> None:
        self.seen.consume(row)
        s = self.saved
        last = (
            row.step == s.step
            if s.step is not None
            else row.t == s.t
            if s.t is not None
            else self.seen.rows == s.rows
        )
        if last:
            if self.seen.last != s.last:
                raise self._other(f"its row of the last step processed ({self._where()}) differs")
            self.last_seen = True

    def finish(self) -> None:
        """At the first new row (or the end): the rows seen again were the stream's."""
        n = self.seen.rows
        if n == 0:
            return
        if n == self.saved.rows and self.seen.digest != self.saved.digest:
            raise self._other(f"its first {n} rows differ from those processed")
        if not self.last_seen:
            raise self._other(f"it does not give the last step processed ({self._where()})")

    def _where(self) -> str:
        s = self.saved
        return (
            f"step {s.step}"
            if s.step is not None
            else f"t = {s.t}"
            if s.t is not None
            else (f"row {s.rows}")
        )

    def _other(self, why: str) -> IvobsError:
        return IvobsError(
            f"--state: {self.name!r} was built from another stream: {why}. A state continues "
            "the stream it was written for; delete it to start afresh on this one"
        )


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
        self.state_path = None
        if args.state:  # checked before the first row is printed
            from ..io.atomic import check_distinct, check_output_path
            from ..io.statefile import lock_path

            self.state_path = check_output_path(args.state, "--state")
            from ._plant import plant_inputs

            outputs = {"--state": self.state_path, "--state's lock": lock_path(self.state_path)}
            check_distinct(outputs, plant_inputs(args, self.spec))
        # the monitor's default (Monitor): boxes met with the strips of the outputs used
        from ..estimators.measured import FILTERED

        est = self.spec.make_estimator(method, defaults=FILTERED)
        self.monitor = Monitor(
            self.spec.system,
            est,
            x0=self.spec.x0,
            tight=not args.no_tight,
            clear_after=args.clear_after,
        )
        self.start = self.spec.x0_step
        self.stream = _Stream(self.start)
        self.replay: _Replay | None = None

    @property
    def resumed(self) -> bool:
        return self.monitor.k > 0 or self.replay is not None

    def load(self, clock: StepClock) -> None:
        """Continue from the state file, if it exists (under the lock)."""
        from ..io.statefile import check_monitor_state, malformed, read_state_file
        from ..monitor.persist import check_model

        if self.state_path is None or not self.state_path.exists():
            return
        name = str(self.state_path)
        data = read_state_file(self.state_path)
        mon = self.monitor
        saved_monitor = data.get("monitor")
        try:  # the model first: a state of another plant is refused saying so
            check_model(
                mon, saved_monitor.get("model") if isinstance(saved_monitor, dict) else None
            )
            check_monitor_state(data, mon.sys, mon.estimator, name, self.start)
            mon.restore(data["monitor"])
        except IvobsError as exc:
            if str(exc).startswith("--state"):
                raise
            raise IvobsError(f"--state: {name!r}: {exc}") from None
        except (TypeError, ValueError, KeyError, AttributeError, IndexError) as exc:
            raise malformed(name, "monitor.estimator.state", f"{exc}") from None
        saved = _Stream.saved(data["stream"])
        _probe(mon, name, saved.t)
        self.stream = saved
        if saved.rows:
            self.replay = _Replay(saved, name)
        if saved.step is not None:
            clock.resume(saved.step + 1)
        elif mon.k:
            clock.resume(self.start + mon.k)

    def header(self, columns: list[str], source: str, line: int) -> None:
        """A (restarted) stream's header: the columns of the stream the state was built on."""
        saved = self.stream.columns
        if self.resumed and saved and [c.lower() for c in columns] != [c.lower() for c in saved]:
            raise IvobsError(
                f"{source}, line {line}: columns {','.join(columns)}, but the state "
                f"{str(self.state_path)!r} was built from a stream with {','.join(saved)}; "
                "delete the state to start afresh on this stream"
            )
        self.stream.columns = list(columns)

    def save(self) -> None:
        if self.state_path is None:
            return
        from ..io.statefile import write_state_file

        write_state_file(
            self.state_path, self.monitor.method, self.monitor.state(), self.stream.entries()
        )


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


def _check_args(args: argparse.Namespace) -> None:
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


def main(args: argparse.Namespace) -> int:
    from ..io.statefile import StateLock

    _check_args(args)
    session = _Session(args)
    with contextlib.ExitStack() as stack:
        if session.state_path is not None:
            stack.enter_context(StateLock(session.state_path))
        return _stream(args, session)
    return 2  # pragma: no cover - mypy: the with block returns


def _stream(args: argparse.Namespace, session: _Session) -> int:
    """Read the rows, print one line per step, save the state; the exit status says whether an
    alarm was raised on the whole stream (its resumed parts included)."""
    from ..io.logs import LogParser, csv_cell
    from ..monitor.records import output_names

    mon = session.monitor
    sys_ = mon.sys
    source = args.input or "<stdin>"
    parser = LogParser(sys_.nu, sys_.ny, source)
    clock = StepClock(sys_, source, session.start)
    session.load(clock)
    out = csv.writer(sys.stdout, lineterminator="\n")
    if not session.resumed:
        cols = [f"{b}_{i + 1}" for b in ("lower", "upper") for i in range(sys_.nx)]
        bias = [f"bias_{b}_{i + 1}" for b in ("lower", "upper") for i in range(sys_.ny)]
        out.writerow(["k", *cols, "alarm", "reason", *FAULT_COLUMNS, *bias, "fault_isolated"])
        sys.stdout.flush()
    fh: TextIO
    try:
        fh = open(args.input, encoding="utf-8-sig", newline="") if args.input else sys.stdin
    except OSError as exc:
        raise IvobsError(f"--input: cannot read {args.input!r}: {exc.strerror}") from None
    k0 = session.start
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
                session.header(parser.columns, source, lineno)
                continue
            row = parser.row(text, lineno)
            index += 1
            replay = session.replay
            if replay is not None:
                if replay.done(row, index - 1, bool(args.input)):
                    replay.see(row)
                    continue
                replay.finish()
                session.replay = None
            in_step = True
            for placed in clock.place(row):  # a gap: its steps, measurements missing
                t_k = placed.t if sys_.is_continuous else None  # discrete time counts steps
                step = mon.update(placed.u if sys_.nu else None, placed.y, t_k)
                start = "" if step.fault_start is None else k0 + step.fault_start
                out.writerow(
                    [
                        k0 + step.step,
                        *(csv_cell(v, "nan") for v in step.lower),
                        *(csv_cell(v, "nan") for v in step.upper),
                        int(step.alarm),
                        step.reason,
                        start,
                        step.fault_duration,
                        output_names(step.outputs),
                        *map(csv_cell, _or_nan(step.bias_lower, sys_.ny)),  # empty: none
                        *map(csv_cell, _or_nan(step.bias_upper, sys_.ny)),
                        step.isolation,
                    ]
                )
            sys.stdout.flush()
            # printed first, saved second: after a crash a step may be printed twice (the same
            # line), never lost
            session.stream.consume(row)
            unsaved += 1
            in_step = False
            if unsaved >= args.save_every:
                session.save()
                unsaved = 0
        if session.replay is not None:
            session.replay.finish()
    except UnicodeDecodeError as exc:
        from ..io.logs import not_utf8

        raise not_utf8(source, exc) from None
    finally:
        if unsaved and not in_step:
            session.save()
        if fh is not sys.stdin:
            fh.close()
    return 1 if mon.alarms else 0
