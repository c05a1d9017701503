"""Solving LMIs with CVXPY: Clarabel first, SCS as fallback, status always checked.

A design that the solver reports as infeasible, unbounded or inaccurate raises
:class:`ivobs.DesignError`; callers must also verify the property they needed on the numbers
they extract (e.g. that ``A - LC`` is Schur), since a solver tolerance is not a proof. A caller
that can prove what it needs on the numbers (a ``certify`` callback, e.g. the bounded-real
certificate of an H∞ gain) may accept an answer the solver reports as inaccurate.

The solvers' own warnings (CVXPY's "Solution may be inaccurate ...") are caught here and not
passed on: the status they announce is in the error message, or, for an inaccurate answer that
was certified, in the returned description, so the user sees one ivobs message, not a solver's.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
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


def solve(problem: Any, what: str, certify: Callable[[], bool] | None = None) -> str:
    """Solve with Clarabel, then SCS; return how it was solved (the solver's name, or
    ``"<solver> (inaccurate, certified)"``) or raise ``DesignError``.

    ``certify``: called when a solver answers ``optimal_inaccurate`` with finite values (they are
    then in the problem's variables); True accepts that answer (the caller proved it). Without
    it, or when it returns False, the next solver is tried."""
    import cvxpy as cp

    statuses = []
    for solver in ("CLARABEL", "SCS"):
        # cvxpy's installed_solvers() has no annotations
        if solver not in cp.installed_solvers():  # type: ignore[no-untyped-call]
            continue
        kwargs: dict[str, Any] = {"eps": 1e-9, "max_iters": 200000} if solver == "SCS" else {}
        with warnings.catch_warnings():
            # the status carries what the warning says (module docstring)
            warnings.simplefilter("ignore")
            try:
                problem.solve(solver=solver, **kwargs)
            except cp.error.SolverError as exc:
                statuses.append(f"{solver}: {exc}")
                continue
        statuses.append(f"{solver}: {problem.status}")
        values = [v.value for v in problem.variables()]
        if not all(x is not None and np.all(np.isfinite(x)) for x in values):
            continue
        if problem.status == cp.OPTIMAL:
            return solver
        if certify is not None and problem.status == cp.OPTIMAL_INACCURATE and certify():
            return f"{solver} (inaccurate, certified)"
    raise DesignError(
        f"{what}: the LMI has no (accurate) solution ({'; '.join(statuses)}); a nearly "
        "unobservable or badly scaled (A, C) often causes this: pass an explicit gain L=... "
        "(e.g. from scipy.signal.place_poles), or use another method ('kkl', 'interval-split', "
        "'fixed-time')"
    )
