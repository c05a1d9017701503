"""The fixed-time estimator [Wang2020] contains the true state at every step, floating-point
rounding included, on every path (the loop of ``run()``, the whole-record path, ``step()`` with a
JSON round trip of its state at every step), and never flags an admissible sample.

The true trajectories are simulated here in exact rational arithmetic (:func:`exact_run`), with
every disturbance on a vertex of its bounds, and the measurements are the doubles nearest to the
exact outputs, as a logger records them (so an output on the edge of its bounds may be recorded
just outside it). Systems: the paper's example, the servo motor, random systems (singular ``A``
through the output injection of Remark 1, asymmetric bounds, ``D u``), a time-varying system
(Remark 4) with singular steps, time-varying bounds, and scale cases (states of 1e6-1e10, an
output injection of 1e3).
"""

from __future__ import annotations

import json
import warnings
from fractions import Fraction

import numpy as np
import pytest

import ivobs
from ivobs import Box, LinearSystem
from ivobs.testing import random_system


def exact_run(
    sys: LinearSystem, x0: np.ndarray, u: np.ndarray, d: np.ndarray
) -> tuple[list[list[Fraction]], np.ndarray]:
    """``x[k]`` exactly (rationals) and ``y[k]`` rounded to the nearest double, for the inputs
    ``u`` and the disturbances ``d`` (doubles, taken as exact)."""

    def mul(M: np.ndarray, v: list[Fraction]) -> list[Fraction]:
        return [
            sum((Fraction(float(m)) * x for m, x in zip(row, v) if m != 0), Fraction(0))
            for row in M
        ]

    x = [Fraction(float(v)) for v in x0]
    X, Y = [], np.empty((len(d), sys.ny))
    for k in range(len(d)):
        A, B, C, D, E, F = sys.matrices_at(k)
        uk = [Fraction(float(v)) for v in u[k]]
        dk = [Fraction(float(v)) for v in d[k]]
        X.append(x)
        Y[k] = [float(a + b + c) for a, b, c in zip(mul(C, x), mul(D, uk), mul(F, dk))]
        x = [a + b + c for a, b, c in zip(mul(A, x), mul(B, uk), mul(E, dk))]
    return X, Y


def vertices(sys: LinearSystem, T: int, rng: np.random.Generator) -> np.ndarray:
    """A random vertex of the bounds of ``d`` at every step."""
    lo, hi = sys.d_over(T)
    return np.where(rng.random(lo.shape) < 0.5, lo, hi)


def misses(lo: np.ndarray, hi: np.ndarray, X: list[list[Fraction]], start: int) -> list[int]:
    """The steps from ``start`` whose box does not contain the exact state."""
    return [
        k
        for k in range(start, len(X))
        if not all(a <= x <= b for a, x, b in zip(lo[k].tolist(), X[k], hi[k].tolist()))
    ]


def check(est, X, u, y, vectorised=True):
    """Every path contains the exact state at every step from ``valid_from`` and flags no
    sample; the whole-record path and ``step()`` give the loop's widths to rounding."""
    vf = est.valid_from
    saves = set(np.linspace(0, len(y) - 1, 8).astype(int).tolist()) | {vf}
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an inconsistency warning would fail
        loop = est.run(u, y, vectorize=False)
        runs = [loop] + ([est.run(u, y, vectorize=True)] if vectorised else [])
        est.reset()
        boxes = []
        for k in range(len(y)):
            boxes.append(est.step(u[k], y[k]))
            if k in saves:  # the state through JSON, and on from the restored one
                est.restore(json.loads(json.dumps(est.state())))
    lo = np.array([b.lo for b in boxes])
    hi = np.array([b.hi for b in boxes])
    for r_lo, r_hi in [(r.lower, r.upper) for r in runs] + [(lo, hi)]:
        assert misses(r_lo, r_hi, X, vf) == []
        assert np.all(r_lo[vf:] <= r_hi[vf:])
        scale = 1.0 + np.abs(loop.upper[vf:])
        np.testing.assert_allclose(r_hi[vf:] - r_lo[vf:], loop.width[vf:], rtol=1e-9, atol=0)
        assert np.max(np.abs(r_lo[vf:] - loop.lower[vf:]) / scale) < 1e-12
    assert not any(r.inconsistent.any() for r in runs)
    return loop


T = 300


def _record(sys, x0, seed, T=T):
    """An exact record of ``T`` steps from ``x0``: normal inputs, vertex disturbances."""
    rng = np.random.default_rng(seed)
    u = rng.normal(size=(T, sys.nu))
    X, y = exact_run(sys, x0, u, vertices(sys, T, rng))
    return X, u, y


@pytest.mark.parametrize("s", [1, 2, 4])
def test_paper_example_contains_the_state(s):
    sc = ivobs.scenarios.get("dinh2019")
    X, u, y = _record(sc.system, sc.x_true0, s)
    est = ivobs.make_estimator("fixed-time", sc.system, s=s, strips=False)  # the paper's box
    res = check(est, X, u, y)
    # eq. (11): the width is 2 |T Md| r, to rounding
    Tm, Md = est.design.T, est.design.Md
    w = 2 * np.abs(Tm @ Md) @ np.tile(sc.system.d_at(0).radius, s + 1)
    np.testing.assert_allclose(res.width[s:], np.broadcast_to(w, (T - s, 2)), rtol=1e-12)


def test_servo_motor_contains_the_state():
    sc = ivobs.scenarios.get("servo-motor")
    X, u, y = _record(sc.system, sc.x_true0, 0)
    check(ivobs.make_estimator("fixed-time", sc.system), X, u, y)


CASES = [
    # (seed, nx, ny, invertible, symmetric, feedthrough, s_extra)
    (0, 2, 1, True, True, False, 0),
    (1, 3, 1, True, False, False, 1),
    (2, 3, 2, False, True, False, 0),
    (3, 3, 2, False, False, True, 2),
    (4, 4, 1, False, False, False, 0),
    (5, 4, 2, True, False, True, 1),
    (6, 2, 2, False, True, True, 3),
]


@pytest.mark.parametrize("case", CASES)
def test_random_systems_contain_the_state(case):
    """Singular ``A`` (Remark 1: output injection), asymmetric bounds (a known centre), ``D u``,
    longer windows."""
    seed, nx, ny, inv, sym, ft, extra = case
    sys = random_system(
        seed, nx=nx, ny=ny, nu=2, invertible=inv, symmetric_bounds=sym, feedthrough=ft
    )
    X, u, y = _record(sys, np.random.default_rng(seed).uniform(-5, 5, nx), seed, T=150)
    est = ivobs.make_estimator("fixed-time", sys, s=nx - 1 + extra)
    assert (est.design.L is None) == inv
    check(est, X, u, y)


def _ltv_system(singular_every=3):
    """Observable at every step; ``A(k)`` singular every third step (Remark 1 per step)."""

    def A(k):
        a = np.array(
            [
                [0.8, 0.5 + 0.3 * np.sin(0.2 * k), 0.0],
                [0.0, 0.9, 0.4 * np.cos(0.1 * k)],
                [0.1, 0.0, 0.7],
            ]
        )
        if singular_every and k % singular_every == 0:
            a[2] = 0.0
        return a

    return LinearSystem(
        A,
        np.array([[0.0], [1.0], [0.5]]),
        lambda k: np.array([[1.0, 0.1 * np.sin(0.3 * k), 0.0]]),
        D=lambda k: np.array([[0.2 * np.cos(k)]]),
        E=np.array([[0.1, 0.0], [0.0, 0.1], [0.05, 0.0]]),
        F=np.array([[0.0, 0.05]]),
        d=Box(np.array([-0.5, -1.0]), np.ones(2)),
    )


def test_time_varying_system_contains_the_state():
    """Remark 4: a design per window (``T_k``), singular ``A(k)`` every third step."""
    sys = _ltv_system()
    X, u, y = _record(sys, np.array([1.0, -2.0, 0.5]), 1, T=120)
    est = ivobs.make_estimator("fixed-time", sys, s=3)
    check(est, X, u, y, vectorised=False)


def test_time_varying_bounds_contain_the_state():
    base = random_system(11, nx=2, ny=1, nu=1, symmetric_bounds=False)
    k = np.arange(T)[:, None]
    lo = base.d.lo - 0.3 * (1 + np.sin(0.1 * k))
    hi = base.d.hi + 0.2 * (1 + np.cos(0.07 * k))
    sys = LinearSystem(base.A, base.B, base.C, E=base.E, F=base.F, d=Box(lo, hi))
    X, u, y = _record(sys, np.array([2.0, -1.0]), 3)
    check(ivobs.make_estimator("fixed-time", sys), X, u, y)


def test_large_states_contain_the_state():
    """States of 1e6 to 1e10 (an unstable plant, ρ(A) = 1.03, from 1e6), bounds of 1e-3:
    every rounding of the window's evaluation is of the size of the state, far above the
    disturbance; the boxes still contain the exact state, and stay narrow relative to it."""
    base = random_system(7, nx=3, ny=2, nu=1, rho=1.03)
    d = Box.symmetric(np.full(5, 1e-3))
    sys = LinearSystem(base.A, base.B, base.C, E=base.E, F=base.F, d=d)
    X, u, y = _record(sys, np.array([1e6, -2e6, 5e5]), 2)
    assert 1e9 < max(abs(float(v)) for v in X[-1]) < 1e11
    res = check(ivobs.make_estimator("fixed-time", sys), X, u, y)
    x_last = np.array([float(v) for v in X[-1]])
    assert np.all(res.width[-1] < 1e-6 * np.abs(x_last).max())


def test_large_output_injection_contains_the_state():
    """Singular ``A`` with an output injection of entries ~1e3 (Remark 1, given by the user):
    the stacked matrices of ``A - LC`` and the known input ``L y`` are large; the certified
    gain and its rounding bound still contain the state, at states of 1e6."""
    base = random_system(2, nx=3, ny=2, nu=1, invertible=False)
    rng = np.random.default_rng(3)
    L = rng.uniform(-1e3, 1e3, size=(3, 2))
    assert np.linalg.cond(base.A - L @ base.C) < 1e8
    X, u, y = _record(base, np.array([1e6, -3e5, 2e6]), 4)
    est = ivobs.make_estimator("fixed-time", base, L=L)
    check(est, X, u, y)


def test_remark1_singular_A_without_noise_is_the_state_itself():
    """``A = [[0, 1], [0, 0.5]]``, ``C = [1, 0]``, no disturbance: from ``k = s`` the box is the
    state up to the proven rounding of its evaluation (Remark 3), and contains it exactly."""
    sys = LinearSystem([[0.0, 1.0], [0.0, 0.5]], None, [[1.0, 0.0]])
    X, y = exact_run(sys, np.array([3.0, -2.0]), np.zeros((40, 0)), np.zeros((40, 0)))
    est = ivobs.make_estimator("fixed-time", sys)
    res = check(est, X, np.zeros((40, 0)), y)
    assert np.all(res.width[1:] <= 1e-14 * (1 + np.abs(res.upper[1:])))


def test_recorded_outputs_just_outside_their_bounds_are_not_flagged():
    """``x = (-0.1, 0.2)`` (constant), ``y = (x1, x2, x1 + x2) + v``, ``|v| <= 0.005``; ``v`` on
    the vertices that put the parity residual ``y3 - y1 - y2 = v3 - v1 - v2`` on the edge of
    its bound ``0.015``. ``y1 = -0.1 - 0.005`` is recorded as the double nearest to it,
    ``-0.10500000000000001``, outside the exact set: the parity test (its proven rounding
    bound included) accepts every sample, and the boxes contain the state."""
    sys = LinearSystem(
        np.eye(2),
        None,
        [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
        E=np.zeros((2, 3)),
        F=np.eye(3),
        d=Box.symmetric([0.005, 0.005, 0.005]),
    )
    n = 60
    v = np.where(np.arange(n)[:, None] % 2 == 0, 1.0, -1.0) * np.array([0.005, 0.005, -0.005])
    X, y = exact_run(sys, np.array([-0.1, 0.2]), np.zeros((n, 0)), v)
    assert y[1, 0] == -0.10500000000000001
    est = ivobs.make_estimator("fixed-time", sys, s=0)
    check(est, X, np.zeros((n, 0)), y)
