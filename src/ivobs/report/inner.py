"""Inner bounds on the true hull of a nonlinear estimation problem: a tightness reference.

**Not an estimator, not an enclosure.** For a step ``k`` and each state ``i`` it maximises and
minimises ``x_i[k]`` by local optimisation (SciPy's SLSQP, several starts) over the initial
state in the prior box, the unknown parameters and signals in their bounds at every step
``0..k``, subject to every measurement being explained: ``h(x_j, u_j, p_j, d_j) = y_j`` for
``j = 0..k`` (the noise is among the signals ``d``). Every feasible point found is a state the
plant can really be in given the data, so the hull of the points found is **inside** the
tightest box (the true hull); a guaranteed method's box must contain it, and its width divided
by this hull's is an upper bound on how far the method is from the tightest box.

Feasibility is accepted to ``tol`` (default 1e-8 on the measurement residuals): the inner hull
is inner up to that tolerance. The simulated truth, when given, is one start (a feasible point
by construction, so at least one point is always found), and ``starts`` more are drawn near it
(random starts over the whole box rarely reach the measurement manifold on chaotic maps).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import IvobsError
from ..sets import Box
from ..simulate_nonlinear import point_functions

__all__ = ["inner_hull"]


def _rollout(sys: Any, z: np.ndarray, u: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """States ``x_0..x_k`` and outputs ``h(x_j, u_j, w_j)`` from ``z = (x_0, w_0, .., w_k)``."""
    f, h = point_functions(sys)
    nx, nw = sys.nx, sys.nw
    x = list(z[:nx])
    W = z[nx:].reshape(k + 1, nw)
    X, Hs = [], []
    for j in range(k + 1):
        rest = list(u[j]) + list(W[j])
        X.append(x)
        Hs.append(h(*x, *rest))
        if j < k:
            x = [float(v) for v in f(*x, *rest)]
    return np.array(X, dtype=float), np.array(Hs, dtype=float)


def inner_hull(
    sys: Any,
    x0: Box,
    u: Any,
    y: Any,
    k: int,
    *,
    starts: int = 4,
    seed: int = 0,
    truth: Any = None,
    tol: float = 1e-8,
    maxiter: int = 200,
) -> tuple[np.ndarray, np.ndarray, int]:
    """``(lo, hi, n_points)``: the hull of the feasible ``x[k]`` found (module docstring).

    ``truth``: optional :class:`~ivobs.Trajectory` from :func:`~ivobs.simulate_nonlinear`
    (``x``, ``p``, ``d``) used as one start.
    """
    from scipy.optimize import minimize

    if not hasattr(sys, "f_exprs"):
        raise IvobsError(f"sys: expected an ivobs.NonlinearSystem, got {type(sys).__name__}")
    nx = sys.nx
    U = np.zeros((k + 1, 0)) if sys.nu == 0 else np.asarray(u, dtype=float)[: k + 1]
    Y = np.asarray(y, dtype=float)[: k + 1]
    pl = [sys.param_bounds[n][0] for n in sys.param_names]
    ph = [sys.param_bounds[n][1] for n in sys.param_names]
    wlo = np.array(pl + [sys.signal_bounds[n][0] for n in sys.signal_names], dtype=float)
    whi = np.array(ph + [sys.signal_bounds[n][1] for n in sys.signal_names], dtype=float)
    lo = np.concatenate([x0.lo, np.tile(wlo, k + 1)])
    hi = np.concatenate([x0.hi, np.tile(whi, k + 1)])
    rng = np.random.default_rng(seed)
    inits = [rng.uniform(lo, hi) for _ in range(starts)]
    if truth is not None:
        p = truth.p if truth.p is not None else np.zeros((truth.T, 0))
        w = np.hstack([p[: k + 1], truth.d[: k + 1]]).ravel()
        zt = np.concatenate([truth.x[0], w])
        # starts near the truth: random ones far from it rarely reach the measurement manifold
        jitter = [zt + 0.1 * (hi - lo) * rng.standard_normal(zt.size) for _ in range(starts)]
        inits = [zt, *jitter, *inits]

    def cons(z: np.ndarray) -> np.ndarray:
        r: np.ndarray = (_rollout(sys, z, U, k)[1] - Y).ravel()
        return r

    found: list[np.ndarray] = []
    for i in range(nx):
        for sign in (1.0, -1.0):

            def obj(z: np.ndarray, i: int = i, sign: float = sign) -> float:
                return -sign * float(_rollout(sys, z, U, k)[0][k, i])

            for z0 in inits:
                try:
                    r = minimize(obj, np.clip(z0, lo, hi), method="SLSQP",
                                 bounds=list(zip(lo, hi)), options={"maxiter": maxiter},
                                 constraints=[{"type": "eq", "fun": cons}])  # fmt: skip
                    z = np.clip(r.x, lo, hi)
                    if np.max(np.abs(cons(z)), initial=0.0) <= tol:
                        found.append(_rollout(sys, z, U, k)[0][k])
                except (ValueError, ZeroDivisionError, OverflowError, ArithmeticError):
                    continue  # a start outside the model's domain: skip it
    if truth is not None:
        found.append(np.asarray(truth.x[k], dtype=float))
    if not found:
        raise IvobsError("inner_hull: no feasible point found; give truth= or more starts")
    pts = np.array(found)
    return pts.min(axis=0), pts.max(axis=0), len(found)
