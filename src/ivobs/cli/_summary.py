"""One JSON summary for ``ivobs compare --json`` and ``ivobs run --json``: a document with the
record (name, source, steps) and one object per method (or baseline), so that a script reads
both commands the same way."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["summary_document", "write_json"]


def _num(v: Any) -> float | None:
    """A finite number, or None (JSON has no NaN or infinity)."""
    v = float(v)
    return v if math.isfinite(v) else None


def _plain(v: Any) -> Any:
    """An option value as JSON: arrays as lists, other objects by their text."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return str(v)


def _row(r: Any, names: Sequence[str], first_step: int, inconsistent: Any) -> dict[str, Any]:
    est = r.estimate
    flags = None if est is None else np.flatnonzero(est.inconsistent)  # set by Estimate
    if inconsistent is not None:
        flags = np.asarray(inconsistent, dtype=int)
    widths = None if r.mean_width is None else [_num(w) for w in r.mean_width]
    return {
        "method": r.method,
        "guaranteed": bool(r.guaranteed),
        "ok": bool(r.ok),
        "error": r.error or None,
        "options": dict(r.options),
        "mean_width": widths,
        "mean_width_by_state": None if widths is None else dict(zip(names, widths)),
        "steps": None if est is None else int(est.T),
        "valid_from": None if est is None else int(est.valid_from),
        "inconsistent_steps": None if flags is None else [int(k) + first_step for k in flags],
        "contains_truth": r.contains,
        "misses": r.misses,
        "design_time_s": _num(r.design_time),
        "run_time_s": _num(r.run_time),
        "cpu_time_s": _num(r.cpu_time),
    }


def summary_document(
    name: str,
    source: str,
    results: Sequence[Any],
    *,
    horizon: int,
    burn_in: int,
    state_names: Sequence[str] | None = None,
    first_step: int = 0,
    inconsistent: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The summary of ``results`` (:class:`~ivobs.report.MethodResult`, one per method) on one
    record. Steps are the record's (``first_step``: the step of its first row);
    ``inconsistent``: per method, the steps to report instead of its estimate's flags (the
    alarms ``ivobs run`` prints). ``contains_truth`` and ``misses`` are None without a true
    state; a baseline has ``guaranteed: false``."""
    nx = next((r.estimate.nx for r in results if r.estimate is not None), 0)
    names = list(state_names) if state_names else [f"x{i + 1}" for i in range(nx)]
    rows = [_row(r, names, first_step, (inconsistent or {}).get(r.method)) for r in results]
    return {
        "scenario": name,
        "source": source,
        "horizon": int(horizon),
        "first_step": int(first_step),
        "burn_in": int(burn_in),
        "methods": rows,
    }


def write_json(path: str, doc: dict[str, Any]) -> None:
    """``doc`` as JSON to ``path`` (atomically), or to standard output for ``-``."""
    text = json.dumps(doc, indent=2, allow_nan=False, default=_plain)
    if path == "-":
        print(text)
        return
    from ..io.atomic import write_text_atomic

    write_text_atomic(path, text + "\n")
