"""Float64 simulators written for the tests (not the library's own): every disturbance on a
random vertex of its box, the adversarial case of the containment tests."""

from __future__ import annotations

import numpy as np

import ivobs


def simulate_vertex(
    sys: ivobs.LinearSystem, x0: ivobs.Box, u: np.ndarray, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """``x+ = A x + B u + E d``, ``y = C x + D u + F d``, every ``d[k]`` on a random vertex of
    the model's box, from a random vertex of ``x0``: the states and outputs."""
    rng = np.random.default_rng(seed)
    A, B, C, D, E, F = sys.matrices_at(0)
    d = sys.d_at(0)
    x = np.where(rng.integers(0, 2, sys.nx).astype(bool), x0.hi, x0.lo)
    xs, ys = [], []
    for k in range(u.shape[0]):
        dk = np.where(rng.integers(0, 2, sys.nd).astype(bool), d.hi, d.lo)
        xs.append(x)
        ys.append(C @ x + D @ u[k] + F @ dk)
        x = A @ x + B @ u[k] + E @ dk
    return np.array(xs), np.array(ys)


def servo_vertex(T: int, seed: int = 0):
    """The servo of [Tang2019] under a constant 2 V from its true initial state, every
    disturbance on a vertex: ``(scenario, u, x, y)``."""
    sc = ivobs.scenarios.get("servo-motor")
    s = sc.system
    A, B, C, E, F = (np.asarray(m, dtype=float) for m in (s.A, s.B, s.C, s.E, s.F))
    rng = np.random.default_rng(seed)
    d = np.where(rng.random((T, s.nd)) < 0.5, s.d.lo, s.d.hi)
    u = np.full((T, 1), 2.0)
    x = np.zeros((T, s.nx))
    x[0] = sc.x_true0
    for k in range(T - 1):
        x[k + 1] = A @ x[k] + B @ u[k] + E @ d[k]
    return sc, u, x, x @ C.T + d @ F.T
