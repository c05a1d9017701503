"""The ``quadruple-tank`` scenario is [Johansson2000]'s linearised process, and every method
contains the true state on it.

The paper's numbers (Table I: areas ``A_i``, outlet areas ``a_i``, ``k_c``, ``g``; Table II: the
operating levels ``h⁰``, pump gains ``k_i``, valve settings ``γ_i`` and the time constants
``T_i`` it prints) are written here again, and the model of eq. (3) is built and discretised here
with a zero-order hold (the matrix exponential of the augmented matrix), independently of
:mod:`ivobs.scenarios.quadtank`.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.linalg import expm

import ivobs

# [Johansson2000, Table I]
AREA = np.array([28.0, 32.0, 28.0, 32.0])  # A_i, cm²
OUTLET = np.array([0.071, 0.057, 0.071, 0.057])  # a_i, cm²
KC, G = 0.50, 981.0  # V/cm, cm/s²
# [Johansson2000, Table II]: h⁰ (cm), k (cm³/(V s)), γ, and the printed T (s)
POINTS = {
    "minimum": ((12.4, 12.7, 1.8, 1.4), (3.33, 3.35), (0.70, 0.60), (62, 90, 23, 30)),
    "nonminimum": ((12.6, 13.0, 4.8, 4.9), (3.14, 3.29), (0.43, 0.34), (63, 91, 39, 56)),
}


def johansson(phase: str, w: float, v: float, Ts: float) -> tuple[np.ndarray, ...]:
    """Eq. (3) of [Johansson2000] with the printed time constants, held over ``Ts``."""
    _, (k1, k2), (g1, g2), T = POINTS[phase]
    A1, A2, A3, A4 = AREA
    Ac = np.diag([-1.0 / t for t in T])
    Ac[0, 2] = A3 / (A1 * T[2])
    Ac[1, 3] = A4 / (A2 * T[3])
    Bc = np.array(
        [[g1 * k1 / A1, 0], [0, g2 * k2 / A2], [0, (1 - g2) * k2 / A3], [(1 - g1) * k1 / A4, 0]]
    )
    aug = np.zeros((10, 10))  # [x; u; w]: the hold of u and w over one sample
    aug[:4, :4], aug[:4, 4:6], aug[:4, 6:] = Ac, Bc, np.eye(4)
    Phi = expm(aug * Ts)
    A, B, Ew = Phi[:4, :4], Phi[:4, 4:6], Phi[:4, 6:]
    E = np.hstack([Ew, np.zeros((4, 2))])
    C = KC * np.eye(2, 4)
    F = np.hstack([np.zeros((2, 4)), np.eye(2)])
    r = np.r_[np.full(4, w), np.full(2, v)]
    return A, B, C, E, F, r


@pytest.mark.parametrize("phase", ["minimum", "nonminimum"])
def test_the_printed_time_constants_follow_from_the_tanks(phase):
    """``T_i = (A_i / a_i) sqrt(2 h⁰_i / g)`` ([Johansson2000], below eq. (3)) from Tables I-II
    agrees with the printed ``T_i`` to their rounding (at most 0.9 s off)."""
    h0, _, _, printed = POINTS[phase]
    T = AREA / OUTLET * np.sqrt(2.0 * np.array(h0) / G)
    assert np.all(np.abs(T - np.array(printed)) < 0.9), T


@pytest.mark.parametrize(
    "phase, w, v, Ts", [("minimum", 0.001, 0.01, 1.0), ("nonminimum", 0.002, 0.05, 0.5)]
)
def test_the_scenario_is_johanssons_linearisation(phase, w, v, Ts):
    sc = ivobs.scenarios.get("quadruple-tank", phase=phase, w=w, v=v, Ts=Ts, horizon=10)
    s = sc.system
    A, B, C, E, F, r = johansson(phase, w, v, Ts)
    assert s.is_discrete and (s.nx, s.nu, s.ny, s.nd) == (4, 2, 2, 6)
    np.testing.assert_allclose(s.A, A, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s.B, B, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(s.E, E, rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(s.C, C)
    np.testing.assert_array_equal(s.F, F)
    np.testing.assert_array_equal(s.D, np.zeros((2, 2)))
    np.testing.assert_array_equal(s.d.hi, r)
    np.testing.assert_array_equal(s.d.lo, -r)
    # the coupling of eq. (3): tank 3 drains into tank 1, tank 4 into tank 2, nothing else
    assert A[0, 2] > 0 and A[1, 3] > 0 and A[0, 1] == A[2, 0] == A[3, 1] == 0
    assert sc.x0.contains(sc.x_true0) and sc.u.shape == (10, 2)


def test_a_bad_operating_point_is_refused_by_name():
    with pytest.raises(ivobs.IvobsError, match="phase: expected one of 'minimum'"):
        ivobs.scenarios.get("quadruple-tank", phase="P-")


def vertex_run(T: int, seed: int) -> tuple[np.ndarray, ...]:
    """The plant simulated here (eq. (3) held over 1 s, :func:`johansson`): ``x[0]`` a random
    vertex of the prior box, ``d`` on random vertices of its bounds at every step."""
    A, B, C, E, F, r = johansson("minimum", 0.001, 0.01, 1.0)
    rng = np.random.default_rng(seed)
    x = np.where(rng.random(4) < 0.5, -1.0, 1.0)
    u = np.column_stack([0.5 * np.sin(np.arange(T) / 40.0), 0.5 * np.cos(np.arange(T) / 70.0)])
    xs, ys = np.empty((T, 4)), np.empty((T, 2))
    for k in range(T):
        d = np.where(rng.random(6) < 0.5, -r, r)
        xs[k], ys[k] = x, C @ x + F @ d
        x = A @ x + B @ u[k] + E @ d
    return u, ys, xs


SLOW = {"constrained-zonotope", "nl-constrained-zonotope", "exact", "intersect"}


@pytest.mark.parametrize("method", ivobs.methods())
def test_every_method_contains_the_truth_with_vertex_disturbances(method):
    sc = ivobs.scenarios.get("quadruple-tank", horizon=10)
    T = 60 if method in SLOW else 300
    u, y, x = vertex_run(T, seed=7)
    est = ivobs.make_estimator(method, sc.system, x0=sc.x0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no measurement may look inconsistent
        res = est.run(u, y)
    vf = res.valid_from
    assert vf < 10
    assert np.isfinite(res.lower[vf:]).all() and np.isfinite(res.upper[vf:]).all()
    inside = (res.lower[vf:] <= x[vf:]) & (x[vf:] <= res.upper[vf:])
    assert inside.all(), np.argwhere(~inside)[:3]
    # the bounds shrink from the prior box (2 cm wide) to a fraction of it on the measured levels
    assert (res.upper - res.lower)[-1, :2].max() < 0.5
