"""Wall time of a 200-job campaign: 4 scenarios x 5 fast methods x 10 seeds, vertex disturbances.

Measures, with a fresh results table in a temporary folder:

1. the campaign on local processes (one per CPU; includes starting the pool: a fork server
   that imports ivobs and CVXPY once, then the workers);
2. the same command again: a resume with every job already in the table (0 recomputed);
3. for comparison, the same grid in this process (``workers=0``, serial);
4. with ``--dask``, the grid on a ``dask.distributed.LocalCluster`` (one worker per CPU,
   one thread each; cluster start-up not included).

Each row of the table records its own design and run times; their sum is the work done, the
wall time shows what the engine adds (start-up, scheduling, writing rows). The machine's load
average is printed: on a shared machine the wall time includes waiting for a core.

Run: ``python benchmarks/bench_campaign.py [--dask] [--workers N]``.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import textwrap
import time
from pathlib import Path

from ivobs import campaign

SPEC = """
name = "bench: 4 scenarios x 5 fast methods x 10 seeds"
scenarios = ["servo-motor", "dinh2019", "efimov-planar", "henon"]
methods = ["fixed-time", "reachability", "zonotope", "interval-split", "kkl"]
seeds = { start = 0, stop = 10 }
disturbance = "vertex"
horizon = 200
"""


def _work(rows: list[dict]) -> float:
    return sum(r["job_time"] or 0.0 for r in rows)


def _line(label: str, res: campaign.CampaignResult, wall: float) -> None:
    rate = res.ran / wall if wall > 0 and res.ran else float("nan")
    print(
        f"{label:<34} {wall:7.2f} s wall   {res.ran:4d} jobs run, {res.skipped:4d} skipped   "
        f"{rate:6.1f} jobs/s   ({res.count('ok')} ok, {res.count('failed')} failed, "
        f"{res.count('error')} errors)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--workers", type=int, default=None, help="local processes (default: CPUs)")
    ap.add_argument("--dask", action="store_true", help="also run on a Dask LocalCluster")
    ap.add_argument("--no-serial", action="store_true", help="skip the in-process run")
    args = ap.parse_args()
    n = args.workers or os.cpu_count() or 1

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "bench.toml"
        path.write_text(textwrap.dedent(SPEC))
        spec = campaign.load_spec(path)
        assert len(spec.jobs()) == 200
        print(f"# {spec.name}: 200 jobs, horizon 200; {os.cpu_count()} CPUs, "
              f"load average {os.getloadavg()[0]:.2f} at start")  # fmt: skip

        t0 = time.perf_counter()
        stamps: list[float] = []
        first = campaign.run_campaign(
            spec,
            workers=n,
            output=Path(tmp) / "local.csv",
            on_row=lambda row: stamps.append(time.perf_counter() - t0),
        )
        wall = time.perf_counter() - t0
        _line(f"local processes ({n})", first, wall)
        assert first.ran == 200 and first.complete and not first.violations
        print(f"{'':<34} first row after {stamps[0]:.2f} s (pool start-up: imports ivobs, CVXPY)")
        print(
            f"{'':<34} sum of job times {_work(first.rows):.2f} s "
            f"(design reused in {sum(bool(r['design_reused']) for r in first.rows)} jobs)"
        )

        t0 = time.perf_counter()
        again = campaign.run_campaign(spec, workers=n, output=Path(tmp) / "local.csv")
        _line("resume (all done)", again, time.perf_counter() - t0)
        assert again.ran == 0 and again.skipped == 200

        if not args.no_serial:
            t0 = time.perf_counter()
            serial = campaign.run_campaign(spec, workers=0, output=Path(tmp) / "serial.csv")
            _line("this process (serial)", serial, time.perf_counter() - t0)

        if args.dask:
            from distributed import LocalCluster

            with LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                              dashboard_address=None) as cluster:  # fmt: skip
                t0 = time.perf_counter()
                dres = campaign.run_campaign(spec, scheduler=cluster.scheduler_address,
                                             output=Path(tmp) / "dask.csv")  # fmt: skip
                _line(f"Dask LocalCluster ({n} workers)", dres, time.perf_counter() - t0)

        print(f"# load average {os.getloadavg()[0]:.2f} at end\n")
        print(first.summary())


if __name__ == "__main__":
    main()
