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
import weakref
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from typing import Any

import numpy as np

from ...errors import IvobsError
from ...sets.lp import LinearProgram, basis_codes, basis_of
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
    "check_basis_codes",
    "with_saved_bases",
]

PARALLEL = (os.cpu_count() or 1) > 1
"""Solve the min and the max programs in two threads."""

ITERATION_LIMIT = 20_000
"""Simplex iterations allowed per program (typically 60-110 here, a few thousand on unstable
systems over a long horizon). A program stopped by it still gives a safe bound (S) from its last
multipliers; :attr:`WarmStartedLP.capped` counts them."""

OK, INFEASIBLE, UNSURE = "ok", "infeasible", "unsure"
"""Verdicts of a solve: bounds found; infeasible with a certificate; infeasible says HiGHS, but
no certificate (the sample is dropped without a report)."""


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

    def bases(self) -> tuple[Any, ...]:
        """The bases the next step of each chain starts from."""
        return tuple(c.prog.basis() for c in self.chains)

    def start(self, bases: tuple[Any, Any]) -> None:
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


def _fits(b: Any, n_col: int, n_row: int) -> bool:
    return b is not None and len(b.col_status) == n_col and len(b.row_status) == n_row


_Entry = tuple[
    tuple["weakref.ref[np.ndarray]", ...],
    tuple[object, ...],
    "WarmStartedLP | None",
    tuple[Any, ...],
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
    ) -> tuple[Any, ...] | None:
        """The bases the next step from these arrays and tag starts from; None if unknown."""
        entry = self._find(arrays, tag)
        return None if entry is None else entry[3]

    def start_of(self, state: Any, tag: tuple[object, ...], n_col: int) -> tuple[Any, Any] | None:
        """The bases the next step of ``state`` (a state with ``history``, ``basis_min`` and
        ``basis_max``) starts from: those saved with it (``n_col`` columns: its program's), or
        those of its warm-started program; None if neither (a cold start)."""
        if state.basis_min.size and state.basis_max.size:
            return basis_of(state.basis_min, n_col), basis_of(state.basis_max, n_col)
        bases = self.bases(state.history, tag)
        return None if bases is None else (bases[0], bases[1])

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
        # HiGHS's scaling is off: it would be kept from the first solve and extended row by
        # row as the program grows, so a program rebuilt after ``restore()`` would be scaled
        # (and solved) differently from the one built step by step; the shift to the centres
        # already scales the program. The iteration limit bounds a solve that stalls (its last
        # multipliers still give a safe bound).
        self.prog = LinearProgram(iteration_limit=ITERATION_LIMIT, scale=False)
        self._synced: tuple[np.ndarray, np.ndarray, np.ndarray, int, int] | None = None
        self._cost_col: int | None = None  # the one column with a nonzero cost in the model
        self.relaxed = lp.relaxed  # rows given to HiGHS as ranges (else equalities)
        self.pending: Any = None  # a saved basis for the rebuilt model
        self.capped = 0  # programs stopped by the iteration budget

    def solve(self, first: int, data: SafeBoundData) -> tuple[np.ndarray, str]:
        """Safe lower bounds of ``sense * x[first + i]`` and the verdict (OK, INFEASIBLE with a
        certificate, UNSURE)."""
        self.relaxed = self.lp.relaxed
        self.sync()
        prog = self.prog
        # every step starts from the basis alone (no factorisation or pricing weights kept from
        # the previous step): the same start as the program rebuilt from a saved state
        prog.restart()
        out = np.full(self.lp.nx, -np.inf)
        order = range(self.lp.nx) if self.sense > 0 else reversed(range(self.lp.nx))
        for n, i in enumerate(order):
            col = first + i
            if self._cost_col is not None and self._cost_col != col:
                prog.set_cost(np.array([self._cost_col]), np.zeros(1))
            prog.set_cost(np.array([col]), np.array([self.sense]))
            self._cost_col = col
            status = prog.solve(primal=n > 0)
            if status != "optimal":
                # a warm start can stall at a tiny infeasibility: only a cold solve decides
                prog.cold()
                status = prog.solve()
            if status == "infeasible":
                verdict, status = self._second_opinions(data)
                if verdict is not None:
                    return out, verdict
            if status == "failed" and not self.relaxed:
                # numerical trouble on the equalities (large magnitudes): the ranges from now on
                self._relax()
                status = prog.solve()
            if status == "limit":
                self.capped += 1  # the budget is spent: the bound of the last multipliers
            elif status != "optimal":
                prog.cold()  # numerical trouble: a second opinion from the primal simplex
                status = prog.solve(primal=True)
                if status == "infeasible" and self._certified(data):
                    return out, INFEASIBLE
            # (S) holds for any multipliers: those of the last basis even if it is not optimal
            # (and the variable bound, λ = 0, if there are none)
            lam = prog.row_duals()
            # (multipliers of another program, e.g. one whose rows did not fit the model after
            # data beyond the float range, give no bound: the variable bound stays)
            if lam is not None and lam.shape == data.free.shape:
                lam = self.lp.duals(lam, col)  # of the original rows (HiGHS sees them scaled)
                out[i] = safe_min(np.where(data.free, 0.0, lam), data, col, self.sense)
        return out, OK

    def _second_opinions(self, data: SafeBoundData) -> tuple[str | None, str]:
        """HiGHS found the program infeasible: the verdict (INFEASIBLE with a certificate,
        UNSURE without; None if it was a rounding and the program is solved after all) and the
        status after the second opinions a missing certificate calls for."""
        prog, status = self.prog, "infeasible"
        if self._certified(data):
            return INFEASIBLE, status
        if not self.relaxed:
            # equalities of floating-point data can be infeasible by a rounding
            self._relax()
            status = prog.solve()
        if status == "infeasible" and not self._certified(data):
            prog.cold()  # no certificate: a second opinion from a cold start
            status = prog.solve()
        if status == "infeasible":
            return (INFEASIBLE if self._certified(data) else UNSURE), status
        return None, status

    def _relax(self) -> None:
        """HiGHS sees the rows as their ranges ``rhs ± tau`` from now on (this step and, via
        the program, the next ones), from a cold start."""
        self.relaxed = True
        _lo, _hi, rlo, rhi = self.lp.shifted(True)
        self.prog.set_row_bounds(rlo, rhi)
        self.prog.cold()

    def _certified(self, data: SafeBoundData) -> bool:
        ray = self.prog.dual_ray()
        if ray is None or ray.shape != self.lp.row_scale.shape:
            return False
        return certifies_infeasibility(self.lp.duals(ray), data)

    def sync(self) -> None:
        """Bring the HiGHS model up to date with the program."""
        lp = self.lp
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
                    and np.array_equal(lp.hvals[:n], o_vals)
                )
                same = prefix and (n_row, n_col, lp.rows.size) == (o_nrow, o_ncol, n)
                extends = prefix and not same and bool(np.all(lp.rows[n:] >= o_nrow))
        if extends:
            assert old is not None
            self._append(old[3], old[4])
        elif not same:
            self._rebuild()
        lo, hi, rlo, rhi = lp.shifted(self.relaxed)
        self.prog.set_bounds(lo, hi)
        self.prog.set_row_bounds(rlo, rhi)
        self._synced = (lp.rows.copy(), lp.cols.copy(), lp.hvals.copy(), n_row, n_col)

    def _append(self, o_nrow: int, o_ncol: int) -> None:
        lp = self.lp
        _, starts, idx, vals = lp.csr(o_nrow)
        lo, hi, rlo, rhi = lp.shifted(self.relaxed, o_ncol, o_nrow)
        self.prog.add_cols(lo, hi)
        self.prog.add_rows((starts, idx, vals), rlo, rhi)

    def _rebuild(self) -> None:
        lp, prog = self.lp, self.prog
        n_col = lp.lo.size
        m, starts, idx, vals = lp.csr(0)
        lo, hi, rlo, rhi = lp.shifted(self.relaxed)
        basis = prog.basis() if prog.n_cols == n_col and prog.n_rows == m else None
        if _fits(self.pending, n_col, m):
            basis, self.pending = self.pending, None  # the basis saved with a restored state
        prog.clear()
        prog.add_cols(lo, hi)
        prog.add_rows((starts, idx, vals), rlo, rhi)
        prog.set_basis(basis)  # same shape (time-varying window): a good start
        self._cost_col = None


def with_saved_bases(state: Any, find: Any) -> Any:
    """``state`` with the bases its next step starts from (``find(state)``) written as status
    codes, when it has none yet and both are valid (what :meth:`Estimator.state` saves)."""
    if state.basis_min.size:
        return state
    bases = find(state)
    if bases is None or not all(b.valid for b in bases):
        return state
    return replace(state, basis_min=basis_codes(bases[0]), basis_max=basis_codes(bases[1]))


def check_basis_codes(state: Any) -> None:
    """Refuse a restored state whose ``basis_min``/``basis_max`` are not HiGHS basis status
    codes (0-4)."""
    for key in ("basis_min", "basis_max"):
        codes = getattr(state, key)
        if codes.ndim != 1 or (codes.size and (codes.min() < 0 or codes.max() > 4)):
            raise IvobsError(
                f"state: entry {key!r}: expected HiGHS basis status codes 0-4, got "
                f"{codes[:8]!r}; the state was altered or is not from Estimator.state() "
                "of this estimator"
            )
