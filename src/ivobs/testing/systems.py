"""Tools to check guaranteed estimators: random systems and adversarial trajectories.

Used by ivobs' own property tests, and useful to check an estimator on your own plant: a
guaranteed method must contain the true state at every step for *every* admissible disturbance,
and vertex (bang-bang) disturbances are the ones that reach the edges of the reachable sets.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import IvobsError
from ..linalg import is_observable
from ..model import LinearSystem
from ..result import Estimate
from ..sets import Box
from ..simulate import Trajectory, simulate, vertex_disturbance

__all__ = ["adversarial_run", "assert_contains", "random_system"]


def random_system(
    rng: Any = None,
    nx: int = 3,
    ny: int = 1,
    nu: int = 1,
    nd: int | None = None,
    *,
    rho: float | None = 0.9,
    invertible: bool = True,
    symmetric_bounds: bool = True,
    feedthrough: bool = False,
) -> LinearSystem:
    """A random observable discrete-time system with bounded ``d`` in both equations.

    ``rho`` rescales ``A`` to that spectral radius (None keeps the raw draw, possibly unstable);
    ``invertible=False`` makes ``A`` singular (one zero eigenvalue); asymmetric bounds when
    ``symmetric_bounds=False``; ``feedthrough`` adds a nonzero ``D``.
    """
    rng = np.random.default_rng(rng)
    nd = nx + ny if nd is None else nd
    for _ in range(1000):
        A = rng.normal(size=(nx, nx))
        if not invertible:
            V = rng.normal(size=(nx, nx))
            lam = rng.uniform(-1, 1, nx)
            lam[0] = 0.0
            A = V @ np.diag(lam) @ np.linalg.inv(V)
        if rho is not None:
            r = np.max(np.abs(np.linalg.eigvals(A)))
            if r < 1e-6:
                continue
            A = A * (rho / r)
        C = rng.normal(size=(ny, nx))
        if (
            is_observable(A, C)
            and np.linalg.cond(np.vstack([C @ np.linalg.matrix_power(A, i) for i in range(nx)]))
            < 1e6
        ):
            break
    else:  # pragma: no cover - practically unreachable
        raise RuntimeError("could not draw an observable system")
    B = rng.normal(size=(nx, nu)) if nu else None
    E = rng.normal(size=(nx, nd)) * 0.3
    F = rng.normal(size=(ny, nd)) * 0.1
    r = rng.uniform(0.2, 1.0, nd)
    c = rng.uniform(-0.5, 0.5, nd) * r if not symmetric_bounds else np.zeros(nd)
    D = rng.normal(size=(ny, nu)) if (feedthrough and nu) else None
    return LinearSystem(A, B, C, D=D, E=E, F=F, d=Box(c - r, c + r))


def adversarial_run(
    sys: LinearSystem, x0: Box, T: int, seed: Any = None, hold: int = 1
) -> Trajectory:
    """Simulate from a random vertex of ``x0`` with vertex disturbances and random inputs (and
    interval matrices on vertices of their boxes, redrawn every step: ``sys.realisation``)."""
    rng = np.random.default_rng(seed)
    x_true0 = np.where(rng.integers(0, 2, sys.nx).astype(bool), x0.hi, x0.lo)
    u = rng.normal(size=(T, sys.nu))
    d = None
    if sys.nd:
        box = sys.d
        if not isinstance(box, Box):
            raise IvobsError("adversarial_run: expected constant disturbance bounds (a Box)")
        d = vertex_disturbance(box, T, seed=rng, hold=hold)
    matrices = sys.realisation("vertex", T, rng) if sys.is_uncertain else None
    return simulate(sys, x_true0, u, d, matrices=matrices)


def assert_contains(est: Estimate, x: Any, tol: float = 0.0) -> None:
    """Raise ``AssertionError`` naming the first step and state that leave the box."""
    ok = est.contains(x, tol=tol)
    if not np.all(ok):
        k = int(np.argmin(ok.reshape(-1, ok.shape[-1]).all(axis=0)))
        x = np.asarray(x)
        raise AssertionError(
            f"{est.method}: true state leaves the box at step {k}: x = {x[..., k, :]}, "
            f"lower = {est.lower[..., k, :]}, upper = {est.upper[..., k, :]}"
        )
