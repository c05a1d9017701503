"""Many simulated records at once: :func:`simulate_batch`.

Batch studies (campaigns, Monte Carlo soundness checks) simulate thousands of records of one
system; a loop over :func:`~ivobs.simulate` costs one Python step per record and step. Here a
step advances every record with one matrix product, ``X[k+1] = X[k] Aᵀ + U[k] Bᵀ + D[k] Eᵀ``
(discrete time, matrices given per step: time-varying systems too), so the cost is one Python
step per time step. The records equal :func:`~ivobs.simulate`'s up to the rounding of the
matrix products (a batched product may sum in another order: a few ulps), tested record by
record.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ._validate import as_float_array, as_signal
from .errors import IvobsError
from .model import LinearSystem
from .simulate import Trajectory, _check_d

__all__ = ["simulate_batch"]


def _batch(name: str, value: Any, n: int, T: int | None) -> np.ndarray:
    """``value`` as ``(B, T, n)``: a ``(T, n)`` signal is shared by every record."""
    arr = as_signal(name, value, n, T)
    return arr if arr.ndim == 3 else arr[None]


def simulate_batch(
    sys: LinearSystem,
    x0: Any,
    u: Any = None,
    d: Any = None,
    *,
    T: int | None = None,
    check_bounds: bool = True,
) -> Trajectory:
    """Simulate ``B`` records of a discrete-time ``sys`` at once.

    Parameters
    ----------
    x0 : (B, nx) true initial states (or (nx,): the same for every record).
    u : (B, T, nu) or (T, nu) known inputs (shared by every record when 2-D); None: zero.
    d : (B, T, nd) or (T, nd) disturbances; None: zero.
    T : number of steps when neither ``u`` nor ``d`` gives it.
    check_bounds : raise :class:`IvobsError` if ``d`` leaves the system's bounds.

    Notes
    -----
    Returns a :class:`~ivobs.Trajectory` whose ``x, y, u, d`` are ``(B, T, ·)`` (a batch that
    :meth:`~ivobs.Estimator.run` takes as is).
    """
    if not isinstance(sys, LinearSystem):
        raise IvobsError(f"sys: expected an ivobs.LinearSystem, got {type(sys).__name__}")
    if sys.is_continuous:
        raise IvobsError("simulate_batch: discrete-time systems only (use simulate for dt = 0)")
    X0 = np.atleast_2d(as_float_array("x0", x0))
    if X0.ndim != 2 or X0.shape[1] != sys.nx or not np.all(np.isfinite(X0)):
        raise IvobsError(f"x0: expected finite (B, {sys.nx}) or ({sys.nx},) states, got {X0.shape}")
    B = X0.shape[0]
    U = None if u is None else _batch("u", u, sys.nu, T)
    D = None if d is None else _batch("d", d, sys.nd, T)
    sizes = {a.shape[0] for a in (X0, U, D) if a is not None} - {1}
    if len(sizes) > 1:
        raise IvobsError(f"x0, u, d: disagree on the number of records {sorted(sizes)}")
    B = sizes.pop() if sizes else B
    steps = {a.shape[1] for a in (U, D) if a is not None}
    if len(steps) > 1 or (T is not None and steps and T not in steps):
        raise IvobsError(f"u, d, T: disagree on the number of steps {sorted(steps)} / {T}")
    if not steps and T is None:
        raise IvobsError("T: give the number of steps (no array signal to infer it from)")
    T = steps.pop() if steps else int(T)  # type: ignore[arg-type]
    U = np.broadcast_to(np.zeros((1, T, sys.nu)) if U is None else U, (B, T, sys.nu))
    D = np.broadcast_to(np.zeros((1, T, sys.nd)) if D is None else D, (B, T, sys.nd))
    x = np.empty((B, T, sys.nx))
    y = np.empty((B, T, sys.ny))
    xk = np.broadcast_to(X0, (B, sys.nx)).copy()
    for k in range(T):
        A, Bm, C, Dm, E, F = sys.matrices_at(k)
        x[:, k] = xk
        y[:, k] = xk @ C.T + U[:, k] @ Dm.T + D[:, k] @ F.T
        xk = xk @ A.T + U[:, k] @ Bm.T + D[:, k] @ E.T
        if not np.all(np.isfinite(xk)):
            raise IvobsError(
                f"simulate_batch: a state diverged to non-finite values at step {k + 1}"
            )
    if check_bounds:
        for b in range(B):  # the same check, and message, as simulate's
            _check_d(sys, D[b], y[b])
    t = np.arange(T) * sys.sampling_period
    return Trajectory(x=x, y=y, u=np.array(U), d=np.array(D), t=t)
