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

**Trust**: a spec with ``imports = ["my_package.my_estimators"]`` would import those modules
(in this process and in every worker), running their code: it is refused unless
``load_spec(path, allow_code=True)`` (``--allow-code``). ``output`` and ``summary`` must lie in
the spec's folder unless ``allow_outside=True`` (``--allow-outside``); the results table and the
summary are two files, neither of them the spec.
"""

from __future__ import annotations

from .designs import check_designs
from .job import Job
from .results import COLUMNS, ResultsFile, read_results
from .run import CampaignResult, run_campaign
from .spec import DISTURBANCES, CampaignSpec, MethodEntry, load_spec, loads_spec
from .summary import SummaryRow, summarize, summary_markdown
from .worker import DESIGN_CACHE, run_job

__all__ = [
    "COLUMNS",
    "DESIGN_CACHE",
    "DISTURBANCES",
    "CampaignResult",
    "CampaignSpec",
    "Job",
    "MethodEntry",
    "ResultsFile",
    "SummaryRow",
    "check_designs",
    "load_spec",
    "loads_spec",
    "read_results",
    "run_campaign",
    "run_job",
    "summarize",
    "summary_markdown",
]
