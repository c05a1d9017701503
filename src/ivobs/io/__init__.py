"""Files: operating ivobs on real data.

* **System files** (TOML, :mod:`ivobs.io.systemfile`, :mod:`ivobs.io.systemwrite`): the model
  ``x[k+1] = A x[k] + B u[k] + E d[k]``, ``y[k] = C x[k] + D u[k] + F d[k]``, the disturbance
  bounds, the prior box on ``x[0]`` and a method with its options (:mod:`ivobs.io.options`).
  Every rejected file raises :class:`~ivobs.IvobsError` naming the file, the line and the key
  (:mod:`ivobs.io.reader`). The format is documented in ``docs/operating.md``.
* **Logs** (CSV, :mod:`ivobs.io.logs`): a step or time column, ``u1, u2, ...`` and
  ``y1, y2, ...``; an empty cell or ``NaN`` is a missing sample. The true state of a logged
  record (:mod:`ivobs.io.truth`) is read by the same parser, one column per state.
* **Monitor state files** (JSON, :mod:`ivobs.io.statefile`).
* **Atomic writes** (:mod:`ivobs.io.atomic`): every file ivobs writes goes to a temporary file
  in the same folder and is then renamed, so a crash or an error never leaves a half-written
  file behind.

**Trust**: a matrix or a bound may name a Python callable by import path
(``A = { python = "ivobs.scenarios:pendulum_A", params = { L0 = 1.0, L1 = 0.5, omega = 1.0 } }``).
Loading a file runs no code by default: only functions of ivobs' own scenarios
(``ivobs.scenarios`` and below) are resolved; any other callable is refused, naming the file,
the line and the path, unless ``load_system(path, allow_code=True)`` (``--allow-code`` on the
command line) says that you trust the file.

The names below are imported on first use (:pep:`562`): importing :mod:`ivobs.io.atomic` (as
the result and plot modules do) loads no estimator.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .atomic import (
        atomic_path,
        check_distinct,
        check_output_path,
        same_file,
        write_text_atomic,
    )
    from .callables import callable_ref
    from .logs import Log, LogParser, LogRow, log_from_frame, not_utf8, read_log, write_log
    from .reader import KeyLines
    from .systemfile import SystemFile, load_system, loads_system
    from .systemwrite import dumps_system, equal_systems, save_system
    from .truth import read_truth

__all__ = [
    "KeyLines",
    "Log",
    "LogParser",
    "LogRow",
    "SystemFile",
    "atomic_path",
    "callable_ref",
    "check_distinct",
    "check_output_path",
    "dumps_system",
    "equal_systems",
    "load_system",
    "loads_system",
    "log_from_frame",
    "not_utf8",
    "read_log",
    "read_truth",
    "same_file",
    "save_system",
    "write_log",
    "write_text_atomic",
]

_WHERE = {
    name: module
    for module, names in (
        ("atomic", "atomic_path check_output_path check_distinct same_file write_text_atomic"),
        ("callables", "callable_ref"),
        ("logs", "Log LogParser LogRow not_utf8 read_log log_from_frame write_log"),
        ("reader", "KeyLines"),
        ("systemfile", "SystemFile load_system loads_system"),
        ("systemwrite", "dumps_system equal_systems save_system"),
        ("truth", "read_truth"),
    )
    for name in names.split()
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value  # once resolved, an ordinary attribute
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
