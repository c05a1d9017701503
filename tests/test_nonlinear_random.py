"""``nl-interval`` on random contracting maps with polynomial and trigonometric terms, an input,
an uncertain parameter and nonlinear outputs: the exact (40-digit) state stays in the box at
every one of 10^4 steps with every unknown switching between the vertices of its bounds."""

from __future__ import annotations

import re

import mpmath as mp
import numpy as np
import pytest

import ivobs
from nlsystems import simulate, violations

T = 10_000


def _random_system(seed: int) -> tuple[list[str], list[str]]:
    """A random contracting 3-state map with polynomial and trigonometric terms, process noise
    on every state and nonlinear outputs (coefficients are 3-digit decimals)."""
    rng = np.random.default_rng(seed)

    def c() -> str:
        return f"{rng.uniform(-0.4, 0.4):.3f}"

    f = [
        f"{c()}*x1 + {c()}*tanh(x2 - x3) + 0.2*sin(x1*x3) + {c()}*u1 + w1",
        f"{c()}*x2 + 0.25*cos(x1) * x3 + {c()}*x1**2/(1 + x1**2) + p*x2 + w2",
        f"{c()}*x3 + 0.3*atan(x1 + x2) - 0.05*x3**3/(1 + x3**2) + w3",
    ]
    h = ["x1 + 0.5*x2**2 + v1", "exp(0.2*x3) + x2 + v2"]
    return f, h


@pytest.mark.parametrize("seed", [0])
def test_random_polynomial_trigonometric_systems_are_contained(seed: int) -> None:
    f_text, h_text = _random_system(seed)
    bounds = {"w1": (-0.01, 0.01), "w2": (-0.01, 0.01), "w3": (-0.01, 0.01)}
    noise = [(-0.05, 0.05), (-0.05, 0.05)]
    sys = ivobs.NonlinearSystem(
        f=f_text,
        h=h_text,
        states=["x1", "x2", "x3"],
        inputs=["u1"],
        params={"p": (-0.1, 0.1)},
        d={**bounds, "v1": noise[0], "v2": noise[1]},
    )
    env = {"sin": mp.sin, "cos": mp.cos, "tanh": mp.tanh, "atan": mp.atan, "exp": mp.exp}
    env["mpf"] = mp.mpf

    def exact(text: str) -> str:  # decimals are exact in the model: mpf('0.437'), not a double
        return re.sub(r"(\d+\.\d+)", r"mpf('\1')", text)

    fc = [compile(exact(e.replace(" + w", " + d_w")), "<f>", "eval") for e in f_text]
    hc = [compile(exact(e.rsplit(" + v", 1)[0]), "<h>", "eval") for e in h_text]

    def scope(x, u, p):  # type: ignore[no-untyped-def]
        return {**env, "x1": x[0], "x2": x[1], "x3": x[2], "u1": u[0], "p": p["p"]}

    def f(x, u, p, d):  # type: ignore[no-untyped-def]
        ns = {**scope(x, u, p), "d_w1": d["w1"], "d_w2": d["w2"], "d_w3": d["w3"]}
        return [eval(code, ns) for code in fc]

    def h(x, u, p):  # type: ignore[no-untyped-def]
        return [eval(code, scope(x, u, p)) for code in hc]

    rng = np.random.default_rng(seed + 10)
    U = rng.uniform(-1, 1, (T, 1))
    X, Y = simulate(
        f,
        h,
        [0.1, -0.2, 0.3],
        T,
        params={"p": (-0.1, 0.1)},
        process=bounds,
        noise=noise,
        u=U,
        seed=seed,
    )
    est = ivobs.make_estimator("nl-interval", sys, x0=ivobs.Box([-1, -1, -1], [1, 1, 1]))
    res = est.run(U, Y)
    assert violations(X, res.lower, res.upper) == []
    w = res.upper - res.lower
    assert np.isfinite(w).all() and w[-5000:].max() < 2.0
    assert w[-1000:].mean() <= 1.2 * w[1000:2000].mean()
