"""The programs of an estimator's states, kept warm-started from step to step.

A :class:`WarmStartedLP` is a :class:`~.program.TrajectoryLP` with the HiGHS model that solves
its ``2 nx`` programs (:class:`~.highs.Chain`); :class:`WarmStarts` keeps one per state the
estimator advanced to (a cache outside the online state), with the basis each such state's next
step starts from.
"""

from __future__ import annotations

import os
import weakref
from concurrent.futures import ThreadPoolExecutor

import highspy
import numpy as np

from .highs import INFEASIBLE, OK, UNSURE, Chain, basis_fits
from .program import TrajectoryLP

__all__ = ["PARALLEL", "WarmStartedLP", "WarmStarts"]

PARALLEL = (os.cpu_count() or 1) > 1
"""With two models (``one_model=False``), solve the minima and the maxima in two threads."""

_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    """Two workers for the two chains of programs (HiGHS releases the GIL while it solves)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="ivobs-exact")
    return _POOL


class WarmStartedLP:
    """A :class:`TrajectoryLP` with the HiGHS models that solve its ``2 nx`` programs and keep
    their bases from step to step: one model for all of them (a chain ``min x[k][0], ...,
    min x[k][n-1], max x[k][n-1], ..., max x[k][0]``) or, with ``one_model=False``, one for
    the minima and one for the maxima, solved in two threads."""

    def __init__(
        self, lp: TrajectoryLP, parallel: bool | None = None, one_model: bool = True
    ) -> None:
        self.lp = lp
        if one_model:
            self.chains: tuple[Chain, ...] = (Chain(lp, (1.0, -1.0)),)
        else:
            self.chains = (Chain(lp, (1.0,)), Chain(lp, (-1.0,)))
        self.parallel = (PARALLEL if parallel is None else parallel) and len(self.chains) > 1

    def bases(self) -> tuple[highspy.HighsBasis, highspy.HighsBasis]:
        """The bases the next step of the minima and of the maxima starts from (the same basis
        twice with one model)."""
        b = [c.h.getBasis() for c in self.chains]
        return b[0], b[-1]

    def start(self, bases: tuple[highspy.HighsBasis, highspy.HighsBasis]) -> None:
        """Start the chains of a rebuilt program from ``bases`` (saved by :meth:`bases`; one
        model starts from the first): now if they fit the program, else at the first solve
        whose program they fit (a moving window keeps one block more than the state: the basis
        is that of the next program)."""
        for c, b in zip(self.chains, bases, strict=False):
            c.pending = b
            if basis_fits(b, self.lp.lo.size, self.lp.row_lo.size):
                c.sync()

    @property
    def capped(self) -> int:
        """Programs stopped by the iteration budget so far."""
        return sum(c.capped for c in self.chains)

    def last_x_box(self) -> tuple[np.ndarray, np.ndarray, str]:
        """Bounds of ``x`` of the newest block: ``(lower, upper, verdict)``.

        ``verdict`` is :data:`OK`, :data:`INFEASIBLE` (certified) or :data:`UNSURE`; unless
        it is OK, the bounds are the variable bounds (the interval prediction).
        """
        lp = self.lp
        sl = lp.last_x
        lower, upper = lp.lo[sl].copy(), lp.hi[sl].copy()
        data = lp.bound_data()
        if self.parallel:
            jobs = [_pool().submit(c.solve, sl.start, data) for c in self.chains]
            results = [job.result() for job in jobs]
        else:
            results = [c.solve(sl.start, data) for c in self.chains]
        lp.relaxed = lp.relaxed or any(c.relaxed for c in self.chains)
        verdicts = [v for _, v in results]
        if INFEASIBLE in verdicts:
            return lower, upper, INFEASIBLE
        if UNSURE in verdicts:
            return lower, upper, UNSURE
        bounds = np.concatenate([b for b, _ in results])  # rows: minima, then maxima
        return np.maximum(lower, bounds[0]), np.minimum(upper, -bounds[1]), OK


_Entry = tuple[
    tuple["weakref.ref[np.ndarray]", ...],
    tuple[object, ...],
    "WarmStartedLP | None",
    tuple[highspy.HighsBasis, ...],
]


class WarmStarts:
    """The warm-started programs of the states an estimator advanced to, and the bases each
    such state's next step starts from: a cache, not part of any state (a state holds data
    only; its bases are written out when it is saved).

    A program belongs to the data it was last advanced to: the arrays of a state (a step makes
    new arrays, and never modifies them once in a state) and a tag of its scalars. A state
    with other arrays (restored from a saved state, or built otherwise) has no program here
    and gets one rebuilt from its history (from the bases saved with it, if any). Taking a
    program removes it (advancing modifies it) but keeps the state's bases (copies); an entry
    goes when its first array does.
    """

    def __init__(self) -> None:
        self._entries: dict[int, _Entry] = {}

    def _find(self, arrays: tuple[np.ndarray, ...], tag: tuple[object, ...]) -> _Entry | None:
        entry = self._entries.get(id(arrays[0]))
        if entry is None:
            return None
        refs, saved_tag = entry[0], entry[1]
        if saved_tag != tag or any(r() is not a for r, a in zip(refs, arrays, strict=True)):
            return None
        return entry

    def take(self, arrays: tuple[np.ndarray, ...], tag: tuple[object, ...]) -> WarmStartedLP | None:
        """The program of exactly these arrays (the same objects) and tag, removed from the
        cache; None if there is none."""
        entry = self._find(arrays, tag)
        if entry is None:
            return None
        self._entries[id(arrays[0])] = (entry[0], entry[1], None, entry[3])
        return entry[2]

    def bases(
        self, arrays: tuple[np.ndarray, ...], tag: tuple[object, ...]
    ) -> tuple[highspy.HighsBasis, ...] | None:
        """The bases the next step from these arrays and tag starts from; None if unknown."""
        entry = self._find(arrays, tag)
        return None if entry is None else entry[3]

    def put(
        self, arrays: tuple[np.ndarray, ...], tag: tuple[object, ...], warm: WarmStartedLP
    ) -> None:
        """Keep ``warm`` (and a copy of its bases) as the program of ``arrays`` and ``tag``, as
        long as ``arrays[0]`` lives."""
        key = id(arrays[0])
        cache = weakref.ref(self)  # no reference cycle: the models go with the estimator

        def forget(ref: weakref.ref[np.ndarray]) -> None:
            owner = cache()
            if owner is not None:
                owner._forget(key, ref)

        first = weakref.ref(arrays[0], forget)
        refs = (first, *(weakref.ref(a) for a in arrays[1:]))
        self._entries[key] = (refs, tag, warm, warm.bases())

    def _forget(self, key: int, ref: weakref.ref[np.ndarray]) -> None:
        entry = self._entries.get(key)
        if entry is not None and entry[0][0] is ref:
            del self._entries[key]

    def __len__(self) -> int:
        """The programs held (states whose program was taken do not count)."""
        return sum(e[2] is not None for e in self._entries.values())
