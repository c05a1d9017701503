"""A minimal text progress bar for long runs (no dependency).

Shown only on a terminal: ``enabled=None`` draws when the stream (``sys.stderr`` by default) is a
TTY, so logs, pipes, notebooks' captured output and test runs stay clean. Redraws at most every
``interval`` seconds and always once at the end.
"""

from __future__ import annotations

import sys
import time
from typing import Any, TextIO

import numpy as np

from .errors import IvobsError

__all__ = ["Progress"]


class Progress:
    """``with Progress(total, "exact") as bar: ... bar.update()``.

    Parameters
    ----------
    total : number of steps expected.
    desc : label printed before the bar.
    enabled : True (always draw), False (never), None (draw when ``stream`` is a TTY).
    stream : where to draw (``sys.stderr`` at construction time by default).
    interval : minimum time between redraws, in seconds.
    """

    WIDTH = 30

    def __init__(
        self,
        total: int,
        desc: str = "",
        enabled: bool | None = None,
        stream: TextIO | None = None,
        interval: float = 0.2,
    ):
        self.total = max(int(total), 0)
        self.desc = desc
        self.stream = sys.stderr if stream is None else stream
        if enabled is None:
            isatty = getattr(self.stream, "isatty", None)
            enabled = bool(isatty()) if callable(isatty) else False
        elif not isinstance(enabled, (bool, np.bool_)):
            raise IvobsError(f"progress: expected True, False or None, got {enabled!r}")
        self.enabled = bool(enabled)
        self.interval = float(interval)
        self.count = 0
        self._start = time.perf_counter()
        self._last = -float("inf")
        self._closed = False

    def update(self, n: int = 1) -> None:
        """Count ``n`` more steps (redraws if enough time has passed)."""
        self.count += n
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last >= self.interval or self.count >= self.total:
            self._last = now
            self._draw(now)

    def _draw(self, now: float) -> None:
        frac = min(self.count / self.total, 1.0) if self.total else 1.0
        filled = round(frac * self.WIDTH)
        elapsed = now - self._start
        rate = self.count / elapsed if elapsed > 0 else 0.0
        eta = (self.total - self.count) / rate if rate > 0 else 0.0
        bar = "#" * filled + "." * (self.WIDTH - filled)
        label = f"{self.desc} " if self.desc else ""
        self.stream.write(
            f"\r{label}[{bar}] {self.count}/{self.total} "
            f"({rate:.1f} steps/s, {elapsed:.1f}s elapsed, eta {eta:.1f}s)"
        )
        self.stream.flush()

    def close(self) -> None:
        """Final redraw and newline (only if anything was drawn)."""
        if self._closed:
            return
        self._closed = True
        if self.enabled:
            self._draw(time.perf_counter())
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
