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
``min x[k][0], ..., min x[k][n-1]`` (and the maxima in reverse order).

Soundness under floating point. The returned bounds are not the solver's objective values (which
hold up to its tolerances) but *safe dual bounds* (Neumaier & Shcherbina, Math. Program. 99, 2004):
for any multipliers ``λ`` and any box ``l <= z <= u`` containing the feasible set,
``min c^T z >= λ^T b + Σ_j min(r_j l_j, r_j u_j)`` with ``r = c - M^T λ``. HiGHS's row duals
give a ``λ`` for which this is tight; whatever the solver returns, the bound is valid. To make every
variable bounded, each ``x[j]`` carries the box already proven at step ``j`` (slightly widened),
and ``x[k]`` the interval prediction from ``x[k-1]``: these bounds are implied by the constraints,
so they do not change the optimum.

Moving window (``window=N``): only the blocks ``j = k-N .. k`` are kept, ``x[k-N]`` constrained
to the box this estimator returned at step ``k-N`` (and every ``x[j]`` in the window to its own
box). Each step then costs a bounded amount; the box is still guaranteed and never tighter than
the full-horizon one (its constraints are implied by the full problem).

Faults and missing data. A measurement that makes the LP infeasible cannot be explained by any
admissible ``x[0]`` and ``d``: it is reported as inconsistent (``on_inconsistent``) and dropped,
and the step is predicted without it (HiGHS's verdict is taken from a cold start: a warm start
may stall at a tiny infeasibility). NaN components of ``y[k]`` are missing: their rows are free
rows (no constraint).

Data used: ``x0``, the bounds ``d`` and ``u[0..k]``, ``y[0..k]`` for the box of ``x[k]`` (the
filtered hull; ``d[k]`` enters through ``y[k]``).
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import highspy
import numpy as np

from .._progress import Progress
from ..errors import IvobsError
from ..model import LinearSystem
from ..sets import Box, image_bounds
from . import register
from .base import Design, Estimator

__all__ = ["Exact", "ExactDesign"]

_VAR_MARGIN = 1e-9
"""Relative widening of the (implied) variable bounds, so that they never cut a true trajectory."""


_PARALLEL = (os.cpu_count() or 1) > 1
"""Solve the min and the max programs in two threads."""

_LP_TOL = 1e-9
"""HiGHS primal and dual feasibility tolerances."""


def _widen(lo: np.ndarray, hi: np.ndarray, rel: float = _VAR_MARGIN) -> tuple[np.ndarray, ...]:
    m = rel * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
    return lo - m, hi + m


@dataclass(frozen=True)
class ExactDesign(Design):
    """``window``: number of past steps ``N`` kept in the LP (``None``: the full horizon)."""

    window: int | None = None


def _new_highs() -> highspy.Highs:
    h = highspy.Highs()
    h.setOptionValue("output_flag", False)
    h.setOptionValue("presolve", "off")
    h.setOptionValue("threads", 1)
    # tighter than HiGHS's 1e-7 defaults: the safe bound is only as tight as the duals
    h.setOptionValue("primal_feasibility_tolerance", _LP_TOL)
    h.setOptionValue("dual_feasibility_tolerance", _LP_TOL)
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


class _TrajectoryLP:
    """The sparse LP over blocks ``(x[j], d[j])`` of consecutive steps.

    Rows of block ``b``: the dynamics rows linking it to block ``b-1`` (none for the first block),
    then the ``ny`` measurement rows (free rows, bounds ``±inf``, for missing or dropped
    components, so that the matrix does not depend on which samples are available). The matrix
    is kept in COO form, stored row by row, with the row and column bounds; two
    :class:`_Chain` s (one HiGHS model each) solve the ``min`` and the ``max`` programs.
    """

    def __init__(self, nx: int, nd: int, ny: int, parallel: bool):
        self.nx, self.nd, self.ny, self.nb = nx, nd, ny, nx + nd
        self.n_dyn: list[int] = []  # dynamics rows of each block
        self.rows = np.zeros(0, dtype=np.int64)
        self.cols = np.zeros(0, dtype=np.int64)
        self.vals = np.zeros(0)
        self.row_lo = np.zeros(0)
        self.row_hi = np.zeros(0)
        self.lo = np.zeros(0)
        self.hi = np.zeros(0)
        self.chains = (_Chain(self, 1.0), _Chain(self, -1.0))
        self.parallel = parallel

    @property
    def n_blocks(self) -> int:
        return len(self.n_dyn)

    # -- building ----------------------------------------------------------------------------
    def push(
        self,
        dynamics: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
        measurement: tuple[np.ndarray, np.ndarray, np.ndarray],
        x_bounds: tuple[np.ndarray, np.ndarray],
        d_bounds: tuple[np.ndarray, np.ndarray],
    ) -> None:
        """Append the block ``(x[j], d[j])``: ``dynamics = (A, E, B u)`` of step ``j-1`` (the
        link from the previous block), ``measurement = (C, F, y - D u)`` of step ``j`` (NaN in
        the right-hand side: a free row)."""
        nx, nd, nb = self.nx, self.nd, self.nb
        off = self.lo.size
        self.lo = np.concatenate([self.lo, x_bounds[0], d_bounds[0]])
        self.hi = np.concatenate([self.hi, x_bounds[1], d_bounds[1]])
        if dynamics is not None:
            A, E, bu = dynamics
            self._append_rows(np.hstack([-A, -E, np.eye(nx), np.zeros((nx, nd))]), off - nb, bu)
        C, F, rhs = measurement
        self._append_rows(np.hstack([C, F]), off, rhs)
        self.n_dyn.append(0 if dynamics is None else nx)

    def _append_rows(self, dense: np.ndarray, col0: int, rhs: np.ndarray) -> None:
        r, c = np.nonzero(dense)
        free = np.isnan(rhs)
        self.rows = np.concatenate([self.rows, r + self.row_lo.size])
        self.cols = np.concatenate([self.cols, c + col0])
        self.vals = np.concatenate([self.vals, dense[r, c]])
        self.row_lo = np.concatenate([self.row_lo, np.where(free, -np.inf, rhs)])
        self.row_hi = np.concatenate([self.row_hi, np.where(free, np.inf, rhs)])

    def pop_front(self) -> None:
        """Remove the oldest block, its rows and the dynamics rows that reach into it."""
        n_del = self.n_dyn[0] + self.ny + self.n_dyn[1]
        keep = self.rows >= n_del
        self.rows = self.rows[keep] - n_del
        self.cols = self.cols[keep] - self.nb
        self.vals = self.vals[keep]
        self.row_lo, self.row_hi = self.row_lo[n_del:], self.row_hi[n_del:]
        self.lo, self.hi = self.lo[self.nb :], self.hi[self.nb :]
        self.n_dyn.pop(0)
        self.n_dyn[0] = 0

    def free_last_measurement(self) -> None:
        """Drop the measurement of the newest block (an inconsistent sample): free rows."""
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
    def last_x_box(self) -> tuple[np.ndarray, np.ndarray, bool]:
        """Bounds of ``x`` of the newest block: ``(lower, upper, feasible)``.

        ``feasible`` is False when HiGHS finds the constraints infeasible (from a cold start);
        the bounds are then the variable bounds.
        """
        first = self.lo.size - self.nb
        lower = self.lo[first : first + self.nx].copy()
        upper = self.hi[first : first + self.nx].copy()
        free = np.isinf(self.row_lo)
        rhs = np.where(free, 0.0, self.row_lo)
        if self.parallel:
            jobs = [_pool().submit(c.solve, first, free, rhs) for c in self.chains]
            (lo_b, ok_lo), (hi_b, ok_hi) = (job.result() for job in jobs)
        else:
            (lo_b, ok_lo), (hi_b, ok_hi) = (c.solve(first, free, rhs) for c in self.chains)
        if not (ok_lo and ok_hi):
            return lower, upper, False
        return np.maximum(lower, lo_b), np.minimum(upper, -hi_b), True

    def safe_min(self, lam: np.ndarray, rhs: np.ndarray, col: int, sense: float) -> float:
        """``λ^T b + Σ min(r l, r u)``, ``r = c - M^T λ``, ``c = sense e_col``: a lower bound on
        ``min c^T z`` valid for every ``λ`` (Neumaier & Shcherbina 2004)."""
        r = -np.bincount(self.cols, weights=self.vals * lam[self.rows], minlength=self.lo.size)
        r[col] += sense
        return float(lam @ rhs + np.minimum(r * self.lo, r * self.hi).sum())


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

    def solve(self, first: int, free: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, bool]:
        """Safe lower bounds of ``sense * x[first + i]``; False if found infeasible."""
        self._sync()
        lp, h = self.lp, self.h
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
                return out, False
            if status == highspy.HighsModelStatus.kOptimal:
                lam = np.where(free, 0.0, np.asarray(h.getSolution().row_dual))
            else:  # numerical trouble: the bound with λ = 0 (the variable bound) stays valid
                lam = np.zeros(rhs.size)
            out[i] = lp.safe_min(lam, rhs, col, self.sense)
        return out, True

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
        h.changeColsBounds(n_col, np.arange(n_col, dtype=np.int32), lp.lo, lp.hi)
        h.changeRowsBounds(n_row, np.arange(n_row, dtype=np.int32), lp.row_lo, lp.row_hi)
        self._synced = (lp.rows.copy(), lp.cols.copy(), lp.vals.copy(), n_row, n_col)

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
        empty = np.zeros(0, np.int32)
        self.h.addCols(n_new, np.zeros(n_new), lp.lo[o_ncol:], lp.hi[o_ncol:], 0, empty, empty,
                       np.zeros(0))  # fmt: skip
        self.h.addRows(m, lp.row_lo[o_nrow:], lp.row_hi[o_nrow:], vals.size, starts, idx, vals)

    def _rebuild(self) -> None:
        lp, h = self.lp, self.h
        n_col = lp.lo.size
        m, starts, idx, vals = self._csr(0)
        empty = np.zeros(0, np.int32)
        basis = h.getBasis() if h.getNumCol() == n_col and h.getNumRow() == m else None
        h.clearModel()
        h.addCols(n_col, np.zeros(n_col), lp.lo, lp.hi, 0, empty, empty, np.zeros(0))
        h.addRows(m, lp.row_lo, lp.row_hi, vals.size, starts, idx, vals)
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
        }

    def state(self) -> dict[str, Any]:
        """The online state (JSON-serialisable): the kept history; the LP is rebuilt on restore."""
        out = super().state()
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
        x_pred = self._prediction(state, k)
        dynamics = self._dynamics(k - 1, state["u"][-1]) if k > 0 else None
        lp.push(dynamics, self._measurement(k, u_k, y_k), x_pred, (d_k.lo, d_k.hi))
        N = self.design.window
        if N is not None and lp.n_blocks > N + 1:
            lp.pop_front()
        lo, hi, feasible = lp.last_x_box()
        used = 1.0
        if not feasible:
            state["_inconsistent"] = True
            used = 0.0
            lp.free_last_measurement()
            lo, hi, feasible = lp.last_x_box()
        # the two bounds are both valid: if rounding crossed them, their hull is still valid
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        x_lo, x_hi = lp.tighten_last_x(*_widen(lo, hi))
        self._remember(state, x_lo, x_hi, u_k, y_k, d_k, used)
        return lo, hi

    def _prediction(self, state: dict[str, Any], k: int) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``x[k]`` implied by the box of ``x[k-1]`` (Lemma 1), widened slightly."""
        if k == 0:
            assert self.x0 is not None
            return self.x0.lo.copy(), self.x0.hi.copy()
        A, B, _, _, E, _ = self.sys.matrices_at(k - 1)
        lo, hi = image_bounds(A, state["xlo"][-1], state["xhi"][-1])
        dlo, dhi = image_bounds(E, state["dlo"][-1], state["dhi"][-1])
        bu = B @ state["u"][-1]
        return _widen(lo + dlo + bu, hi + dhi + bu)

    def _dynamics(self, j: int, u_j: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        A, B, _, _, E, _ = self.sys.matrices_at(j)
        return A, E, B @ u_j

    def _measurement(
        self, j: int, u_j: np.ndarray, y_j: np.ndarray, used: bool = True
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(C, F, y - D u)`` of step ``j``; NaN (missing, or a dropped sample) = free row."""
        _, _, C, D, _, F = self.sys.matrices_at(j)
        rhs = y_j - D @ u_j if used else np.full(self.sys.ny, np.nan)
        return C, F, rhs

    def _remember(
        self,
        state: dict[str, Any],
        lo: np.ndarray,
        hi: np.ndarray,
        u_k: np.ndarray,
        y_k: np.ndarray,
        d_k: Box,
        used: float,
    ) -> None:
        N = self.design.window
        new = {"xlo": lo, "xhi": hi, "y": y_k, "u": u_k, "dlo": d_k.lo, "dhi": d_k.hi}
        for key, val in new.items():
            hist = np.vstack([state[key], np.asarray(val, dtype=float)[None, :]])
            state[key] = hist if N is None else hist[-N:]
        used_hist = np.append(state["used"], used)
        state["used"] = used_hist if N is None else used_hist[-N:]

    def _rebuild(self, state: dict[str, Any], k: int) -> _TrajectoryLP:
        """The LP of the kept history (empty at step 0; after ``restore()`` the same program)."""
        lp = _TrajectoryLP(self.sys.nx, self.sys.nd, self.sys.ny, _PARALLEL)
        m = state["xlo"].shape[0]
        for i, j in enumerate(range(k - m, k)):
            dynamics = self._dynamics(j - 1, state["u"][i - 1]) if i > 0 else None
            meas = self._measurement(j, state["u"][i], state["y"][i], bool(state["used"][i]))
            x_b = (state["xlo"][i], state["xhi"][i])
            lp.push(dynamics, meas, x_b, (state["dlo"][i], state["dhi"][i]))
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
