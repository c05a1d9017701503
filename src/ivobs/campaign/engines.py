"""Where jobs run: this process, local processes, or a Dask distributed cluster. Each engine
calls ``emit(row)`` with every finished job's row (in the campaign process)."""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from ..errors import IvobsError
from .job import Job
from .worker import error_row, run_job

_SINGLE_THREAD_ENV = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


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


def run_here(jobs: Sequence[Job], emit: Callable[[dict[str, Any]], None]) -> None:
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


def run_local(jobs: Sequence[Job], workers: int, emit: Callable[[dict[str, Any]], None]) -> None:
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
                        emit(error_row(job, exc))
        except BaseException:
            pool.shutdown(wait=False, cancel_futures=True)
            raise


def dask_client(scheduler: Any, timeout: float) -> tuple[Any, bool]:
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


def run_dask(jobs: Sequence[Job], client: Any, emit: Callable[[dict[str, Any]], None]) -> None:
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
                row = error_row(job, exc)
            fut.release()
            emit(row)
    except BaseException:
        client.cancel(futures)
        raise
