"""Examples with interval matrices (docs/uncertain.md): a friction known to ±5 %.

``servo-uncertain`` is the DC servo motor of [Tang2019, Section VII, Example 1] whose viscous
friction is known to ±5 % only. The Euler-discretised speed equation has
``A22 = 1 − Ts b / J = 0.8495``: the friction term ``Ts b / J = 0.1505`` within ±5 % gives the
interval matrix entry ``A22 ∈ [1 − 1.05 · 0.1505, 1 − 0.95 · 0.1505] = [0.841975, 0.857025]``,
every other entry exact. The plant may use any ``A22`` in that interval at every step.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem
from ..sets import Box
from .registry import Scenario, check_horizon, constant_input, paper_signal, register_scenario
from .tang2019 import servo_system

FRICTION = 0.1505
"""``Ts b / J`` of the servo motor's speed equation ([Tang2019]'s ``A22 = 1 − 0.1505``)."""

SPREAD = 0.05
"""The relative uncertainty of the friction (±5 %)."""

_KINDS = {"paper": "sinusoidal", "sinusoidal": "sinusoidal", "vertex": "vertex",
          "uniform": "uniform", "zero": "nominal", "center": "nominal"}  # fmt: skip
"""The realisation of the interval matrix under each disturbance kind."""


def servo_uncertain_system() -> LinearSystem:
    """The servo motor of [Tang2019, Section VII, Example 1] with ``A22`` the interval
    ``1 − 0.1505 [0.95, 1.05]`` (module docstring)."""
    exact = servo_system()  # A22 = 1 - FRICTION
    lo, hi = np.array(exact.A), np.array(exact.A)
    lo[1, 1] = 1 - (1 + SPREAD) * FRICTION
    hi[1, 1] = 1 - (1 - SPREAD) * FRICTION
    return LinearSystem(Box(lo, hi), exact.B, exact.C, E=exact.E, F=exact.F, d=exact.d)


@register_scenario(
    "servo-uncertain", "[Tang2019] servo motor, viscous friction known to ±5 % (interval A)"
)
def _servo_uncertain(horizon: int = 200) -> Scenario:
    T = check_horizon(horizon)
    sys = servo_uncertain_system()

    def matrices(kind: str, seed: Any, T: int) -> dict[str, np.ndarray]:
        if kind not in _KINDS:
            raise IvobsError(
                f"servo-uncertain: disturbance kind {kind!r} is not available "
                f"(use one of {', '.join(_KINDS)})"
            )
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool) and seed >= 0:
            seed = np.random.SeedSequence([int(seed), 7])  # not the disturbance's own stream
        return sys.realisation(_KINDS[kind], T, seed)

    return Scenario(
        name="servo-uncertain",
        system=sys,
        x0=Box.symmetric(0.2 * np.ones(3)),
        x_true0=np.array([0.0015, 0.0148, 0.0]),
        u=constant_input([2.0], T),
        horizon=T,
        source="[Tang2019, Section VII, Example 1] with an interval friction entry",
        description="Euler-discretised DC servo motor (Ts = 0.1 s), x = (θ, n, i), viscous "
        "friction ±5 %: A22 in [0.841975, 0.857025]; |w| <= (0.0225, 0.0225, 0.0404), "
        "|v| <= 0.0564, u = 2 V",
        reference={"A22": (1 - (1 + SPREAD) * FRICTION, 1 - (1 - SPREAD) * FRICTION)},
        state_names=("θ (rad)", "n (rad/s)", "i (A)"),
        _disturbance=paper_signal("sinusoidal", sys),
        _matrices=matrices,
        notes="'paper' moves A22 as a sinusoid across its interval and the disturbances as "
        "sinusoids filling their bounds; 'vertex' puts A22 and every disturbance on a bound, "
        "redrawn at every step; horizon 200 steps chosen by ivobs",
    )
