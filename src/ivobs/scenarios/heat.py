"""Large systems (not from a paper): a discretised heat equation with a few point sensors."""

from __future__ import annotations

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem
from ..sets import Box
from .registry import Scenario, check_horizon, paper_signal, register_scenario


def heat_gain(system: LinearSystem, share: float = 0.5) -> np.ndarray:
    """A gain for the ``heat-1d`` scenario that keeps ``A - LC`` nonnegative: each sensor feeds
    back only into its own node, ``L[s_j, j] = share * A[s_j, s_j]`` (``0 <= share <= 1``).
    Then ``A - LC >= 0`` and its row sums are at most ``1 - cooling``: Schur without any LMI,
    for any ``nx`` (``interval`` and ``interval-split`` with ``L=``)."""
    C = system.sparse("C").tocoo()
    A = system.sparse("A")
    L = np.zeros((system.nx, system.ny))
    L[C.col, C.row] = share * A.diagonal()[C.col] / C.data
    return L


@register_scenario("heat-1d", "ivobs: 1-D heat equation, nx states (sparse A), point sensors")
def _heat_1d(
    nx: int = 50,
    sensors: int = 3,
    horizon: int = 500,
    alpha: float = 0.4,
    cooling: float = 0.01,
) -> Scenario:
    """A rod heated in its middle, explicit-Euler discretised on ``nx`` interior nodes::

        x_i+ = x_i + alpha (x_(i-1) - 2 x_i + x_(i+1)) - cooling x_i + b_i u + q + w_i

    (``alpha = κ Δt / h²``; the end nodes see the boundary temperatures ``d_0``, ``d_1`` in place
    of ``x_(-1)``, ``x_nx``). ``A = (1 - 2 alpha - cooling) I + alpha (shifts)`` is sparse
    (tridiagonal), nonnegative when ``2 alpha + cooling <= 1`` (the explicit scheme's stability
    condition) and Schur with radius ``<= 1 - cooling``. ``d = (d_0, d_1, q, v)``: boundary
    temperatures in ``[0, 0.2]``, an unknown uniform heat source ``|q| <= 0.005`` and the sensor
    noise ``|v| <= 0.02``; ``sensors`` point sensors at equal spacing; heater profile ``b``
    around the middle, input ``u[k] = 1 + 0.5 sin(2 pi k / 100)``.
    """
    from scipy.sparse import csr_matrix, diags

    T = check_horizon(horizon)
    if isinstance(nx, bool) or not isinstance(nx, (int, np.integer)) or nx < 3:
        raise IvobsError(f"nx: expected an integer >= 3, got {nx!r}")
    if isinstance(sensors, bool) or not isinstance(sensors, (int, np.integer)):
        raise IvobsError(f"sensors: expected an integer, got {sensors!r}")
    if not 1 <= sensors <= nx:
        raise IvobsError(f"sensors: expected 1..{nx} point sensors, got {sensors}")
    alpha, cooling = float(alpha), float(cooling)
    if not (alpha > 0 and cooling >= 0 and 2 * alpha + cooling <= 1):
        raise IvobsError(
            f"alpha, cooling: expected alpha > 0, cooling >= 0 and 2 alpha + cooling <= 1 (the "
            f"explicit scheme's stability and nonnegativity), got alpha = {alpha}, "
            f"cooling = {cooling}"
        )
    n, ny = int(nx), int(sensors)
    off = np.full(n - 1, alpha)
    A = diags([off, np.full(n, 1 - 2 * alpha - cooling), off], [-1, 0, 1], format="csr")
    z = (np.arange(n) + 1.0) / (n + 1)
    heater = np.exp(-(((z - 0.5) / 0.05) ** 2))
    B = (0.05 * np.where(heater > 1e-3, heater, 0.0))[:, None]
    where = np.round((np.arange(ny) + 1.0) * (n + 1) / (ny + 1)).astype(int) - 1
    C = csr_matrix((np.ones(ny), (np.arange(ny), where)), shape=(ny, n))
    E = np.zeros((n, 3 + ny))
    E[0, 0] = E[n - 1, 1] = alpha
    E[:, 2] = 1.0
    F = np.hstack([np.zeros((ny, 3)), np.eye(ny)])
    lo = np.concatenate([[0.0, 0.0, -0.005], np.full(ny, -0.02)])
    hi = np.concatenate([[0.2, 0.2, 0.005], np.full(ny, 0.02)])
    sys = LinearSystem(A, B, C, E=E, F=F, d=Box(lo, hi))
    k = np.arange(T)
    u = (1.0 + 0.5 * np.sin(2 * np.pi * k / 100))[:, None]
    x_true0 = 0.5 + 0.3 * np.sin(np.pi * z)
    return Scenario(
        name="heat-1d",
        system=sys,
        x0=Box(np.zeros(n), np.full(n, 1.2)),
        x_true0=x_true0,
        u=u,
        horizon=T,
        source="ivobs (not from a paper): explicit-Euler 1-D heat equation for large systems",
        description=f"rod on {n} nodes, alpha = {alpha}, cooling = {cooling}, heater in the "
        f"middle, {ny} point sensors at nodes {where.tolist()}, boundary temperatures in "
        "[0, 0.2], |q| <= 0.005, |v| <= 0.02",
        reference={"L": heat_gain(sys), "sensors": where},
        _disturbance=paper_signal("sinusoidal", sys),
        notes="reference['L'] = heat_gain(system): each sensor feeds back into its own node with "
        "half the diagonal of A, so A - LC >= 0 and Schur for any nx (interval, interval-split "
        "with L=...; docs/scale.md lists which methods suit which nx); 'paper' uses sinusoids",
    )
