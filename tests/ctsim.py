"""Continuous-time plants whose disturbance switches inside each sampling period, simulated
here (not by ivobs): a lightly damped oscillator with exact matrix exponentials per constant
piece, and second-order nonlinear plants with a DOP853 integrator at tight tolerances per
piece. Shared by tests/test_continuous_disturbances.py and benchmarks/bench_continuous.py."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.linalg import expm

import ivobs

# a lightly damped oscillator sampled every quarter period, its position measured
A_OSC = np.array([[0.0, 1.0], [-1.0, -0.04]])
TS_OSC = np.pi / 2
SWITCHES = 8  # sign changes of d per sample (32 per period of the oscillator)
T_OSC = 60
X0_BOX = ivobs.Box([0.0, -1.0], [1.0, 1.0])


def oscillator() -> ivobs.LinearSystem:
    """``x' = A x + [0; 1] d1``, ``y = x1 + d2``; ``|d1| <= 1``, ``|d2| <= 0.01``."""
    E = np.array([[0.0, 0.0], [1.0, 0.0]])
    F = np.array([[0.0, 1.0]])
    return ivobs.LinearSystem(
        A_OSC, None, [[1.0, 0.0]], E=E, F=F, d=ivobs.Box([-1.0, -0.01], [1.0, 0.01]), dt=0
    )


def simulate_oscillator(seed: int = 1, T: int = T_OSC) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` sampled every ``TS_OSC``; ``d1 = sign(velocity)`` on each of the
    ``SWITCHES`` pieces of a period (energy pumped in), noise on its vertices."""
    rng = np.random.default_rng(seed)
    h = TS_OSC / SWITCHES
    Ph = expm(A_OSC * h)
    gh = np.linalg.solve(A_OSC, Ph - np.eye(2)) @ np.array([0.0, 1.0])  # ∫_0^h e^{As} ds E
    x = np.array([0.5, -0.3])
    xs, ys = [], []
    for _ in range(T):
        xs.append(x.copy())
        ys.append([x[0] + 0.01 * rng.choice([-1.0, 1.0])])
        for _ in range(SWITCHES):
            x = Ph @ x + gh * (1.0 if x[1] >= 0 else -1.0)
    return np.array(xs), np.array(ys)


def misses(res: ivobs.Estimate, xs: np.ndarray, tol: float = 0.0) -> int:
    """Steps whose (finite) box leaves the true state out by more than ``tol``."""
    ok = np.all(np.isfinite(res.lower), axis=1)
    out = (xs < res.lower - tol) | (xs > res.upper + tol)
    return int(np.sum(ok & np.any(out, axis=1)))


def second_order(velocity: str) -> ivobs.NonlinearSystem:
    """``p' = v``, ``v' = velocity`` (an expression of ``p``, ``v``, ``d``), position measured;
    ``|d| <= 1``, noise ``|n| <= 0.01``."""
    return ivobs.NonlinearSystem(
        states=["p", "v"],
        outputs=["y"],
        f=["v", velocity],
        h=["p + n"],
        d={"d": (-1.0, 1.0), "n": (-0.01, 0.01)},
        dt=0,
    )


def nl_oscillator() -> ivobs.NonlinearSystem:
    return second_order("-p - 0.04*v + d")


def nl_vdp() -> ivobs.NonlinearSystem:
    return second_order("(1 - p**2)*v - p + 0.3*d")


def osc_rhs(z, d):
    return np.array([z[1], -z[0] - 0.04 * z[1] + d])


def vdp_rhs(z, d):
    return np.array([z[1], (1 - z[0] ** 2) * z[1] - z[0] + 0.3 * d])


def simulate_nl(rhs, x0, Ts: float, T: int, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` of ``x' = rhs(x, d)`` sampled every ``Ts``, ``d = sign(x2)`` held on each of
    ``SWITCHES`` pieces of a period, position measured with noise on its vertices."""
    rng = np.random.default_rng(seed)
    x = np.array(x0, dtype=float)
    xs, ys = [], []
    for _ in range(T):
        xs.append(x.copy())
        ys.append([x[0] + 0.01 * rng.choice([-1.0, 1.0])])
        for _ in range(SWITCHES):
            d = 1.0 if x[1] >= 0 else -1.0
            sol = solve_ivp(
                lambda t, z, d=d: rhs(z, d), (0.0, Ts / SWITCHES), x, method="DOP853",
                rtol=1e-12, atol=1e-13,
            )  # fmt: skip
            x = sol.y[:, -1]
    return np.array(xs), np.array(ys)
