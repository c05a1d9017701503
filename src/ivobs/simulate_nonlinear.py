"""Trajectories of a :class:`~ivobs.NonlinearSystem`: a float64 simulator (docs/nonlinear.md).

``x[0] = x0``, ``y[k] = h(x[k], u[k], p[k], d[k])``, ``x[k+1] = f(x[k], u[k], p[k], d[k])`` for
``k = 0 .. T-1``, the model's expressions evaluated at points in double precision (compiled
once per system with SymPy's ``lambdify`` on the ``math`` module).

The unknown parameters ``p`` (``sys.param_names``) and signals ``d`` (``sys.signal_names``) are
given as ``(T, n)`` arrays or as a kind (``"vertex"``, ``"uniform"``, ``"zero"``,
``"sinusoidal"``, :func:`~ivobs.simulate.disturbance`) filling their bounds.

**This is not an exact trajectory of the model.** Each step rounds (a few ulps per operation),
and on a chaotic map such as Hénon those errors grow exponentially, so after a few dozen steps a
float64 run is far from the exact trajectory from the same ``x0``. Every simulated ``x[k+1]`` is
within a few ulps of ``f`` evaluated exactly at the simulated ``x[k]``: a trajectory of the model
with unknowns a few ulps outside their bounds. The nonlinear estimators bound their own rounding
and add no margin (docs/nonlinear.md), so they are not promised to contain such a record where
it touches the edge of the exact set (in practice the boxes are far wider than those ulps). A
record whose every step is exact comes from interval arithmetic at high precision
(tests/exactsim.py, what the soundness tests use).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._validate import as_signal, as_vector
from .errors import IvobsError
from .model.nonlinear import NonlinearSystem
from .sets import Box
from .simulate import Trajectory, _check_within, _infer_T, disturbance

__all__ = ["point_functions", "simulate_nonlinear"]

_CACHE_ATTR = "_point_fns"


def point_functions(sys: NonlinearSystem) -> tuple[Any, Any]:
    """``(f, h)``: float functions of ``(x..., u..., p..., d...)`` returning lists (cached on
    the system)."""
    if sys.is_continuous or getattr(sys, "continuous", None) is not None:
        raise IvobsError(
            "sys: a continuous-time model (or its discretize() flow) has no point map to "
            "simulate step by step; integrate the ODE (e.g. scipy.integrate.solve_ivp with "
            "u and the unknowns held over each period)"
        )
    cached: tuple[Any, Any] | None = getattr(sys, _CACHE_ATTR, None)
    if cached is not None:
        return cached
    import sympy as sp

    s = sys._sym
    order = sys.state_names + sys.input_names + sys.param_names + sys.signal_names
    args = [s[n] for n in order]
    known = {s[n]: sp.Float(v, 17) for n, v in sys.known_params.items()}
    f_ex = [e.xreplace(known) for e in sys.f_exprs]
    h_ex = [e.xreplace(known) for e in sys.h_exprs]
    fns = (sp.lambdify(args, f_ex, "math"), sp.lambdify(args, h_ex, "math"))
    setattr(sys, _CACHE_ATTR, fns)
    return fns


def _signal(what: str, sig: Any, box: Box, T: int, seed: Any) -> np.ndarray:
    n = box.dim
    if sig is None:
        sig = "zero"
    if isinstance(sig, str):
        if n == 0:
            return np.zeros((T, 0))
        return np.asarray(disturbance(sig, box, T, seed), dtype=float)
    return as_signal(what, sig, n, T, allow_batch=False)


def _param_box(sys: NonlinearSystem) -> Box:
    lo, hi = np.array([sys.param_bounds[n] for n in sys.param_names], dtype=float).reshape(-1, 2).T
    return Box(lo, hi)


def simulate_nonlinear(
    sys: NonlinearSystem,
    x0: Any,
    u: Any = None,
    d: Any = None,
    *,
    p: Any = None,
    T: int | None = None,
    seed: Any = None,
    check_bounds: bool = True,
) -> Trajectory:
    """Simulate ``sys`` from the true initial state ``x0`` in float64 (module docstring).

    Parameters
    ----------
    x0 : (nx,) true initial state.
    u : (T, nu) known inputs (``None`` when ``nu = 0``).
    d : (T, nd) signals (``sys.signal_names`` order) or a kind (``"vertex"``, ``"uniform"``,
        ``"zero"``, ``"sinusoidal"``); ``None``: the bounds' centre.
    p : (T, np) unknown parameters (``sys.param_names`` order) or a kind, likewise.
    T : number of steps when no array gives it.
    seed : for the random kinds (``p`` uses ``seed + 1`` when ``seed`` is an integer).
    check_bounds : raise :class:`IvobsError` when ``d`` or ``p`` leave their bounds.

    Returns
    -------
    Trajectory
        The signals in ``d`` and the parameters in ``p``.
    """
    if not isinstance(sys, NonlinearSystem):
        raise IvobsError(f"sys: expected an ivobs.NonlinearSystem, got {type(sys).__name__}")
    x0 = as_vector("x0", x0, sys.nx)
    T = _infer_T(T, *(s for s in (u, d, p) if not isinstance(s, str)))
    u_arr = as_signal("u", u, sys.nu, T, allow_batch=False)
    pseed = seed + 1 if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) else seed
    d_arr = _signal("d", d, sys.d, T, seed)
    pbox = _param_box(sys)
    p_arr = _signal("p", p, pbox, T, pseed)
    if check_bounds:
        for what, arr, box in (("d", d_arr, sys.d), ("p", p_arr, pbox)):
            _check_within(what, arr, box.lo, box.hi)
    f, h = point_functions(sys)
    x = np.empty((T, sys.nx))
    y = np.empty((T, sys.ny))
    xk = [float(v) for v in x0]
    for k in range(T):
        rest = u_arr[k].tolist() + p_arr[k].tolist() + d_arr[k].tolist()
        x[k] = xk
        try:
            y[k] = h(*xk, *rest)
            xk = [float(v) for v in f(*xk, *rest)]
        except (ValueError, ZeroDivisionError, OverflowError) as exc:
            raise IvobsError(
                f"simulate: the model is undefined at step {k} ({exc}; x = {x[k].tolist()})"
            ) from None
        if not all(np.isfinite(xk)):
            raise IvobsError(f"simulate: the state diverged to non-finite values at step {k + 1}")
    return Trajectory(x=x, y=y, u=u_arr, d=d_arr, t=np.arange(T) * sys.sampling_period, p=p_arr)
