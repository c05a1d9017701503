"""The results table (CSV): one line per finished job, appended and flushed at once; read back
with typed values. A line cut short by a crash is dropped (its job reruns)."""

from __future__ import annotations

import csv
import json
import os
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from ..errors import IvobsError
from .job import canonical

__all__ = ["COLUMNS", "ResultsFile", "read_results"]

COLUMNS = (
    "job_id", "scenario", "scenario_options", "disturbance", "method", "options", "seed",
    "burn_in", "horizon", "status", "contains", "valid_from", "inconsistent", "mean_width",
    "widths", "design_time", "design_reused", "run_time", "job_time", "host", "worker",
    "finished", "ivobs_version", "warnings", "error",
)  # fmt: skip
"""Columns of the results table, in order (one line per job)."""


def _cell(v: Any) -> str:
    """One CSV field on one line (a row is one line: a cut-off last line is easy to drop)."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, dict)):
        return canonical(v)
    return " ".join(str(v).split("\n")).replace("\r", " ")


_PARSE: dict[str, Callable[[str], Any]] = {
    "scenario_options": json.loads, "options": json.loads, "seed": int, "burn_in": int,
    "horizon": int, "valid_from": int, "inconsistent": int, "mean_width": float,
    "widths": json.loads, "design_time": float, "run_time": float, "job_time": float,
    "contains": lambda s: s == "true", "design_reused": lambda s: s == "true",
}  # fmt: skip


def _parse_row(raw: dict[str, str]) -> dict[str, Any]:
    return {k: (None if v == "" else _PARSE.get(k, str)(v)) for k, v in raw.items()}


def _parse_table(text: str, path: Path) -> list[dict[str, Any]]:
    """Rows of a results table's text (complete lines only)."""
    lines = text.splitlines()
    if not text.endswith("\n"):
        lines = lines[:-1]  # a line cut off by a crash (dropped, its job reruns)
    if not lines:
        return []
    try:
        return _parse_lines(lines, path)
    except csv.Error as exc:  # a field over csv's 128 KiB limit, a NUL byte
        raise IvobsError(f"output: {str(path)!r} is not a results table ({exc})") from None


def _parse_lines(lines: list[str], path: Path) -> list[dict[str, Any]]:
    reader = csv.reader(lines)
    header = next(reader)
    if tuple(header) != COLUMNS:
        raise IvobsError(
            f"output: {str(path)!r} is not a results table of this ivobs version (its first "
            f"line is not the header {','.join(COLUMNS[:4])},...); choose another output file"
        )
    rows = []
    for line, fields in enumerate(reader, start=2):
        if len(fields) != len(COLUMNS):
            raise IvobsError(
                f"output: {str(path)!r}, line {line}: expected {len(COLUMNS)} fields, got "
                f"{len(fields)}; the file was edited: fix or delete that line"
            )
        try:
            rows.append(_parse_row(dict(zip(COLUMNS, fields))))
        except (ValueError, RecursionError):
            raise IvobsError(
                f"output: {str(path)!r}, line {line}: a cell is not what this column holds; "
                "the file was edited: fix or delete that line"
            ) from None
    return rows


class ResultsFile:
    """The CSV table, opened for appending: existing rows read, a cut-off last line removed,
    an exclusive lock held (two campaigns never interleave their lines)."""

    def __init__(self, path: Path):
        self.path = path
        self.rows: list[dict[str, Any]] = []
        self.fh: Any = None

    def __enter__(self) -> ResultsFile:
        path = self.path
        if not path.parent.is_dir():
            raise IvobsError(f"output: the folder {str(path.parent)!r} does not exist")
        try:
            self.fh = open(path, "a+", newline="", encoding="utf-8")
        except OSError as exc:
            raise IvobsError(f"output: cannot open {str(path)!r}: {exc.strerror or exc}") from None
        try:
            self._lock()
            self._read()
        except BaseException:
            self.fh.close()
            raise
        return self

    def _lock(self) -> None:
        try:
            import fcntl
        except ImportError:  # pragma: no cover - Windows: no lock
            return
        try:
            fcntl.flock(self.fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise IvobsError(
                f"output: another campaign is writing to {str(self.path)!r}; wait for it or "
                "choose another output file"
            ) from None
        except OSError:  # pragma: no cover - file systems without locks
            pass

    def _read(self) -> None:
        fh = self.fh
        fh.seek(0)
        try:
            text = fh.read()
        except UnicodeDecodeError:
            raise IvobsError(
                f"output: {str(self.path)!r} is not a results table (not UTF-8 text); choose "
                "another output file"
            ) from None
        self.rows = _parse_table(text, self.path)
        if text and not text.endswith("\n"):  # remove the cut-off line before appending
            keep = text.rfind("\n") + 1
            fh.truncate(len(text[:keep].encode("utf-8")))
            text = text[:keep]
        fh.seek(0, os.SEEK_END)
        if not text:
            try:
                csv.writer(fh, lineterminator="\n").writerow(COLUMNS)
                fh.flush()
            except OSError as exc:
                raise IvobsError(
                    f"output: cannot write {str(self.path)!r}: {exc.strerror or exc}"
                ) from None

    def append(self, row: dict[str, Any]) -> None:
        cells = [_cell(row.get(c)) for c in COLUMNS]
        try:
            csv.writer(self.fh, lineterminator="\n").writerow(cells)
            self.fh.flush()
        except OSError as exc:  # a full disk: the rows before are whole, a cut line is dropped
            raise IvobsError(
                f"output: cannot append to {str(self.path)!r}: {exc.strerror or exc}; the rows "
                "written before are intact (a cut-off last line is dropped when the table is "
                "read): make room and run the same command again to resume"
            ) from None
        self.rows.append(_parse_row(dict(zip(COLUMNS, cells))))

    def __exit__(self, *exc: Any) -> None:
        self.fh.close()


def read_results(path: str | os.PathLike[str]) -> list[dict[str, Any]]:
    """The rows of a results table, parsed (numbers, booleans, lists; ``None`` for blanks).
    A job that ran more than once (``retry_errors``) keeps its last row. Safe to call while a
    campaign is writing the table."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise IvobsError(f"results: cannot read {str(path)!r}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise IvobsError(f"results: {str(path)!r} is not a results table (not UTF-8)") from None
    return list(latest_rows(_parse_table(text, path)).values())


def latest_rows(rows: Iterable[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for r in rows:
        out.pop(r["job_id"], None)
        out[r["job_id"]] = r
    return out
