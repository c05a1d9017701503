"""The examples of [Tang2019, Section VII]: the DC servo motor and Example 2."""

from __future__ import annotations

import numpy as np

from ..model import LinearSystem
from ..sets import Box
from .registry import Scenario, check_horizon, constant_input, paper_signal, register_scenario


def servo_system() -> LinearSystem:
    """The DC servo motor of [Tang2019, Section VII, Example 1] (``servo-motor``'s model)."""
    A = np.array([[1, 0.1, 0], [0, 0.8495, 0.4977], [0, -0.0357, 0.9995]])
    B = np.array([[0.0], [0.0], [0.0729]])
    C = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    w_bar = np.array([0.0225, 0.0225, 0.0404])
    v_bar = np.array([0.0564, 0.0564])
    return LinearSystem.from_process_measurement(A, B, C, np.eye(3), np.eye(2), w_bar, v_bar)


@register_scenario("servo-motor", "[Tang2019] §VII Ex. 1: DC servo motor, 3 states, 2 outputs")
def _servo(horizon: int = 100) -> Scenario:
    T = check_horizon(horizon)
    sys = servo_system()
    ref = {
        "L1": np.array([[0.9998, 0.1000], [0.0157, 1.5371], [0.0315, 1.3453]]),
        "L2": np.array([[0.7582, 0.0784], [-2.5012, 0.6764], [-0.0040, -0.0360]]),
        "p0": np.zeros(3),
        "H0": 0.2 * np.eye(3),
    }
    return Scenario(
        name="servo-motor",
        system=sys,
        x0=Box.symmetric(0.2 * np.ones(3)),
        x_true0=np.array([0.0015, 0.0148, 0.0]),
        u=constant_input([2.0], T),
        horizon=T,
        source="[Tang2019, Section VII, Example 1]",
        description="Euler-discretised DC servo motor (Ts = 0.1 s), x = (θ, n, i), "
        "|w| <= (0.0225, 0.0225, 0.0404), |v| <= 0.0564, u = 2 V",
        reference=ref,
        state_names=("θ (rad)", "n (rad/s)", "i (A)"),
        _disturbance=paper_signal("sinusoidal", sys),
        notes="the paper does not give its disturbance signals: 'paper' uses sinusoids filling "
        "the bounds (ivobs.sinusoidal_disturbance); horizon 100 steps chosen by ivobs",
    )


@register_scenario("tang-example2", "[Tang2019] §VII Ex. 2: no nonnegative A - LC exists")
def _tang2(horizon: int = 50) -> Scenario:
    T = check_horizon(horizon)
    A = np.array([[1.0, 0.5], [-0.5, 1.0]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[0.0, 1.0]])
    sys = LinearSystem.from_process_measurement(A, B, C, np.eye(2), np.eye(1), [0.1, 0.1], [0.1])
    ref = {
        "L": np.array([[-0.8479], [1.6739]]),
        "eig": np.array([0.3258, 0.0003]),
        "R": np.array([[0.3258, 0.2000], [0.0, 0.0003]]),
        "S": np.array([[5.1686, 6.3352], [1.5843, 3.1676]]),
        "e1": np.array([1.0, 0.0]),
        "e2": np.array([0.5, -1.0]),
        "p0": np.array([1.0, 1.0]),
        "H0": 0.5 * np.eye(2),
        "x_t0": (np.array([0.5, 0.5]), np.array([1.5, 1.5])),
    }
    return Scenario(
        name="tang-example2",
        system=sys,
        x0=Box([0.5, 0.5], [1.5, 1.5]),
        x_true0=np.array([1.2, 0.9]),
        u=np.zeros((T, 1)),
        horizon=T,
        source="[Tang2019, Section VII, Example 2]",
        description="A = [[1, .5], [-.5, 1]], C = [0 1], |w| <= 0.1, |v| <= 0.1",
        reference=ref,
        _disturbance=paper_signal("sinusoidal", sys),
        notes="the paper prints F = I2, which does not fit its scalar output y = x2 + F v; "
        "ivobs uses one noise channel F = 1 (this reproduces the paper's H∞ gain "
        "L = (-0.8479, 1.6739) to 5e-4); u = 0 and sinusoidal disturbances chosen by ivobs",
    )
