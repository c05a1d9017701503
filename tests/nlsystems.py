"""Nonlinear test systems and their exact records (one place for the nonlinear tests).

Every record comes from the rigorous simulator of tests/exactsim.py (60-digit intervals from the
model's own expressions, every parameter and signal on a random vertex of its bounds at every
step, each state and measurement an exact value of the model): the containment checks rely on
no margin of the estimators. ``Record.misses(lower, upper)`` lists the steps whose box does not
hold the whole enclosure of the true state.
"""

from __future__ import annotations

from functools import cache
from importlib import resources

import numpy as np

import ivobs
from exactsim import Record, simulate
from ivobs.scenarios.nonlinear import tank6_system

__all__ = ["HENON_X0", "Record", "cora_tank", "henon", "henon_record", "simulate", "tank_record"]

HENON_X0 = ivobs.Box([0.2, 0.0], [0.4, 0.2])


def henon(output: str = "x1", a: tuple[float, float] = (1.39, 1.41)) -> ivobs.NonlinearSystem:
    """The Hénon map with an uncertain ``a(t)``, process noise on ``x1`` and the output
    ``x1 + v1`` or ``x2 + v1`` ([Efimov2013]'s example as a full nonlinear model; with the
    defaults and ``y = x1`` it is the ``henon-nl`` scenario's model)."""
    return ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=[f"{output} + v1"],
        states=["x1", "x2"],
        params={"a": a, "b": 0.3},
        d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )


@cache
def henon_record(T: int, seed: int, output: str = "x1") -> tuple[ivobs.NonlinearSystem, Record]:
    """The Hénon map of :func:`henon` and ``T`` exact steps from ``(0.3, 0.1)`` (simulated once
    per arguments: copy ``Y`` before changing it)."""
    sys = henon(output)
    return sys, simulate(sys, [0.3, 0.1], T, seed=seed)


def tank_record(T: int, seed: int) -> tuple[ivobs.NonlinearSystem, np.ndarray, Record]:
    """CORA's six tanks (the ``cora-tank6-nl`` model), the inflows ``u = 0.3`` (levels settle
    near 20-26: no tank runs dry) and ``T`` exact steps from levels ``20 ± 3``."""
    sys = tank6_system()
    U = np.full((T, 3), 0.3)
    x0 = 20.0 + np.random.default_rng(seed).uniform(-3, 3, 6)
    return sys, U, simulate(sys, x0, T, U, seed=seed)


def cora_tank() -> dict[str, np.ndarray]:
    """CORA's six-tank test data (src/ivobs/data/cora_tank6_nl.npz)."""
    with resources.files("ivobs.data").joinpath("cora_tank6_nl.npz").open("rb") as fh:
        return dict(np.load(fh))
