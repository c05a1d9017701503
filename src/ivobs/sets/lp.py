"""One linear program held by HiGHS (``highspy``'s public ``Highs`` API), built once and then
changed: objectives, variable and row bounds, appended rows and columns, warm-started bases.

    min cᵀz   subject to   row_lo <= M z <= row_hi,   lo <= z <= hi

Every set-membership method that asks linear programs (the hull of a constrained zonotope, the
``exact`` trajectory program, the ``dual-window`` refreshes) goes through :class:`LinearProgram`.
Nothing here is a bound: callers certify what they return from the multipliers
(:meth:`LinearProgram.row_duals`, :meth:`LinearProgram.dual_ray`) by weak duality, so any
answer of the solver, optimal or not, gives a valid bound ([Neumaier2004]).

Sign convention (HiGHS's): at an optimum the reduced costs are ``c − Mᵀλ`` (``λ``: the row
duals), so ``λᵀb − Σ_j |c_j − (Mᵀλ)_j| r`` bounds ``min cᵀz`` over ``{M z = b, |z_j| <= r}``.

HiGHS writes nothing: its ``output_flag`` option is set before its first call that could log
(:class:`_QuietHighs`).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

__all__ = ["LinearProgram", "basis_codes", "basis_of", "csc"]

_I32 = np.int32


def _highspy() -> Any:
    import highspy  # imported where a program is built (it is slow to import)

    return highspy


@cache
def _quiet_highs() -> Any:
    """``highspy.Highs`` with its ``output_flag`` off before anything is logged: its
    constructor enables the callbacks, which prints HiGHS's banner unless the option is already
    off, so the option is set there."""
    highspy = _highspy()

    class QuietHighs(highspy.Highs):  # type: ignore[misc, name-defined]
        def enableCallbacks(self) -> Any:
            self.setOptionValue("output_flag", False)
            return super().enableCallbacks()

    return QuietHighs


def csc(M: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The dense ``M`` in compressed columns ``(start, index, value)`` (HiGHS's format)."""
    nz = M.T != 0
    start = np.zeros(M.shape[1] + 1, dtype=_I32)
    np.cumsum(nz.sum(axis=1), out=start[1:])
    return start, nz.nonzero()[1].astype(_I32), M.T[nz]


class LinearProgram:
    """A HiGHS model (simplex, one thread, no presolve unless asked), changed in place.

    Feasibility tolerances ``1e-9`` (primal), ``1e-10`` (dual): tighter than HiGHS's ``1e-7``,
    as a certified bound is only as tight as the multipliers it is evaluated at.

    Parameters
    ----------
    presolve : HiGHS's presolve (off: the basis of one solve warm-starts the next).
    iteration_limit : simplex iterations per solve (None: HiGHS's); a solve stopped by it
        reports ``"limit"`` and its last multipliers.
    scale : HiGHS's scaling of the matrix (off when a rebuilt program must be solved the same
        way as one extended row by row).
    ipm : the interior-point method instead of the simplex (a second opinion when the simplex
        fails on an ill-conditioned program).
    """

    def __init__(
        self,
        *,
        presolve: bool = False,
        iteration_limit: int | None = None,
        scale: bool = True,
        ipm: bool = False,
    ) -> None:
        self._hs = _highspy()
        h = self.h = _quiet_highs()()
        h.setOptionValue("threads", 1)
        h.setOptionValue("presolve", "on" if presolve else "off")
        if ipm:
            h.setOptionValue("solver", "ipm")
        h.setOptionValue("primal_feasibility_tolerance", 1e-9)
        h.setOptionValue("dual_feasibility_tolerance", 1e-10)
        if iteration_limit is not None:
            h.setOptionValue("simplex_iteration_limit", int(iteration_limit))
        if not scale:
            h.setOptionValue("simplex_scale_strategy", 0)
        status = self._hs.HighsModelStatus
        self._status = {
            status.kOptimal: "optimal",
            status.kInfeasible: "infeasible",
            status.kUnboundedOrInfeasible: "infeasible",
            status.kIterationLimit: "limit",
        }

    # -- the model ------------------------------------------------------------------------------
    @property
    def n_cols(self) -> int:
        return int(self.h.getNumCol())

    @property
    def n_rows(self) -> int:
        return int(self.h.getNumRow())

    def load(
        self,
        cols: tuple[np.ndarray, np.ndarray, np.ndarray],
        n_rows: int,
        lo: np.ndarray,
        hi: np.ndarray,
        row_lo: np.ndarray,
        row_hi: np.ndarray,
        cost: np.ndarray | None = None,
    ) -> None:
        """Replace the model: ``M`` in compressed columns ``cols`` (:func:`csc`), ``n_rows``
        rows; bounds as in the module docstring (``±inf``: none); ``cost`` (default 0)."""
        start, index, value = cols
        n = lo.size
        c = np.zeros(n) if cost is None else np.ascontiguousarray(cost, dtype=float)
        self.h.passModel(n, n_rows, index.size, 1, 1, 0.0, c, _f(lo), _f(hi), _f(row_lo),
                         _f(row_hi), start.astype(_I32), index.astype(_I32), _f(value),
                         np.zeros(n, dtype=_I32))  # fmt: skip

    def clear(self) -> None:
        """An empty model (no rows, no columns)."""
        self.h.clearModel()

    def add_cols(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Append columns without entries (their rows come with :meth:`add_rows`)."""
        e = np.zeros(0, _I32)
        self.h.addCols(lo.size, np.zeros(lo.size), _f(lo), _f(hi), 0, e, e, np.zeros(0))

    def add_rows(
        self, rows: tuple[np.ndarray, np.ndarray, np.ndarray], row_lo: np.ndarray,
        row_hi: np.ndarray,
    ) -> None:  # fmt: skip
        """Append rows given in compressed rows ``(start, index, value)``."""
        start, index, value = rows
        self.h.addRows(row_lo.size, _f(row_lo), _f(row_hi), index.size, start.astype(_I32),
                       index.astype(_I32), _f(value))  # fmt: skip

    def set_cost(self, cols: np.ndarray, values: np.ndarray) -> None:
        """Change the cost of the columns ``cols``."""
        self.h.changeColsCost(cols.size, cols.astype(_I32), _f(values))

    def set_bounds(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """Change every variable bound."""
        n = lo.size
        self.h.changeColsBounds(n, np.arange(n, dtype=_I32), _f(lo), _f(hi))

    def set_row_bounds(self, row_lo: np.ndarray, row_hi: np.ndarray) -> None:
        """Change every row bound."""
        n = row_lo.size
        self.h.changeRowsBounds(n, np.arange(n, dtype=_I32), _f(row_lo), _f(row_hi))

    # -- solving --------------------------------------------------------------------------------
    def solve(self, primal: bool = False, devex: bool = False) -> str:
        """Solve from the current basis (dual simplex; ``primal``: the primal simplex, for a
        changed objective whose last basis is still feasible): ``"optimal"``, ``"infeasible"``,
        ``"limit"`` (iteration limit) or ``"failed"``.

        ``devex``: the dual simplex prices by Devex instead of dual steepest edge. From a basis
        that is not the slack basis, steepest-edge weights cost a solve per row to set up, and
        once they exist the primal simplex keeps them up to date at a solve per iteration: for
        one dual solve from a given basis followed by a chain of short primal ones, that is
        most of the work. (From the slack basis Devex can fail where steepest edge does not.)"""
        self.h.setOptionValue("simplex_strategy", 4 if primal else 1)
        self.h.setOptionValue("simplex_dual_edge_weight_strategy", 1 if devex else -1)
        self.h.run()
        return self._status.get(self.h.getModelStatus(), "failed")

    def iterations(self) -> int:
        """Simplex iterations of the last solve."""
        return int(self.h.getInfo().simplex_iteration_count)

    def restart(self) -> None:
        """Forget the solver's work (factorisation, pricing weights) but keep the basis: the
        next solve starts as a program rebuilt from that basis would."""
        basis = self.h.getBasis()
        self.h.clearSolver()
        if basis.valid:
            self.h.setBasis(basis)

    def cold(self) -> None:
        """Forget the basis too: the next solve starts from scratch."""
        self.h.clearSolver()

    def objective(self) -> float:
        """The objective value of the last solve (the solver's, not a bound)."""
        return float(self.h.getInfo().objective_function_value)

    def primal(self) -> np.ndarray:
        """``z`` of the last solve."""
        return np.asarray(self.h.getSolution().col_value, dtype=float)

    def row_duals(self) -> np.ndarray | None:
        """``λ`` of the last solve (None when HiGHS has none)."""
        sol = self.h.getSolution()
        if not sol.dual_valid:
            return None
        lam = np.asarray(sol.row_dual, dtype=float)
        return lam if lam.size == self.n_rows else None

    def dual_ray(self) -> np.ndarray | None:
        """A Farkas ray of an infeasible program (None when HiGHS has none)."""
        _, has, ray = self.h.getDualRay()
        ray = np.asarray(ray, dtype=float)
        return ray if has and ray.size == self.n_rows else None

    # -- bases ----------------------------------------------------------------------------------
    def basis(self) -> Any:
        """HiGHS's current basis (a ``highspy.HighsBasis``)."""
        return self.h.getBasis()

    def set_basis(self, basis: Any) -> None:
        """Start the next solve from ``basis`` (ignored if None or invalid)."""
        if basis is not None and basis.valid:
            self.h.setBasis(basis)


def basis_codes(basis: Any) -> np.ndarray:
    """A HiGHS basis as int8 status codes (the columns, then the rows), for a saved state."""
    codes = [int(v) for v in basis.col_status] + [int(v) for v in basis.row_status]
    return np.array(codes, dtype=np.int8)


def basis_of(codes: np.ndarray, n_col: int) -> Any:
    """The HiGHS basis of :func:`basis_codes` codes (``n_col`` columns)."""
    hs = _highspy()
    b = hs.HighsBasis()
    status = [hs.HighsBasisStatus(int(v)) for v in codes]
    b.col_status, b.row_status = status[:n_col], status[n_col:]
    b.valid, b.alien = True, False
    return b


def _f(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=float)
