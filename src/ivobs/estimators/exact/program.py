"""The trajectory program: a sparse linear program over the blocks ``(x[j], d[j])``.

The variables are the blocks ``(x[j], d[j])`` of consecutive steps, the constraints the
dynamics rows ``x[j+1] - A_j x[j] - E_j d[j] = B_j u[j]`` and the measurement rows
``C_j x[j] + F_j d[j] = y[j] - D_j u[j]``, each a range ``rhs ± tau``
(:mod:`~ivobs.estimators.exact.rows`). The program is built incrementally: a block per step,
the oldest block dropped in a moving window. It holds numbers only; the HiGHS models that solve
it live in :mod:`~ivobs.estimators.exact.highs`.
"""

from __future__ import annotations

import numpy as np

from .rows import Dynamics, Measurement
from .safe import SafeBoundData, bound_data

__all__ = ["TrajectoryLP"]


class TrajectoryLP:
    """The sparse program over blocks ``(x[j], d[j])`` of consecutive steps.

    Rows of block ``b``: the dynamics rows linking it to block ``b-1`` (none for the first block),
    then the ``ny`` measurement rows (free rows, bounds ``±inf``, for missing or dropped
    components, so that the matrix does not depend on which samples are available). The matrix
    is kept in COO form, stored row by row, with the row ranges and the variable bounds (in the
    original coordinates) and the shifts ``m`` (per column) and ``M m`` (per row) of the
    program HiGHS sees (``z = m + z'``: ``m`` the centre of the interval prediction of ``x[j]``
    and of the box of ``d[j]``, so that HiGHS's absolute tolerances act at the scale of the
    widths, not of ``|x|``).

    HiGHS also sees the program scaled by powers of two, ``z' = S z''`` and each row multiplied
    by ``r_i``: ``S`` the state scaling ``x_scale`` (the balancing of the model,
    :func:`~ivobs.estimators._balanced.balancing`, so that states of magnitudes ``1e6`` and
    ``1e-3`` reach it as numbers of the same size) and ``r_i`` the power of two nearest the
    inverse of the row's largest scaled entry. Its row duals ``λ''`` are those of the original
    rows times ``r``; :meth:`duals` maps them back. The bounds are the safe bounds (S) of the
    original program for whatever multipliers come back, so the scaling changes how well HiGHS
    solves, never what is proven. The scaling is fixed per state (not per step), so that a
    moving window of a time-invariant system keeps one matrix and its basis.
    """

    def __init__(self, nx: int, nd: int, ny: int, x_scale: np.ndarray | None = None):
        self.nx, self.nd, self.ny, self.nb = nx, nd, ny, nx + nd
        self.x_scale = np.ones(nx) if x_scale is None else np.asarray(x_scale, dtype=float)
        self.col_scale = np.zeros(0)  # S, per column (x: x_scale, d: 1)
        self.row_scale = np.zeros(0)  # r, per row
        self.hvals = np.zeros(0)  # the entries HiGHS sees, r_i M_ij S_j
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

    @property
    def last_x(self) -> slice:
        """The columns of ``x`` of the newest block."""
        first = self.lo.size - self.nb
        return slice(first, first + self.nx)

    # -- building ----------------------------------------------------------------------------
    def push(
        self,
        dynamics: Dynamics | None,
        measurement: Measurement,
        x_bounds: tuple[np.ndarray, np.ndarray],
        d_bounds: tuple[np.ndarray, np.ndarray],
        x_centre: np.ndarray,
    ) -> None:
        """Append the block ``(x[j], d[j])``: ``dynamics`` of step ``j-1`` (the link from the
        previous block), ``measurement`` of step ``j`` (NaN in the right-hand side: a free row);
        rows are ranges ``rhs ± tau``. ``x_centre``: the shift of ``x[j]`` in the program HiGHS
        sees."""
        nx, nd, nb = self.nx, self.nd, self.nb
        off = self.lo.size
        self.lo = np.concatenate([self.lo, x_bounds[0], d_bounds[0]])
        self.hi = np.concatenate([self.hi, x_bounds[1], d_bounds[1]])
        d_centre = 0.5 * (d_bounds[0] + d_bounds[1])
        self.shift = np.concatenate([self.shift, x_centre, d_centre])
        self.col_scale = np.concatenate([self.col_scale, self.x_scale, np.ones(nd)])
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
        scaled = dense * self.col_scale[col0 : col0 + dense.shape[1]]
        big = np.abs(scaled).max(axis=1, initial=0.0)
        with np.errstate(divide="ignore"):
            e = np.where(big > 0.0, np.clip(-np.round(np.log2(big)), -500, 500), 0.0)
        row_scale = np.exp2(e)
        self.rows = np.concatenate([self.rows, r + self.row_lo.size])
        self.cols = np.concatenate([self.cols, c + col0])
        self.vals = np.concatenate([self.vals, dense[r, c]])
        self.hvals = np.concatenate([self.hvals, scaled[r, c] * row_scale[r]])
        self.row_scale = np.concatenate([self.row_scale, row_scale])
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
        self.vals, self.hvals = self.vals[keep], self.hvals[keep]
        self.row_lo, self.row_hi = self.row_lo[n_del:], self.row_hi[n_del:]
        self.rhs = self.rhs[n_del:]
        self.row_shift, self.row_scale = self.row_shift[n_del:], self.row_scale[n_del:]
        self.lo, self.hi = self.lo[self.nb :], self.hi[self.nb :]
        self.shift, self.col_scale = self.shift[self.nb :], self.col_scale[self.nb :]
        self.n_dyn.pop(0)
        self.n_dyn[0] = 0

    def free_last_measurement(self) -> None:
        """Drop the measurement of the newest block (an inconsistent sample): free rows."""
        self.rhs[-self.ny :] = np.nan
        self.row_lo[-self.ny :] = -np.inf
        self.row_hi[-self.ny :] = np.inf

    def replace_last_measurement(self, measurement: Measurement) -> None:
        """Replace the measurement rows of the newest block (the last ``ny`` rows) by
        ``measurement``: a row rebuilt over a tighter box of its state (``nl-horizon``)."""
        first = self.row_lo.size - self.ny
        keep = self.rows < first
        self.rows, self.cols, self.vals = self.rows[keep], self.cols[keep], self.vals[keep]
        self.hvals = self.hvals[keep]
        self.rhs, self.row_shift = self.rhs[:first], self.row_shift[:first]
        self.row_scale = self.row_scale[:first]
        self.row_lo, self.row_hi = self.row_lo[:first], self.row_hi[:first]
        C, F, rhs, tau = measurement
        self._append_rows(np.hstack([C, F]), self.lo.size - self.nb, rhs, tau)

    def tighten_last_x(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Intersect the bounds of ``x`` of the newest block with ``[lo, hi]`` (the box just
        proven for it, widened) and return the new bounds. Intersecting (rather than replacing)
        keeps the prior ``x0`` exact on the first block."""
        sl = self.last_x
        self.lo[sl] = np.maximum(self.lo[sl], lo)
        self.hi[sl] = np.minimum(self.hi[sl], hi)
        return self.lo[sl].copy(), self.hi[sl].copy()

    # -- what the solvers need -----------------------------------------------------------------
    def bound_data(self) -> SafeBoundData:
        """The data of the safe bounds (S) of this program (a column has at most
        ``nx + ny + 1`` entries)."""
        return bound_data(self.rows, self.cols, self.vals, self.row_lo, self.row_hi, self.lo,
                          self.hi, self.nx + self.ny + 1)  # fmt: skip

    def shifted(
        self, relaxed: bool, col0: int = 0, row0: int = 0
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Variable bounds (from column ``col0``) and row bounds (from row ``row0``) of the
        program HiGHS sees, ``z'' = S⁻¹ (z - m)``, rows times ``r``: the equalities ``a_i^T z
        = rhs_i`` (ranged rows slow the simplex down by a third), or the ranges ``rhs_i ±
        tau_i`` if ``relaxed``."""
        s, rs = self.shift[col0:], self.row_shift[row0:]
        cs, r = self.col_scale[col0:], self.row_scale[row0:]
        lo, hi = (self.lo[col0:] - s) / cs, (self.hi[col0:] - s) / cs
        if relaxed:
            return lo, hi, (self.row_lo[row0:] - rs) * r, (self.row_hi[row0:] - rs) * r
        mid = (self.rhs[row0:] - rs) * r
        free = np.isnan(mid)
        return lo, hi, np.where(free, -np.inf, mid), np.where(free, np.inf, mid)

    def duals(self, lam: np.ndarray, col: int | None = None) -> np.ndarray:
        """Multipliers of the original rows from the row duals (or a dual ray) of the program
        HiGHS sees: ``r λ''``, times the scale of the objective's column ``col`` (the scaled
        program's objective is ``z''_col = z_col / S_col`` up to a constant)."""
        out: np.ndarray = lam * self.row_scale
        return out if col is None else out * self.col_scale[col]

    def csr(self, start: int) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        """Rows ``start..`` of the matrix in CSR form: ``(number of rows, starts, columns,
        values)``."""
        sel = slice(int(np.searchsorted(self.rows, start)), None)
        r = self.rows[sel] - start
        m = self.row_lo.size - start
        starts = np.searchsorted(r, np.arange(m)).astype(np.int32)
        return m, starts, self.cols[sel].astype(np.int32), self.hvals[sel]
