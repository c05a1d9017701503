"""A :class:`~ivobs.LinearSystem` as a :class:`~ivobs.NonlinearSystem` (the nonlinear methods
then take linear models too)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import IvobsError
from ...sets import Box

__all__ = ["MAX_CONVERTED_STATES", "linear_spec"]

MAX_CONVERTED_STATES = 60
"""Largest linear system converted (its expressions are generated code, one term per entry)."""


def linear_spec(lin: Any, who: str) -> dict[str, Any]:
    """Keyword arguments of :class:`~ivobs.NonlinearSystem` for the linear model ``lin``."""
    if lin.is_continuous or lin.is_time_varying:
        raise IvobsError(
            f"sys: {who} takes a time-invariant discrete-time LinearSystem (or a "
            "NonlinearSystem); this one is continuous-time or time-varying"
        )
    if lin.nd and not (isinstance(lin.d, Box) and not lin.d.is_time_varying):
        raise IvobsError(
            f"sys: {who} needs constant disturbance bounds (a Box), not bounds that vary with "
            "the step or the measurement"
        )
    if lin.nx > MAX_CONVERTED_STATES:
        raise IvobsError(
            f"sys: {who} converts linear systems of at most {MAX_CONVERTED_STATES} states, got "
            f"{lin.nx}; use a linear method"
        )
    A, B, C, D, E, F = (np.asarray(m, dtype=float) for m in lin.matrices_at(0))
    box = lin.d_at(0) if lin.nd else None

    def affine(M: np.ndarray, N: np.ndarray, G: np.ndarray) -> Any:
        def fn(x: Any, u: Any, p: Any, d: Any) -> list[Any]:
            dv = [d[f"d{j + 1}"] for j in range(G.shape[1])]
            rows = []
            for i in range(M.shape[0]):
                terms = [float(c) * v for c, v in zip(M[i], x) if c != 0.0]
                terms += [float(c) * v for c, v in zip(N[i], u) if c != 0.0]
                terms += [float(c) * v for c, v in zip(G[i], dv) if c != 0.0]
                rows.append(sum(terms[1:], terms[0]) if terms else 0)
            return rows

        return fn

    return {
        "f": affine(A, B, E),
        "h": affine(C, D, F),
        "states": [f"x{i + 1}" for i in range(lin.nx)],
        "inputs": [f"u{i + 1}" for i in range(lin.nu)],
        "d": {f"d{j + 1}": (float(box.lo[j]), float(box.hi[j])) for j in range(lin.nd)}
        if box is not None
        else {},
        "dt": lin.dt,
    }
