"""Nonlinear test models (as ivobs.NonlinearSystem) and their high-precision simulators.

The simulators are written here, from the equations, in mpmath at 200 bits: on the chaotic
Hénon map a float64 run is not a trajectory of the model; at 200 bits the simulator's own
error per step (about 2^-200 relative) is far below every margin of the estimators, so each
simulated step is a step of the model with parameters and disturbances within 2^-190 of the
vertices of their bounds.
"""

from __future__ import annotations

import numpy as np
from mpmath import mp, mpf
from mpmath import sqrt as msqrt

import ivobs
from ivobs.scenarios.nonlinear import tank6_system

PREC = 200


def henon_system(a=(1.39, 1.41), b=0.3, w=0.005, v=0.02, output="x1"):
    return ivobs.NonlinearSystem(
        f=["1 - a*x1**2 + x2 + w1", "b*x1"],
        h=[f"{output} + v1"],
        states=["x1", "x2"],
        params={"a": a, "b": b},
        d={"w1": (-w, w), "v1": (-v, v)},
        dt=True,
    )


def simulate_henon(T, seed, x0=("0.3", "0.1"), a=("1.39", "1.41"), w="0.005", v="0.02", out=0):
    """Parameters and disturbances on the vertices of their bounds, switching at random at
    every step; returns the true states (rounded to float64 for the comparison, the bounds are
    compared with a margin of 1 ulp) and the float64 measurement record."""
    rng = np.random.default_rng(seed)
    with mp.workprec(PREC):
        x = [mpf(x0[0]), mpf(x0[1])]
        av = [mpf(a[0]), mpf(a[1])]
        W, V, b = mpf(w), mpf(v), mpf("0.3")
        X = np.empty((T, 2))
        Y = np.empty((T, 1))
        for k in range(T):
            ak = av[rng.integers(2)]
            wk = W * (2 * int(rng.integers(2)) - 1)
            vk = V * (2 * int(rng.integers(2)) - 1)
            X[k] = [float(x[0]), float(x[1])]
            Y[k, 0] = float(x[out] + vk)
            x = [1 - ak * x[0] ** 2 + x[1] + wk, b * x[0]]
    return X, Y


def tank_system():
    """CORA's six tanks, as the ``cora-tank6-nl`` scenario builds them (one model, not two)."""
    return tank6_system()


def simulate_tank(T, seed, u, x0=20.0, w="0.001", v="0.2"):
    """The six tanks at 200 bits with vertex disturbances switching at random."""
    rng = np.random.default_rng(seed)
    with mp.workprec(PREC):
        k, g, h = mpf("0.015"), mpf("9.81"), mpf("0.5")
        s = msqrt(2 * g)
        W, V = mpf(w), mpf(v)
        x = [mpf(x0) + mpf(float(r)) for r in rng.uniform(-3, 3, 6)]
        X, Y = np.empty((T, 6)), np.empty((T, 3))
        for t in range(T):
            X[t] = [float(xi) for xi in x]
            vv = [V * (2 * int(rng.integers(2)) - 1) for _ in range(3)]
            Y[t] = [float(x[1] + vv[0]), float(x[3] + vv[1]), float(x[4] + vv[2])]
            q = [msqrt(xi) for xi in x]
            u1, u2, u3 = (mpf(float(c)) for c in u[t])
            nxt = [
                x[0] + h * (-k * s * q[0] + u1),
                x[1] + h * (s * (q[0] - q[1])),
                x[2] + h * (k * s * (q[1] - q[2])),
                x[3] + h * (k * s * (q[2] - q[3] + u2)),
                x[4] + h * (k * s * (q[3] - q[4] + u3)),
                x[5] + h * (k * s * (q[4] - q[5])),
            ]
            x = [xi + W * (2 * int(rng.integers(2)) - 1) for xi in nxt]
    return X, Y


def cora_tank():
    """CORA's test data (src/ivobs/data/cora_tank6_nl.npz)."""
    from importlib import resources

    with resources.files("ivobs.data").joinpath("cora_tank6_nl.npz").open("rb") as fh:
        return dict(np.load(fh))
