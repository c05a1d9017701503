"""The examples of [Efimov2013, Section IV]: the planar system and the Hénon map."""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem
from ..model.nonlinear._runtime import dn as _lo
from ..model.nonlinear._runtime import up as _hi
from ..sets import Box
from ..simulate import _rng
from .registry import Scenario, check_horizon, register_scenario


@register_scenario("efimov-planar", "[Efimov2013] §IV.A: planar system, no nonnegative A - LC")
def _efimov_planar(horizon: int = 50) -> Scenario:
    T = check_horizon(horizon)
    A = np.array([[0.3, -0.7], [0.6, -0.5]])
    C = np.array([[1.0, 0.0]])
    delta, V = 0.5, 0.1
    # d = (δb1, δb2, v): b = b0(t) + δb(t, x) with b0 a known input (B = I), v the noise
    E = np.hstack([np.eye(2), np.zeros((2, 1))])
    F = np.array([[0.0, 0.0, 1.0]])
    sys = LinearSystem(A, np.eye(2), C, E=E, F=F, d=Box([-delta, -delta, -V], [delta, delta, V]))
    k = np.arange(T)
    u = np.column_stack([np.sin(0.1 * k), np.cos(0.2 * k)])  # b0(t)

    def d_paper(kk: int, x: np.ndarray) -> np.ndarray:
        return np.array([delta * np.sin(0.5 * kk * x[1]), delta * np.sin(0.3 * kk), V * np.sin(kk)])

    ref = {
        "L": np.array([[0.3], [0.6]]),
        "eig_D": np.array([0.0, -0.5]),
        "R": np.array([[-0.5, 0.0], [1.0, 0.0]]),
        "S": np.array([[0.609, 0.814], [-1.162, 0.581]]),
    }
    return Scenario(
        name="efimov-planar",
        system=sys,
        x0=Box([-2.0, -2.0], [2.0, 2.0]),
        x_true0=np.array([1.0, -1.0]),
        u=u,
        horizon=T,
        source="[Efimov2013, Section IV.A], observers (4) and (5)",
        description="x+ = Ax + b0(t) + δb(t, x), y = x1 + v, |δb| <= 0.5, |v| <= 0.1",
        reference=ref,
        _disturbance=lambda kind, seed, T: d_paper if kind == "paper" else None,
        notes="initial state (1, -1) and prior box [-2, 2]^2 chosen by ivobs; the paper's printed "
        "R = [[-0.5, 0], [1, 0]] is not nonnegative (no nonnegative matrix has the "
        "spectrum {0, -0.5}: its trace would be negative)",
    )


def henon_bounds(k: Any, y: Any, *, a_lo: float, a_hi: float, V: float, delta: float) -> Box:
    """Bounds of (b, v), b = 1 - a x1^2 + d, from the measurement y = x1 + v [Efimov2013, Remark 1].

    ``x1 ∈ [y - V, y + V]`` so ``x1^2 ∈ [max(0, |y| - V)^2, (|y| + V)^2]``. The paper prints
    ``(|y| - V)^2`` for the lower end, which is unsound when ``|y| < V`` (then ``x1`` may be 0).
    Each bound is rounded outward, so the box holds the real-number interval.
    A module-level function (bound to its parameters with ``functools.partial``) so that system
    files can name it: ``d = { python = "ivobs.scenarios:henon_bounds", params = {...} }``.
    """
    y0 = np.nan if y is None else float(np.ravel(y)[0])
    if np.isnan(y0):
        raise IvobsError(
            "henon: the nonlinear term is bounded from the measurement y[k], which is missing "
            f"at step {k}; this scenario cannot predict through a missing sample"
        )
    # Outward rounding: every operation is rounded to the far side (one ulp is enough, since a
    # correctly rounded result is within half an ulp), so the box holds the real-number bounds.
    sq_lo = _lo(max(0.0, _lo(abs(y0) - V)) ** 2)
    sq_hi = _hi(_hi(abs(y0) + V) ** 2)
    b_lo = _lo(_lo(1.0 - _hi(a_hi * sq_hi)) - delta)
    b_hi = _hi(_hi(1.0 - _lo(a_lo * sq_lo)) + delta)
    return Box([b_lo, -V], [b_hi, V])


def henon_remark1_system(
    a: tuple[float, float] = (1.0, 1.4), V: float = 0.1, delta: float = 0.015
) -> LinearSystem:
    """The Hénon map as [Efimov2013, Remark 1] writes it: ``x+ = A x + r b``, ``y = x1 + v``,
    ``A = [[0, 1], [0.3, 0]]``, ``r = (1, 0)``, with the nonlinear term ``b = 1 - a x1^2 + d``
    (``a ∈ a``, ``|d| <= delta``) a disturbance bounded at each step from the measurement by
    :func:`henon_bounds` (``|v| <= V``). Defaults: the ``henon`` scenario's values."""
    A = np.array([[0.0, 1.0], [0.3, 0.0]])
    C = np.array([[1.0, 0.0]])
    # d = (b, v), b = 1 - a(t) x1^2 + d(t) enters through r = (1, 0); v is the output noise
    E = np.array([[1.0, 0.0], [0.0, 0.0]])
    F = np.array([[0.0, 1.0]])
    bounds = partial(henon_bounds, a_lo=a[0], a_hi=a[1], V=V, delta=delta)
    return LinearSystem(A, None, C, E=E, F=F, d=bounds)


@register_scenario(
    "henon", "[Efimov2013] §IV.B: Hénon map, uncertain a(t), bounds from y (Remark 1)"
)
def _henon(horizon: int = 200) -> Scenario:
    T = check_horizon(horizon)
    a_lo, a_hi, V, delta = 1.0, 1.4, 0.1, 0.015
    sys = henon_remark1_system((a_lo, a_hi), V, delta)

    def factory(kind: str, seed: Any, T: int) -> Any:
        rng = _rng(seed)
        if kind == "paper":

            def d_fn(k: int, x: np.ndarray) -> np.ndarray:
                a = 1.2 + 0.2 * np.sin(0.05 * k)
                return np.array([1.0 - a * x[0] ** 2 + delta * np.sin(0.3 * k), V * np.sin(k)])

            return d_fn
        if kind in ("vertex", "uniform"):
            draws: dict[int, tuple[float, float, float]] = {}

            def d_adv(k: int, x: np.ndarray) -> np.ndarray:
                if k not in draws:
                    if kind == "vertex":
                        a = float(rng.choice([a_lo, a_hi]))
                        dist, v = rng.choice([-delta, delta]), rng.choice([-V, V])
                    else:
                        a = rng.uniform(a_lo, a_hi)
                        dist, v = rng.uniform(-delta, delta), rng.uniform(-V, V)
                    # Assumption 1 (bounded state): keep the orbit on the attractor by taking
                    # the other vertex of a(t) when this one would throw x1 out of [-1.3, 1.3]
                    if abs(1.0 - a * x[0] ** 2 + x[1] + dist) > 1.3:
                        a = a_lo + a_hi - a
                    draws[k] = (a, dist, v)
                a, dist, v = draws[k]
                return np.array([1.0 - a * x[0] ** 2 + dist, v])

            return d_adv
        raise IvobsError(
            f"henon: disturbance kind {kind!r} is not available "
            "(use 'paper', 'vertex' or 'uniform')"
        )

    return Scenario(
        name="henon",
        system=sys,
        x0=Box([-1.5, -1.5], [1.5, 1.5]),
        x_true0=np.array([0.1, 0.1]),
        u=np.zeros((T, 0)),
        horizon=T,
        source="[Efimov2013, Section IV.B], Theorem 1 with L = (-0.1, 0.1)",
        description="x+ = Ax + r(1 - a(t) x1^2 + d), y = x1 + v, a in [1, 1.4], |d| <= 0.015, "
        "|v| <= 0.1; the nonlinear term is bounded from y (Remark 1)",
        reference={"L": np.array([[-0.1], [0.1]]), "a": (a_lo, a_hi), "V": V, "delta": delta},
        _disturbance=factory,
        notes="a(t) = 1.2 + 0.2 sin(0.05k), d = 0.015 sin(0.3k), v = 0.1 sin k chosen by ivobs "
        "(the paper gives none); adversarial runs take a(t) on its vertices but switch "
        "vertex when the orbit would leave [-1.3, 1.3] (the paper assumes a bounded state: "
        "random vertex switching makes the Hénon map escape to infinity)",
    )
