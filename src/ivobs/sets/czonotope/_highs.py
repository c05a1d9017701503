"""The hull LPs of a constrained zonotope with HiGHS (``highspy``) called directly.

``scipy.optimize.linprog`` converts its arguments, builds sparse matrices and a result object
on every call, and starts every program from scratch: for the small programs of a filter step
that was most of the time. Here the feasible set ``{A ξ = b, ‖ξ‖∞ <= r}`` is passed once (in
compressed columns) to a reused ``highspy.Highs`` object and only the objective changes between
the hull's programs, each warm-started from the optimal basis of the previous one. HiGHS is
imported where a program is solved (it is slow to import).

Cost of a solve: ``Highs.run`` has a fixed cost of ~65 µs on this machine even for a program
already solved (a quarter of it reading ``/sys/devices/system/cpu`` for the thread count, the
rest assessing the model and copying options; no option removes it), against ~100 µs of
simplex iterations for a warm-started servo program. :func:`block_duals` pays it once for all
the programs of a hull, but its multipliers differ from the chain's where the programs are
degenerate (see :data:`BLOCK_MAX`).
"""

from __future__ import annotations

import os
import sys
import threading
from functools import cache
from typing import Any

import numpy as np

__all__ = ["BLOCK_MAX", "BLOCK_SIZE", "block_duals", "chain_duals", "linprog_duals"]

BLOCK_MAX = 0
"""Largest ``K m`` (objectives times factors) whose ``K`` programs :func:`~.hull.hull_certificates`
solves as one block program (:func:`block_duals`) instead of a warm-started chain
(:func:`chain_duals`); 0: never (the default).

Measured 2026-11-27 (BENCHMARKS.md, "Constrained-zonotope hull speed"): with ``BLOCK_MAX =
2000`` the servo's constrained-zonotope runs ~1.25x faster (its hull LPs ~1.8x) and Hénon's
nl-constrained-zonotope ~1.2x, with the same guarantee, but the boxes are not those of the
chain: on the degenerate programs of a thin set the block solve returns other optimal
multipliers, which steer the elimination elsewhere (servo, 2,000 steps: mean width equal to
5e-6, single boxes up to 4.9 % wider or narrower). On tank30 (120 programs of 81 x 552) the
block solve is 7x slower than the chain (no warm start): hence a size limit."""

BLOCK_SIZE = 2000
"""The size limit ``K m`` of a caller that chooses the block program (``nl-constrained-zonotope``
by default, whose boxes need not be those of the chain): up to it one solve from scratch beats
``K`` warm-started ones (Hénon, K m ~ 150: 1.2x per step, BENCHMARKS.md "nl-constrained-zonotope
speed (2026-11-27 evening)"); tank30's 66,240 is far beyond."""

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


def _csc(A: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``A`` in compressed columns: ``(start, index, value)``."""
    At = A.T
    nz = At != 0
    start = np.zeros(A.shape[1] + 1, dtype=np.int32)
    # the counts and their running sum by the ufuncs directly (integers: exact either way)
    np.add.accumulate(np.add.reduce(nz, axis=1, dtype=np.int32), out=start[1:])
    return start, nz.nonzero()[1].astype(np.int32), At[nz]


def _pass(
    h: Any,
    cost: np.ndarray,
    csc: tuple[np.ndarray, np.ndarray, np.ndarray],
    shape: tuple[int, int],
    b: np.ndarray,
    radius: float,
    K: int = 1,
) -> None:
    """Pass ``K`` copies of ``{A ξ = b, ‖ξ‖∞ <= radius}`` (``A`` (nc, m) of shape ``shape`` in
    compressed columns ``csc``; block diagonal: copy ``i`` has the columns ``i m .. (i + 1) m - 1``
    and the rows ``i nc .. (i + 1) nc - 1``) with the cost ``cost`` (K m,) to ``h``, as arrays
    (``Highs.passModel`` of arrays: no ``HighsLp`` object filled field by field)."""
    nc, m = shape
    start, index, value = csc
    nnz = index.size
    if K > 1:  # np.tile and a list of shifted pieces cost more here
        offset = np.arange(K, dtype=np.int32)[:, None]
        block_start = np.empty(K * m + 1, dtype=np.int32)
        np.add(start[:-1], offset * nnz, out=block_start[:-1].reshape(K, m))
        block_start[-1] = K * nnz
        start = block_start
        index = (index + offset * nc).ravel()
        value = np.concatenate([value] * K)
        b = np.concatenate([b] * K)
    n = K * m
    lower, upper = np.full(n, -radius), np.full(n, radius)
    integrality = np.zeros(n, dtype=np.int32)  # all continuous (HiGHS wants one per column)
    h.passModel(n, K * nc, K * nnz, 1, 1, 0.0, cost, lower, upper, b, b, start, index, value,
                integrality)  # fmt: skip


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

    m = Gs.shape[1]
    mu = np.empty((Gs.shape[0], A.shape[0]))
    idx = np.arange(m, dtype=np.int32)
    csc = _csc(A)
    for n_chain, rows in enumerate(chains):
        h = _solver(n_chain % 2)
        _pass(h, np.zeros(m), csc, A.shape, b, radius)
        for i in rows:
            h.changeColsCost(m, idx, np.ascontiguousarray(Gs[i]))
            duals = _solve(h)
            if isinstance(duals, str):
                return duals
            mu[i] = duals
    if not np.logical_and.reduce(np.isfinite(mu), axis=None):
        return "failed"
    return mu


def _solve(h: Any) -> Any:
    """Run the loaded program: its equality multipliers, or ``"infeasible"`` / ``"failed"``."""
    h.run()
    status = h.getModelStatus()
    infeasible, optimal = _statuses()
    if status == infeasible:
        return "infeasible"
    sol = h.getSolution()
    if status != optimal or not sol.dual_valid:
        return "failed"
    return sol.row_dual


@cache
def _statuses() -> tuple[Any, Any]:
    """HiGHS' ``kInfeasible`` and ``kOptimal`` model statuses, looked up once (an import
    statement and two attribute lookups per solve cost ~3 µs, twelve solves a servo step)."""
    import highspy

    return highspy.HighsModelStatus.kInfeasible, highspy.HighsModelStatus.kOptimal


def block_duals(Gs: np.ndarray, A: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray | str:
    """The multipliers of :func:`chain_duals` from ONE program: the ``K`` programs side by side
    (block diagonal, a copy of the factors per objective, the sum of the objectives),
    ``min Σ_i Gs_iᵀξ_i : A ξ_i = b, ‖ξ_i‖∞ <= radius``, whose equality multipliers are those of
    the ``K`` programs (the blocks share nothing). On small programs HiGHS' fixed cost of a
    solve (~65 µs on the servo's 8 x 46, most of a warm-started solve) dominates, so one solve
    from scratch beats ``K`` warm-started ones; on large ones (tank30) the warm starts win
    (:data:`BLOCK_MAX`). Any multipliers give sound bounds; the optimal ones the LP's."""

    K, nc = Gs.shape[0], A.shape[0]
    h = _solver(0)
    _pass(h, np.ascontiguousarray(Gs, dtype=float).ravel(), _csc(A), A.shape, b, radius, K)
    duals = _solve(h)
    if isinstance(duals, str):
        return duals
    mu = np.asarray(duals, dtype=float).reshape(K, nc)
    if not np.isfinite(mu).all():
        return "failed"
    return mu


def linprog_duals(Gs: np.ndarray, A: np.ndarray, b: np.ndarray, radius: float) -> np.ndarray | None:
    """Equality multipliers ``μ`` (K, nc) of ``min {Gs_iᵀξ : A ξ = b, ‖ξ‖∞ <= radius}``, each
    program solved from scratch as ``scipy.optimize.linprog(Gs[i], A_eq=A, b_eq=b,
    bounds=(-radius, radius), method="highs")`` solves it, bit for bit (the same HiGHS, the
    same options, the same model, a fresh solver object per program), without linprog's
    per-call work (input checks, a sparse matrix and option validation per call, the bound
    marginals built in a Python loop): ~40 % less time on tank30's fallbacks (81 x 552, 120
    programs: 6.3-9.2 ms -> 3.4-5.8 ms per program). A row of NaN where HiGHS does not
    report an optimum (the caller then runs linprog's further attempts). ``None`` when SciPy's
    bundled HiGHS is not where (or not what) SciPy 1.15+ keeps: the caller then uses linprog."""
    try:
        import scipy.optimize._highspy._core as core  # SciPy's own HiGHS build (private)
        from scipy.sparse import csc_array

        options = core.HighsOptions()  # linprog's: presolve on, dual simplex, silent
        options.presolve = "on"
        options.highs_debug_level = core.HighsDebugLevel.kHighsDebugLevelNone
        options.log_to_console = False
        options.output_flag = False
        options.simplex_strategy = 1  # kSimplexStrategyDual
        new_solver, optimal = core._Highs, core.HighsModelStatus.kOptimal
    except (ImportError, AttributeError):  # pragma: no cover - another SciPy: linprog itself
        return None
    K, m = Gs.shape
    nc = A.shape[0]
    S = csc_array(A)  # as linprog builds it (explicit zeros dropped, int32 indices)
    mu = np.full((K, nc), np.nan)
    csc = (S.indptr, S.indices, S.data)
    cost = np.ascontiguousarray(Gs, dtype=float)
    for i in range(K):
        h = new_solver()
        h.passOptions(options)
        # the arrays straight to HiGHS (a HighsLp filled field by field converts them element
        # by element, ~0.8 ms per tank30 program): the same model
        _pass(h, cost[i], csc, (nc, m), b, float(radius))
        h.run()
        if h.getModelStatus() != optimal:
            continue
        sol = h.getSolution()
        x, con = np.array(sol.col_value), b - np.array(sol.row_value)
        # linprog's own check of an optimum (``_check_result``: bounds and residuals within
        # 10 sqrt(1e-9)), which turns a failed one into status 4
        fun = h.getInfo().objective_function_value
        if np.isnan(x).any() or np.isnan(fun) or np.isnan(con).any():
            continue
        if np.any(x < -radius - _TOL) or np.any(x > radius + _TOL) or np.any(abs(con) > _TOL):
            continue
        mu[i] = sol.row_dual
    return mu


_TOL = float(np.sqrt(1e-9) * 10)
"""``scipy.optimize.linprog``'s tolerance on the bounds and residuals of an optimum."""
