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

    ``run(v, x0)`` returns ``(data, shared)``: ``data[j]`` ``(B, T, p_j)`` is the response to the
    per-stream signals from ``x[0] = 0``; ``shared[j]`` ``(T, p_j)`` the response to ``x0``, the
    constants ``g``, ``h`` and the signals that are the same for every stream (2-D, or
    broadcast with stride 0), computed once; ``o_j = data[j] + shared[j]``. The callers fold
    ``shared`` into the data-free offsets (the radius) they add anyway, so it costs no pass
    over the batch. For one record (no batch axis) everything is in ``data`` and ``shared`` is
    None. Shared signals listed in ``as_data`` are copied per stream instead (cheaper when the
    caller has no offset to add). ``temp``: as in :meth:`LinearFilter.run`.
    """

    def __init__(
        self,
        M: Any,
        W: Sequence[np.ndarray],
        H: Sequence[np.ndarray],
        J: Sequence[Sequence[np.ndarray | None]] | None = None,
        g: np.ndarray | None = None,
        h: Sequence[np.ndarray | None] | None = None,
        block: int | None = None,
    ):
        self.args = (M, list(W), list(H), J, g, h)
        self.block = block
        nj, ns = len(H), len(W)
        self.J = J if J is not None else [[None] * ns for _ in range(nj)]
        self._cache: dict[tuple[bool, ...], tuple[LinearFilter, LinearFilter]] = {}
        self._full: LinearFilter | None = None

    def _filters(self, flags: tuple[bool, ...]) -> tuple[LinearFilter, LinearFilter]:
        hit = self._cache.get(flags)
        if hit is not None:
            return hit
        M, W, H, _, g, h = self.args
        data = [s for s, f in enumerate(flags) if not f]
        shared = [s for s, f in enumerate(flags) if f]
        fd = LinearFilter(
            M, [W[s] for s in data], H, [[Jj[s] for s in data] for Jj in self.J], block=self.block
        )
        fs = LinearFilter(
            M,
            [W[s] for s in shared],
            H,
            [[Jj[s] for s in shared] for Jj in self.J],
            g,
            h,
            block=self.block,
        )
        self._cache[flags] = (fd, fs)
        return fd, fs

    def run(
        self,
        v: Sequence[np.ndarray],
        x0: np.ndarray | None = None,
        out: Sequence[np.ndarray | None] | None = None,
        as_data: Sequence[int] = (),
        temp: Sequence[int] = (),
    ) -> tuple[list[np.ndarray], list[np.ndarray] | None]:
        lead = max(a.ndim for a in v) - 2
        T = v[0].shape[-2]
        if lead == 0:
            if self._full is None:
                M, W, H, _, g, h = self.args
                self._full = LinearFilter(M, W, H, self.J, g, h, block=self.block)
            return self._full.run(v, T=T, x0=x0, out=out, temp=temp), None
        B = max(a.shape[0] for a in v if a.ndim == 3)
        flags = tuple(is_shared(a, lead) and s not in as_data for s, a in enumerate(v))
        if all(flags):  # the same record for every stream: still one response per stream
            flags = (False, *flags[1:])
        fd, fs = self._filters(flags)
        dv = [np.broadcast_to(a, (B, *a.shape[-2:])) for a, f in zip(v, flags) if not f]
        sv = [a[(0,) * (a.ndim - 2)] for a, f in zip(v, flags) if f]
        data = fd.run(dv, T=T, out=out, temp=temp)
        shared = fs.run(sv, T=T, x0=x0)
        return data, shared
