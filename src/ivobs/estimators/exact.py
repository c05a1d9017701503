"""The exact reference: the tightest box any guaranteed method can give from the same data.

The set-membership problem (002, Section I) asks for "all the admissible state values that are
consistent with the measurements and the bounded uncertainties". For the model

::

    x[j+1] = A_j x[j] + B_j u[j] + E_j d[j],    y[j] = C_j x[j] + D_j u[j] + F_j d[j],
    x[0] ∈ x0,   d[j] ∈ d_j = sys.d_at(j, y[j])        (one d[j] in both equations)

that set at step ``k`` is the projection on ``x[k]`` of the polytope of trajectories
``z = (x[0], d[0], ..., x[k], d[k])`` satisfying the equations for ``j <= k``. Its interval hull,
component by component, is given by two linear programs per state::

    lower_k[i] = min x[k][i],   upper_k[i] = max x[k][i]   over that polytope.          (LP)

No guaranteed method that uses ``x0``, ``d``, ``u[0..k]``, ``y[0..k]`` can return a smaller box
(a tighter one would exclude a state the data cannot rule out), so this is the reference the
other methods are measured against (``Estimate.tightness_ratio``).

Formulation. The LP is kept sparse: the variables are the blocks ``(x[j], d[j])``, the constraints
the dynamics rows ``x[j+1] - A_j x[j] - E_j d[j] = B_j u[j]`` and the measurement rows
``C_j x[j] + F_j d[j] = y[j] - D_j u[j]``. It is built incrementally (a block per step; the oldest
block dropped in a moving window) and handed to two HiGHS models (``highspy``), one for the ``nx``
minimisations and one for the ``nx`` maximisations, solved in two threads. Each model keeps its
basis from program to program and from step to step (only the cost, the bounds or appended rows
change), so every solve is warm-started: a chain of neighbouring objectives
``min x[k][0], ..., min x[k][n-1]`` (and the maxima in reverse order). HiGHS sees the program
shifted to the centres of the variable bounds (``z = m + z'``; ``m``: the centre of the interval
prediction of ``x[j]`` and of the box of ``d[j]``), so that its absolute tolerances act at the
scale of the widths, not of ``|x|`` (a state near ``1e9`` with a width of 10 is an ordinary LP).

Soundness under floating point. The data are floating-point numbers, so each equation is kept up
to the rounding of one floating-point evaluation of it: row ``i`` is the range
``|a_i^T z - b_i| <= tau_i``, with (``γ_n = n ε / (1 - n ε)``, ``ε = 2^-52``, Higham 2002 §3.1)

::

    dynamics:     tau = γ_{nx+nu+nd} (|A| x̄ + |B| |u| + |E| d̄) + γ_{nu} |B| |u|
    measurement:  tau = γ_{nx+nu+nd} (|C| x̄ + |D| |u| + |F| d̄) + γ_{nu+1} (|y| + |D| |u|)

(``x̄``, ``d̄``: bounds on ``|x[j]|``, ``|d[j]|``). The second term covers the computation of the
right-hand side ``B u`` or ``y - D u``; the first lets the data be a floating-point simulation of
the model (a trajectory from :func:`ivobs.simulate`, a logger's rounding of ``y``). The program
is therefore a relaxation of (LP) by rounding-level amounts: its hull contains the exact one and
exceeds it by about ``ε`` times the magnitudes involved.

The returned bounds are not the solver's objective values (which hold up to its tolerances) but
*safe dual bounds* (Neumaier & Shcherbina, Math. Program. 99, 2004): for any multipliers ``λ``
and any box ``l <= z <= u`` containing the feasible set, with ``r = c - M^T λ``,

::

    min c^T z  >=  Σ_i min(λ_i b_i^lo, λ_i b_i^hi) + Σ_j min(r_j l_j, r_j u_j).       (S)

HiGHS's row duals give a ``λ`` for which (S) is tight; whatever the solver returns, (S) is valid.
(S) is evaluated in floating point and the rounding of that evaluation is subtracted, a bound
(Higham §3.1, dot products): with ``N`` the length of the longest sum,

::

    safe = fl(S) - γ_N ( Σ_i |λ_i| max|b_i| + Σ_j |r̂_j| w_j + Σ_i |λ_i| (|M| w)_i + |c|^T w )

(``w_j = max(|l_j|, |u_j|)``; the third term is the error of the reduced costs ``r̂`` computed
from ``λ``), rounded once more downwards. So the bound holds in exact arithmetic whatever ``λ``
is, and a bound too tight by rounding can never become, as a variable bound of later programs, a
constraint that cuts the true trajectory. Every variable bound is itself proven: ``x[0] ∈ x0``,
``d[j] ∈ d_j`` (the model), ``x[k]`` within the interval prediction from ``x[k-1]`` (Lemma 1,
widened by the same kind of error term and the dynamics range), and each past ``x[j]`` within the
box proven at step ``j`` (widened by :data:`_VAR_MARGIN` relative, which keeps the optimum off
those implied bounds); none of them changes the optimum.

Moving window (``window=N``): only the blocks ``j = k-N .. k`` are kept, ``x[k-N]`` constrained
to the box this estimator returned at step ``k-N`` (and every ``x[j]`` in the window to its own
box). Each step then costs a bounded amount; the box is still guaranteed and never tighter than
the full-horizon one (its constraints are implied by the full problem).

Faults and missing data. A measurement is reported inconsistent (``on_inconsistent``) only with a
*certificate*: HiGHS declares the program infeasible and its dual ray ``λ`` satisfies (S) with
``c = 0`` and a safe value ``> 0`` (Farkas: ``0 >= safe > 0`` for any feasible ``z``), evaluated
as above, so the report is never false under the model's assumptions (the Monitor raises alarms
from it). The sample is then dropped and the step predicted without it. A sample that lies outside
what the interval prediction of ``x[k]`` can explain (Lemma 1, rounding subtracted) is certified
inconsistent before any LP (gross faults, and right-hand sides beyond HiGHS's infinite bound
``1e20``, which HiGHS would take as free rows). When HiGHS says
infeasible but no certificate holds (a warm start may stall at a tiny infeasibility: the verdict
is retaken from a cold start with the dual, then the primal simplex), the sample is dropped
*silently*: the box is still guaranteed (the program without ``y[k]``, or the interval
prediction), only less tight. NaN components of ``y[k]`` are missing: their rows are free rows
(no constraint).

Data used: ``x0``, the bounds ``d`` and ``u[0..k]``, ``y[0..k]`` for the box of ``x[k]`` (the
filtered hull; ``d[k]`` enters through ``y[k]``).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import highspy
import numpy as np

from .._progress import Progress
from ..errors import IvobsError
from ..linalg import gamma
from ..model import LinearSystem
from ..sets import Box, image_bounds
from . import register
from .base import Design, Estimator, check_size

__all__ = ["Exact", "ExactDesign"]

_VAR_MARGIN = 1e-9
"""Relative widening of the proven boxes when they become variable bounds of later programs (not
needed for soundness: it keeps the optimum off those implied bounds, which helps the simplex)."""

_PARALLEL = (os.cpu_count() or 1) > 1
"""Solve the min and the max programs in two threads."""

_PRIMAL_TOL = 1e-9
"""HiGHS primal feasibility tolerance (on the shifted program)."""

_DUAL_TOL = 1e-10
"""HiGHS dual feasibility tolerance: the safe bound loses up to this times the sum of the
widths of the variables (two runs that end on different optimal bases, e.g. ``step()`` after
``restore()`` and ``run()``, then agree to about that much: 5e-9 for 16 steps of 2 states)."""

_ITERATION_LIMIT = 100_000
"""Simplex iterations allowed per program (typically 60-110 here)."""

_EPS = float(np.finfo(float).eps)
_TINY = float(np.finfo(float).smallest_subnormal)

OK, INFEASIBLE, UNSURE = "ok", "infeasible", "unsure"
"""Verdicts of a solve: bounds found; infeasible with a certificate; infeasible says HiGHS, but
no certificate (the sample is dropped without a report)."""


def _gamma(n: int) -> float:
    """``γ_n = n ε / (1 - n ε)``: relative error bound of a length-``n`` dot product
    (Higham, *Accuracy and Stability of Numerical Algorithms*, 2002, §3.1), ``ε = 2^-52`` (twice
    the unit roundoff, which also absorbs the rounding of the error terms themselves)."""
    return gamma(n, _EPS)


def _widen(lo: np.ndarray, hi: np.ndarray, rel: float = _VAR_MARGIN) -> tuple[np.ndarray, ...]:
    m = rel * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
    return lo - m, hi + m


def _mag(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.maximum(np.abs(lo), np.abs(hi))


@dataclass(frozen=True)
class ExactDesign(Design):
    """``window``: number of past steps ``N`` kept in the LP (``None``: the full horizon)."""

    window: int | None = None


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
        h = highspy.Highs()
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
    return h


_INFEASIBLE = (
    highspy.HighsModelStatus.kInfeasible,
    highspy.HighsModelStatus.kUnboundedOrInfeasible,
)

_POOL: ThreadPoolExecutor | None = None


def _pool() -> ThreadPoolExecutor:
    """Two workers for the two chains of programs (HiGHS releases the GIL while it solves)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=2, thread_name_prefix="ivobs-exact")
    return _POOL


@dataclass(frozen=True)
class _Bounds:
    """The data of (S) for one step, shared by the ``2 nx`` programs: row ranges (0 on free
    rows), variable bounds, their magnitudes and ``|M| w``, and ``γ_N``."""

    row_lo: np.ndarray
    row_hi: np.ndarray
    row_mag: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    w: np.ndarray
    Mw: np.ndarray
    gamma: float
    n_terms: int


class _TrajectoryLP:
    """The sparse LP over blocks ``(x[j], d[j])`` of consecutive steps.

    Rows of block ``b``: the dynamics rows linking it to block ``b-1`` (none for the first block),
    then the ``ny`` measurement rows (free rows, bounds ``±inf``, for missing or dropped
    components, so that the matrix does not depend on which samples are available). The matrix
    is kept in COO form, stored row by row, with the row ranges and the variable bounds (in the
    original coordinates) and the shifts ``m`` (per column) and ``M m`` (per row) of the
    program HiGHS sees; two :class:`_Chain` s (one HiGHS model each) solve the ``min`` and the
    ``max`` programs.
    """

    def __init__(self, nx: int, nd: int, ny: int, parallel: bool):
        self.nx, self.nd, self.ny, self.nb = nx, nd, ny, nx + nd
        self.n_dyn: list[int] = []  # dynamics rows of each block
        self.rows = np.zeros(0, dtype=np.int64)
        self.cols = np.zeros(0, dtype=np.int64)
        self.vals = np.zeros(0)
        self.rhs = np.zeros(0)  # NaN on free rows
        self.row_lo = np.zeros(0)
        self.row_hi = np.zeros(0)
        self.relaxed = False  # HiGHS sees the ranges (True) or the equalities at rhs
        self.row_shift = np.zeros(0)
        self.lo = np.zeros(0)
        self.hi = np.zeros(0)
        self.shift = np.zeros(0)
        self.chains = (_Chain(self, 1.0), _Chain(self, -1.0))
        self.parallel = parallel

    @property
    def n_blocks(self) -> int:
        return len(self.n_dyn)

    # -- building ----------------------------------------------------------------------------
    def push(
        self,
        dynamics: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
        measurement: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        x_bounds: tuple[np.ndarray, np.ndarray],
        d_bounds: tuple[np.ndarray, np.ndarray],
        x_centre: np.ndarray,
    ) -> None:
        """Append the block ``(x[j], d[j])``: ``dynamics = (A, E, B u, tau)`` of step ``j-1``
        (the link from the previous block), ``measurement = (C, F, y - D u, tau)`` of step ``j``
        (NaN in the right-hand side: a free row); rows are ranges ``rhs ± tau``. ``x_centre``:
        the shift of ``x[j]`` in the program HiGHS sees."""
        nx, nd, nb = self.nx, self.nd, self.nb
        off = self.lo.size
        self.lo = np.concatenate([self.lo, x_bounds[0], d_bounds[0]])
        self.hi = np.concatenate([self.hi, x_bounds[1], d_bounds[1]])
        d_centre = 0.5 * (d_bounds[0] + d_bounds[1])
        self.shift = np.concatenate([self.shift, x_centre, d_centre])
        if dynamics is not None:
            A, E, bu, tau = dynamics
            dense = np.hstack([-A, -E, np.eye(nx), np.zeros((nx, nd))])
            self._append_rows(dense, off - nb, bu, tau)
        C, F, rhs, tau = measurement
        self._append_rows(np.hstack([C, F]), off, rhs, tau)
        self.n_dyn.append(0 if dynamics is None else nx)

    def _append_rows(self, dense: np.ndarray, col0: int, rhs: np.ndarray, tau: np.ndarray) -> None:
        r, c = np.nonzero(dense)
        free = np.isnan(rhs)
        self.rows = np.concatenate([self.rows, r + self.row_lo.size])
        self.cols = np.concatenate([self.cols, c + col0])
        self.vals = np.concatenate([self.vals, dense[r, c]])
        self.rhs = np.concatenate([self.rhs, rhs])
        self.row_lo = np.concatenate([self.row_lo, np.where(free, -np.inf, rhs - tau)])
        self.row_hi = np.concatenate([self.row_hi, np.where(free, np.inf, rhs + tau)])
        shift = dense @ self.shift[col0 : col0 + dense.shape[1]]
        self.row_shift = np.concatenate([self.row_shift, shift])

    def pop_front(self) -> None:
        """Remove the oldest block, its rows and the dynamics rows that reach into it."""
        n_del = self.n_dyn[0] + self.ny + self.n_dyn[1]
        keep = self.rows >= n_del
        self.rows = self.rows[keep] - n_del
        self.cols = self.cols[keep] - self.nb
        self.vals = self.vals[keep]
        self.row_lo, self.row_hi = self.row_lo[n_del:], self.row_hi[n_del:]
        self.rhs = self.rhs[n_del:]
        self.row_shift = self.row_shift[n_del:]
        self.lo, self.hi = self.lo[self.nb :], self.hi[self.nb :]
        self.shift = self.shift[self.nb :]
        self.n_dyn.pop(0)
        self.n_dyn[0] = 0

    def free_last_measurement(self) -> None:
        """Drop the measurement of the newest block (an inconsistent sample): free rows."""
        self.rhs[-self.ny :] = np.nan
        self.row_lo[-self.ny :] = -np.inf
        self.row_hi[-self.ny :] = np.inf

    def tighten_last_x(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Intersect the bounds of ``x`` of the newest block with ``[lo, hi]`` (the box just
        proven for it, widened) and return the new bounds. Intersecting (rather than replacing)
        keeps the prior ``x0`` exact on the first block."""
        first = self.lo.size - self.nb
        sl = slice(first, first + self.nx)
        self.lo[sl] = np.maximum(self.lo[sl], lo)
        self.hi[sl] = np.minimum(self.hi[sl], hi)
        return self.lo[sl].copy(), self.hi[sl].copy()

    # -- solving -----------------------------------------------------------------------------
    def last_x_box(self) -> tuple[np.ndarray, np.ndarray, str]:
        """Bounds of ``x`` of the newest block: ``(lower, upper, verdict)``.

        ``verdict`` is :data:`OK`, :data:`INFEASIBLE` (certified) or :data:`UNSURE`; unless
        it is OK, the bounds are the variable bounds (the interval prediction).
        """
        first = self.lo.size - self.nb
        lower = self.lo[first : first + self.nx].copy()
        upper = self.hi[first : first + self.nx].copy()
        data = self._bounds()
        if self.parallel:
            jobs = [_pool().submit(c.solve, first, data) for c in self.chains]
            (lo_b, v_lo), (hi_b, v_hi) = (job.result() for job in jobs)
        else:
            (lo_b, v_lo), (hi_b, v_hi) = (c.solve(first, data) for c in self.chains)
        self.relaxed = self.relaxed or any(c.relaxed for c in self.chains)
        if INFEASIBLE in (v_lo, v_hi):
            return lower, upper, INFEASIBLE
        if UNSURE in (v_lo, v_hi):
            return lower, upper, UNSURE
        return np.maximum(lower, lo_b), np.minimum(upper, -hi_b), OK

    def _bounds(self) -> _Bounds:
        free = np.isinf(self.row_lo)
        row_lo = np.where(free, 0.0, self.row_lo)
        row_hi = np.where(free, 0.0, self.row_hi)
        w = _mag(self.lo, self.hi)
        Mw = np.bincount(self.rows, weights=np.abs(self.vals) * w[self.cols],
                         minlength=row_lo.size)  # fmt: skip
        # the longest sum of (S) and of its error terms (a column has <= nx + ny + 1 entries)
        n = max(row_lo.size, w.size, self.nx + self.ny + 2) + 2
        return _Bounds(row_lo, row_hi, _mag(row_lo, row_hi), self.lo, self.hi, w, Mw,
                       _gamma(n), n)  # fmt: skip

    def safe_min(self, lam: np.ndarray, data: _Bounds, col: int | None, sense: float) -> float:
        """A lower bound on ``min c^T z`` (``c = sense e_col``; ``c = 0`` if ``col`` is None) that
        holds in exact arithmetic for every ``λ``: (S) minus the bound on its rounding (module
        docstring). ``-inf`` if it cannot be evaluated (non-finite multipliers)."""
        r = -np.bincount(self.cols, weights=self.vals * lam[self.rows], minlength=data.w.size)
        if col is not None:
            r[col] += sense
        with np.errstate(invalid="ignore", over="ignore"):
            value = (
                np.minimum(lam * data.row_lo, lam * data.row_hi).sum()
                + np.minimum(r * data.lo, r * data.hi).sum()
            )
            a = np.abs(lam)
            err = a @ data.row_mag + np.abs(r) @ data.w + a @ data.Mw
            if col is not None:
                err += abs(sense) * data.w[col]
            bound = value - (data.gamma * err + 4 * data.n_terms * _TINY)
        if not np.isfinite(bound):
            return -np.inf
        return float(np.nextafter(bound, -np.inf))

    def certifies_infeasibility(self, ray: np.ndarray, data: _Bounds) -> bool:
        """Farkas: ``λ`` proves the program infeasible if (S) with ``c = 0`` is safely ``> 0``
        (for a feasible ``z`` it would be ``<= 0``). Both signs of HiGHS's ray are tried."""
        lam = np.where(np.isinf(self.row_lo), 0.0, ray)
        return any(self.safe_min(s * lam, data, None, 0.0) > 0.0 for s in (1.0, -1.0))


class _Chain:
    """One HiGHS model solving ``min sense * x_last[i]`` for every ``i`` of the newest block.

    Before solving, the model is synchronised with the LP as cheaply as the change allows: new
    bounds only (a moving window of a time-invariant system: same matrix, the basis is kept),
    appended rows and columns (full horizon: the basis is kept), or a rebuild. The ``nx``
    programs are solved one after the other, each warm-started from the previous optimum (dual
    simplex for the first, whose data changed; primal simplex for the next ones, where only the
    cost changed and the previous optimum is still feasible).
    """

    def __init__(self, lp: _TrajectoryLP, sense: float):
        self.lp, self.sense = lp, sense
        self.h = _new_highs()
        self._synced: tuple[np.ndarray, np.ndarray, np.ndarray, int, int] | None = None
        self._cost_col: int | None = None  # the one column with a nonzero cost in the model
        self.relaxed = lp.relaxed  # rows given to HiGHS as ranges (else equalities)

    def solve(self, first: int, data: _Bounds) -> tuple[np.ndarray, str]:
        """Safe lower bounds of ``sense * x[first + i]`` and the verdict (OK, INFEASIBLE with a
        certificate, UNSURE)."""
        self.relaxed = self.lp.relaxed
        self._sync()
        lp, h = self.lp, self.h
        out = np.full(lp.nx, -np.inf)
        order = range(lp.nx) if self.sense > 0 else reversed(range(lp.nx))
        free = np.isinf(lp.row_lo)
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
                if self._certified(data):
                    return out, INFEASIBLE
                if not self.relaxed:
                    # equalities of floating-point data can be infeasible by a rounding: HiGHS
                    # sees the ranges from now on (this step and, via the LP, the next ones)
                    self.relaxed = True
                    _lo, _hi, rlo, rhi = self._shifted()
                    h.changeRowsBounds(rlo.size, np.arange(rlo.size, dtype=np.int32), rlo, rhi)
                    h.clearSolver()
                    status = self._run(1)
                if status in _INFEASIBLE and not self._certified(data):
                    h.clearSolver()  # no certificate: a second opinion from the primal simplex
                    status = self._run(4)
                if status in _INFEASIBLE:
                    return out, INFEASIBLE if self._certified(data) else UNSURE
            if status != highspy.HighsModelStatus.kOptimal:
                h.clearSolver()  # numerical trouble: a second opinion from the primal simplex
                status = self._run(4)
                if status in _INFEASIBLE and self._certified(data):
                    return out, INFEASIBLE
            # (S) holds for any multipliers: those of the last basis even if it is not optimal
            # (and the variable bound, λ = 0, if there are none)
            sol = h.getSolution()
            if sol.dual_valid and len(sol.row_dual) == free.size:
                lam = np.where(free, 0.0, np.asarray(sol.row_dual))
                out[i] = lp.safe_min(lam, data, col, self.sense)
        return out, OK

    def _certified(self, data: _Bounds) -> bool:
        _status, has_ray, ray = self.h.getDualRay()
        ray = np.asarray(ray, dtype=float)
        if not has_ray or ray.size != self.lp.row_lo.size:
            return False
        return self.lp.certifies_infeasibility(ray, data)

    def _run(self, strategy: int) -> highspy.HighsModelStatus:
        self.h.setOptionValue("simplex_strategy", strategy)
        self.h.run()
        return self.h.getModelStatus()

    def _sync(self) -> None:
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
        lo, hi, rlo, rhi = self._shifted()
        h.changeColsBounds(n_col, np.arange(n_col, dtype=np.int32), lo, hi)
        h.changeRowsBounds(n_row, np.arange(n_row, dtype=np.int32), rlo, rhi)
        self._synced = (lp.rows.copy(), lp.cols.copy(), lp.vals.copy(), n_row, n_col)

    def _shifted(self, col0: int = 0, row0: int = 0) -> tuple[np.ndarray, ...]:
        """Variable bounds (from column ``col0``) and row bounds (from row ``row0``) of the
        program HiGHS sees, ``z' = z - m``: the equalities ``a_i^T z = rhs_i`` (ranged rows
        slow the simplex down by a third), or the ranges ``rhs_i ± tau_i`` once relaxed."""
        lp = self.lp
        s, rs = lp.shift[col0:], lp.row_shift[row0:]
        lo, hi = lp.lo[col0:] - s, lp.hi[col0:] - s
        if self.relaxed:
            return lo, hi, lp.row_lo[row0:] - rs, lp.row_hi[row0:] - rs
        mid = lp.rhs[row0:] - rs
        free = np.isnan(mid)
        return lo, hi, np.where(free, -np.inf, mid), np.where(free, np.inf, mid)

    def _csr(self, start: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """Rows ``start..`` of the LP in CSR form."""
        lp = self.lp
        sel = slice(int(np.searchsorted(lp.rows, start)), None)
        r = lp.rows[sel] - start
        m = lp.row_lo.size - start
        starts = np.searchsorted(r, np.arange(m)).astype(np.int32)
        return m, starts, lp.cols[sel].astype(np.int32), lp.vals[sel]

    def _append(self, o_nrow: int, o_ncol: int) -> None:
        lp = self.lp
        n_new = lp.lo.size - o_ncol
        m, starts, idx, vals = self._csr(o_nrow)
        lo, hi, rlo, rhi = self._shifted(o_ncol, o_nrow)
        empty = np.zeros(0, np.int32)
        self.h.addCols(n_new, np.zeros(n_new), lo, hi, 0, empty, empty, np.zeros(0))
        self.h.addRows(m, rlo, rhi, vals.size, starts, idx, vals)

    def _rebuild(self) -> None:
        lp, h = self.lp, self.h
        n_col = lp.lo.size
        m, starts, idx, vals = self._csr(0)
        lo, hi, rlo, rhi = self._shifted()
        empty = np.zeros(0, np.int32)
        basis = h.getBasis() if h.getNumCol() == n_col and h.getNumRow() == m else None
        h.clearModel()
        h.addCols(n_col, np.zeros(n_col), lo, hi, 0, empty, empty, np.zeros(0))
        h.addRows(m, rlo, rhi, vals.size, starts, idx, vals)
        if basis is not None and basis.valid:
            h.setBasis(basis)  # same shape (time-varying window): a good start
        self._cost_col = None


@register
class Exact(Estimator):
    """Exact interval hull of the states consistent with the data (two LPs per state per step).

    Parameters
    ----------
    sys : LinearSystem (discrete time; time-varying matrices and bounds allowed)
    x0 : Box, the prior box on ``x[0]`` (required)
    window : None (full horizon, the reference; cost grows with ``k``) or an int ``N >= 1``
        (moving window of ``N`` past steps whose first state is bounded by this estimator's own
        box: bounded cost per step, still guaranteed, never tighter than the full horizon)
    progress : None (a progress bar in ``run()`` when stderr is a terminal), True or False
    on_inconsistent : 'warn', 'raise' or 'ignore' (measurements that make the LP infeasible)

    Data used for the box of ``x[k]``: ``x0``, ``d``, ``u[0..k]``, ``y[0..k]``. See the module
    docstring for the formulation and the safe (solver-tolerance independent) bounds.
    """

    name = "exact"
    order = 100
    summary = "linear-programming reference: the tightest guaranteed box from the same data"
    reference = "set-membership hull (002 §I) by LP with HiGHS; safe bounds (Neumaier 2004)"
    supports_time_varying = True
    needs_x0 = True

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        window: int | None = None,
        progress: bool | None = None,
        on_inconsistent: str = "warn",
    ):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)
        check_size(self.name, sys.nx, "solves 2 nx linear programs over the whole trajectory")
        if window is not None and (
            isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1
        ):
            raise IvobsError(
                f"window: expected None (full horizon) or a number of steps >= 1, got {window!r}"
            )
        if progress is not None and not isinstance(progress, bool):
            raise IvobsError(f"progress: expected None, True or False, got {progress!r}")
        self.design = ExactDesign(window=None if window is None else int(window))
        self.progress = progress
        self.valid_from = 0

    # -- state ----------------------------------------------------------------------------
    def _initial_state(self) -> dict[str, Any]:
        s = self.sys
        return {
            "xlo": np.zeros((0, s.nx)),  # LP bounds of the kept past states (proven boxes)
            "xhi": np.zeros((0, s.nx)),
            "y": np.zeros((0, s.ny)),
            "u": np.zeros((0, s.nu)),
            "dlo": np.zeros((0, s.nd)),
            "dhi": np.zeros((0, s.nd)),
            "used": np.zeros(0),  # 1.0 where the measurement entered the LP, 0.0 if dropped
            "relaxed": 0.0,  # 1.0 once HiGHS needed the row ranges (see _Chain._shifted)
            "plo": np.zeros((0, s.nx)),  # interval predictions (row ranges and shifts of the LP)
            "phi": np.zeros((0, s.nx)),
        }

    def save_state(self, st: Any) -> dict[str, Any]:
        """The online state (JSON-serialisable): the kept history; the LP is rebuilt on restore."""
        out = super().save_state(st)
        out["state"].pop("lp", None)
        return out

    # -- one step -------------------------------------------------------------------------
    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        lp = state.get("lp")
        if lp is None:
            lp = state["lp"] = self._rebuild(state, k)
        d_k = self.sys.d_at(k, y_k)
        if k > 0:
            prev = (state["xlo"][-1], state["xhi"][-1], state["dlo"][-1], state["dhi"][-1])
            dynamics = self._dynamics(k - 1, state["u"][-1], *prev)
            p_lo, p_hi = self._prediction(k - 1, state["u"][-1], prev, dynamics[3])
        else:
            assert self.x0 is not None
            dynamics = None
            p_lo, p_hi = self.x0.lo.copy(), self.x0.hi.copy()
        meas = self._measurement(k, u_k, y_k, True, p_lo, p_hi, d_k.lo, d_k.hi)
        gross = self._outside_prediction(meas, p_lo, p_hi, d_k.lo, d_k.hi)
        if gross:  # certainly inconsistent already by interval arithmetic: no LP needed
            meas = self._measurement(k, u_k, y_k, False, p_lo, p_hi, d_k.lo, d_k.hi)
        lp.push(dynamics, meas, (p_lo, p_hi), (d_k.lo, d_k.hi), 0.5 * (p_lo + p_hi))
        N = self.design.window
        if N is not None and lp.n_blocks > N + 1:
            lp.pop_front()
        lo, hi, verdict = lp.last_x_box()
        used = 1.0
        if gross:
            state["_inconsistent"] = True
            used = 0.0
        elif verdict != OK:
            # certified: a fault under the model's assumptions; unsure: dropped without a report
            state["_inconsistent"] = verdict == INFEASIBLE
            used = 0.0
            lp.free_last_measurement()
            lo, hi, _ = lp.last_x_box()  # if still not OK: the variable bounds (the prediction)
        # both bounds are proven: if they cross, the data are inconsistent; the hull stays valid
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        x_lo, x_hi = lp.tighten_last_x(*_widen(lo, hi))
        state["relaxed"] = float(lp.relaxed)
        self._remember(state, x_lo, x_hi, u_k, y_k, d_k, used, p_lo, p_hi)
        return lo, hi

    @staticmethod
    def _outside_prediction(
        meas: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
        p_lo: np.ndarray,
        p_hi: np.ndarray,
        d_lo: np.ndarray,
        d_hi: np.ndarray,
    ) -> bool:
        """A measurement row certainly violated over the interval prediction of ``x[k]`` (which
        contains every state consistent with the model and the past data) and the box of
        ``d[k]``: ``|y − D u − (C x + F d)| > tau`` for every such ``x``, ``d`` (Lemma 1, with
        the rounding of its evaluation, ``γ (|C| x̄ + |F| d̄)``, subtracted). A certificate of
        inconsistency that needs no LP, and one HiGHS could not give for right-hand sides
        beyond its infinite bound (``1e20``), which it treats as free rows."""
        C, F, rhs, tau = meas
        lo_c, hi_c = image_bounds(C, p_lo, p_hi)
        lo_f, hi_f = image_bounds(F, d_lo, d_hi)
        n = C.shape[1] + F.shape[1] + 2
        err = _gamma(n) * (np.abs(C) @ _mag(p_lo, p_hi) + np.abs(F) @ _mag(d_lo, d_hi))
        with np.errstate(invalid="ignore"):  # NaN (missing) compares False
            above = rhs - tau > hi_c + hi_f + 2.0 * err
            below = rhs + tau < lo_c + lo_f - 2.0 * err
        return bool(np.any(above | below))

    def _prediction(
        self, j: int, u_j: np.ndarray, prev: tuple[np.ndarray, ...], tau: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``x[j+1]`` implied by the box of ``x[j]`` (Lemma 1) and the dynamics rows
        (range ``tau``), widened by the rounding of their evaluation
        (``γ_{nx+nd+nu+3} (|A| x̄ + |E| d̄ + |B| |u|)``) and by :data:`_VAR_MARGIN`."""
        A, B, _, _, E, _ = self.sys.matrices_at(j)
        x_lo, x_hi, d_lo, d_hi = prev
        lo, hi = image_bounds(A, x_lo, x_hi)
        dlo, dhi = image_bounds(E, d_lo, d_hi)
        bu = B @ u_j
        n = self.sys.nx + self.sys.nd + self.sys.nu + 3
        err = _gamma(n) * (np.abs(A) @ _mag(x_lo, x_hi) + np.abs(E) @ _mag(d_lo, d_hi)
                           + np.abs(B) @ np.abs(u_j)) + tau  # fmt: skip
        return _widen(lo + dlo + bu - err, hi + dhi + bu + err)

    def _dynamics(
        self,
        j: int,
        u_j: np.ndarray,
        x_lo: np.ndarray,
        x_hi: np.ndarray,
        d_lo: np.ndarray,
        d_hi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(A, E, B u, tau)`` of step ``j``: ``x[j+1] - A x[j] - E d[j] ∈ B u ± tau`` with
        ``tau = γ_{nx+nu+nd} (|A| x̄ + |B| |u| + |E| d̄) + γ_{nu} |B| |u|`` (module docstring);
        ``x̄``, ``d̄`` from the boxes of ``x[j]`` and ``d[j]``."""
        A, B, _, _, E, _ = self.sys.matrices_at(j)
        s = self.sys
        bu_mag = np.abs(B) @ np.abs(u_j)
        tau = (
            _gamma(s.nx + s.nu + s.nd)
            * (np.abs(A) @ _mag(x_lo, x_hi) + bu_mag + np.abs(E) @ _mag(d_lo, d_hi))
            + _gamma(s.nu) * bu_mag
        )
        return A, E, B @ u_j, tau

    def _measurement(
        self,
        j: int,
        u_j: np.ndarray,
        y_j: np.ndarray,
        used: bool,
        x_lo: np.ndarray,
        x_hi: np.ndarray,
        d_lo: np.ndarray,
        d_hi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(C, F, y - D u, tau)`` of step ``j``; NaN (missing, or a dropped sample) = free row.
        ``tau = γ_{nx+nu+nd} (|C| x̄ + |D| |u| + |F| d̄) + γ_{nu+1} (|y| + |D| |u|)`` with ``x̄``
        from the interval prediction of ``x[j]`` (module docstring)."""
        _, _, C, D, _, F = self.sys.matrices_at(j)
        s = self.sys
        if not used:
            return C, F, np.full(s.ny, np.nan), np.zeros(s.ny)
        du_mag = np.abs(D) @ np.abs(u_j)
        tau = _gamma(s.nx + s.nu + s.nd) * (
            np.abs(C) @ _mag(x_lo, x_hi) + du_mag + np.abs(F) @ _mag(d_lo, d_hi)
        ) + _gamma(s.nu + 1) * (np.abs(y_j) + du_mag)
        return C, F, y_j - D @ u_j, tau

    def _remember(
        self,
        state: dict[str, Any],
        lo: np.ndarray,
        hi: np.ndarray,
        u_k: np.ndarray,
        y_k: np.ndarray,
        d_k: Box,
        used: float,
        p_lo: np.ndarray,
        p_hi: np.ndarray,
    ) -> None:
        N = self.design.window
        new = {"xlo": lo, "xhi": hi, "y": y_k, "u": u_k, "dlo": d_k.lo, "dhi": d_k.hi,
               "plo": p_lo, "phi": p_hi}  # fmt: skip
        for key, val in new.items():
            hist = np.vstack([state[key], np.asarray(val, dtype=float)[None, :]])
            state[key] = hist if N is None else hist[-N:]
        used_hist = np.append(state["used"], used)
        state["used"] = used_hist if N is None else used_hist[-N:]

    def _rebuild(self, state: dict[str, Any], k: int) -> _TrajectoryLP:
        """The LP of the kept history (empty at step 0; after ``restore()`` the same program)."""
        lp = _TrajectoryLP(self.sys.nx, self.sys.nd, self.sys.ny, _PARALLEL)
        lp.relaxed = bool(state["relaxed"])
        m = state["xlo"].shape[0]
        for i, j in enumerate(range(k - m, k)):
            dynamics = None
            if i > 0:
                prev = (state[key][i - 1] for key in ("xlo", "xhi", "dlo", "dhi"))
                dynamics = self._dynamics(j - 1, state["u"][i - 1], *prev)
            p_lo, p_hi = state["plo"][i], state["phi"][i]
            d_lo, d_hi = state["dlo"][i], state["dhi"][i]
            meas = self._measurement(j, state["u"][i], state["y"][i], bool(state["used"][i]),
                                     p_lo, p_hi, d_lo, d_hi)  # fmt: skip
            x_b = (state["xlo"][i], state["xhi"][i])
            lp.push(dynamics, meas, x_b, (d_lo, d_hi), 0.5 * (p_lo + p_hi))
        return lp

    # -- offline loop with a progress bar --------------------------------------------------
    def _loop(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None, bar: Any = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if bar is not None and bar.enabled:
            return super()._loop(u, y, t, bar)
        desc = "exact" if self.design.window is None else f"exact (window {self.design.window})"
        with Progress(y.shape[0], desc, enabled=self.progress) as own:
            return super()._loop(u, y, t, own)
