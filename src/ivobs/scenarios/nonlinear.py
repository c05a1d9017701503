"""Nonlinear examples as :class:`~ivobs.NonlinearSystem` (docs/nonlinear.md).

- ``henon-nl``: [Efimov2013]'s Hénon map with ``a(t) ∈ [1.39, 1.41]`` as a full nonlinear model
  (``henon`` is the Remark-1 version, where the nonlinear term is a disturbance bounded from y);
- ``pendulum-nl``: a damped pendulum with an input torque and a length known to ±5 %;
- ``cora-tank6-nl``: CORA's six-tank cascade ``tank6EqDT_inflow4`` with its observer test's
  data ([Althoff2021]; src/ivobs/data/cora_tank6_nl.npz);
- ``cstr``: a continuous stirred-tank reactor (first-order exothermic reaction);
- ``unicycle-range``: a 2-D unicycle measured by its ranges to three beacons and a compass;
- ``range-only``: a vehicle of unknown speed and turn rate measured by its ranges to two
  beacons and its heading (weakly observable: ``nl-horizon``, docs/nonlinear.md);
- ``chain10-nl``: ten states coupled by ``tanh`` and ``sin`` terms (scale).

The continuous-time plants (pendulum, CSTR, unicycle, chain) are **defined by their explicit
Euler map** with the step written in the expressions: the model ivobs estimates is that
discrete-time map, not the ODE (a guaranteed discretisation of an ODE is not done here).

Disturbance kinds: the unknown parameters take the same kind as the signals (``"vertex"``:
both on the vertices of their bounds at every step); ``"paper"`` is uniform (seed 0), as no
paper gives a signal; ``cora-tank6-nl`` also has ``"recorded"`` (CORA's measurements, no true
state stored).
"""

from __future__ import annotations

from importlib import resources
from typing import Any

import numpy as np

from ..model.nonlinear import NonlinearSystem
from ..sets import Box
from ..simulate import Trajectory
from .registry import Scenario, check_horizon, constant_input, paper_signal, register_scenario


def henon_nl_system(
    a: tuple[float, float] = (1.39, 1.41), w: float = 0.005, v: float = 0.02
) -> NonlinearSystem:
    """Hénon, ``a(t) ∈ a``, ``|w1| <= w`` on ``x1``, ``y = x1 + v1``, ``|v1| <= v``; the
    defaults are ``henon-nl``'s (``henon_nl_system((1.0, 1.4), 0.015, 0.1)`` is the model of the
    ``henon`` scenario, whose Remark-1 version is
    :func:`~ivobs.scenarios.efimov2013.henon_remark1_system`)."""
    return NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=["x1 + v1"],
        states=["x1", "x2"],
        params={"a": (a[0], a[1]), "b": 0.3},
        d={"w1": (-w, w), "v1": (-v, v)},
    )


@register_scenario("henon-nl", "Hénon map, uncertain a(t) in [1.39, 1.41], full nonlinear model")
def _henon_nl(horizon: int = 200) -> Scenario:
    T = check_horizon(horizon)
    sys = henon_nl_system()
    return Scenario(
        name="henon-nl",
        system=sys,
        x0=Box([0.2, 0.0], [0.4, 0.2]),
        x_true0=np.array([0.3, 0.1]),
        u=np.zeros((T, 0)),
        horizon=T,
        source="[Efimov2013, Section IV.B] (the Hénon map), as a full nonlinear model",
        description="x1+ = 1 - a x1^2 + x2 + w, x2+ = 0.3 x1, y = x1 + v; a(t) in [1.39, 1.41] "
        "unknown at every step, |w| <= 0.005, |v| <= 0.02",
        _disturbance=paper_signal("uniform", sys),
        notes="bounds, x0 box and true x0 chosen by ivobs (a narrower a-range than [Efimov2013]'s "
        "[1, 1.4] keeps vertex-switched orbits bounded)",
    )


PENDULUM_STEP = 0.05


@register_scenario("pendulum-nl", "pendulum, input torque, length known to ±5 %, y = angle")
def _pendulum_nl(horizon: int = 200) -> Scenario:
    T = check_horizon(horizon)
    h = PENDULUM_STEP
    sys = NonlinearSystem(
        f=[f"th + {h}*om", f"om + {h}*(-9.81/L*sin(th) - om + u1/L**2) + w1"],
        h=["th + v1"],
        states=["th", "om"],
        inputs=["u1"],
        params={"L": (0.95, 1.05)},
        d={"w1": (-0.01, 0.01), "v1": (-0.01, 0.01)},
        dt=h,
    )
    k = np.arange(T)
    u = (2.0 * np.sin(0.05 * k))[:, None]
    return Scenario(
        name="pendulum-nl",
        system=sys,
        x0=Box([0.3, -0.2], [0.7, 0.2]),
        x_true0=np.array([0.5, 0.0]),
        u=u,
        horizon=T,
        source="textbook pendulum (m = 1 kg, g = 9.81, damping 1/s), explicit Euler step 0.05 s",
        description="th+ = th + h om, om+ = om + h(-g/L sin th - om + u/L^2) + w, "
        "y = th + v; L in [0.95, 1.05] m unknown, |w| <= 0.01, |v| <= 0.01 rad",
        _disturbance=paper_signal("uniform", sys),
        notes="the model is the Euler map with h = 0.05 s (not the ODE); torque u = 2 sin(0.05k); "
        "the damping (1/s) exceeds the energy explicit Euler adds (1 + h^2 g/L per step), so "
        "the map oscillates instead of spinning up",
    )


TANK_F = [
    "x1 + 0.5*(-k*sqrt(2*g)*sqrt(x1) + u1) + w1",
    "x2 + 0.5*(sqrt(2*g)*(sqrt(x1) - sqrt(x2))) + w2",
    "x3 + 0.5*(k*sqrt(2*g)*(sqrt(x2) - sqrt(x3))) + w3",
    "x4 + 0.5*(k*sqrt(2*g)*(sqrt(x3) - sqrt(x4) + u2)) + w4",
    "x5 + 0.5*(k*sqrt(2*g)*(sqrt(x4) - sqrt(x5) + u3)) + w5",
    "x6 + 0.5*(k*sqrt(2*g)*(sqrt(x5) - sqrt(x6))) + w6",
]
"""CORA's ``tank6EqDT_inflow4`` (tank 2 without the factor k, as CORA writes it), W on x+."""


def tank6_system() -> NonlinearSystem:
    """CORA's six tanks: ``|w_i| <= 0.001``, outputs ``x2, x4, x5`` with ``|v| <= 0.2``."""
    d = {f"w{i}": (-0.001, 0.001) for i in range(1, 7)}
    d.update({f"v{i}": (-0.2, 0.2) for i in range(1, 4)})
    return NonlinearSystem(
        f=TANK_F,
        h=["x2 + v1", "x4 + v2", "x5 + v3"],
        states=[f"x{i}" for i in range(1, 7)],
        inputs=["u1", "u2", "u3"],
        params={"k": 0.015, "g": 9.81},
        d=d,
        dt=0.5,
    )


@register_scenario("cora-tank6-nl", "CORA's nonlinear six-tank cascade with its recorded data")
def _tank6(horizon: int = 20) -> Scenario:
    T = check_horizon(horizon)
    with resources.files("ivobs.data").joinpath("cora_tank6_nl.npz").open("rb") as fh:
        z = {k: np.array(v) for k, v in np.load(fh).items()}
    sys = tank6_system()
    n_rec = z["y"].shape[0]
    u = np.vstack([z["u"], np.tile(z["u"][-1], (max(0, T - n_rec), 1))])[:T]
    recorded = Trajectory(
        x=np.full((n_rec, 6), np.nan),
        y=z["y"],
        u=z["u"],
        d=np.full((n_rec, 9), np.nan),
        t=np.arange(n_rec) * 0.5,
    )
    return Scenario(
        name="cora-tank6-nl",
        system=sys,
        x0=Box(z["R0_c"] - 4.0, z["R0_c"] + 4.0),
        x_true0=np.asarray(z["R0_c"], dtype=float),
        u=u,
        horizon=T,
        source="CORA v2026.0.1 test_nonlinearSysDT_observe_01_tank, model tank6EqDT_inflow4 "
        "([Althoff2021]); data in ivobs/data/cora_tank6_nl.npz",
        description="six tanks, outflows k sqrt(2 g x_i), explicit step 0.5 s; y = (x2, x4, x5) "
        "+ v, |v| <= 0.2, |w| <= 0.001",
        recorded=recorded,
        reference={
            "saved_methods": z["saved_methods"],
            "saved_lo": z["saved_lo"],
            "saved_hi": z["saved_hi"],
        },
        _disturbance=paper_signal("uniform", sys),
        notes="'recorded' is CORA's 20-step record (no true state stored); x_true0 for "
        "simulations is R0's centre; beyond 20 steps the last input is held",
    )


CSTR_STEP = 0.02


@register_scenario("cstr", "continuous stirred-tank reactor, rate constant known to ±2 %, y = T")
def _cstr(horizon: int = 300) -> Scenario:
    T = check_horizon(horizon)
    h = CSTR_STEP
    rate = "7.2e10*kr*exp(-8750/T)*C"
    sys = NonlinearSystem(
        f=[
            f"C + {h}*((1 - C) - {rate}) + w1",
            f"T + {h}*((350 - T) + 209.2*{rate} + 2.092*(Tc - T)) + w2",
        ],
        h=["T + v1"],
        states=["C", "T"],
        inputs=["Tc"],
        params={"kr": (0.98, 1.02)},
        d={"w1": (-1e-4, 1e-4), "w2": (-0.01, 0.01), "v1": (-0.1, 0.1)},
        dt=h,
    )
    return Scenario(
        name="cstr",
        system=sys,
        x0=Box([0.8, 305.0], [1.0, 315.0]),
        x_true0=np.array([0.9, 310.0]),
        u=constant_input(300.0, T),
        horizon=T,
        source="the CSTR of Seborg et al. / Henson & Seborg (q/V = 1/min, E/R = 8750 K, "
        "k0 = 7.2e10/min, -dH/(rho Cp) = 209.2, UA/(V rho Cp) = 2.092), explicit Euler 0.02 min",
        description="C+ = C + h((1 - C) - k0 e^(-8750/T) C) + w1, T+ = T + h((350 - T) + "
        "209.2 k0 e^(-8750/T) C + 2.092 (Tc - T)) + w2, y = T + v; k0 = 7.2e10 kr, kr in "
        "[0.98, 1.02]",
        _disturbance=paper_signal("uniform", sys),
        notes="the model is the Euler map with h = 0.02 min (not the ODE); coolant Tc = 300 K "
        "held; start below the steady state so that the reactor heats up. The uncertain rate is "
        "the scaled factor kr (order 1); k0 in [7.056e10, 7.344e10] as the parameter gives the "
        "same widths (docs/nonlinear_sets.md)",
    )


BEACONS = ((0.0, 0.0), (10.0, 0.0), (0.0, 10.0))
UNICYCLE_STEP = 0.1


@register_scenario("unicycle-range", "unicycle, ranges to three beacons and a compass")
def _unicycle(horizon: int = 200) -> Scenario:
    T = check_horizon(horizon)
    h = UNICYCLE_STEP
    ranges = [f"sqrt((px - {bx})**2 + (py - {by})**2) + v{i + 1}" for i, (bx, by) in
              enumerate(BEACONS)]  # fmt: skip
    sys = NonlinearSystem(
        f=[f"px + {h}*sp*cos(th) + w1", f"py + {h}*sp*sin(th) + w2", f"th + {h}*om + w3"],
        h=[*ranges, "th + v4"],
        states=["px", "py", "th"],
        inputs=["sp", "om"],
        d={
            "w1": (-0.01, 0.01),
            "w2": (-0.01, 0.01),
            "w3": (-0.005, 0.005),
            "v1": (-0.05, 0.05),
            "v2": (-0.05, 0.05),
            "v3": (-0.05, 0.05),
            "v4": (-0.05, 0.05),
        },
        dt=h,
    )
    k = np.arange(T)
    u = np.column_stack([np.full(T, 1.0), 0.2 + 0.05 * np.sin(0.007 * k)])
    return Scenario(
        name="unicycle-range",
        system=sys,
        x0=Box([2.0, 2.0, -0.2], [4.0, 4.0, 0.2]),
        x_true0=np.array([3.0, 3.0, 0.0]),
        u=u,
        horizon=T,
        source="kinematic unicycle, explicit Euler step 0.1 s; beacons at (0,0), (10,0), (0,10)",
        description="p+ = p + h s (cos th, sin th) + w, th+ = th + h om + w3; y = three ranges "
        "|p - b_i| + v_i (|v_i| <= 0.05) and a compass th + v4 (|v4| <= 0.05)",
        _disturbance=paper_signal("uniform", sys),
        notes="speed 1 m/s, turn rate 0.2 + 0.05 sin(0.007k) rad/s (it circles around the beacon "
        "at (0, 10)); the model is the Euler map",
    )


RANGE_BEACONS = ((8.0, -3.0), (12.0, 3.0))
RANGE_STEP = 0.1


def range_only_system(
    beacons: tuple[tuple[float, float], ...] = RANGE_BEACONS,
    speed_walk: float = 0.002,
    noise: float = 0.01,
) -> NonlinearSystem:
    """The model of ``range-only``: ``p+ = p + h v (cos th, sin th)``, ``v+ = v + w1`` (a slow
    random walk, ``|w1| <= speed_walk``), ``th+ = th + h om + w2`` (``|w2| <= 0.002``) with the
    turn rate ``om ∈ [0.15, 0.25]`` an unknown parameter; ``y = (|p - b_i| + r_i, th + c)``,
    one range per beacon (``|r_i| <= noise``) and a compass (``|c| <= 0.02``)."""
    h = RANGE_STEP
    n = len(beacons)
    ranges = [f"sqrt((px - {bx})**2 + (py - {by})**2) + r{i + 1}" for i, (bx, by) in
              enumerate(beacons)]  # fmt: skip
    d: dict[str, Any] = {"w1": (-speed_walk, speed_walk), "w2": (-0.002, 0.002)}
    d.update({f"r{i + 1}": (-noise, noise) for i in range(n)})
    d["c"] = (-0.02, 0.02)
    return NonlinearSystem(
        f=[f"px + {h}*v*cos(th)", f"py + {h}*v*sin(th)", "v + w1", f"th + {h}*om + w2"],
        h=[*ranges, "th + c"],
        states=["px", "py", "v", "th"],
        params={"om": (0.15, 0.25)},
        d=d,
        dt=h,
    )


@register_scenario("range-only", "vehicle of unknown speed and turn rate, two ranges, a compass")
def _range_only(horizon: int = 1000) -> Scenario:
    T = check_horizon(horizon)
    sys = range_only_system()
    return Scenario(
        name="range-only",
        system=sys,
        x0=Box([-0.1, -0.1, 0.95, -0.02], [0.1, 0.1, 1.05, 0.02]),
        x_true0=np.array([0.0, 0.0, 1.0, 0.0]),
        u=np.zeros((T, 0)),
        horizon=T,
        source="ivobs (a weakly observable plant for nl-horizon, not from a paper)",
        description="p+ = p + h v (cos th, sin th), v+ = v + w1, th+ = th + h om + w2, om in "
        "[0.15, 0.25], |w| <= 0.002; y = the ranges |p - b_i| + r_i to beacons at (8, -3) and "
        "(12, 3) (|r_i| <= 0.01) and a compass th + c (|c| <= 0.02); h = 0.1 s",
        _disturbance=paper_signal("uniform", sys),
        notes="the speed is seen only through the history of the ranges, from two beacons close "
        "together (a weak geometry); the start is a position fix. A recursive filter loses part "
        "of what a window of ranges pins (docs/nonlinear.md, 'Moving-horizon estimation'). "
        "With one beacon (range_only_system(((8.0, -3.0),))) the window's first-order "
        "remainders outgrow the range noise and every method drifts. The model is the Euler map",
    )


CHAIN_N = 10


@register_scenario("chain10-nl", "ten states coupled by tanh and sin, 4 outputs (scale)")
def _chain10(horizon: int = 100) -> Scenario:
    T = check_horizon(horizon)
    n = CHAIN_N
    f = ["0.8*x1 + 0.05*sin(x2) + 0.2*u1 + w1"]
    for i in range(2, n + 1):
        nxt = f" + 0.05*sin(x{i + 1})" if i < n else ""
        f.append(f"0.8*x{i} + c*tanh(x{i - 1}){nxt} + w{i}")
    outs = (1, 4, 7, 10)
    d: dict[str, Any] = {f"w{i}": (-0.01, 0.01) for i in range(1, n + 1)}
    d.update({f"v{j}": (-0.05, 0.05) for j in range(1, len(outs) + 1)})
    sys = NonlinearSystem(
        f=f,
        h=[f"x{i} + v{j + 1}" for j, i in enumerate(outs)],
        states=[f"x{i}" for i in range(1, n + 1)],
        inputs=["u1"],
        params={"c": (0.18, 0.22)},
        d=d,
    )
    k = np.arange(T)
    return Scenario(
        name="chain10-nl",
        system=sys,
        x0=Box(np.full(n, -1.0), np.full(n, 1.0)),
        x_true0=np.linspace(-0.5, 0.5, n),
        u=(np.sin(0.1 * k) * 2.0)[:, None],
        horizon=T,
        source="ivobs (a scale test, not from a paper)",
        description="x_i+ = 0.8 x_i + c tanh(x_(i-1)) + 0.05 sin(x_(i+1)) + w_i, c in "
        "[0.18, 0.22]; y = (x1, x4, x7, x10) + v, |w| <= 0.01, |v| <= 0.05",
        _disturbance=paper_signal("uniform", sys),
    )
