"""The HiGHS models that solve the trajectory program, warm-started from step to step.

Two HiGHS models (``highspy``) per program, one for the ``nx`` minimisations and one for the
``nx`` maximisations, solved in two threads. Each model keeps its basis from program to program
and from step to step (only the cost, the bounds or appended rows change), so every solve is
warm-started: a chain of neighbouring objectives ``min x[k][0], ..., min x[k][n-1]`` (and the
maxima in reverse order). The returned bounds are not the solver's objective values but the safe
bounds (S) of its multipliers (:mod:`~ivobs.estimators.exact.safe`, [Neumaier2004]), valid
whatever the solver returns; an infeasible verdict counts only with a Farkas certificate.
"""

from __future__ import annotations

import os
import sys
import weakref
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Protocol, cast

import highspy
import numpy as np

from .program import TrajectoryLP
from .safe import SafeBoundData, certifies_infeasibility, safe_min

__all__ = [
    "INFEASIBLE",
    "OK",
    "PARALLEL",
    "UNSURE",
    "Chain",
    "WarmStartedLP",
    "WarmStarts",
    "basis_array",
    "basis_of",
]

PARALLEL = (os.cpu_count() or 1) > 1
"""Solve the min and the max programs in two threads."""

_PRIMAL_TOL = 1e-9
"""HiGHS primal feasibility tolerance (on the shifted program)."""

_DUAL_TOL = 1e-10
"""HiGHS dual feasibility tolerance: the safe bound loses up to this times the sum of the
widths of the variables (two solves of one program that end on different optimal bases agree to
about that much, e.g. a state saved without bases and restored: 5e-9 for 16 steps of 2
states)."""

_ITERATION_LIMIT = 20_000
"""Simplex iterations allowed per program (typically 60-110 here, a few thousand on unstable
systems over a long horizon). A program stopped by it still gives a safe bound (S) from its last
multipliers; :attr:`WarmStartedLP.capped` counts them."""

OK, INFEASIBLE, UNSURE = "ok", "infeasible", "unsure"
"""Verdicts of a solve: bounds found; infeasible with a certificate; infeasible says HiGHS, but
no certificate (the sample is dropped without a report)."""

_INFEASIBLE = (
    highspy.HighsModelStatus.kInfeasible,
    highspy.HighsModelStatus.kUnboundedOrInfeasible,
)


class _Unstubbed(Protocol):
    """The methods of ``highspy.Highs`` used here that its type stubs omit."""

    def changeRowsBounds(
        self, num: int, indices: np.ndarray, lower: np.ndarray, upper: np.ndarray
    ) -> highspy.HighsStatus: ...

    def getDualRay(self) -> tuple[highspy.HighsStatus, bool, np.ndarray]: ...


def _unstubbed(h: highspy.Highs) -> _Unstubbed:
    return cast(_Unstubbed, h)


_BANNER_SILENCED = False


@contextmanager
def _first_highs_silenced() -> Iterator[None]:
    """Around the first ``highspy.Highs()`` of the process: HiGHS >= 1.15 prints its banner
    ("Running HiGHS ...") from C++ when the object is constructed, before any option (such as
    ``output_flag``) can be set. The C-level standard output is sent to ``/dev/null`` for that
    one call (HiGHS prints the banner once per process)."""
    global _BANNER_SILENCED
    if _BANNER_SILENCED:
        yield
        return
    _BANNER_SILENCED = True
    try:
        sys.stdout.flush()
        saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    except (OSError, ValueError, AttributeError):  # no file descriptor 1: nothing to silence
        yield
        return
    try:
        os.dup2(null, 1)
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def _new_highs() -> highspy.Highs:
    with _first_highs_silenced():
        h = highspy.Highs()  # type: ignore[no-untyped-call]  # its __init__ is unannotated
    h.setOptionValue("output_flag", False)
    h.setOptionValue("presolve", "off")
    h.setOptionValue("threads", 1)
    # tighter than HiGHS's 1e-7 defaults: the safe bound is only as tight as the duals
    h.setOptionValue("primal_feasibility_tolerance", _PRIMAL_TOL)
    h.setOptionValue("dual_feasibility_tolerance", _DUAL_TOL)
    # a bound on the work of one program: a solve that stalls (seen with Devex pricing, tried
    # and dropped: cora-vehicle6 never finished) ends as not optimal, and the safe bound (S)
    # of its last multipliers (or the variable bounds) is used; ~100 iterations are typical
    h.setOptionValue("simplex_iteration_limit", _ITERATION_LIMIT)
    # no HiGHS scaling: it is kept from the first solve and extended row by row as the program
    # grows, so a program rebuilt after restore() would be scaled (and solved) differently from
    # the one built step by step; the shift to the centres already scales the program
    h.setOptionValue("simplex_scale_strategy", 0)
    return h


def basis_array(b: highspy.HighsBasis) -> np.ndarray:
    """A HiGHS basis as int8 codes (the column statuses, then the row statuses)."""
    codes = [int(v) for v in b.col_status] + [int(v) for v in b.row_status]
    return np.array(codes, dtype=np.int8)


def basis_of(codes: np.ndarray, n_col: int) -> highspy.HighsBasis:
    """The HiGHS basis of :func:`basis_array` codes (``n_col`` columns)."""
    b = highspy.HighsBasis()
    status = [highspy.HighsBasisStatus(int(v)) for v in codes]
    b.col_status, b.row_status = status[:n_col], status[n_col:]
    b.valid, b.alien = True, False
    return b


_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    """Two workers for the two chains of programs (HiGHS releases the GIL while it solves)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="ivobs-exact")
    return _POOL


class WarmStartedLP:
    """A :class:`TrajectoryLP` with its two HiGHS chains (the ``min`` and the ``max``
    programs), which keep their bases from step to step."""

    def __init__(self, lp: TrajectoryLP, parallel: bool | None = None):
        self.lp = lp
        self.chains = (Chain(lp, 1.0), Chain(lp, -1.0))
        self.parallel = PARALLEL if parallel is None else parallel

    def bases(self) -> tuple[highspy.HighsBasis, ...]:
        """The bases the next step of each chain starts from."""
        return tuple(c.h.getBasis() for c in self.chains)

    def start(self, bases: tuple[highspy.HighsBasis, highspy.HighsBasis]) -> None:
        """Start the chains of a rebuilt program from ``bases`` (saved by :meth:`bases`): now
        if they fit the program, else at the first solve whose program they fit (a moving
        window keeps one block more than the state: the basis is that of the next program)."""
        for c, b in zip(self.chains, bases, strict=True):
            c.pending = b
            if _fits(b, self.lp.lo.size, self.lp.row_lo.size):
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
            (lo_b, v_lo), (hi_b, v_hi) = (job.result() for job in jobs)
        else:
            (lo_b, v_lo), (hi_b, v_hi) = (c.solve(sl.start, data) for c in self.chains)
        lp.relaxed = lp.relaxed or any(c.relaxed for c in self.chains)
        if INFEASIBLE in (v_lo, v_hi):
            return lower, upper, INFEASIBLE
        if UNSURE in (v_lo, v_hi):
            return lower, upper, UNSURE
        return np.maximum(lower, lo_b), np.minimum(upper, -hi_b), OK


def _fits(b: highspy.HighsBasis | None, n_col: int, n_row: int) -> bool:
    return b is not None and len(b.col_status) == n_col and len(b.row_status) == n_row


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


class Chain:
    """One HiGHS model solving ``min sense * x_last[i]`` for every ``i`` of the newest block.

    Before solving, the model is synchronised with the program as cheaply as the change allows:
    new bounds only (a moving window of a time-invariant system: same matrix, the basis is
    kept), appended rows and columns (full horizon: the basis is kept), or a rebuild. The ``nx``
    programs are solved one after the other, each warm-started from the previous optimum (dual
    simplex for the first, whose data changed; primal simplex for the next ones, where only the
    cost changed and the previous optimum is still feasible).
    """

    def __init__(self, lp: TrajectoryLP, sense: float):
        self.lp, self.sense = lp, sense
        self.h = _new_highs()
        self._synced: tuple[np.ndarray, np.ndarray, np.ndarray, int, int] | None = None
        self._cost_col: int | None = None  # the one column with a nonzero cost in the model
        self.relaxed = lp.relaxed  # rows given to HiGHS as ranges (else equalities)
        self.pending: highspy.HighsBasis | None = None  # a saved basis for the rebuilt model
        self.capped = 0  # programs stopped by the iteration budget

    def solve(self, first: int, data: SafeBoundData) -> tuple[np.ndarray, str]:
        """Safe lower bounds of ``sense * x[first + i]`` and the verdict (OK, INFEASIBLE with a
        certificate, UNSURE)."""
        self.relaxed = self.lp.relaxed
        self.sync()
        lp, h = self.lp, self.h
        # every step starts from the basis alone (no factorisation or pricing weights kept from
        # the previous step): the same start as the program rebuilt from a saved state
        basis = h.getBasis()
        h.clearSolver()
        if basis.valid:
            h.setBasis(basis)
        out = np.full(lp.nx, -np.inf)
        order = range(lp.nx) if self.sense > 0 else reversed(range(lp.nx))
        for n, i in enumerate(order):
            col = first + i
            if self._cost_col is not None and self._cost_col != col:
                h.changeColCost(self._cost_col, 0.0)
            h.changeColCost(col, self.sense)
            self._cost_col = col
            status = self._run(1 if n == 0 else 4)
            if status != highspy.HighsModelStatus.kOptimal:
                # a warm start can stall at a tiny infeasibility: only a cold solve decides
                h.clearSolver()
                status = self._run(1)
            if status in _INFEASIBLE:
                verdict, status = self._second_opinions(status, data)
                if verdict is not None:
                    return out, verdict
            if status == highspy.HighsModelStatus.kIterationLimit:
                self.capped += 1  # the budget is spent: the bound of the last multipliers
            elif status != highspy.HighsModelStatus.kOptimal:
                h.clearSolver()  # numerical trouble: a second opinion from the primal simplex
                status = self._run(4)
                if status in _INFEASIBLE and self._certified(data):
                    return out, INFEASIBLE
            # (S) holds for any multipliers: those of the last basis even if it is not optimal
            # (and the variable bound, λ = 0, if there are none)
            sol = h.getSolution()
            if sol.dual_valid and len(sol.row_dual) == data.free.size:
                lam = np.where(data.free, 0.0, np.asarray(sol.row_dual))
                out[i] = safe_min(lam, data, col, self.sense)
        return out, OK

    def _second_opinions(
        self, status: highspy.HighsModelStatus, data: SafeBoundData
    ) -> tuple[str | None, highspy.HighsModelStatus]:
        """HiGHS found the program infeasible (``status``): the verdict (INFEASIBLE with a
        certificate, UNSURE without; None if it was a rounding and the program is solved after
        all) and the status after the second opinions a missing certificate calls for."""
        h = self.h
        if self._certified(data):
            return INFEASIBLE, status
        if not self.relaxed:
            # equalities of floating-point data can be infeasible by a rounding: HiGHS sees the
            # ranges from now on (this step and, via the program, the next ones)
            self.relaxed = True
            _lo, _hi, rlo, rhi = self.lp.shifted(True)
            _unstubbed(h).changeRowsBounds(rlo.size, np.arange(rlo.size, dtype=np.int32), rlo, rhi)
            h.clearSolver()
            status = self._run(1)
        if status in _INFEASIBLE and not self._certified(data):
            h.clearSolver()  # no certificate: a second opinion from the primal simplex
            status = self._run(4)
        if status in _INFEASIBLE:
            return (INFEASIBLE if self._certified(data) else UNSURE), status
        return None, status

    def _certified(self, data: SafeBoundData) -> bool:
        _status, has_ray, ray = _unstubbed(self.h).getDualRay()
        ray = np.asarray(ray, dtype=float)
        if not has_ray or ray.size != self.lp.row_lo.size:
            return False
        return certifies_infeasibility(ray, data)

    def _run(self, strategy: int) -> highspy.HighsModelStatus:
        self.h.setOptionValue("simplex_strategy", strategy)
        self.h.run()
        return self.h.getModelStatus()

    def sync(self) -> None:
        """Bring the HiGHS model up to date with the program."""
        lp, h = self.lp, self.h
        n_row, n_col = lp.row_lo.size, lp.lo.size
        old = self._synced
        same = extends = False
        if old is not None:
            o_rows, o_cols, o_vals, o_nrow, o_ncol = old
            n = o_rows.size
            if n_row >= o_nrow and n_col >= o_ncol and lp.rows.size >= n:
                prefix = (
                    np.array_equal(lp.rows[:n], o_rows)
                    and np.array_equal(lp.cols[:n], o_cols)
                    and np.array_equal(lp.vals[:n], o_vals)
                )
                same = prefix and (n_row, n_col, lp.rows.size) == (o_nrow, o_ncol, n)
                extends = prefix and not same and bool(np.all(lp.rows[n:] >= o_nrow))
        if extends:
            assert old is not None
            self._append(old[3], old[4])
        elif not same:
            self._rebuild()
        lo, hi, rlo, rhi = lp.shifted(self.relaxed)
        h.changeColsBounds(n_col, np.arange(n_col, dtype=np.int32), lo, hi)
        _unstubbed(h).changeRowsBounds(n_row, np.arange(n_row, dtype=np.int32), rlo, rhi)
        self._synced = (lp.rows.copy(), lp.cols.copy(), lp.vals.copy(), n_row, n_col)

    def _append(self, o_nrow: int, o_ncol: int) -> None:
        lp = self.lp
        n_new = lp.lo.size - o_ncol
        m, starts, idx, vals = lp.csr(o_nrow)
        lo, hi, rlo, rhi = lp.shifted(self.relaxed, o_ncol, o_nrow)
        empty = np.zeros(0, np.int32)
        self.h.addCols(n_new, np.zeros(n_new), lo, hi, 0, empty, empty, np.zeros(0))
        self.h.addRows(m, rlo, rhi, vals.size, starts, idx, vals)

    def _rebuild(self) -> None:
        lp, h = self.lp, self.h
        n_col = lp.lo.size
        m, starts, idx, vals = lp.csr(0)
        lo, hi, rlo, rhi = lp.shifted(self.relaxed)
        empty = np.zeros(0, np.int32)
        basis = h.getBasis() if h.getNumCol() == n_col and h.getNumRow() == m else None
        if _fits(self.pending, n_col, m):
            basis, self.pending = self.pending, None  # the basis saved with a restored state
        h.clearModel()
        h.addCols(n_col, np.zeros(n_col), lo, hi, 0, empty, empty, np.zeros(0))
        h.addRows(m, rlo, rhi, vals.size, starts, idx, vals)
        if basis is not None and basis.valid:
            h.setBasis(basis)  # same shape (time-varying window): a good start
        self._cost_col = None
