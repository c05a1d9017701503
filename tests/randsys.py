"""Seeded random test systems for the soundness property tests and benchmarks.

* :func:`random_nonlinear`: discrete-time maps with 2-5 states, polynomial terms of degree 2-3,
  ``sin``/``cos``/``tanh``/``exp`` terms, uncertain parameters (intervals, one multiplying a
  nonlinear term, one an uncertain linear coefficient), an input or none, process noise on every
  state and 1-2 outputs with additive noise, some of them nonlinear. The coefficients are
  scaled so that, for every parameter in its bounds, every ``|u| <= 1`` and every disturbance,
  the box ``|x|_inf <= R`` is invariant (``|f_i| <= 0.9 R`` there) and the map contracts in the
  infinity norm on it (Jacobian row sums ``<= 0.9``): the true state stays bounded and so must
  the widths.
* :func:`random_interval_linear`: linear systems with interval matrices ``A``, ``B``, ``C``,
  ``D`` (some entries exact), ``|A0|_inf + |R_A|_inf <= 0.8``, process noise on every state
  and measurement noise on every output.

Imported by tests/test_nl_sound_random.py and benchmarks/bench_nl_sound.py (one copy).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

import ivobs

R = 2.0
"""Half-width of the invariant box of the random maps."""

# (template, sup |term| over |x| <= R, sup of the row sum of |d term / dx| there)
_TERMS = [
    ("x{j}**2", R**2, 2 * R),
    ("x{j}**3", R**3, 3 * R**2),
    ("x{j}*x{k}", R**2, 2 * R),
    ("sin(x{j})", 1.0, 1.0),
    ("cos(x{j})", 1.0, 1.0),
    ("tanh(x{j} - x{k})", 1.0, 2.0),
    ("exp(-x{j}**2)", 1.0, 0.86),  # max |2 t exp(-t^2)| = sqrt(2/e) < 0.86
    ("x{k}*sin(x{j})", R, R + 1.0),
    ("exp(x{j}/4)", float(np.exp(R / 4)), float(np.exp(R / 4)) / 4),
]
_OUTPUTS = [
    "x{a}",
    "x{a} + 0.5*x{b}**2",
    "sin(x{a}) + 0.5*x{b}",
    "tanh(x{a} + x{b}) + 0.3*x{a}",
    "exp(x{a}/5) + x{b}",
    "x{a}*x{b} + x{a}",
]
P1 = (0.8, 1.2)  # multiplies one nonlinear term of each row
P2 = (-0.05, 0.05)  # an uncertain coefficient of x1 in the last row


@dataclass
class Case:
    """A random system, the true initial state, the estimators' initial box and the inputs."""

    system: ivobs.NonlinearSystem | ivobs.LinearSystem
    x_true0: np.ndarray
    x0: ivobs.Box
    u: np.ndarray | None
    text: str


def _coef(value: float) -> str:
    """A 3-decimal coefficient no larger in magnitude than ``value`` (rounded towards 0)."""
    return f"{np.trunc(value * 1000) / 1000:.3f}"


def _row(rng: np.random.Generator, i: int, n: int, nu: int, w: float) -> str:
    a = float(rng.uniform(0.2, 0.6) * rng.choice([-1, 1]))
    picks = rng.choice(len(_TERMS), size=int(rng.integers(2, 4)), replace=False)
    terms = []
    for t in picks:
        tmpl, m, lip = _TERMS[int(t)]
        j, k = (int(v) for v in rng.integers(1, n + 1, 2))
        terms.append((tmpl.format(j=j, k=k), m, lip, float(rng.uniform(0.3, 1.0))))
    b = float(rng.uniform(0.05, 0.2)) if nu else 0.0
    extra = P2[1] if i == n - 1 else 0.0  # the p2*x1 term
    # scale the nonlinear coefficients: Jacobian row sum <= 0.9 and |f_i| <= 0.9 R on the box
    lip = sum(c * P1[1] * lp for _, _, lp, c in terms)
    mag = sum(c * P1[1] * m for _, m, _, c in terms)
    s = min((0.9 - abs(a) - extra) / lip, (0.9 * R - abs(a) * R - b - w - extra * R) / mag)
    parts = [f"{_coef(a)}*x{i + 1}"]
    for q, (txt, _, _, c) in enumerate(terms):
        sign = "-" if rng.integers(2) else "+"
        parts.append(f"{sign} {_coef(s * c)}*{'p1*' if q == 0 else ''}{txt}")
    if nu:
        parts.append(f"+ {_coef(b)}*u1")
    if extra:
        parts.append("+ p2*x1")
    return " ".join(parts) + f" + w{i + 1}"


def random_nonlinear(seed: int, T: int = 0) -> Case:
    """A random nonlinear system (see the module docstring) and ``T`` inputs in ``[-1, 1]``."""
    rng = np.random.default_rng(seed)
    n, ny, nu = int(rng.integers(2, 6)), int(rng.integers(1, 3)), int(rng.integers(0, 2))
    wbar = float(rng.choice([0.005, 0.01, 0.02]))
    f = [_row(rng, i, n, nu, wbar) for i in range(n)]
    h = []
    for j in range(ny):
        tmpl = _OUTPUTS[0 if j == 0 and rng.integers(2) else int(rng.integers(1, len(_OUTPUTS)))]
        a, b = (int(v) for v in rng.choice(np.arange(1, n + 1), 2, replace=False))
        h.append(tmpl.format(a=a, b=b) + f" + v{j + 1}")
    vbar = float(rng.choice([0.02, 0.05]))
    d = {f"w{i + 1}": (-wbar, wbar) for i in range(n)}
    d.update({f"v{j + 1}": (-vbar, vbar) for j in range(ny)})
    params = {"p1": P1, "p2": P2} if any("p2" in r for r in f) else {"p1": P1}
    sys = ivobs.NonlinearSystem(
        f=f,
        h=h,
        states=[f"x{i + 1}" for i in range(n)],
        inputs=["u1"] if nu else [],
        params=params,
        d=d,
    )
    u = rng.uniform(-1, 1, (T, 1)) if nu else None
    text = "f = " + "; ".join(f) + " | h = " + "; ".join(h)
    x_true0 = rng.uniform(-0.5, 0.5, n)
    return Case(sys, x_true0, ivobs.Box(-np.ones(n), np.ones(n)), u, text)


def random_interval_linear(seed: int, T: int = 0, cooperative: bool = False) -> Case:
    """A random linear system with interval ``A``, ``B``, ``C``, ``D`` (see the module
    docstring) and ``T`` inputs in ``[-1, 1]``; ``cooperative``: ``A0 >= 0`` (the ``interval``
    method needs a gain that makes ``A0 - L C0`` nonnegative, ``L = 0`` then)."""
    rng = np.random.default_rng(seed)
    n, ny = int(rng.integers(2, 6)), int(rng.integers(1, 3))
    A0 = rng.uniform(0 if cooperative else -1, 1, (n, n))
    RA = np.where(rng.random((n, n)) < 0.5, rng.uniform(0, 0.03, (n, n)), 0.0)
    A0 *= (0.8 - np.abs(RA).sum(axis=1).max()) / np.abs(A0).sum(axis=1).max()
    B0 = rng.uniform(-1, 1, (n, 1))
    C0 = rng.uniform(-1, 1, (ny, n))
    RC = np.where(rng.random((ny, n)) < 0.3, 0.02, 0.0)
    D0 = rng.uniform(-0.2, 0.2, (ny, 1))
    W = np.full(n, float(rng.choice([0.01, 0.02])))
    V = np.full(ny, float(rng.choice([0.02, 0.05])))
    base = ivobs.LinearSystem.from_process_measurement(A0, B0, C0, np.eye(n), np.eye(ny), W, V)
    sys = ivobs.LinearSystem(
        ivobs.Box(A0 - RA, A0 + RA),
        ivobs.Box(B0 - 0.02, B0 + 0.02),
        ivobs.Box(C0 - RC, C0 + RC),
        D=ivobs.Box(D0 - 0.01, D0 + 0.01),
        E=base.E,
        F=base.F,
        d=base.d,
    )
    u = rng.uniform(-1, 1, (T, 1))
    x_true0 = rng.uniform(-0.5, 0.5, n)
    text = f"n={n}, ny={ny}, |A0|+R_A row sums <= 0.8"
    return Case(sys, x_true0, ivobs.Box(-np.ones(n), np.ones(n)), u, text)
