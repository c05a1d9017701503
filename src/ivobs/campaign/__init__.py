"""Campaigns: a grid of scenarios × methods × options × seeds, run locally or on a Dask cluster.

A **campaign spec** (TOML, :func:`load_spec`) names the grid; every **job** (one scenario,
disturbance, method, option set and seed, identified by a stable hash: :attr:`Job.id`) gives one
row of the results table (:data:`COLUMNS`: the metrics of :func:`ivobs.report.compare`, times,
host, status). Rows are appended as jobs finish, so running a campaign again resumes it; a
method that declines the system is a ``failed`` row, any other exception an ``error`` row. Jobs
run on local processes, in this process (``workers=0``) or on a Dask cluster (``ivobs[cluster]``);
each worker reuses its designs across seeds (:data:`DESIGN_CACHE`).

**Trust**: a spec with ``imports = [...]`` (modules whose code would run here and in every
worker) is refused unless ``allow_code=True`` (``--allow-code``); ``output`` and ``summary``
must lie in the spec's folder unless ``allow_outside=True`` (``--allow-outside``). The spec
format, the engines and the table are described in ``docs/campaign.md``.
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
