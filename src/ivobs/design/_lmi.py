"""Solving LMIs with CVXPY: Clarabel first, SCS as fallback, status always checked.

A design that the solver reports as infeasible, unbounded or inaccurate raises
:class:`ivobs.DesignError`; callers must also verify the property they needed on the numbers
they extract (e.g. that ``A - LC`` is Schur), since a solver tolerance is not a proof.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import DesignError

__all__ = ["MAX_LMI_STATES", "check_size", "solve", "sym"]

MAX_LMI_STATES = 200
"""Above this state dimension dense LMI designs are refused (they do not scale): pass a gain."""


def sym(M: Any) -> Any:
    """``(M + M^T) / 2`` for a CVXPY expression (CVXPY needs explicit symmetry for ``>>``)."""
    return (M + M.T) / 2


def check_size(nx: int, what: str) -> None:
    """Refuse dense LMIs above :data:`MAX_LMI_STATES` states with a pointer to what scales."""
    if nx > MAX_LMI_STATES:
        raise DesignError(
            f"{what}: a dense LMI with nx = {nx} > {MAX_LMI_STATES} states does not scale; "
            "pass an explicit gain L=..., or use the 'kkl' (Sylvester) or 'fixed-time' methods"
        )


def solve(problem: Any, what: str) -> str:
    """Solve with Clarabel, then SCS; return the solver name used or raise ``DesignError``."""
    import cvxpy as cp

    statuses = []
    for solver in ("CLARABEL", "SCS"):
        # cvxpy's installed_solvers() has no annotations
        if solver not in cp.installed_solvers():  # type: ignore[no-untyped-call]
            continue
        try:
            kwargs: dict[str, Any] = {"eps": 1e-9, "max_iters": 200000} if solver == "SCS" else {}
            problem.solve(solver=solver, **kwargs)
        except cp.error.SolverError as exc:
            statuses.append(f"{solver}: {exc}")
            continue
        statuses.append(f"{solver}: {problem.status}")
        if problem.status == cp.OPTIMAL and _finite(problem):
            return solver
    raise DesignError(
        f"{what}: the LMI has no (accurate) solution ({'; '.join(statuses)}); a nearly "
        "unobservable or badly scaled (A, C) often causes this: pass an explicit gain L=... "
        "(e.g. from scipy.signal.place_poles), or use another method ('kkl', 'interval-split', "
        "'fixed-time')"
    )


def _finite(problem: Any) -> bool:
    for v in problem.variables():
        if v.value is None or not np.all(np.isfinite(v.value)):
            return False
    return True
