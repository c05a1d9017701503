"""The quadruple tank of [Johansson2000]: four levels, the two lower ones measured.

Two pumps (voltages ``v1``, ``v2``) fill four tanks through two three-way valves: pump 1 sends the
share ``γ1`` of its flow to tank 1 and ``1 − γ1`` to tank 4, pump 2 ``γ2`` to tank 2 and
``1 − γ2`` to tank 3; tank 3 drains into tank 1 and tank 4 into tank 2. The lower levels ``h1``,
``h2`` are measured (``y = k_c h``). Linearised at an operating point ([Johansson2000, eq. (3)],
deviations from ``h⁰``, ``v⁰``)::

    dx/dt = [[-1/T1, 0, A3/(A1 T3), 0],        [[γ1 k1/A1, 0],
             [0, -1/T2, 0, A4/(A2 T4)],  x  +   [0, γ2 k2/A2],         u  +  w
             [0, 0, -1/T3, 0],                  [0, (1-γ2) k2/A3],
             [0, 0, 0, -1/T4]]                  [(1-γ1) k1/A4, 0]]
    y = [[k_c, 0, 0, 0], [0, k_c, 0, 0]] x + v,        T_i = (A_i / a_i) sqrt(2 h⁰_i / g)

with the numbers of [Johansson2000, Table I] (``A1 = A3 = 28 cm²``, ``A2 = A4 = 32 cm²``,
``k_c = 0.50 V/cm``) and [Johansson2000, Table II] (the operating points ``P−``, minimum phase,
and ``P+``, non-minimum phase: ``k1``, ``k2``, ``γ1``, ``γ2`` and the time constants ``T_i`` as
printed), discretised with a zero-order hold of ``Ts`` seconds (``w`` held too).

What ivobs chose (the paper has no disturbance model): ``|w_i| <= w`` cm/s on each level's rate
(default 0.001: unmodelled inflow) and ``|v_j| <= v`` V of sensor noise (default 0.01); the prior
box ``|x| <= 1`` cm around the operating point, the true ``x[0] = (0.5, −0.5, 0.3, −0.3)`` cm, and
known pump voltages ``u[k] = (0.5 sin(2π k / 300), 0.5 cos(2π k / 450))`` V (deviations).
"""

from __future__ import annotations

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem
from ..sets import Box
from .registry import Scenario, check_horizon, register_scenario

__all__ = ["OPERATING_POINTS", "TANK_AREAS", "quadtank_system"]

TANK_AREAS = (28.0, 32.0, 28.0, 32.0)
"""``A1..A4`` (cm²), [Johansson2000, Table I]."""

KC = 0.50
"""Level sensor gain ``k_c`` (V/cm), [Johansson2000, Table I]."""

OPERATING_POINTS = {
    "minimum": {"T": (62.0, 90.0, 23.0, 30.0), "k": (3.33, 3.35), "gamma": (0.70, 0.60)},
    "nonminimum": {"T": (63.0, 91.0, 39.0, 56.0), "k": (3.14, 3.29), "gamma": (0.43, 0.34)},
}
"""[Johansson2000, Table II]: ``P−`` (``"minimum"``, minimum phase) and ``P+``
(``"nonminimum"``): time constants ``T1..T4`` (s), pump gains ``k1``, ``k2`` (cm³/(V s)), valve
settings ``γ1``, ``γ2``."""


def quadtank_system(
    phase: str = "minimum", w: float = 0.001, v: float = 0.01, Ts: float = 1.0
) -> LinearSystem:
    """The linearised quadruple tank (module docstring) at the operating point ``phase``,
    discretised with a hold of ``Ts`` s; ``d = (w1..w4, v1, v2)`` within ``±w`` (cm/s, on the
    rates) and ``±v`` (V, on the sensors)."""
    if phase not in OPERATING_POINTS:
        raise IvobsError(
            f"phase: expected one of {', '.join(map(repr, OPERATING_POINTS))}, got {phase!r}"
        )
    w, v, Ts = float(w), float(v), float(Ts)
    if not (w >= 0 and v >= 0 and Ts > 0 and np.isfinite(w + v + Ts)):
        raise IvobsError(f"w, v, Ts: expected w >= 0, v >= 0, Ts > 0, got {w}, {v}, {Ts}")
    op = OPERATING_POINTS[phase]
    A1, A2, A3, A4 = TANK_AREAS
    T1, T2, T3, T4 = op["T"]
    k1, k2 = op["k"]
    g1, g2 = op["gamma"]
    A = np.array(
        [
            [-1 / T1, 0, A3 / (A1 * T3), 0],
            [0, -1 / T2, 0, A4 / (A2 * T4)],
            [0, 0, -1 / T3, 0],
            [0, 0, 0, -1 / T4],
        ]
    )
    B = np.array(
        [
            [g1 * k1 / A1, 0],
            [0, g2 * k2 / A2],
            [0, (1 - g2) * k2 / A3],
            [(1 - g1) * k1 / A4, 0],
        ]
    )
    C = np.array([[KC, 0, 0, 0], [0, KC, 0, 0]])
    E = np.hstack([np.eye(4), np.zeros((4, 2))])
    F = np.hstack([np.zeros((2, 4)), np.eye(2)])
    r = np.r_[np.full(4, w), np.full(2, v)]
    # the scenario simulates this sampled model: its disturbances are held over each period
    return LinearSystem(A, B, C, E=E, F=F, d=Box(-r, r), dt=0).discretize(Ts, disturbances="held")


@register_scenario(
    "quadruple-tank", "[Johansson2000]: quadruple tank, 4 levels, the 2 lower ones measured"
)
def _quadruple_tank(
    horizon: int = 2000,
    phase: str = "minimum",
    w: float = 0.001,
    v: float = 0.01,
    Ts: float = 1.0,
) -> Scenario:
    """The quadruple tank (module docstring) over ``horizon`` samples of ``Ts`` s."""
    T = check_horizon(horizon)
    sys = quadtank_system(phase, w, v, Ts)
    k = np.arange(T)
    u = np.column_stack([0.5 * np.sin(2 * np.pi * k / 300.0), 0.5 * np.cos(2 * np.pi * k / 450.0)])
    return Scenario(
        name="quadruple-tank",
        system=sys,
        x0=Box(-np.ones(4), np.ones(4)),
        x_true0=np.array([0.5, -0.5, 0.3, -0.3]),
        u=u,
        horizon=T,
        source="[Johansson2000, eq. (3), Tables I-II]",
        description=f"quadruple tank at P{'-' if phase == 'minimum' else '+'} ({phase} phase), "
        f"levels h1..h4 (cm, deviations), h1 and h2 measured (k_c = {KC} V/cm), Ts = {Ts} s, "
        f"|w| <= {w} cm/s on the rates, |v| <= {v} V on the sensors",
        reference={"operating_point": dict(OPERATING_POINTS[phase]), "areas": TANK_AREAS},
        state_names=("h1", "h2", "h3", "h4"),
        notes="the paper has no disturbance model: w, v, the prior box |x| <= 1 cm, x[0] and "
        "the input sinusoids are ivobs's choice; 'paper' is not available (use 'vertex', "
        "'uniform', 'sinusoidal' or 'zero')",
    )
