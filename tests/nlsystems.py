"""Nonlinear test systems and a high-precision simulator written here (not ivobs.simulate).

The simulator runs in 40-digit mpmath with the parameters and signals on the vertices of their
bounds, switching at random at every step. Its trajectory is a true trajectory of the model: each
step's rounding (about 1e-40 relative) changes the constants by far less than the outward
enclosures of the decimal bounds the estimators use (>= 1e-17 relative), and each measurement is
rounded to the double on the side of the noise bound that keeps ``|y - h(x)| <= v`` exact.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import mpmath as mp
import numpy as np

import ivobs

DPS = 40


def henon(output: str = "x1", a: tuple[float, float] = (1.39, 1.41)) -> ivobs.NonlinearSystem:
    """The Hénon map with an uncertain ``a(t)``, process noise on ``x1`` and an output
    ``x1 + v1`` or ``x2 + v1`` ([Efimov2013]'s example as a full nonlinear model)."""
    return ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=[f"{output} + v1"],
        states=["x1", "x2"],
        params={"a": a, "b": 0.3},
        d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    )


HENON_X0 = ivobs.Box([0.2, 0.0], [0.4, 0.2])


def henon_mp(output: str = "x1") -> tuple[Callable[..., list[Any]], Callable[..., list[Any]]]:
    """``f(x, u, p, d)`` and the noise-free output ``g(x, u, p)`` in mpmath."""
    b = mp.mpf(3) / 10
    idx = 0 if output == "x1" else 1

    def f(x: Sequence[Any], u: Any, p: dict[str, Any], d: dict[str, Any]) -> list[Any]:
        return [1 - p["a"] * x[0] ** 2 + x[1] + d["w1"], b * x[0]]

    def g(x: Sequence[Any], u: Any, p: dict[str, Any]) -> list[Any]:
        return [x[idx]]

    return f, g


def _inward(value: Any, centre: Any, bound: Any) -> float:
    """The double nearest ``value`` such that ``|y - centre| <= bound`` exactly."""
    y = float(value)
    while abs(mp.mpf(y) - centre) > bound:
        y = math.nextafter(y, float(centre))
    return y


def simulate(
    f: Callable[..., list[Any]],
    g: Callable[..., list[Any]],
    x0: Sequence[float],
    T: int,
    *,
    params: dict[str, tuple[float, float]],
    process: dict[str, tuple[float, float]],
    noise: Sequence[tuple[float, float]],
    u: np.ndarray | None = None,
    seed: int = 0,
) -> tuple[list[list[Any]], np.ndarray]:
    """The states (mpf) and measurements ``y = g(x) + v`` (doubles) of ``T`` steps, every
    unknown on a random vertex of its bounds at every step."""
    rng = np.random.default_rng(seed)
    mp.mp.dps = DPS
    x = [mp.mpf(v) for v in x0]
    X, Y = [], np.empty((T, len(noise)))
    dec = {k: (mp.mpf(str(lo)), mp.mpf(str(hi))) for k, (lo, hi) in {**params, **process}.items()}
    vb = [(mp.mpf(str(lo)), mp.mpf(str(hi))) for lo, hi in noise]
    for k in range(T):
        pick = {n: dec[n][int(rng.integers(2))] for n in dec}
        p = {n: pick[n] for n in params}
        d = {n: pick[n] for n in process}
        uk = [] if u is None else [mp.mpf(float(v)) for v in u[k]]
        X.append(x)
        for i, (gi, (lo, hi)) in enumerate(zip(g(x, uk, p), vb)):
            v = lo if rng.integers(2) else hi
            Y[k, i] = _inward(gi + v, gi + (lo + hi) / 2, (hi - lo) / 2)  # y - g in [lo, hi]
        x = f(x, uk, p, d)
    return X, Y


def violations(X: list[list[Any]], lower: np.ndarray, upper: np.ndarray) -> list[int]:
    """Steps where the exact state leaves the box (compared exactly, in mpmath)."""
    bad = []
    for k, x in enumerate(X):
        for i, v in enumerate(x):
            if not (mp.mpf(float(lower[k, i])) <= v <= mp.mpf(float(upper[k, i]))):
                bad.append(k)
                break
    return bad
