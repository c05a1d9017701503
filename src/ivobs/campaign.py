"""Campaigns: a grid of scenarios × methods × options × seeds, run locally or on a Dask cluster.

A **campaign spec** (TOML) names the grid::

    name = "fast methods under vertex disturbances"
    scenarios = ["servo-motor", "dinh2019"]
    methods = ["interval-split", "zonotope", { name = "kkl", options = { tune = [true, false] } }]
    seeds = { start = 0, stop = 10 }          # or a list: [0, 1, 2]
    disturbance = "vertex"                    # or a list: a grid axis too
    horizon = 200                             # scenarios that accept a horizon
    burn_in = 20                              # steps left out of the mean widths
    output = "results.csv"                    # relative to the spec's folder
    summary = "summary.md"                    # optional Markdown summary

    [options.zonotope]                        # a grid: every combination of the listed values
    order = [6, 12]

Every **job** (one scenario, disturbance, method, option set and seed) simulates the scenario
with that seed, designs the method for its system, runs it on the record and gives one row of
the results table: the mean width per state after the burn-in (and their mean), whether every
box contains the true state, ``valid_from``, the design and run times, the host and worker that
ran it, and the error if it failed. The metrics are those of :func:`ivobs.report.compare`.

* **Job ids** are a stable hash of the job's parameters (:attr:`Job.id`): the same spec gives the
  same ids on every machine and every run.
* **Incremental results**: each finished job is appended to the CSV table at once (one line,
  flushed). Running the campaign again skips the ids already in the table, so an interrupted
  campaign resumes without recomputing what is done (a line cut short by a crash is dropped and
  its job rerun).
* **Failures are rows**: a method that declines the system (an :class:`~ivobs.IvobsError`, e.g.
  an infeasible design) gives ``status = failed``; any other exception gives ``status = error``
  with its type, message and location. Neither stops the campaign.
* **Engines**: local processes (:class:`concurrent.futures.ProcessPoolExecutor`, the default),
  this process (``workers=0``, for debugging), or a Dask distributed cluster
  (``scheduler="tcp://host:8786"``: ``dask.distributed.Client`` does the scheduling; Dask is the
  optional extra ``ivobs[cluster]``). Worker processes run with single-threaded BLAS.
* **Design reuse**: a design depends on the system and the options, not on the seed, so each
  worker keeps the estimators it designed (:data:`DESIGN_CACHE`) and reuses them for the other
  seeds; the row then records the original design time and ``design_reused = true``.

Loading a spec with ``imports = ["my_package.my_estimators"]`` imports those modules (in this
process and in every worker): that runs their code, so load specs from trusted sources only.
"""

from __future__ import annotations

import contextlib
import csv
import datetime as _dt
import hashlib
import importlib
import itertools
import json
import math
import multiprocessing
import os
import socket
import sys
import threading
import time
import tomllib
import traceback
import warnings
from collections import OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from .errors import IvobsError

__all__ = [
    "COLUMNS",
    "DESIGN_CACHE",
    "CampaignResult",
    "CampaignSpec",
    "Job",
    "MethodEntry",
    "load_spec",
    "loads_spec",
    "read_results",
    "run_campaign",
    "run_job",
    "summarize",
    "summary_markdown",
]

DISTURBANCES = ("vertex", "uniform", "sinusoidal", "zero", "center", "paper", "recorded")
"""Disturbance kinds a spec may name (see :meth:`ivobs.scenarios.Scenario.simulate`)."""

COLUMNS = (
    "job_id", "scenario", "scenario_options", "disturbance", "method", "options", "seed",
    "burn_in", "horizon", "status", "contains", "valid_from", "inconsistent", "mean_width",
    "widths", "design_time", "design_reused", "run_time", "job_time", "host", "worker",
    "finished", "ivobs_version", "warnings", "error",
)  # fmt: skip
"""Columns of the results table, in order (one line per job)."""

DESIGN_CACHE = 64
"""Estimators kept per worker process (and thread) for reuse across seeds."""

_SINGLE_THREAD_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


# ============================================================================================
# jobs
# ============================================================================================
def _canonical(value: Any) -> str:
    """JSON with sorted keys and no spaces: the stable text a job id hashes."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True)


@dataclass(frozen=True)
class Job:
    """One cell of the grid. ``burn_in=None``: a tenth of the record (as ``ivobs compare``)."""

    scenario: str
    method: str
    seed: int
    disturbance: str = "vertex"
    options: dict[str, Any] = field(default_factory=dict)
    scenario_options: dict[str, Any] = field(default_factory=dict)
    burn_in: int | None = None
    imports: tuple[str, ...] = ()

    def params(self) -> dict[str, Any]:
        """Everything that determines the result (``imports`` only make names available)."""
        return {
            "scenario": self.scenario,
            "scenario_options": self.scenario_options,
            "disturbance": self.disturbance,
            "method": self.method,
            "options": self.options,
            "seed": self.seed,
            "burn_in": self.burn_in,
        }

    @cached_property
    def id(self) -> str:
        """16 hex digits of the SHA-256 of the canonical JSON of :meth:`params`."""
        return hashlib.sha256(_canonical(self.params()).encode()).hexdigest()[:16]

    def design_key(self) -> str:
        """Jobs with the same key share a design (they differ only in seed and disturbance)."""
        return _canonical(
            [self.scenario, self.scenario_options, self.method, self.options, list(self.imports)]
        )

    def to_dict(self) -> dict[str, Any]:
        """Plain values, for another process or a Dask worker."""
        return {**self.params(), "imports": list(self.imports), "job_id": self.id}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Job:
        return cls(
            scenario=d["scenario"], method=d["method"], seed=d["seed"],
            disturbance=d["disturbance"], options=dict(d["options"]),
            scenario_options=dict(d["scenario_options"]), burn_in=d["burn_in"],
            imports=tuple(d.get("imports", ())),
        )  # fmt: skip


# ============================================================================================
# the spec
# ============================================================================================
@dataclass
class MethodEntry:
    """A method of the spec and its options grid (``{option: [values to try]}``)."""

    name: str
    grid: dict[str, list[Any]] = field(default_factory=dict)

    def option_sets(self) -> list[dict[str, Any]]:
        keys = list(self.grid)
        return [dict(zip(keys, combo)) for combo in itertools.product(*self.grid.values())]


@dataclass
class CampaignSpec:
    """A validated campaign spec (see the module docstring for the format)."""

    scenarios: list[str]
    methods: list[MethodEntry]
    seeds: list[int]
    disturbances: list[str] = field(default_factory=lambda: ["vertex"])
    scenario_options: dict[str, dict[str, Any]] = field(default_factory=dict)
    burn_in: int | None = None
    output: Path = Path("results.csv")
    summary: Path | None = None
    imports: list[str] = field(default_factory=list)
    name: str = ""
    description: str = ""
    source: str = "<spec>"

    def jobs(self) -> list[Job]:
        """The grid, scenario-major: scenario × disturbance × method × option set × seed."""
        out = []
        for sc, dist, entry in itertools.product(self.scenarios, self.disturbances, self.methods):
            for opts in entry.option_sets():
                for seed in self.seeds:
                    out.append(Job(
                        scenario=sc, method=entry.name, seed=seed, disturbance=dist,
                        options=opts, scenario_options=dict(self.scenario_options.get(sc, {})),
                        burn_in=self.burn_in, imports=tuple(self.imports),
                    ))  # fmt: skip
        return out


class _SpecReader:
    """Validate a parsed spec; errors name the file, the line and the key."""

    KEYS = (
        "name", "description", "scenarios", "methods", "seeds", "disturbance", "horizon",
        "burn_in", "scenario_options", "options", "output", "summary", "imports",
    )  # fmt: skip

    def __init__(self, text: str, source: str):
        from .io import KeyLines  # the system files' key -> line map

        self.source = source
        self.lines = KeyLines(text)
        try:
            self.doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise IvobsError(f"{source}: not valid TOML ({exc})") from None

    def fail(self, key: tuple[str, ...], msg: str) -> IvobsError:
        line = self.lines.line(key)
        where = f", line {line}" if line else ""
        return IvobsError(f"{self.source}{where}: {'.'.join(key) or '(top level)'}: {msg}")

    # -- small checks ----------------------------------------------------------------------
    def string(self, key: tuple[str, ...], v: Any) -> str:
        if not isinstance(v, str) or not v.strip():
            raise self.fail(key, f"expected a non-empty string, got {v!r}")
        return v.strip()

    def integer(self, key: tuple[str, ...], v: Any, low: int = 0) -> int:
        if isinstance(v, bool) or not isinstance(v, int) or v < low:
            raise self.fail(key, f"expected an integer >= {low}, got {v!r}")
        return v

    def table(self, key: tuple[str, ...], v: Any) -> dict[str, Any]:
        if not isinstance(v, dict):
            raise self.fail(key, f"expected a table, got {v!r}")
        return v

    def strings(self, key: tuple[str, ...], v: Any, allow_one: bool = False) -> list[str]:
        if allow_one and isinstance(v, str):
            v = [v]
        if not isinstance(v, list) or not v:
            raise self.fail(key, f"expected a non-empty list of strings, got {v!r}")
        out = [self.string(key, s) for s in v]
        dup = sorted({s for s in out if out.count(s) > 1})
        if dup:
            raise self.fail(key, f"listed twice: {', '.join(dup)}")
        return out

    def plain(self, key: tuple[str, ...], v: Any) -> Any:
        """TOML values a job id can hash (no dates and times)."""
        if isinstance(v, (_dt.date, _dt.time)):
            raise self.fail(key, f"dates and times are not option values (got {v!r})")
        if isinstance(v, float) and not math.isfinite(v):
            raise self.fail(key, f"expected a finite number, got {v!r}")
        if isinstance(v, list):
            return [self.plain(key, x) for x in v]
        if isinstance(v, dict):
            return {k: self.plain((*key, k), x) for k, x in v.items()}
        return v

    # -- the parts of the spec ------------------------------------------------------------
    def read(self, base_dir: Path, stem: str) -> CampaignSpec:
        doc = self.doc
        for k in doc:
            if k not in self.KEYS:
                raise self.fail((k,), f"unknown key {k!r}; allowed keys: {', '.join(self.KEYS)}")
        for k in ("scenarios", "methods"):
            if k not in doc:
                raise self.fail((), f"missing key {k!r} (a list of names)")
        imports = self.imports(doc.get("imports", []))
        scen = self.scenarios(doc["scenarios"])
        methods = self.methods(doc["methods"], doc.get("options", {}))
        seeds = self.seeds(doc.get("seeds", [0]))
        dists = self.strings(("disturbance",), doc.get("disturbance", "vertex"), allow_one=True)
        for d in dists:
            if d not in DISTURBANCES:
                raise self.fail(
                    ("disturbance",),
                    f"unknown disturbance {d!r}; expected one of {', '.join(DISTURBANCES)}",
                )
        sopts = self.scenario_options(scen, doc.get("scenario_options", {}), doc.get("horizon"))
        if "recorded" in dists:
            self.check_recorded(scen, sopts)
        burn_in = None
        if "burn_in" in doc:
            burn_in = self.integer(("burn_in",), doc["burn_in"])
            self.check_burn_in(scen, sopts, burn_in)
        output = base_dir / self.string(("output",), doc.get("output", f"{stem}.csv"))
        summary = doc.get("summary")
        spec = CampaignSpec(
            scenarios=scen, methods=methods, seeds=seeds, disturbances=dists,
            scenario_options=sopts, burn_in=burn_in, output=output,
            summary=None if summary is None else base_dir / self.string(("summary",), summary),
            imports=imports, name=str(doc.get("name", "")),
            description=str(doc.get("description", "")), source=self.source,
        )  # fmt: skip
        self.check_unique(spec)
        return spec

    def imports(self, v: Any) -> list[str]:
        if v == []:
            return []
        mods = self.strings(("imports",), v)
        for m in mods:
            try:
                importlib.import_module(m)
            except Exception as exc:
                raise self.fail(("imports",), f"cannot import {m!r}: {exc}") from None
        return mods

    def scenarios(self, v: Any) -> list[str]:
        from . import scenarios

        names = self.strings(("scenarios",), v)
        known = scenarios.names()
        for n in names:
            if n not in known:
                raise self.fail(
                    ("scenarios",), f"unknown scenario {n!r}; known: {', '.join(known)}"
                )
        return names

    def methods(self, v: Any, options: Any) -> list[MethodEntry]:
        from .estimators import get as get_method

        key = ("methods",)
        if not isinstance(v, list) or not v:
            raise self.fail(key, f"expected a non-empty list of method names, got {v!r}")
        options = self.table(("options",), options)
        grids: dict[str, dict[str, list[Any]]] = {}
        for name, table in options.items():
            cls = self.method_class(("options", name), name, get_method)
            grids[cls.name] = self.grid(
                ("options", name), cls, self.table(("options", name), table)
            )
        entries: list[MethodEntry] = []
        for i, item in enumerate(v):
            if isinstance(item, str):
                cls = self.method_class(key, item, get_method)
                entries.append(MethodEntry(cls.name, grids.get(cls.name, {})))
                continue
            if not isinstance(item, dict):
                raise self.fail(key, f"entry {i}: expected a name or {{ name = ..., options = "
                                     f"{{...}} }}, got {item!r}")  # fmt: skip
            extra = sorted(set(item) - {"name", "options"})
            if extra or "name" not in item:
                raise self.fail(key, f"entry {i}: expected the keys name and options, got "
                                     f"{sorted(item)}")  # fmt: skip
            cls = self.method_class(key, item["name"], get_method)
            grid = self.grid(key, cls, self.table(key, item.get("options", {})))
            entries.append(MethodEntry(cls.name, grid))
        listed = {e.name for e in entries}
        for name in grids:
            if name not in listed:
                raise self.fail(("options", name), f"method {name!r} is not in methods")
        return entries

    def method_class(self, key: tuple[str, ...], name: Any, get_method: Callable) -> Any:
        try:
            return get_method(self.string(key, name))
        except IvobsError as exc:
            if str(exc).startswith(self.source):
                raise
            raise self.fail(key, str(exc).removeprefix("method: ")) from None

    def grid(self, key: tuple[str, ...], cls: Any, table: dict[str, Any]) -> dict[str, list]:
        allowed = cls.options()
        out: dict[str, list[Any]] = {}
        for opt, val in table.items():
            k = (*key, opt)
            if opt not in allowed:
                raise self.fail(k, f"{cls.name} does not accept the option {opt!r}; accepted: "
                                   f"{', '.join(allowed) or '(none)'}")  # fmt: skip
            val = self.plain(k, val)
            values = val if isinstance(val, list) else [val]
            if not values:
                raise self.fail(k, "an empty list of values gives no jobs; give at least one")
            out[opt] = values
        return out

    def seeds(self, v: Any) -> list[int]:
        key = ("seeds",)
        if isinstance(v, dict):
            extra = sorted(set(v) - {"start", "stop", "step", "count"})
            if extra:
                raise self.fail((*key, extra[0]), "expected the keys start, stop, step or count")
            start = self.integer((*key, "start"), v.get("start", 0))
            step = self.integer((*key, "step"), v.get("step", 1), low=1)
            if ("stop" in v) == ("count" in v):
                raise self.fail(key, "give either stop (exclusive) or count, e.g. "
                                     "{ start = 0, stop = 10 }")  # fmt: skip
            if "count" in v:
                seeds = [
                    start + step * i
                    for i in range(self.integer((*key, "count"), v["count"], low=1))
                ]
            else:
                seeds = list(range(start, self.integer((*key, "stop"), v["stop"]), step))
            if not seeds:
                raise self.fail(key, f"the range {v} holds no seed")
            return seeds
        if not isinstance(v, list) or not v:
            raise self.fail(key, f"expected a list of integers or {{ start = 0, stop = 10 }}, "
                                 f"got {v!r}")  # fmt: skip
        seeds = [self.integer(key, s) for s in v]
        dup = sorted({s for s in seeds if seeds.count(s) > 1})
        if dup:
            raise self.fail(key, f"listed twice: {dup}")
        return seeds

    def scenario_options(
        self, scen: list[str], table: Any, horizon: Any
    ) -> dict[str, dict[str, Any]]:
        out: dict[str, dict[str, Any]] = {s: {} for s in scen}
        table = self.table(("scenario_options",), table)
        for name, opts in table.items():
            k = ("scenario_options", name)
            if name not in scen:
                raise self.fail(k, f"scenario {name!r} is not in scenarios")
            for opt, val in self.table(k, opts).items():
                if opt not in _builder_params(name):
                    raise self.fail(
                        (*k, opt),
                        f"scenario {name!r} has no option {opt!r}; "
                        f"accepted: {', '.join(_builder_params(name))}",
                    )
                out[name][opt] = self.plain((*k, opt), val)
        if horizon is not None:
            self.horizon(scen, horizon, out)
        for name in scen:  # build each once here: bad option values fail now, not per job
            try:
                _scenario(name, out[name])
            except IvobsError as exc:
                raise self.fail(("scenario_options", name), str(exc)) from None
        return out

    def horizon(self, scen: list[str], v: Any, out: dict[str, dict[str, Any]]) -> None:
        key = ("horizon",)
        takers = [s for s in scen if "horizon" in _builder_params(s)]
        if isinstance(v, dict):
            per = {}
            for name, h in v.items():
                if name not in scen:
                    raise self.fail((*key, name), f"scenario {name!r} is not in scenarios")
                if name not in takers:
                    raise self.fail((*key, name), f"scenario {name!r} has no horizon option")
                per[name] = self.integer((*key, name), h, low=1)
        else:
            h = self.integer(key, v, low=1)
            if not takers:
                raise self.fail(key, f"none of the scenarios ({', '.join(scen)}) has a horizon "
                                     "option")  # fmt: skip
            per = dict.fromkeys(takers, h)
        for name, h in per.items():
            if "horizon" in out[name]:
                raise self.fail(key, f"scenario {name!r}: horizon given twice (here and in "
                                     "[scenario_options])")  # fmt: skip
            out[name]["horizon"] = h

    def check_burn_in(self, scen: list[str], sopts: dict[str, dict], burn_in: int) -> None:
        for name in scen:
            sc = _scenario(name, sopts[name])
            T = int(sc.t.size) if sc.t is not None else int(sc.horizon)
            if burn_in >= T:
                raise self.fail(("burn_in",), f"{burn_in} leaves no step of scenario {name!r} "
                                              f"({T} steps); lower it")  # fmt: skip

    def check_recorded(self, scen: list[str], sopts: dict[str, dict]) -> None:
        """``disturbance = "recorded"`` needs scenarios with a stored record (every job of the
        others would fail)."""
        without = [n for n in scen if _scenario(n, sopts[n]).recorded is None]
        if without:
            raise self.fail(("disturbance",), f"'recorded' needs scenarios with a stored record; "
                                              f"none in: {', '.join(without)}")  # fmt: skip

    def check_unique(self, spec: CampaignSpec) -> None:
        seen: dict[str, Job] = {}
        for job in spec.jobs():
            if job.id in seen:
                raise self.fail(
                    ("methods",),
                    f"two entries give the same jobs ({job.method} "
                    f"with options {job.options or '{}'}); "
                    "list each method and option set once",
                )
            seen[job.id] = job


def _builder_params(name: str) -> list[str]:
    """Keyword options of a scenario builder (``horizon``, ``seed``, ...)."""
    from . import scenarios

    return scenarios.options(name)


def loads_spec(text: str, source: str = "<spec>", base_dir: str | os.PathLike[str] = ".",
               stem: str = "campaign") -> CampaignSpec:  # fmt: skip
    """Parse and validate a spec given as text (paths relative to ``base_dir``)."""
    return _SpecReader(text, source).read(Path(base_dir), stem)


def load_spec(path: str | os.PathLike[str]) -> CampaignSpec:
    """Read and validate a spec file; ``output`` and ``summary`` are relative to its folder.
    Errors (:class:`~ivobs.IvobsError`) name the file, the line and the key."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise IvobsError(f"spec: cannot read {str(path)!r}: {exc.strerror or exc}") from None
    return loads_spec(text, source=str(path), base_dir=path.parent, stem=path.stem)


# ============================================================================================
# one job (runs in a worker)
# ============================================================================================
_SCENARIOS: OrderedDict[str, Any] = OrderedDict()
_DESIGNS: OrderedDict[tuple[str, int], tuple[Any, float]] = OrderedDict()


def _lru(cache: OrderedDict, key: Any, make: Callable[[], Any], size: int) -> tuple[Any, bool]:
    """``(value, reused)`` from a small LRU cache."""
    if key in cache:
        cache.move_to_end(key)
        return cache[key], True
    value = make()
    cache[key] = value
    while len(cache) > size:
        cache.popitem(last=False)
    return value, False


def _scenario(name: str, options: dict[str, Any]) -> Any:
    from . import scenarios

    key = _canonical([name, options, threading.get_ident()])
    return _lru(_SCENARIOS, key, lambda: scenarios.get(name, **options), 16)[0]


def _design(job: Job, sc: Any) -> tuple[Any, float, bool]:
    """``(estimator, design time, reused)``; a design that failed fails again from the cache
    (an infeasible LMI is not retried for every seed)."""
    from .estimators import make_estimator

    def attempt() -> tuple[Any, float]:
        t0 = time.perf_counter()
        try:
            est = make_estimator(job.method, sc.system, x0=sc.x0, **job.options)
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


def check_designs(spec: CampaignSpec) -> list[str]:
    """Construct every estimator of the spec once (per scenario, method and option set): an
    invalid option value (every job of it would fail) raises :class:`~ivobs.IvobsError` naming
    the spec and the method's options. Returns one line per design that the method declines
    (``DesignError``, or a system class it does not support: those jobs are recorded as
    ``failed``, which is expected)."""
    from .errors import DesignError
    from .estimators import make_estimator

    for mod in spec.imports:
        importlib.import_module(mod)
    declined: list[str] = []
    seen: set[str] = set()
    for job in spec.jobs():
        key = job.design_key()
        if key in seen:
            continue
        seen.add(key)
        sc = _scenario(job.scenario, job.scenario_options)
        try:
            make_estimator(job.method, sc.system, x0=sc.x0, **job.options)
        except DesignError as exc:
            declined.append(f"{job.method} {job.options or ''} on {job.scenario}: {exc}")
        except IvobsError as exc:
            if not job.options or "support" in str(exc):
                declined.append(f"{job.method} on {job.scenario}: {exc}")
                continue
            raise IvobsError(
                f"{spec.source}: options.{job.method} = {job.options} (scenario "
                f"{job.scenario}): {exc}"
            ) from None
    return declined


def run_job(job: Job | dict[str, Any]) -> dict[str, Any]:
    """Run one job and return its row (a dict over :data:`COLUMNS`); never raises for a failing
    method or scenario: the error goes into the row."""
    import numpy as np

    from . import __version__

    job = Job.from_dict(job) if isinstance(job, dict) else job
    t_start = time.perf_counter()
    row: dict[str, Any] = {**_job_columns(job), "status": "ok", "host": socket.gethostname(),
                           "worker": _worker_name(), "ivobs_version": __version__}  # fmt: skip
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            for mod in job.imports:
                importlib.import_module(mod)
            sc = _scenario(job.scenario, job.scenario_options)
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
    return {
        "job_id": job.id, "scenario": job.scenario, "scenario_options": job.scenario_options,
        "disturbance": job.disturbance, "method": job.method, "options": job.options,
        "seed": job.seed, "burn_in": job.burn_in,
    }  # fmt: skip


def _error_row(job: Job, exc: BaseException) -> dict[str, Any]:
    """The row of a job whose worker could not return one (e.g. Dask's ``KilledWorker``)."""
    return {**_job_columns(job), "status": "error", "error": f"{type(exc).__name__}: {exc}",
            "finished": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")}  # fmt: skip


# ============================================================================================
# the results table
# ============================================================================================
def _cell(v: Any) -> str:
    """One CSV field on one line (a row is one line: a cut-off last line is easy to drop)."""
    if v is None:
        return ""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, dict)):
        return _canonical(v)
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
    reader = csv.reader(lines)
    header = next(reader)
    if tuple(header) != COLUMNS:
        raise IvobsError(
            f"output: {str(path)!r} is not a results table of this ivobs version "
            f"(columns {header[:4]}...; expected {list(COLUMNS[:4])}...); choose another "
            "output file"
        )
    rows = []
    for line, fields in enumerate(reader, start=2):
        if len(fields) != len(COLUMNS):
            raise IvobsError(
                f"output: {str(path)!r}, line {line}: expected {len(COLUMNS)} fields, got "
                f"{len(fields)}; the file was edited: fix or delete that line"
            )
        rows.append(_parse_row(dict(zip(COLUMNS, fields))))
    return rows


class _ResultsFile:
    """The CSV table, opened for appending: existing rows read, a cut-off last line removed,
    an exclusive lock held (two campaigns never interleave their lines)."""

    def __init__(self, path: Path):
        self.path = path
        self.rows: list[dict[str, Any]] = []
        self.fh: Any = None

    def __enter__(self) -> _ResultsFile:
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
        text = fh.read()
        self.rows = _parse_table(text, self.path)
        if text and not text.endswith("\n"):  # remove the cut-off line before appending
            keep = text.rfind("\n") + 1
            fh.truncate(len(text[:keep].encode("utf-8")))
            text = text[:keep]
        fh.seek(0, os.SEEK_END)
        if not text:
            csv.writer(fh, lineterminator="\n").writerow(COLUMNS)
            fh.flush()

    def append(self, row: dict[str, Any]) -> None:
        cells = [_cell(row.get(c)) for c in COLUMNS]
        csv.writer(self.fh, lineterminator="\n").writerow(cells)
        self.fh.flush()
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
    return list(_latest(_parse_table(text, path)).values())


def _latest(rows: Iterable[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for r in rows:
        out.pop(r["job_id"], None)
        out[r["job_id"]] = r
    return out


# ============================================================================================
# engines
# ============================================================================================
@contextlib.contextmanager
def _single_thread_blas() -> Iterator[None]:
    """Worker processes inherit this environment: one BLAS thread each (many processes with
    threaded BLAS thrash the cores). Variables the user set are left alone."""
    added = [v for v in _SINGLE_THREAD_ENV if v not in os.environ]
    for v in added:
        os.environ[v] = "1"
    try:
        yield
    finally:
        for v in added:
            os.environ.pop(v, None)


def _run_here(jobs: Sequence[Job], emit: Callable[[dict[str, Any]], None]) -> None:
    for job in jobs:
        emit(run_job(job))


def _watch_parent(pid: int) -> None:
    """Worker initializer: exit when the campaign process is gone (killed with SIGKILL, it
    cannot shut its pool down, and idle workers would otherwise wait for jobs forever)."""

    def watch() -> None:
        while True:
            time.sleep(1.0)
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                os._exit(1)
            except OSError:  # pragma: no cover - exists, but not ours to signal
                pass

    threading.Thread(target=watch, name="ivobs-watch-parent", daemon=True).start()


def _run_local(jobs: Sequence[Job], workers: int, emit: Callable[[dict[str, Any]], None]) -> None:
    """A process pool with a bounded queue (an interruption cancels the queue at once; jobs of
    one design run close together). Workers are forked from a *fork server* that imported ivobs
    and CVXPY once, under the single-thread BLAS environment (not from this process: its BLAS
    threads and other threads must not be forked); later campaigns reuse the server."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(["ivobs.campaign", "cvxpy"])
    todo = iter(jobs)
    pending: dict[Any, Job] = {}
    with (
        _single_thread_blas(),
        ProcessPoolExecutor(
            workers, mp_context=ctx, initializer=_watch_parent, initargs=(os.getpid(),)
        ) as pool,
    ):
        try:
            while True:
                while len(pending) < 2 * workers and (job := next(todo, None)) is not None:
                    pending[pool.submit(run_job, job.to_dict())] = job
                if not pending:
                    return
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    job = pending.pop(fut)
                    try:
                        emit(fut.result())
                    except BrokenProcessPool:
                        lost = ", ".join(j.id for j in [job, *pending.values()])
                        raise IvobsError(
                            "a worker process died (out of memory or killed?) while running "
                            f"jobs {lost}; the finished jobs are saved: run the campaign "
                            "again to resume"
                        ) from None
                    except Exception as exc:  # e.g. a result that could not be pickled
                        emit(_error_row(job, exc))
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def _dask_client(scheduler: Any, timeout: float) -> tuple[Any, bool]:
    """``(client, owned)`` for an address or an existing ``distributed.Client``."""
    try:
        from distributed import Client
    except ImportError:
        raise IvobsError(
            "scheduler: running on a Dask cluster needs dask.distributed; install it with "
            "pip install 'ivobs[cluster]'"
        ) from None
    if isinstance(scheduler, Client):
        return scheduler, False
    try:
        client = Client(str(scheduler), timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise IvobsError(
            f"scheduler: cannot connect to the Dask scheduler at {scheduler!r} ({exc}); start "
            "one with `dask scheduler` and workers with `dask worker ADDRESS`"
        ) from None
    return client, True


def _run_dask(jobs: Sequence[Job], client: Any, emit: Callable[[dict[str, Any]], None]) -> None:
    """One Dask task per job; Dask schedules, retries lost workers and reports ``KilledWorker``
    (recorded as an error row). Workers need ivobs (and ``imports``) installed."""
    from distributed import as_completed

    futures = client.map(run_job, [j.to_dict() for j in jobs], pure=False)
    by_key = {f.key: j for f, j in zip(futures, jobs)}
    try:
        with client.as_current():  # as_completed looks for the current client
            done = as_completed(futures)
        for fut in done:
            job = by_key[fut.key]
            try:
                row = fut.result()
            except Exception as exc:
                row = _error_row(job, exc)
            fut.release()
            emit(row)
    except BaseException:
        client.cancel(futures)
        raise


# ============================================================================================
# running a campaign
# ============================================================================================
@dataclass
class CampaignResult:
    """What :func:`run_campaign` did. ``rows``: the latest row of every job of the spec found in
    the table (in grid order); ``ran``: jobs computed by this call."""

    spec: CampaignSpec
    output: Path
    total: int
    ran: int
    skipped: int
    rows: list[dict[str, Any]]
    wall_time: float
    engine: str

    def count(self, status: str) -> int:
        return sum(r["status"] == status for r in self.rows)

    @property
    def violations(self) -> list[dict[str, Any]]:
        """Rows whose boxes missed the true state: a soundness bug, never expected."""
        return [r for r in self.rows if r["contains"] is False]

    @property
    def complete(self) -> bool:
        return len(self.rows) == self.total

    def summary(self) -> str:
        return summary_markdown(self.rows, self.spec)


def run_campaign(
    spec: CampaignSpec | str | os.PathLike[str],
    *,
    scheduler: Any = None,
    workers: int | None = None,
    output: str | os.PathLike[str] | None = None,
    limit: int | None = None,
    retry_errors: bool = False,
    progress: bool | None = None,
    connect_timeout: float = 10.0,
    on_row: Callable[[dict[str, Any]], None] | None = None,
) -> CampaignResult:
    """Run the jobs of ``spec`` not yet in its results table and return the whole table's rows.

    Parameters
    ----------
    spec : a :class:`CampaignSpec` or the path of a spec file.
    scheduler : a Dask scheduler address (``"tcp://host:8786"``) or a ``distributed.Client``;
        ``None``: local processes.
    workers : local processes (default: the number of CPUs); ``0`` runs in this process.
    output : the results table (default: the spec's ``output``).
    limit : run at most this many new jobs (the rest on a later call).
    retry_errors : rerun jobs whose row has ``status = error`` (not ``failed``: a method that
        declined a system declines it again).
    progress : progress bar on stderr (``None``: on a terminal).
    on_row : called with every new row (in the parent process).
    """
    from ._progress import Progress

    if not isinstance(spec, CampaignSpec):
        spec = load_spec(spec)
    out = Path(output) if output is not None else spec.output
    for name, v in (("workers", workers), ("limit", limit)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
            raise IvobsError(f"{name}: expected an integer >= 0, got {v!r}")
    if scheduler is not None and workers is not None:
        raise IvobsError(
            "workers: applies to local processes; with a scheduler the cluster's workers run "
            "the jobs (start more Dask workers instead)"
        )
    jobs = spec.jobs()
    t0 = time.perf_counter()
    client, owned = (_dask_client(scheduler, connect_timeout) if scheduler is not None
                     else (None, False))  # fmt: skip
    try:
        with _ResultsFile(out) as table:
            latest = _latest(table.rows)
            redo = {"error"} if retry_errors else set()
            todo = [j for j in jobs if j.id not in latest or latest[j.id]["status"] in redo]
            skipped = len(jobs) - len(todo)
            todo.sort(key=lambda j: (j.design_key(), j.disturbance, j.seed))  # stable
            if limit is not None:
                todo = todo[:limit]
            n = (os.cpu_count() or 1) if workers is None else workers
            n = min(n, len(todo))
            engine = (f"Dask cluster {getattr(client.scheduler, 'address', scheduler)}"
                      if client is not None
                      else "this process" if n == 0 else f"{n} local processes")  # fmt: skip
            with Progress(len(todo), "campaign", enabled=progress) as bar:

                def emit(row: dict[str, Any]) -> None:
                    table.append(row)
                    bar.update()
                    if on_row is not None:
                        on_row(row)

                if not todo:
                    pass
                elif client is not None:
                    _run_dask(todo, client, emit)
                elif n == 0:
                    _run_here(todo, emit)
                else:
                    _run_local(todo, n, emit)
            latest = _latest(table.rows)
    finally:
        if owned:
            client.close()
    rows = [latest[j.id] for j in jobs if j.id in latest]
    result = CampaignResult(
        spec=spec, output=out, total=len(jobs), ran=len(todo), skipped=skipped, rows=rows,
        wall_time=time.perf_counter() - t0, engine=engine,
    )  # fmt: skip
    if spec.summary is not None:
        from .io import write_text_atomic

        write_text_atomic(spec.summary, _summary_document(result))
    return result


def _summary_document(result: CampaignResult) -> str:
    spec = result.spec
    head = f"# Campaign {spec.name}".rstrip() + "\n\n"
    if spec.description:
        head += spec.description + "\n\n"
    head += (
        f"{len(result.rows)} of {result.total} jobs in `{result.output.name}` "
        f"(spec `{spec.source}`). Mean width: mean over seeds of the per-job mean width "
        "over states after the burn-in; ± the 95 % confidence half-width (Student t).\n\n"
    )
    return head + summary_markdown(result.rows, spec) + "\n"


# ============================================================================================
# summary
# ============================================================================================
@dataclass
class SummaryRow:
    """One scenario × disturbance × method × option set over its seeds."""

    scenario: str
    disturbance: str
    method: str
    options: dict[str, Any]
    scenario_options: dict[str, Any]
    jobs: int = 0
    ok: int = 0
    mean_width: float = math.nan
    ci95: float = math.nan
    contained: int = 0
    checked: int = 0
    design_time: float = math.nan
    run_time: float = math.nan
    note: str = ""


def summarize(rows: Iterable[dict[str, Any]]) -> list[SummaryRow]:
    """Group rows by scenario, disturbance, method and options (first-seen order): mean width
    over seeds with its 95 % confidence half-width ``t_{0.975, n-1} s / √n``, containment
    counts, mean design and run times, and the most frequent error of the failed jobs."""
    import numpy as np
    from scipy import stats

    groups: dict[str, list[dict[str, Any]]] = {}
    for r in rows:
        key = _canonical([r["scenario"], r["scenario_options"], r["disturbance"], r["method"],
                          r["options"]])  # fmt: skip
        groups.setdefault(key, []).append(r)
    out = []
    for rs in groups.values():
        r0 = rs[0]
        s = SummaryRow(r0["scenario"], r0["disturbance"], r0["method"], r0["options"] or {},
                       r0["scenario_options"] or {}, jobs=len(rs))  # fmt: skip
        ok = [r for r in rs if r["status"] == "ok"]
        s.ok = len(ok)
        w = np.array([r["mean_width"] for r in ok], dtype=float)
        if w.size:
            s.mean_width = float(w.mean())
            if w.size > 1:
                s.ci95 = float(stats.t.ppf(0.975, w.size - 1) * w.std(ddof=1) / np.sqrt(w.size))
            s.design_time = float(np.mean([r["design_time"] for r in ok]))
            s.run_time = float(np.mean([r["run_time"] for r in ok]))
        checked = [r["contains"] for r in ok if r["contains"] is not None]
        s.checked, s.contained = len(checked), sum(checked)
        errors = [r["error"] or r["status"] for r in rs if r["status"] != "ok"]
        if errors:
            top = max(set(errors), key=errors.count)
            s.note = top if len(top) <= 100 else top[:97] + "..."
        out.append(s)
    return out


def _fmt_options(opts: dict[str, Any]) -> str:
    return ", ".join(f"{k}={_canonical(v) if not isinstance(v, str) else v}"
                     for k, v in opts.items()) or "—"  # fmt: skip


def summary_markdown(rows: Iterable[dict[str, Any]], spec: CampaignSpec | None = None) -> str:
    """The summary as a Markdown table (a disturbance column when there are several, an options
    column when any method has options)."""
    summ = summarize(rows)
    if not summ:
        return "(no results yet)"
    many_d = len({s.disturbance for s in summ}) > 1 or (spec and len(spec.disturbances) > 1)
    any_o = any(s.options for s in summ)
    head = ["scenario"] + (["disturbance"] if many_d else []) + ["method"]
    head += (["options"] if any_o else []) + ["ok/jobs", "mean width", "± 95 %", "contained",
                                               "design (s)", "run (s)", "note"]  # fmt: skip
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for s in summ:
        cells = [s.scenario] + ([s.disturbance] if many_d else []) + [s.method]
        cells += [_fmt_options(s.options)] if any_o else []
        contained = (
            "n/a"
            if not s.checked
            else f"{s.contained}/{s.checked}"
            if s.contained == s.checked
            else f"**{s.contained}/{s.checked}**"
        )
        cells += [
            f"{s.ok}/{s.jobs}",
            "—" if math.isnan(s.mean_width) else f"{s.mean_width:.4g}",
            "—" if math.isnan(s.ci95) else f"{s.ci95:.2g}",
            contained,
            "—" if math.isnan(s.design_time) else f"{s.design_time:.3f}",
            "—" if math.isnan(s.run_time) else f"{s.run_time:.4f}",
            s.note.replace("|", "\\|"),
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)
