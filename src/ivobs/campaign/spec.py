"""Campaign specs (TOML): the grid of scenarios × disturbances × methods × option sets × seeds,
read with the file/line errors of :mod:`ivobs.io.reader`."""

from __future__ import annotations

import datetime as _dt
import importlib
import itertools
import math
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._validate import as_bool
from ..errors import IvobsError
from ..io.options import check_option, method_class
from ..io.reader import TomlReader
from .budget import BUDGET, seed_count
from .job import Job, canonical
from .worker import cached_scenario

__all__ = [
    "DISTURBANCES",
    "CampaignSpec",
    "MethodEntry",
    "load_spec",
    "loads_spec",
    "session_options",
]

DISTURBANCES = ("vertex", "uniform", "sinusoidal", "zero", "center", "paper", "recorded")
"""Disturbance kinds a spec may name (see :meth:`ivobs.scenarios.Scenario.simulate`)."""


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
        """The grid, scenario-major: scenario × disturbance × method × option set × seed.

        Each job's options are its option set over the defaults this process changed for its
        method (:func:`ivobs.config.set_defaults`): the worker processes do not share them, so
        the jobs carry them (and their ids differ from those of the classes' defaults)."""
        session = {e.name: session_options(e.name) for e in self.methods}
        grid = itertools.product(self.scenarios, self.disturbances, self.methods)
        return [
            Job(scenario=sc, method=entry.name, seed=seed, disturbance=dist,
                options={**session[entry.name], **opts},
                scenario_options=dict(self.scenario_options.get(sc, {})),
                burn_in=self.burn_in, imports=tuple(self.imports))
            for sc, dist, entry in grid for opts in entry.option_sets() for seed in self.seeds
        ]  # fmt: skip


def session_options(method: str) -> dict[str, Any]:
    """The defaults of ``method`` changed in this process (:mod:`ivobs.config`) as job options:
    plain values (NumPy arrays as lists), without those the worker gives every method itself
    (``strips``: an option passed by the command wins over a changed default)."""
    import numpy as np

    from ..config import overrides
    from ..estimators.measured import FILTERED

    out: dict[str, Any] = {}
    for key, value in overrides(method).items():
        if key in FILTERED:
            continue
        if isinstance(value, np.ndarray):
            value = value.tolist()
        elif isinstance(value, np.generic):
            value = value.item()
        try:
            canonical(value)
        except (TypeError, ValueError):
            raise IvobsError(
                f"{key}: the default of {method} set by ivobs.config.set_defaults is "
                f"{type(value).__name__} {value!r}, which a campaign job cannot carry to its "
                "workers (numbers, strings, booleans, lists and tables only); give it in the "
                "spec's options instead"
            ) from None
        out[key] = value
    return out


class _SpecReader(TomlReader):
    """Validate a parsed spec; errors name the file, the line and the key."""

    KEYS = (
        "name", "description", "scenarios", "methods", "seeds", "disturbance", "horizon",
        "burn_in", "scenario_options", "options", "output", "summary", "imports",
    )  # fmt: skip

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
        return self.once(key, [self.string(key, s) for s in v])

    def once(self, key: tuple[str, ...], values: list[Any]) -> list[Any]:
        """``values``, refused when one is listed twice."""
        dup = sorted(s for s, n in Counter(values).items() if n > 1)
        if dup:
            raise self.fail(key, f"listed twice: {', '.join(map(str, dup))}")
        return values

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

    def __init__(
        self, text: str, source: str, allow_code: bool, allow_outside: bool, allow_large: bool
    ):
        super().__init__(text, source)
        self.allow_code = as_bool("allow_code", allow_code)
        self.allow_outside = as_bool("allow_outside", allow_outside)
        self.budget = None if as_bool("allow_large", allow_large) else BUDGET

    def within(self, key: tuple[str, ...], what: str, value: int, unit: str) -> None:
        """Refuse ``value`` beyond the budget's limit of ``unit`` (:mod:`.budget`)."""
        if self.budget is None:
            return
        limit = {"jobs": self.budget.jobs, "steps": self.budget.steps,
                 "numbers": self.budget.record}[unit]  # fmt: skip
        msg = self.budget.refusal(what, value, limit, unit)
        if msg is not None:
            raise self.fail(key, msg)

    def output(self, key: tuple[str, ...], v: Any, base_dir: Path) -> Path:
        """An output of the spec: relative to its folder, and inside it (after following
        symbolic links) unless ``allow_outside``."""
        path = base_dir / self.string(key, v)
        if not self.allow_outside and not _inside(path, base_dir):
            raise self.fail(
                key,
                f"{v!r} is outside the spec's folder ({str(base_dir)!r}); a spec writes only "
                "there unless you pass --allow-outside (CLI) or allow_outside=True (API)",
            )
        return path

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
        scen = self.scenarios(doc["scenarios"], base_dir)
        methods = self.methods(doc["methods"], doc.get("options", {}))
        seeds = self.seeds(doc.get("seeds", [0]))
        dists = self.strings(("disturbance",), doc.get("disturbance", "vertex"), allow_one=True)
        for d in dists:
            if d not in DISTURBANCES:
                raise self.fail(
                    ("disturbance",),
                    f"unknown disturbance {d!r}; expected one of {', '.join(DISTURBANCES)}",
                )
        settings = sum(math.prod(len(v) for v in e.grid.values()) for e in methods)
        jobs = len(scen) * len(dists) * settings * len(seeds)
        self.within(("seeds",), "scenarios x disturbances x method settings x seeds", jobs, "jobs")
        sopts = self.scenario_options(scen, doc.get("scenario_options", {}), doc.get("horizon"))
        burn_in = self.integer(("burn_in",), doc["burn_in"]) if "burn_in" in doc else None
        self.check_steps(scen, sopts, jobs // len(scen), burn_in)
        if "recorded" in dists:
            self.check_recorded(scen, sopts)
        output = self.output(("output",), doc.get("output", f"{stem}.csv"), base_dir)
        summary = doc.get("summary")
        spec = CampaignSpec(
            scenarios=scen, methods=methods, seeds=seeds, disturbances=dists,
            scenario_options=sopts, burn_in=burn_in, output=output,
            summary=None if summary is None else self.output(("summary",), summary, base_dir),
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
            if not self.allow_code:
                raise self.fail(
                    ("imports",),
                    f"imports Python module {m!r}; loading the spec would run its code: pass "
                    "--allow-code (CLI) or allow_code=True (API) if you trust this spec",
                )
            try:
                importlib.import_module(m)
            except Exception as exc:
                raise self.fail(("imports",), f"cannot import {m!r}: {exc}") from None
        return mods

    def scenarios(self, v: Any, base_dir: Path) -> list[str]:
        """Scenario names, or system files (``*.toml``, relative to the spec's folder: the
        plant simulated from its prior box, :func:`ivobs.io.plant.file_scenario`)."""
        from .. import scenarios

        names = self.strings(("scenarios",), v)
        known = scenarios.names()
        out = []
        for n in names:
            if n.endswith(".toml"):
                path = (base_dir / n).resolve()
                if not path.is_file():
                    raise self.fail(("scenarios",), f"system file {n!r} not found ({path})")
                out.append(str(path))
            elif n not in known:
                raise self.fail(
                    ("scenarios",),
                    f"unknown scenario {n!r}; known: {', '.join(known)} (or a system file "
                    "ending in .toml)",
                )
            else:
                out.append(n)
        return out

    def methods(self, v: Any, options: Any) -> list[MethodEntry]:
        key = ("methods",)
        if not isinstance(v, list) or not v:
            raise self.fail(key, f"expected a non-empty list of method names, got {v!r}")
        options = self.table(("options",), options)
        grids: dict[str, dict[str, list[Any]]] = {}
        for name, table in options.items():
            cls = self.method_class(("options", name), name)
            grids[cls.name] = self.grid(
                ("options", name), cls, self.table(("options", name), table)
            )
        entries: list[MethodEntry] = []
        for i, item in enumerate(v):
            if isinstance(item, str):
                cls = self.method_class(key, item)
                entries.append(MethodEntry(cls.name, grids.get(cls.name, {})))
                continue
            if not isinstance(item, dict):
                raise self.fail(key, f"entry {i}: expected a name or {{ name = ..., options = "
                                     f"{{...}} }}, got {item!r}")  # fmt: skip
            extra = sorted(set(item) - {"name", "options"})
            if extra or "name" not in item:
                raise self.fail(key, f"entry {i}: expected the keys name and options, got "
                                     f"{sorted(item)}")  # fmt: skip
            cls = self.method_class(key, item["name"])
            grid = self.grid(key, cls, self.table(key, item.get("options", {})))
            entries.append(MethodEntry(cls.name, grid))
        for e in entries:  # before a grid's combinations are listed
            combos = math.prod(len(v) for v in e.grid.values())
            self.within(key, f"the options grid of {e.name}", combos, "jobs")
        listed = {e.name for e in entries}
        for name in grids:
            if name not in listed:
                raise self.fail(("options", name), f"method {name!r} is not in methods")
        return entries

    def method_class(self, key: tuple[str, ...], name: Any) -> Any:
        return method_class(self, key, self.string(key, name))

    def grid(self, key: tuple[str, ...], cls: Any, table: dict[str, Any]) -> dict[str, list[Any]]:
        out: dict[str, list[Any]] = {}
        for opt, val in table.items():
            k = (*key, opt)
            check_option(self, key, cls, opt)
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
                count = self.integer((*key, "count"), v["count"], low=1)
                self.within(("seeds", "count"), "seeds", count, "jobs")
                seeds = [start + step * i for i in range(count)]
            else:
                stop = self.integer((*key, "stop"), v["stop"])
                self.within(("seeds", "stop"), "seeds", seed_count(start, stop, step), "jobs")
                seeds = list(range(start, stop, step))
            if not seeds:
                raise self.fail(key, f"the range {v} holds no seed")
            return seeds
        if not isinstance(v, list) or not v:
            raise self.fail(key, f"expected a list of integers or {{ start = 0, stop = 10 }}, "
                                 f"got {v!r}")  # fmt: skip
        return self.once(key, [self.integer(key, s) for s in v])

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
        for name in scen:  # sizes within the budget before anything is built
            msg = None if self.budget is None else self.budget.scenario_sizes(out[name])
            if msg is not None:
                raise self.fail(("scenario_options", name) if name in table else ("horizon",), msg)
        for name in scen:  # build each once here: bad option values fail now, not per job
            try:
                cached_scenario(name, out[name])
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

    def check_steps(
        self, scen: list[str], sopts: dict[str, dict[str, Any]], jobs: int, burn_in: int | None
    ) -> None:
        """The records' sizes (steps × states) and the steps of all ``jobs`` per scenario,
        within the budget, and ``burn_in`` shorter than every record (the scenarios are built:
        their lengths are known)."""
        total = 0
        for name in scen:
            sc = cached_scenario(name, sopts[name])
            T = int(sc.t.size) if sc.t is not None else int(sc.horizon)
            key = ("scenario_options", name) if sopts[name] else ("scenarios",)
            self.within(key, f"scenario {name!r}: steps x states", T * sc.system.nx, "numbers")
            if burn_in is not None and burn_in >= T:
                raise self.fail(("burn_in",), f"{burn_in} leaves no step of scenario {name!r} "
                                              f"({T} steps); lower it")  # fmt: skip
            total += T * jobs
        self.within(("horizon",), "steps over all jobs", total, "steps")

    def check_recorded(self, scen: list[str], sopts: dict[str, dict[str, Any]]) -> None:
        """``disturbance = "recorded"`` needs scenarios with a stored record (every job of the
        others would fail)."""
        without = [n for n in scen if cached_scenario(n, sopts[n]).recorded is None]
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
    """Keyword options of a scenario builder (``horizon``, ``seed``, ...); a system file takes
    ``horizon``."""
    from .. import scenarios

    if name.endswith(".toml"):
        return ["horizon"]
    return scenarios.options(name)


def _inside(path: Path, folder: Path) -> bool:
    """Whether ``path`` lies in ``folder`` or below, symbolic links followed."""
    try:
        return path.resolve().is_relative_to(folder.resolve())
    except (OSError, RuntimeError):  # pragma: no cover - a symbolic link loop
        return False


def loads_spec(text: str, source: str = "<spec>", base_dir: str | os.PathLike[str] = ".",
               stem: str = "campaign", *, allow_code: bool = False, allow_outside: bool = False,
               allow_large: bool = False) -> CampaignSpec:  # fmt: skip
    """Parse and validate a spec given as text (paths relative to ``base_dir``;
    ``allow_code``, ``allow_outside``, ``allow_large``: as in :func:`load_spec`)."""
    reader = _SpecReader(text, source, allow_code, allow_outside, allow_large)
    return reader.read(Path(base_dir), stem)


def load_spec(
    path: str | os.PathLike[str],
    *,
    allow_code: bool = False,
    allow_outside: bool = False,
    allow_large: bool = False,
) -> CampaignSpec:
    """Read and validate a spec file; ``output`` and ``summary`` are relative to its folder.
    Errors (:class:`~ivobs.IvobsError`) name the file, the line and the key.

    Loading runs no code and writes nowhere but the spec's folder by default: a spec with
    ``imports = [...]`` is refused unless ``allow_code=True`` (importing a module runs its
    code, here and in every worker), and an ``output`` or ``summary`` outside the spec's folder
    (absolute, ``../``, or through a symbolic link) unless ``allow_outside=True``. A spec that
    asks for more work than the budget (:data:`~ivobs.campaign.budget.BUDGET`: jobs, steps,
    record sizes) is refused before anything is built unless ``allow_large=True``."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise IvobsError(f"spec: cannot read {str(path)!r}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise IvobsError(f"spec: {str(path)!r} is not UTF-8 text (a TOML file)") from None
    return loads_spec(
        text, source=str(path), base_dir=path.parent, stem=path.stem, allow_code=allow_code,
        allow_outside=allow_outside, allow_large=allow_large,
    )  # fmt: skip
