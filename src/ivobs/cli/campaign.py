"""``ivobs campaign SPEC.toml``: a grid of scenarios × methods × options × seeds.

Runs on local processes by default, or on a Dask distributed cluster with ``--scheduler``.
Results go to one CSV table, one line per job as it finishes; running the same command again
resumes (jobs already in the table are skipped). A summary (mean width over seeds with a 95 %
confidence half-width, containment, times) is printed at the end. See ``docs/campaign.md``.

Exit status: 0; 1 when a box missed the true state, a job raised an unexpected error
(``status = error``; a method that declines a system is ``failed`` and expected) or every job
failed; 2 on a bad spec (``--dry-run`` also constructs every estimator once: invalid option
values are a bad spec).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from . import add_trust_option


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "campaign",
        help="run a grid of scenarios x methods x seeds (local processes or a Dask cluster)",
        description="Run every job of a campaign spec (TOML: scenarios, methods, options grids, "
        "seeds) and append one row per job to a CSV table. Interrupted campaigns resume: jobs "
        "already in the table are not recomputed. See docs/campaign.md.",
    )
    p.add_argument("spec", metavar="SPEC.toml", help="campaign spec")
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="Dask scheduler address (e.g. tcp://10.0.0.5:8786); needs ivobs[cluster]",
    )
    p.add_argument(
        "--workers",
        "-j",
        type=int,
        metavar="N",
        help="local processes (default: number of CPUs; 0: run in this process)",
    )
    p.add_argument("--output", "-o", metavar="FILE", help="results table (default: the spec's)")
    p.add_argument("--summary", metavar="FILE", help="also write the summary as Markdown")
    p.add_argument("--limit", type=int, metavar="N", help="run at most N new jobs, then stop")
    p.add_argument(
        "--retry-errors",
        action="store_true",
        help="rerun jobs recorded with status 'error' (unexpected exceptions, lost workers)",
    )
    p.add_argument(
        "--dry-run", action="store_true", help="count the jobs (total, done, to run) and stop"
    )
    p.add_argument(
        "--progress",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="progress bar (default: on a terminal only)",
    )
    p.add_argument("--quiet", "-q", action="store_true", help="no summary table")
    add_trust_option(p)
    p.add_argument(
        "--allow-outside",
        action="store_true",
        help="let the spec's output and summary lie outside the spec's folder (absolute paths, "
        "../, symbolic links); --output and --summary given here may lie anywhere",
    )
    p.add_argument(
        "--allow-large",
        action="store_true",
        help="run a spec beyond the campaign budget (jobs, steps, record sizes: "
        "docs/campaign.md); off by default, such a spec is refused before any work",
    )
    return p


def main(args: argparse.Namespace) -> int:
    from .. import campaign
    from ..campaign.run import spec_inputs
    from ..io.atomic import check_distinct

    spec = campaign.load_spec(
        args.spec,
        allow_code=args.allow_code,
        allow_outside=args.allow_outside,
        allow_large=args.allow_large,
    )
    if args.summary:
        spec.summary = Path(args.summary)
    output = Path(args.output) if args.output else spec.output
    check_distinct(
        {
            "--output" if args.output else "output": output,
            "--summary" if args.summary else "summary": spec.summary,
        },
        spec_inputs(spec),
    )
    jobs = spec.jobs()
    title = f"campaign {spec.name!r}" if spec.name else f"campaign {args.spec}"
    if args.dry_run:
        done = {r["job_id"] for r in campaign.read_results(output)} if output.is_file() else set()
        n_done = sum(j.id in done for j in jobs)
        declined = campaign.check_designs(spec)
        settings = sum(len(e.option_sets()) for e in spec.methods)
        print(
            f"{title}: {len(jobs)} jobs = {len(spec.scenarios)} scenarios x "
            f"{len(spec.disturbances)} disturbances x {settings} method settings x "
            f"{len(spec.seeds)} seeds; {n_done} already in {output}, "
            f"{len(jobs) - n_done} to run"
        )
        for line in declined:
            print(f"# declined (its jobs will be 'failed'): {line}")
        return 0
    try:
        res = campaign.run_campaign(
            spec,
            scheduler=args.scheduler,
            workers=args.workers,
            output=output,
            limit=args.limit,
            retry_errors=args.retry_errors,
            progress=args.progress,
        )
    except KeyboardInterrupt:
        print(
            f"\nivobs: interrupted; the finished jobs are in {output}: run the same command "
            "again to resume",
            file=sys.stderr,
        )
        raise
    failed, errors = res.count("failed"), res.count("error")
    where = f" on {res.engine}" if res.ran else ""
    print(
        f"# {title}: {res.total} jobs, {res.skipped} already done, {res.ran} run now{where} in "
        f"{res.wall_time:.1f} s; {failed} failed, {errors} errors -> {res.output}"
    )
    if not res.complete:
        print(f"# {res.total - len(res.rows)} jobs left: run the same command again to resume")
    if not args.quiet:
        print()
        print(res.summary())
    if spec.summary is not None:
        print(f"\nsummary: {spec.summary}")
    for r in res.violations:
        print(
            f"ivobs: SOUNDNESS VIOLATION: job {r['job_id']} ({r['method']} on {r['scenario']}, "
            f"seed {r['seed']}): a box missed the true state",
            file=sys.stderr,
        )
    if res.rows and not any(r["status"] == "ok" for r in res.rows):
        print(f"ivobs: every job failed ({failed} failed, {errors} errors): see the error column "
              f"of {res.output}", file=sys.stderr)  # fmt: skip
        return 1
    return 1 if res.violations or errors else 0
