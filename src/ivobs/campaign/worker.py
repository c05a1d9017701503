"""One job, in a worker process: simulate the scenario, design the method (reused across
seeds), run it, and return the job's row of the results table."""

from __future__ import annotations

import contextlib
import datetime as _dt
import importlib
import os
import socket
import sys
import threading
import time
import traceback
import warnings
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..errors import IvobsError
from .job import Job, canonical

__all__ = ["DESIGN_CACHE", "run_job"]

DESIGN_CACHE = 64
"""Estimators kept per worker process (and thread) for reuse across seeds."""


_SCENARIOS: OrderedDict[str, Any] = OrderedDict()
_DESIGNS: OrderedDict[tuple[str, int], tuple[Any, float]] = OrderedDict()


def _lru(
    cache: OrderedDict[Any, Any], key: Any, make: Callable[[], Any], size: int
) -> tuple[Any, bool]:
    """``(value, reused)`` from a small LRU cache."""
    if key in cache:
        cache.move_to_end(key)
        return cache[key], True
    value = make()
    cache[key] = value
    while len(cache) > size:
        cache.popitem(last=False)
    return value, False


def cached_scenario(name: str, options: dict[str, Any]) -> Any:
    from .. import scenarios

    key = canonical([name, options, threading.get_ident()])
    if name.endswith(".toml"):  # a system file: the plant simulated from its prior box
        from ..io.plant import DEFAULT_HORIZON, file_scenario

        horizon = options.get("horizon", DEFAULT_HORIZON)
        return _lru(_SCENARIOS, key, lambda: file_scenario(name, horizon=horizon), 16)[0]
    return _lru(_SCENARIOS, key, lambda: scenarios.get(name, **options), 16)[0]


def _design(job: Job, sc: Any) -> tuple[Any, float, bool]:
    """``(estimator, design time, reused)``; a design that failed fails again from the cache
    (an infeasible LMI is not retried for every seed)."""
    from ..estimators import make_estimator
    from ..estimators.measured import FILTERED

    def attempt() -> tuple[Any, float]:
        t0 = time.perf_counter()
        try:
            # the comparisons' default (ivobs compare): boxes met with the measurement strips
            est = make_estimator(job.method, sc.system, x0=sc.x0, **{**FILTERED, **job.options})
        except Exception as exc:
            return exc, time.perf_counter() - t0
        return est, time.perf_counter() - t0

    def make() -> tuple[Any, float]:
        cold = "cvxpy" not in sys.modules
        out = attempt()
        if cold and "cvxpy" in sys.modules:  # that time included CVXPY's first import (~1.5 s)
            out = attempt()
        return out

    # Per thread: a Dask worker may run several jobs at once on one estimator otherwise.
    (est, dt), reused = _lru(_DESIGNS, (job.design_key(), threading.get_ident()), make,
                             DESIGN_CACHE)  # fmt: skip
    if isinstance(est, Exception):
        raise est  # keeps the original traceback (its innermost frame is reported)
    return est, dt, reused


def _where(exc: BaseException) -> str:
    """``file:line in function`` of the innermost frame (for unexpected errors)."""
    tb = traceback.extract_tb(exc.__traceback__)
    if not tb:
        return ""
    f = tb[-1]
    return f" (at {Path(f.filename).name}:{f.lineno} in {f.name})"


def _worker_name() -> str:
    mod = sys.modules.get("distributed")
    if mod is not None:
        with contextlib.suppress(Exception):
            return str(mod.get_worker().address)
    return f"pid {os.getpid()}"


def run_job(job: Job | dict[str, Any]) -> dict[str, Any]:
    """Run one job and return its row (a dict over :data:`COLUMNS`); never raises for a failing
    method or scenario: the error goes into the row."""
    import numpy as np

    from .. import __version__

    job = Job.from_dict(job) if isinstance(job, dict) else job
    t_start = time.perf_counter()
    row: dict[str, Any] = {**_job_columns(job), "status": "ok", "host": socket.gethostname(),
                           "worker": _worker_name(), "ivobs_version": __version__}  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            for mod in job.imports:
                importlib.import_module(mod)
            sc = cached_scenario(job.scenario, job.scenario_options)
            traj = sc.simulate(job.disturbance, job.seed)
            T = int(traj.y.shape[0])
            row["horizon"] = T
            burn = T // 10 if job.burn_in is None else job.burn_in
            row["burn_in"] = burn
            est, row["design_time"], row["design_reused"] = _design(job, sc)
            t0 = time.perf_counter()
            res = est.run(traj.u, traj.y, t=traj.t if sc.system.is_continuous else None)
            row["run_time"] = time.perf_counter() - t0
            row["valid_from"] = int(res.valid_from)
            row["inconsistent"] = 0 if res.inconsistent is None else int(res.inconsistent.sum())
            if traj.has_truth:
                row["contains"] = bool(np.all(res.contains(traj.x)))
            widths = res.mean_width(burn)
            row["widths"] = [float(w) for w in widths]
            row["mean_width"] = float(np.mean(widths))
        except IvobsError as exc:
            row["status"], row["error"] = "failed", f"{type(exc).__name__}: {exc}"
        except Exception as exc:
            row["status"] = "error"
            row["error"] = f"{type(exc).__name__}: {exc}{_where(exc)}"
    row["warnings"] = " | ".join(sorted({f"{w.category.__name__}: {w.message}" for w in caught}))
    row["job_time"] = time.perf_counter() - t_start
    row["finished"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    return row


def _job_columns(job: Job) -> dict[str, Any]:
    return {"job_id": job.id, **job.params()}


def error_row(job: Job, exc: BaseException) -> dict[str, Any]:
    """The row of a job whose worker could not return one (e.g. Dask's ``KilledWorker``)."""
    return {**_job_columns(job), "status": "error", "error": f"{type(exc).__name__}: {exc}",
            "finished": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")}  # fmt: skip
