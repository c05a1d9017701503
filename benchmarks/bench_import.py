"""Time of ``import ivobs`` in a fresh interpreter (issue 17 goal: <= 0.3 s).

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_import.py [repeats]

Median (and min, max) over ``repeats`` (default 15) fresh subprocesses of the wall time of
``python -c "import ivobs"``, next to the bare interpreter (``python -c pass``) and
``import numpy`` (ivobs' floor). Where the time goes: ``python -X importtime -c "import ivobs"``.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time


def wall(code: str, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-c", code], check=True)
        out.append(time.perf_counter() - start)
    return out


def main(repeats: int) -> None:
    for label, code in (
        ("python -c pass", "pass"),
        ("import numpy", "import numpy"),
        ("import ivobs", "import ivobs"),
    ):
        t = wall(code, repeats)
        print(
            f"{label:16s} median {statistics.median(t) * 1e3:6.0f} ms  "
            f"(min {min(t) * 1e3:.0f}, max {max(t) * 1e3:.0f}, {repeats} runs)"
        )


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 15)
