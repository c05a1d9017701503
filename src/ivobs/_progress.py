"""Progress bars for long runs, drawn by ``tqdm``.

Shown where someone watches: ``enabled=None`` draws when the stream (``sys.stderr`` by default) is
a TTY or the code runs in a Jupyter kernel (there as a notebook widget when ``ipywidgets`` is
installed, through ``tqdm.auto``), so logs, pipes and test runs stay clean. This module only maps
ivobs' ``progress=`` convention (True, False, None) and units onto ``tqdm``.
"""

from __future__ import annotations

import sys
from typing import Any, TextIO

import numpy as np

from .errors import IvobsError

__all__ = ["Progress"]


def in_notebook() -> bool:
    """Whether this process is a Jupyter kernel (IPython with a kernel attached)."""
    shell = sys.modules.get("IPython")
    get = getattr(shell, "get_ipython", None)
    ip = get() if callable(get) else None
    return ip is not None and getattr(ip, "kernel", None) is not None


def _enabled(enabled: Any, stream: TextIO) -> bool:
    if enabled is None:
        isatty = getattr(stream, "isatty", None)
        return (bool(isatty()) if callable(isatty) else False) or in_notebook()
    if not isinstance(enabled, (bool, np.bool_)):
        raise IvobsError(f"progress: expected True, False or None, got {enabled!r}")
    return bool(enabled)


class Progress:
    """``with Progress(total, "exact") as bar: ... bar.update()``.

    Parameters
    ----------
    total : number of items expected.
    desc : label printed before the bar.
    enabled : True (always draw), False (never), None (draw when ``stream`` is a TTY).
    stream : where to draw (``sys.stderr`` at construction time by default).
    interval : minimum time between redraws, in seconds.
    unit : what is counted (``"step"``, ``"job"``): the rate reads ``unit/s``.
    """

    def __init__(
        self,
        total: int,
        desc: str = "",
        enabled: bool | None = None,
        stream: TextIO | None = None,
        interval: float = 0.2,
        unit: str = "step",
    ):
        self.total = max(int(total), 0)
        self.desc = desc
        self.stream = sys.stderr if stream is None else stream
        self.enabled = _enabled(enabled, self.stream)
        self.count = 0
        self._bar: Any = None
        if self.enabled:
            # imported where a bar is drawn: import ivobs stays light
            if in_notebook() and stream is None:
                from tqdm.auto import tqdm  # a widget in the notebook
            else:
                from tqdm import tqdm

            self._bar = tqdm(
                total=self.total,
                desc=desc or None,
                file=None if in_notebook() and stream is None else self.stream,
                mininterval=float(interval),
                unit=unit,
                dynamic_ncols=True,
                leave=True,
            )

    def update(self, n: int = 1) -> None:
        """Count ``n`` more items."""
        self.count += n
        if self._bar is not None:
            self._bar.update(n)

    def close(self) -> None:
        """Final redraw and newline (only if anything was drawn)."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
