"""Disturbance bounds from a CSV file (``[disturbance] csv = "bounds.csv"``): one column per
named bound, one row per step.

The file is named by the system file, not by the user on the command line, so it may be any
file: errors say where (its path, the line, the column's number) and what was expected, and
never quote its content (``csv = "/etc/shadow"`` shows no line of it).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from ..errors import IvobsError
from .logs import read_number

__all__ = ["read_bounds_csv"]


def read_bounds_csv(path: Path) -> dict[str, np.ndarray]:
    """The columns of a bounds file by their header names; raises :class:`~ivobs.IvobsError`
    (without the file's content) when it is not a table of finite numbers."""
    where = f"bounds file {str(path)!r}"
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            rows = [
                (i, r)
                for i, r in enumerate(csv.reader(fh), start=1)
                if r and not r[0].lstrip().startswith("#")
            ]
    except UnicodeDecodeError as exc:
        raise IvobsError(
            f"{where}: not UTF-8 text (byte {exc.start}); expected a CSV file"
        ) from None
    except csv.Error as exc:  # a field over csv's 128 KiB limit, a NUL byte
        raise IvobsError(f"{where}: not a CSV table ({exc})") from None
    except OSError as exc:
        raise IvobsError(f"{where}: cannot read it ({exc.strerror})") from None
    if len(rows) < 2:
        raise IvobsError(f"{where}: needs a header and one row per step")
    header = [h.strip() for h in rows[0][1]]
    if len(set(header)) != len(header):
        raise IvobsError(f"{where}, line {rows[0][0]}: a column name is given twice")
    data = np.empty((len(rows) - 1, len(header)))
    for j, (line, r) in enumerate(rows[1:]):
        if len(r) != len(header):
            raise IvobsError(f"{where}, line {line}: expected {len(header)} fields, got {len(r)}")
        for c, cell in enumerate(r):
            try:
                data[j, c] = read_number(cell)
            except ValueError as exc:
                raise IvobsError(f"{where}, line {line}, column {c + 1}: {exc}") from None
            if not math.isfinite(data[j, c]):
                raise IvobsError(
                    f"{where}, line {line}, column {c + 1}: bounds must be finite numbers"
                )
    return {h: data[:, c] for c, h in enumerate(header)}
