"""What the benchmarks share to time a call: the best CPU time of a few repeats (the figure
least disturbed by other jobs on a shared machine). Imported by the scripts of this folder
(run as ``python benchmarks/<script>.py``, which puts the folder on the path)."""

from __future__ import annotations

import time
from collections.abc import Callable


def cpu_best(fn: Callable[[], object], repeat: int = 3) -> float:
    """Best CPU time (``time.process_time``) of ``repeat`` calls of ``fn``."""
    best = float("inf")
    for _ in range(repeat):
        t0 = time.process_time()
        fn()
        best = min(best, time.process_time() - t0)
    return best
