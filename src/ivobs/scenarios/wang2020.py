"""The example of [Dinh2019] reproduced in [Wang2020, Section 4]: scenario ``dinh2019``."""

from __future__ import annotations

import numpy as np

from ..model import LinearSystem
from ..sets import Box
from .registry import Scenario, check_horizon, constant_input, register_scenario


@register_scenario(
    "dinh2019", "[Wang2020] §4: 2 states, 1 output, d in both equations (fixed-time)"
)
def _dinh2019(horizon: int = 50) -> Scenario:
    T = check_horizon(horizon)
    A = np.array([[5 / 4, 1.0], [-3 / 8, 1 / 8]])
    B = np.array([[1 / 4, 0.0], [0.0, 1 / 8]])
    C = np.array([[1.0, 0.0]])
    E = np.array([[1 / 9, 0.0], [1 / 9, 0.0]])  # D1
    F = np.array([[0.0, 1 / 9]])  # D2
    sys = LinearSystem(A, B, C, E=E, F=F, d=Box(-np.ones(2), np.ones(2)))
    k = np.arange(T)
    d_paper = np.column_stack([np.sin(k), np.sin(k.astype(float) ** 2)])
    x_true0 = np.array([2.3, 1.0])

    ref = {
        "s": 2,
        "Mx": np.array([[1, 0], [0.2353, -1.8824], [-1.2734, -4.8720]]),
        "Mu": np.array(
            [
                [0, 0, 0, 0, 0, 0],
                [0, 0, -0.0588, 0.2353, 0, 0],
                [0, 0, 0.3183, 0.6090, -0.0588, 0.2353],
            ]
        ),
        "Md": np.array(
            [
                [0, 0.1111, 0, 0, 0, 0],
                [0, 0, 0.1830, 0.1111, 0, 0],
                [0, 0, 0.6828, 0, 0.1830, 0.1111],
            ]
        ),
        "Mx_pinv": np.array([[0.6848, 0.4334, -0.1674], [-0.1446, -0.1605, -0.1432]]),
        "Mx_perp": np.array(
            [[0.3152, -0.4334, 0.1674], [-0.4334, 0.5959, -0.2302], [0.1674, -0.2302, 0.0890]]
        ),
        "U1": np.array([-0.5614, 0.7719, -0.2982]),
        "S1": 0.1386,
        "V1": np.array([0, -0.45, -0.45, 0.6187, -0.3937, -0.2391]),
        "T": np.array([[0.7975, 0.2784, -0.1076], [0.1290, -0.5367, 0.0021]]),
    }
    return Scenario(
        name="dinh2019",
        system=sys,
        x0=Box(x_true0 - 1.0, x_true0 + 1.0),
        x_true0=x_true0,
        u=constant_input([1.0, 1.0], T),
        horizon=T,
        source="[Wang2020, Section 4, eq. (1)], the example of [Dinh2019]",
        description="x+ = Ax + Bu + D1 d, y = Cx + D2 d, |d| <= 1, u = (1, 1), "
        "d = (sin k, sin k^2)",
        reference=ref,
        _disturbance=lambda kind, seed, T: d_paper if kind == "paper" else None,
        notes="prior box x0 = x_true0 ± 1 chosen by ivobs (the fixed-time method does not use it); "
        "the paper's Mu prints a 5-entry first row, read as 6 zeros",
    )
