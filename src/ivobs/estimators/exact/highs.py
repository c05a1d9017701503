"""The HiGHS model that solves the ``2 nx`` programs of a step, warm-started from step to step.

One HiGHS model (``highspy``) holds the trajectory program and solves a chain of neighbouring
objectives, ``min x[k][0], ..., min x[k][n-1], max x[k][n-1], ..., max x[k][0]``, each
warm-started from the previous optimum; it keeps its basis from step to step (only the cost, the
bounds or appended rows change). Many programs of the chain need no solve at all: the optimal
basis of the previous one is often optimal for them too, which its multipliers prove (a bound
(S) meeting the objective value of the basis's vertex). The returned bounds are not the solver's
objective values but the safe bounds (S) of its multipliers
(:mod:`~ivobs.estimators.exact.safe`, [Neumaier2004]), valid whatever the solver returns; an
infeasible verdict counts only with a Farkas certificate.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Protocol, cast

import highspy
import numpy as np

from .program import TrajectoryLP
from .safe import SafeBoundData, certifies_infeasibility, safe_mins

__all__ = [
    "GAP_REL",
    "INFEASIBLE",
    "OK",
    "UNSURE",
    "Chain",
    "basis_array",
    "basis_fits",
    "basis_of",
]

_PRIMAL_TOL = 1e-9
"""HiGHS primal feasibility tolerance (on the shifted program)."""

_DUAL_TOL = 1e-10
"""HiGHS dual feasibility tolerance: the safe bound loses up to this times the sum of the
widths of the variables (two solves of one program that end on different optimal bases agree to
about that much, e.g. a state saved without bases and restored: 5e-9 for 16 steps of 2
states)."""

GAP_REL = 1e-9
"""A bound certified by an optimal basis of another objective (no solve) is taken when it is
within this times the width of the variable's bound of the objective value of that basis's
vertex: it is then the optimum to that accuracy (a solve from that basis would stop at once with
the same multipliers; the optimum HiGHS reports is itself only within ``_DUAL_TOL`` times the
widths of the variables)."""


_ITERATION_LIMIT = 20_000
"""Simplex iterations allowed per program (typically 60-110 here, a few thousand on unstable
systems over a long horizon). A program stopped by it still gives a safe bound (S) from its last
multipliers; :attr:`Chain.capped` counts them."""

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

    def getBasicVariables(self) -> tuple[highspy.HighsStatus, np.ndarray]: ...

    def getBasisInverseRow(self, row: int) -> tuple[highspy.HighsStatus, np.ndarray]: ...


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


def basis_fits(b: highspy.HighsBasis | None, n_col: int, n_row: int) -> bool:
    """Whether ``b`` is a basis of a program with ``n_col`` columns and ``n_row`` rows."""
    return b is not None and len(b.col_status) == n_col and len(b.row_status) == n_row


def basis_of(codes: np.ndarray, n_col: int) -> highspy.HighsBasis:
    """The HiGHS basis of :func:`basis_array` codes (``n_col`` columns)."""
    b = highspy.HighsBasis()
    status = [highspy.HighsBasisStatus(int(v)) for v in codes]
    b.col_status, b.row_status = status[:n_col], status[n_col:]
    b.valid, b.alien = True, False
    return b


class Chain:
    """The HiGHS model solving ``min sense * x_last[i]`` for every ``i`` of the newest block and
    every ``sense`` of ``senses`` (``(1.0, -1.0)``: the minima, then the maxima).

    Before solving, the model is synchronised with the program as cheaply as the change allows:
    new bounds only (a moving window of a time-invariant system: same matrix, the basis is
    kept), appended rows and columns (full horizon: the basis is kept), or a rebuild. The
    programs are taken one after the other, each warm-started from the previous optimum (dual
    simplex for the first, whose data changed; primal simplex for the next ones, where only the
    cost changed and the previous optimum is still feasible). After each solve, the next
    programs are tried against the optimal basis just found (:meth:`_certify`): a program for
    which it is optimal too needs no solve.
    """

    def __init__(self, lp: TrajectoryLP, senses: tuple[float, ...]):
        self.lp, self.senses = lp, senses
        self.h = _new_highs()
        self._synced: tuple[np.ndarray, np.ndarray, np.ndarray, int, int] | None = None
        self._cost: tuple[int, float] | None = None  # the one nonzero cost: (column, value)
        self.relaxed = lp.relaxed  # rows given to HiGHS as ranges (else equalities)
        self.pending: highspy.HighsBasis | None = None  # a saved basis for the rebuilt model
        self.capped = 0  # programs stopped by the iteration budget
        self.solves = 0  # programs solved by HiGHS
        self.certified = 0  # programs whose bound an optimal basis of another one certified

    def solve(self, first: int, data: SafeBoundData) -> tuple[np.ndarray, str]:
        """Safe lower bounds of ``sense * x[first + i]`` (a row per sense, a column per ``i``)
        and the verdict (OK, INFEASIBLE with a certificate, UNSURE)."""
        self.relaxed = self.lp.relaxed
        self.sync()
        lp, h = self.lp, self.h
        # every step starts from the basis alone (no factorisation or pricing weights kept from
        # the previous step): the same start as the program rebuilt from a saved state
        basis = h.getBasis()
        h.clearSolver()
        if basis.valid:
            h.setBasis(basis)
        out = np.full((len(self.senses), lp.nx), -np.inf)
        todo = [(s, sense, first + i)
                for s, sense in enumerate(self.senses)
                for i in (range(lp.nx) if sense > 0 else reversed(range(lp.nx)))]  # fmt: skip
        solved: list[tuple[int, float, int]] = []
        lams: list[np.ndarray] = []  # their multipliers: (S) of all of them at the end
        while todo:
            s, sense, col = todo.pop(0)
            self._set_cost(col, sense)
            status = self._run(4 if solved else 1)
            self.solves += 1
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
                solved.append((s, sense, col))
                lams.append(np.asarray(sol.row_dual))
                if todo and status == highspy.HighsModelStatus.kOptimal and sol.value_valid:
                    todo = self._certify(todo, np.asarray(sol.col_value), data, out, first)
        if solved:
            rows, senses, cols = (np.array(v) for v in zip(*solved, strict=True))
            lam = np.array(lams)
            lam[:, data.free] = 0.0
            out[rows, cols - first] = safe_mins(lam, data, cols, senses)
        return out, OK

    def _certify(
        self,
        todo: list[tuple[int, float, int]],
        vertex: np.ndarray,
        data: SafeBoundData,
        out: np.ndarray,
        first: int,
    ) -> list[tuple[int, float, int]]:
        """Try the next programs of ``todo``, in order, against the current basis (optimal for
        the program just solved) until one is not proven; the bounds of those it proves go to
        ``out`` (row ``s``, column ``col - first``); the rest is returned, to be solved.

        The multipliers of a basis ``B`` for the cost ``c = sense e_col`` are
        ``λ = B^-T c_B`` [Bertsimas1997, Section 3.1]: ``sense`` times the row of ``B^-1`` of
        the position of ``col`` among the basic variables (``λ = 0`` if ``col`` is nonbasic).
        (S) holds for any ``λ``; by weak duality it cannot exceed the objective value ``p`` of
        the basis's vertex (a feasible point, up to HiGHS's primal tolerance), and when it meets
        it, ``p - (S) <= GAP_REL (u_col - l_col)``, it is the optimum to that accuracy.
        """
        h, lp = _unstubbed(self.h), self.lp
        status, basic = h.getBasicVariables()
        if status != highspy.HighsStatus.kOk:
            return todo
        basic = np.asarray(basic)
        while todo:
            s, sense, col = todo[0]
            lam = np.zeros((1, data.free.size))
            pos = np.flatnonzero(basic == col)
            if pos.size:
                status, row = h.getBasisInverseRow(int(pos[0]))
                if status != highspy.HighsStatus.kOk:
                    return todo
                lam[0] = sense * np.asarray(row)
                lam[0, data.free] = 0.0
            bound = float(safe_mins(lam, data, np.array([col]), np.array([sense]))[0])
            value = sense * (vertex[col] + lp.shift[col])
            if not value - bound <= GAP_REL * (lp.hi[col] - lp.lo[col]):
                return todo
            out[s, col - first] = bound
            self.certified += 1
            todo = todo[1:]
        return todo

    def _set_cost(self, col: int, sense: float) -> None:
        """The cost ``sense e_col`` (one nonzero)."""
        if self._cost is not None and self._cost[0] != col:
            self.h.changeColCost(self._cost[0], 0.0)
        if self._cost != (col, sense):
            self.h.changeColCost(col, sense)
        self._cost = (col, sense)

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
        if basis_fits(self.pending, n_col, m):
            basis, self.pending = self.pending, None  # the basis saved with a restored state
        h.clearModel()
        h.addCols(n_col, np.zeros(n_col), lo, hi, 0, empty, empty, np.zeros(0))
        h.addRows(m, rlo, rhi, vals.size, starts, idx, vals)
        if basis is not None and basis.valid:
            h.setBasis(basis)  # same shape (time-varying window): a good start
        self._cost = None
