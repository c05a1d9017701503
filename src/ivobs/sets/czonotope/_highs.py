"""The hull LPs of a constrained zonotope with HiGHS (``highspy``) called directly.

``scipy.optimize.linprog`` converts its arguments, builds sparse matrices and a result object
on every call, and starts every program from scratch: for the small programs of a filter step
that was most of the time. Here the feasible set ``{A ξ = b, ‖ξ‖∞ <= r}`` is passed once (in
compressed columns) to a reused ``highspy.Highs`` object and only the objective changes between
the hull's programs, each warm-started from the optimal basis of the previous one. HiGHS is
imported where a program is solved (it is slow to import).
"""

from __future__ import annotations

import os
import sys
import threading
from typing import Any

import numpy as np

__all__ = ["chain_duals"]

_LOCAL = threading.local()


def _silenced_new() -> Any:
    """A ``highspy.Highs`` object; the banner HiGHS >= 1.15 prints from C++ at the first
    construction of the process (before any option can be set) is sent to ``/dev/null``."""
    import highspy

    try:
        sys.stdout.flush()
        saved, null = os.dup(1), os.open(os.devnull, os.O_WRONLY)
    except (OSError, ValueError, AttributeError):  # no file descriptor 1: nothing to silence
        return highspy.Highs()  # type: ignore[no-untyped-call]
    try:
        os.dup2(null, 1)
        return highspy.Highs()  # type: ignore[no-untyped-call]
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


def _solver(i: int) -> Any:
    """The ``i``-th reused HiGHS object of this thread (simplex, no presolve: warm starts)."""
    hs = getattr(_LOCAL, "hs", None)
    if hs is None:
        hs = []
        for _ in range(2):
            h = _silenced_new()
            h.setOptionValue("output_flag", False)
            h.setOptionValue("threads", 1)
            h.setOptionValue("presolve", "off")
            h.setOptionValue("solver", "simplex")
            # tighter than HiGHS' 1e-7 defaults: the certified bound is only as tight as the
            # multipliers (the ``exact`` method's choice)
            h.setOptionValue("primal_feasibility_tolerance", 1e-9)
            h.setOptionValue("dual_feasibility_tolerance", 1e-10)
            hs.append(h)
        _LOCAL.hs = hs
    return hs[i]


def _model(A: np.ndarray, b: np.ndarray, radius: float) -> Any:
    """``{A ξ = b, ‖ξ‖∞ <= radius}`` as a ``highspy.HighsLp`` (compressed columns)."""
    import highspy

    nc, m = A.shape
    At = A.T
    nz = At != 0
    start = np.zeros(m + 1, dtype=np.int32)
    np.cumsum(nz.sum(axis=1), out=start[1:])
    lp = highspy.HighsLp()
    lp.num_col_, lp.num_row_ = m, nc
    lp.col_cost_ = np.zeros(m)
    lp.col_lower_ = np.full(m, -radius)
    lp.col_upper_ = np.full(m, radius)
    lp.row_lower_, lp.row_upper_ = b, b
    lp.a_matrix_.format_ = highspy.MatrixFormat.kColwise
    lp.a_matrix_.start_ = start
    lp.a_matrix_.index_ = np.nonzero(nz)[1].astype(np.int32)
    lp.a_matrix_.value_ = At[nz]
    return lp


def chain_duals(
    Gs: np.ndarray, A: np.ndarray, b: np.ndarray, radius: float, chains: list[list[int]]
) -> np.ndarray | str:
    """Equality multipliers ``μ`` (K, nc) of the ``K`` programs
    ``min {Gs_iᵀξ : A ξ = b, ‖ξ‖∞ <= radius}``, in the sign convention of
    :func:`~.hull._dual_bounds` (``μᵀb - r ‖g - Aᵀμ‖₁`` is the bound).

    The feasible set is the same for all: it is passed to HiGHS once per chain (``chains``:
    lists of rows of ``Gs`` that cover them all) and only the cost changes along a chain, so
    each solve starts from the optimal basis of the previous objective (for a hull: the minima
    of ``x_1 .. x_n`` in one chain, the maxima of ``x_n .. x_1`` in the other; neighbouring
    objectives have close optima, opposite ones do not). ``"infeasible"`` when HiGHS calls
    the set infeasible, ``"failed"`` on any other outcome."""
    import highspy

    m = Gs.shape[1]
    mu = np.empty((Gs.shape[0], A.shape[0]))
    lp = _model(A, b, radius)
    idx = np.arange(m, dtype=np.int32)
    for n_chain, rows in enumerate(chains):
        h = _solver(n_chain % 2)
        h.passModel(lp)
        for i in rows:
            h.changeColsCost(m, idx, np.ascontiguousarray(Gs[i]))
            h.run()
            status = h.getModelStatus()
            if status == highspy.HighsModelStatus.kInfeasible:
                return "infeasible"
            sol = h.getSolution()
            if status != highspy.HighsModelStatus.kOptimal or not sol.dual_valid:
                return "failed"
            mu[i] = sol.row_dual
    if not np.all(np.isfinite(mu)):
        return "failed"
    return mu
