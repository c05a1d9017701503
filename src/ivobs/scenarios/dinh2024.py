"""The examples of [Dinh2024]: the random 8-state system, the pendulum with varying length
(continuous-time LTV) and the discrete-time LTV system."""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from .. import nlmath
from ..errors import IvobsError
from ..linalg import is_observable
from ..model import LinearSystem
from ..sets import Box
from ..simulate import disturbance
from .registry import Scenario, check_horizon, register_scenario


@register_scenario("kkl-random8", "[Dinh2024] Ex. 1: random observable 8 states, 6 outputs")
def _kkl_random8(
    horizon: int = 200,
    seed: int = 1,
    continuous: bool = False,
    t_final: float = 10.0,
    dt: float = 0.01,
) -> Scenario:
    rng = np.random.default_rng(seed)

    while True:  # Matlab's randi: small integer entries
        Fm = rng.integers(-3, 4, size=(8, 8)).astype(float)
        Dm = rng.integers(-2, 3, size=(8, 2)).astype(float)
        Hm = rng.integers(-2, 3, size=(6, 8)).astype(float)
        Wm = rng.integers(1, 3, size=(6, 1)).astype(float)
        if is_observable(Fm, Hm):
            break
    E = np.hstack([Dm, np.zeros((8, 1))])
    F = np.hstack([np.zeros((6, 2)), Wm])
    bounds = Box([-0.5, -0.5, -0.3], [0.5, 0.5, 0.3])
    x_true0 = rng.uniform(-1, 1, 8)
    ref = {"F": None, "D": Dm, "H": Hm, "W": Wm}
    if continuous:
        shift = np.max(np.linalg.eigvals(Fm).real) + 0.5
        Fc = Fm - shift * np.eye(8)  # Hurwitz, so that the figure's states stay bounded
        sys = LinearSystem(Fc, np.eye(8), Hm, E=E, F=F, d=bounds, dt=0)
        t = np.arange(0.0, t_final + dt / 2, dt)
        ref["F"] = Fc

        def d_ct(tt: float, x: np.ndarray) -> np.ndarray:
            return np.array([0.5 * np.sin(2 * tt), 0.5 * np.cos(tt), 0.3 * np.sin(tt)])

        def factory(kind: str, seed_: Any, T: int) -> Any:
            if kind == "paper":
                return d_ct
            return disturbance(kind, bounds, t.size, seed_)

        fields: dict[str, Any] = dict(
            u=np.ones((t.size, 8)),
            horizon=int(t.size),
            source="[Dinh2024, Example 1] (continuous time)",
            description="random observable CT system, 8 states, 6 outputs, u = 1, "
            "d = 0.5(sin 2t, cos t), w = 0.3 sin t",
            t=t,
            _disturbance=factory,
            u_fn=lambda tt: np.ones(8),
            notes=f"random integer matrices (seed {seed}) shifted to be Hurwitz by ivobs",
        )
    else:
        T = check_horizon(horizon)
        Fd = 0.8 * Fm / np.max(np.abs(np.linalg.eigvals(Fm)))  # spectral radius 0.8
        sys = LinearSystem(Fd, np.eye(8), Hm, E=E, F=F, d=bounds)
        ref["F"] = Fd
        k = np.arange(T)
        d_paper = np.column_stack([0.5 * np.sin(2 * k), 0.5 * np.cos(k), 0.3 * np.sin(k)])
        fields = dict(
            u=np.ones((T, 8)),
            horizon=T,
            source="[Dinh2024, Example 1], discrete-time version",
            description="random observable DT system, 8 states, 6 outputs, u = 1, "
            "d = 0.5(sin 2k, cos k), w = 0.3 sin k",
            _disturbance=lambda kind, seed_, T: d_paper if kind == "paper" else None,
            notes=f"random integer matrices (seed {seed}), A scaled to spectral radius 0.8 by "
            "ivobs",
        )
    x0 = Box(x_true0 - 1.0, x_true0 + 1.0)
    return Scenario(name="kkl-random8", system=sys, x0=x0, x_true0=x_true0, reference=ref, **fields)


def pendulum_A(t: Any, *, L0: float, L1: float, omega: float) -> np.ndarray:
    """``A(t) = [[0, 1], [-g / L(t), -c]]``, ``L(t) = L0 + L1 sin(ωt)``, ``g = 9.8``, ``c = 1``
    ([Dinh2024, Example 2]; module-level so that system files can name it). Written with
    :mod:`ivobs.nlmath`, so that a symbolic ``t`` gives its expression (the continuous-time
    ``kkl`` observer bounds it between samples)."""
    c, g = 1.0, 9.8
    return np.array([[0.0, 1.0], [-g / (L0 + L1 * nlmath.sin(omega * t)), -c]])


@register_scenario(
    "pendulum", "[Dinh2024] Ex. 2: pendulum with varying length (continuous-time LTV)"
)
def _pendulum(
    t_final: float = 15.0, dt: float = 0.01, L0: float = 1.0, L1: float = 0.5, omega: float = 1.0
) -> Scenario:
    if not 0 < L1 < L0:
        raise IvobsError(f"L0, L1: expected 0 < L1 < L0, got L0={L0}, L1={L1}")
    A_t = partial(pendulum_A, L0=L0, L1=L1, omega=omega)
    E = np.hstack([np.eye(2), np.zeros((2, 1))])
    F = np.array([[0.0, 0.0, 1.0]])
    bounds = Box([-0.04, -0.04, -0.02], [0.04, 0.04, 0.02])
    sys = LinearSystem(
        A_t, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]), E=E, F=F, d=bounds, dt=0
    )
    t = np.arange(0.0, t_final + dt / 2, dt)

    def u_fn(tt: float) -> np.ndarray:
        return np.array([0.15 * nlmath.sin(3 * tt)])  # traced between samples (input_hold)

    def d_ct(tt: float, x: np.ndarray) -> np.ndarray:
        return np.array([0.04 * np.sin(1.2 * tt), 0.04 * np.sin(1.2 * tt), 0.02 * np.cos(20 * tt)])

    def factory(kind: str, seed: Any, T: int) -> Any:
        return d_ct if kind == "paper" else disturbance(kind, bounds, t.size, seed)

    return Scenario(
        name="pendulum",
        system=sys,
        x0=Box([-1.0, -1.0], [1.0, 1.0]),
        x_true0=np.array([0.5, 0.0]),
        u=np.array([u_fn(tt) for tt in t]),
        horizon=int(t.size),
        source="[Dinh2024, Example 2] (continuous-time LTV)",
        description="θ'' + cθ' + g/L(t) θ = u, L(t) = L0 + L1 sin(ωt), y = θ + w, "
        "d = 0.04(sin 1.2t, sin 1.2t), w = 0.02 cos 20t",
        reference={
            "A_tilde": np.diag([-1.0, -2.0]),
            "B_tilde": np.array([[1.0], [1.0]]),
            "ell": 2.0,
        },
        t=t,
        state_names=("θ", "θ'"),
        _disturbance=factory,
        u_fn=u_fn,
        notes=f"L0 = {L0}, L1 = {L1}, ω = {omega}, θ(0) = 0.5 and the prior box chosen by ivobs "
        "(the paper gives none)",
    )


def kkl_ltv_A(k: int) -> np.ndarray:
    """``F_k = [[1.2, -1 + 0.5 cos k], [0, 0.5 + 0.2 sin k]]`` ([Dinh2024, Example 3];
    module-level so that system files can name it)."""
    return np.array([[1.2, -1.0 + 0.5 * np.cos(k)], [0.0, 0.5 + 0.2 * np.sin(k)]])


@register_scenario(
    "kkl-ltv-dt", "[Dinh2024] Ex. 3: discrete-time LTV system, F_k with cos/sin entries"
)
def _kkl_ltv_dt(horizon: int = 30) -> Scenario:
    T = check_horizon(horizon)

    E = np.hstack([np.eye(2), np.zeros((2, 1))])
    F = np.array([[0.0, 0.0, 1.0]])
    sys = LinearSystem(
        kkl_ltv_A,
        None,
        np.array([[1.0, 0.0]]),
        E=E,
        F=F,
        d=Box([-0.1, -0.1, -0.02], [0.1, 0.1, 0.02]),
    )
    k = np.arange(T)
    d_paper = np.column_stack([0.1 * np.sin(2 * k), -0.1 * np.sin(2 * k), 0.02 * np.cos(20 * k)])
    return Scenario(
        name="kkl-ltv-dt",
        system=sys,
        x0=Box([-2.0, -2.0], [2.0, 2.0]),
        x_true0=np.array([1.0, 0.5]),
        u=np.zeros((T, 0)),
        horizon=T,
        source="[Dinh2024, Example 3] (discrete-time LTV)",
        description="F_k = [[1.2, -1 + .5 cos k], [0, .5 + .2 sin k]], H = [1 0], "
        "d = 0.1(sin 2k, -sin 2k), w = 0.02 cos 20k",
        reference={
            "A_tilde": np.diag([0.1, 0.2]),
            "B_tilde": np.array([[1.0], [1.0]]),
            "gamma": 1.0,
            "k_star": 2,
        },
        _disturbance=lambda kind, seed, T: d_paper if kind == "paper" else None,
        notes="initial state (1, 0.5) and prior box [-2, 2]^2 chosen by ivobs (the paper gives "
        "none); F_k has an eigenvalue 1.2, so the state grows: horizon 30",
    )
