"""Running a campaign: the jobs not yet in the results table, on the chosen engine."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import IvobsError
from .engines import dask_client, run_dask, run_here, run_local
from .job import Job
from .results import ResultsFile, latest_rows
from .spec import CampaignSpec, load_spec
from .summary import summary_markdown

__all__ = ["CampaignResult", "run_campaign"]


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
    allow_code: bool = False,
    allow_outside: bool = False,
    allow_large: bool = False,
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
    allow_code, allow_outside, allow_large : when ``spec`` is a path, as in
        :func:`~ivobs.campaign.load_spec` (a spec that imports modules, writes outside its
        folder, or asks for more than the budget is refused without them).

    The results table and the summary must be two files, neither of them the spec itself.
    """
    from .._progress import Progress

    if not isinstance(spec, CampaignSpec):
        spec = load_spec(
            spec, allow_code=allow_code, allow_outside=allow_outside, allow_large=allow_large
        )
    out = Path(output) if output is not None else spec.output
    from ..io.atomic import check_distinct

    check_distinct({"output": out, "summary": spec.summary}, spec_inputs(spec))
    _check_engine(scheduler, workers, limit)
    jobs = spec.jobs()
    t0 = time.perf_counter()
    client, owned = (dask_client(scheduler, connect_timeout) if scheduler is not None
                     else (None, False))  # fmt: skip
    try:
        with ResultsFile(out) as table:
            todo, skipped = _pending(jobs, table.rows, retry_errors, limit)
            n = (os.cpu_count() or 1) if workers is None else workers
            n = min(n, len(todo))
            engine = (f"Dask cluster {getattr(client.scheduler, 'address', scheduler)}"
                      if client is not None
                      else "this process" if n == 0 else f"{n} local processes")  # fmt: skip
            with Progress(len(todo), "campaign", enabled=progress, unit="job") as bar:

                def emit(row: dict[str, Any]) -> None:
                    table.append(row)
                    bar.update()
                    if on_row is not None:
                        on_row(row)

                if client is not None and todo:
                    run_dask(todo, client, emit)
                elif n == 0:  # this process (no job left: nothing)
                    run_here(todo, emit)
                else:
                    run_local(todo, n, emit)
            latest = latest_rows(table.rows)
    finally:
        if owned and client is not None:
            client.close()
    rows = [latest[j.id] for j in jobs if j.id in latest]
    result = CampaignResult(
        spec=spec, output=out, total=len(jobs), ran=len(todo), skipped=skipped, rows=rows,
        wall_time=time.perf_counter() - t0, engine=engine,
    )  # fmt: skip
    if spec.summary is not None:
        from ..io.atomic import write_text_atomic

        write_text_atomic(spec.summary, _summary_document(result))
    return result


def spec_inputs(spec: CampaignSpec) -> dict[str, Any]:
    """The files a campaign reads, by what they are: the spec, its system files (scenarios
    ending in ``.toml``) and the bounds files those name (its outputs must be none of them,
    :func:`~ivobs.io.atomic.check_distinct`)."""
    from ..io.systemfile import load_system

    source = Path(spec.source)
    inputs: dict[str, Any] = {"the spec": source if source.is_file() else None}
    for name in spec.scenarios:
        if name.endswith(".toml"):
            inputs[f"scenario {name!r}"] = name
            for i, csv in enumerate(load_system(name).files):
                inputs[f"the bounds file {i + 1} of scenario {name!r}"] = csv
    return inputs


def _check_engine(scheduler: Any, workers: int | None, limit: int | None) -> None:
    for name, v in (("workers", workers), ("limit", limit)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v < 0):
            raise IvobsError(f"{name}: expected an integer >= 0, got {v!r}")
    if scheduler is not None and workers is not None:
        raise IvobsError(
            "workers: applies to local processes; with a scheduler the cluster's workers run "
            "the jobs (start more Dask workers instead)"
        )


def _pending(
    jobs: list[Job], rows: list[dict[str, Any]], retry_errors: bool, limit: int | None
) -> tuple[list[Job], int]:
    """The jobs to run now (grouped by design: jobs of one design run close together) and the
    number of jobs already done."""
    latest = latest_rows(rows)
    redo = {"error"} if retry_errors else set()
    todo = [j for j in jobs if j.id not in latest or latest[j.id]["status"] in redo]
    skipped = len(jobs) - len(todo)
    todo.sort(key=lambda j: (j.design_key(), j.disturbance, j.seed))  # stable
    if limit is not None:
        todo = todo[:limit]
    return todo, skipped


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
