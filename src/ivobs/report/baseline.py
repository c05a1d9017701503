"""A baseline that is **not guaranteed**: the Kalman filter's mean ± 3σ, for comparison.

``ivobs compare --baseline kalman`` shows it beside the guaranteed methods so that users see
what the guarantee costs: the band is usually narrower, and it misses the true state at some
steps (under adversarial disturbances, at many). It is no :class:`~ivobs.estimators.Estimator`
(it gives no box that holds the state), so it is not among ``ivobs methods``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..result import Estimate
from ..sets import Box

__all__ = ["BASELINES", "SIGMAS", "check_baseline", "kalman_baseline"]

SIGMAS = 3.0
"""Half-width of the band in standard deviations."""


def _uniform(box: Box) -> tuple[np.ndarray, np.ndarray]:
    """Mean and covariance of a uniform distribution on ``box`` (variance ``r²/3``)."""
    r = 0.5 * (box.hi - box.lo)
    return 0.5 * (box.lo + box.hi), np.diag(r * r / 3.0)


def check_baseline(name: str, system: Any) -> None:
    """Refuse a baseline that ``ivobs compare --baseline`` does not know, or cannot run on
    ``system`` (the Kalman filter needs a discrete-time linear model with exact matrices)."""
    from ..model import LinearSystem

    if name not in BASELINES:
        raise IvobsError(f"--baseline: expected one of {', '.join(BASELINES)}, got {name!r}")
    if isinstance(system, LinearSystem) and not system.is_uncertain and system.is_discrete:
        return
    if not isinstance(system, LinearSystem):
        got = f"a {type(system).__name__} (no extended Kalman filter here)"
    elif system.is_uncertain:
        got = "a LinearSystem with interval matrices"
    else:
        got = "a continuous-time LinearSystem: give --discretize TS"
    raise IvobsError(
        f"--baseline {name}: needs a linear model, a discrete-time LinearSystem with exact "
        f"matrices; got {got}"
    )


def kalman_baseline(system: Any, x0: Box, u: Any, y: Any, *, sigmas: float = SIGMAS) -> Estimate:
    """The Kalman filter [Kalman1960] on ``system``, reported as the box ``x̂ ± sigmas·σ``:
    **not guaranteed** (``info["guaranteed"]`` is False).

    The bounded signals are taken as independent and uniform on their boxes (mean the centre,
    variance ``r²/3`` per component, ``r`` the radius), as is ``x[0]`` on ``x0``. One ``d[k]``
    enters both ``x[k+1] = A x + B u + E d`` and ``y[k] = C x + D u + F d``, so the update by
    ``y[k]`` conditions the pair ``z = (x[k], d[k])`` (covariance ``blkdiag(P, Q)``, output
    ``H = [C F]``) and the prediction maps it by ``[A E]``. The box of ``x[k]`` uses
    ``y[0..k]`` (the time-varying filter, like the ``filter`` methods); a missing sample (NaN)
    leaves its rows out of the update. ``system``: a discrete-time
    :class:`~ivobs.LinearSystem` with exact matrices (:func:`check_baseline`).
    """
    from scipy.linalg import block_diag

    check_baseline("kalman", system)
    y = np.asarray(y, dtype=float).reshape(-1, system.ny)
    T, nx = y.shape[0], system.nx
    u = np.zeros((T, system.nu)) if u is None else np.asarray(u, dtype=float).reshape(T, -1)
    x, P = _uniform(x0)
    lo, hi = np.empty((T, nx)), np.empty((T, nx))
    for k in range(T):
        A, B, C, D, E, F = system.matrices_at(k)
        dc, Q = _uniform(system.d_at(k, y[k]))
        z, Pz = np.concatenate([x, dc]), block_diag(P, Q)
        seen = ~np.isnan(y[k])
        if seen.any():
            H = np.hstack([C, F])[seen]
            e = y[k, seen] - H @ z - (D @ u[k])[seen]
            # least squares: S is singular when a combination of outputs is noise-free
            K = np.linalg.lstsq(H @ Pz @ H.T, H @ Pz, rcond=None)[0].T
            z, Pz = z + K @ e, Pz - K @ H @ Pz
            Pz = 0.5 * (Pz + Pz.T)
        sd = np.sqrt(np.clip(np.diag(Pz)[:nx], 0.0, None))
        lo[k], hi[k] = z[:nx] - sigmas * sd, z[:nx] + sigmas * sd
        M = np.hstack([A, E])
        x, P = M @ z + B @ u[k], M @ Pz @ M.T
    return Estimate(lower=lo, upper=hi, method=f"kalman ±{sigmas:g}σ", info={"guaranteed": False})


BASELINES: dict[str, Callable[..., Estimate]] = {"kalman": kalman_baseline}
"""The baselines ``ivobs compare --baseline`` knows: ``(system, x0, u, y) -> Estimate``."""
