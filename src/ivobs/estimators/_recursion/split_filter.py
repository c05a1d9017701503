"""A linear filter split into the response that differs between the streams of a batch and the
response they share (computed once)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .kernels import is_shared
from .linear_filter import LinearFilter

__all__ = ["SplitFilter"]


class SplitFilter:
    """A :class:`LinearFilter` whose response is split into the part that differs between the
    streams of a batch and the part they share.

    ``run(v, x0)`` returns ``(data, shared)``: ``data[0]`` ``(B, T, n)`` is the response to the
    per-stream signals from ``x[0] = 0``; ``shared[0]`` ``(T, n)`` the response to ``x0``, the
    constant ``g`` and the signals that are the same for every stream (2-D, or broadcast with
    stride 0), computed once; ``x = data[0] + shared[0]``. The callers fold ``shared`` into the
    data-free offsets (the radius) they add anyway, so it costs no pass over the batch. For one
    record (no batch axis) everything is in ``data`` and ``shared`` is None.
    """

    def __init__(self, M: Any, W: Sequence[np.ndarray], g: np.ndarray | None = None):
        self.M, self.W, self.g = M, list(W), g
        self._cache: dict[tuple[bool, ...], tuple[LinearFilter, LinearFilter]] = {}
        self._full: LinearFilter | None = None

    def _filters(self, flags: tuple[bool, ...]) -> tuple[LinearFilter, LinearFilter]:
        hit = self._cache.get(flags)
        if hit is None:
            data = [W for W, f in zip(self.W, flags) if not f]
            shared = [W for W, f in zip(self.W, flags) if f]
            hit = (LinearFilter(self.M, data), LinearFilter(self.M, shared, self.g))
            self._cache[flags] = hit
        return hit

    def run(
        self, v: Sequence[np.ndarray], x0: np.ndarray | None = None
    ) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
        lead = max(a.ndim for a in v) - 2
        T = v[0].shape[-2]
        if lead == 0:
            if self._full is None:
                self._full = LinearFilter(self.M, self.W, self.g)
            return self._full.run(v, T=T, x0=x0), None
        B = max(a.shape[0] for a in v if a.ndim == 3)
        flags = tuple(is_shared(a, lead) for a in v)
        if all(flags):  # the same record for every stream: still one response per stream
            flags = (False, *flags[1:])
        fd, fs = self._filters(flags)
        dv = [np.broadcast_to(a, (B, *a.shape[-2:])) for a, f in zip(v, flags) if not f]
        sv = [a[(0,) * (a.ndim - 2)] for a, f in zip(v, flags) if f]
        return fd.run(dv, T=T), fs.run(sv, T=T, x0=x0)
