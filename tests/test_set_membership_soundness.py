"""Containment of the LP-based set-membership methods (``constrained-zonotope``, ``exact``,
``dual-window``) at every step, rounding included, under disturbances on the vertices of their
bounds.

The records come from tests/exactsim.py (every state and measurement an exact value of the
model with admissible disturbances, computed in 60-digit interval arithmetic), so the check
relies on no margin: these methods bound every floating-point error of their recursion
(``proven_rounding``). The plants are the servo motor, a random stable 4-state system and the
same system scaled to states near 1e7 and 1e-7 (the rounding bounds must hold at every
magnitude), with a sample missing now and then. No admissible sample may be reported
inconsistent. The 10⁴-step runs are ``benchmarks/bench_lp_soundness.py``.
"""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

import ivobs
from exactsim import Record, simulate_linear

OPTIONS = {
    "constrained-zonotope": {},
    "constrained-zonotope-hausdorff": {"elimination": "hausdorff"},
    "exact-window": {"window": 15, "progress": False},
    "dual-window": {},
}


def _method(key: str) -> str:
    return "exact" if key.startswith("exact") else key.replace("-hausdorff", "")


def random_plant(seed: int, scale: float = 1.0) -> tuple[ivobs.LinearSystem, np.ndarray, ivobs.Box]:
    """A stable 4-state, 2-output system whose every state and output has a disturbance of its
    own (as exactsim needs), with states of size ``scale``; its true ``x[0]`` and prior box."""
    rng = np.random.default_rng(seed)
    A = rng.normal(size=(4, 4))
    A *= 0.9 / max(abs(np.linalg.eigvals(A)))
    B = rng.normal(size=(4, 1)) * scale
    C = rng.normal(size=(2, 4))
    D = rng.normal(size=(2, 1)) * scale
    E = np.hstack([np.eye(4), rng.normal(size=(4, 1)) * 0.5, np.zeros((4, 2))])
    F = np.hstack([np.zeros((2, 5)), np.eye(2)])
    r = rng.uniform(0.05, 0.3, 7) * scale
    c = rng.uniform(-0.3, 0.3, 7) * r
    sys = ivobs.LinearSystem(A, B, C, D=D, E=E, F=F, d=ivobs.Box(c - r, c + r))
    x_true = rng.uniform(-1.0, 1.0, 4) * scale
    return sys, x_true, ivobs.Box(x_true - scale, x_true + scale)


@cache
def record(plant: str, T: int) -> tuple[ivobs.LinearSystem, ivobs.Box, np.ndarray, Record]:
    if plant == "servo":
        sc = ivobs.scenarios.get("servo-motor", horizon=T)
        u = sc.simulate("vertex", seed=0).u
        sys, x0 = sc.system, sc.x0
        x_true = 0.5 * (x0.lo + x0.hi) + 0.1
    else:
        scale = {"random": 1.0, "large": 1e7, "small": 1e-7}[plant]
        sys, x_true, x0 = random_plant(3, scale)
        u = np.sin(0.1 * np.arange(T))[:, None]
    rec = simulate_linear(sys, x_true, T, u, seed=11)
    return sys, x0, u, rec


def _run(key: str, plant: str, T: int, missing: bool = False) -> tuple[np.ndarray, ivobs.Estimate]:
    sys, x0, u, rec = record(plant, T)
    y = rec.Y.copy()
    if missing:  # one component every 7 steps, everything at two steps
        y[::7, 0] = np.nan
        y[[40, 41]] = np.nan
    est = ivobs.make_estimator(_method(key), sys, x0=x0, **OPTIONS[key])
    res = est.run(u, y)
    return rec.misses(res.lower, res.upper), res


@pytest.mark.parametrize("key", list(OPTIONS))
@pytest.mark.parametrize("plant", ["servo", "random"])
def test_contains_the_exact_state_at_every_step(key: str, plant: str) -> None:
    misses, res = _run(key, plant, 150)
    assert misses.tolist() == []
    assert not res.inconsistent.any()  # the data are the model's: never a fault


@pytest.mark.parametrize("key", ["constrained-zonotope", "exact-window", "dual-window"])
@pytest.mark.parametrize("plant", ["large", "small"])
def test_contains_the_exact_state_at_every_magnitude(key: str, plant: str) -> None:
    misses, res = _run(key, plant, 100)
    assert misses.tolist() == []
    assert not res.inconsistent.any()
    # and the rounding bounds do not swamp the boxes: the same widths relative to the scale
    scale = 1e7 if plant == "large" else 1e-7
    _, ref = _run(key, "random", 100)
    rel = (res.upper - res.lower)[20:].mean() / scale / (ref.upper - ref.lower)[20:].mean()
    assert 0.95 < rel < 1.05  # (tolerances such as 1 + |c| are not scale-free)


@pytest.mark.parametrize("key", ["constrained-zonotope", "exact-window", "dual-window"])
def test_missing_samples_keep_containment(key: str) -> None:
    misses, res = _run(key, "random", 150, missing=True)
    assert misses.tolist() == []
    assert not res.inconsistent.any()


def test_without_reduction_it_contains_the_exact_state() -> None:
    sys, x0, u, rec = record("random", 150)
    res = ivobs.make_estimator("constrained-zonotope", sys, x0=x0, reduce=False).run(
        u[:25], rec.Y[:25]
    )
    lo, hi = rec.X_lo[:25], rec.X_hi[:25]
    assert Record(lo, hi, rec.Y, None).misses(res.lower, res.upper).tolist() == []


@pytest.mark.parametrize("key", ["constrained-zonotope", "exact-window", "dual-window"])
def test_a_gross_fault_is_reported_and_the_state_kept(key: str) -> None:
    """A sample far outside what the model can produce is a fault: reported, not used."""
    sys, x0, u, rec = record("random", 150)
    y = rec.Y[:60].copy()
    y[30, 1] += 50.0
    res = ivobs.make_estimator(_method(key), sys, x0=x0, **OPTIONS[key]).run(u[:60], y)
    assert res.inconsistent[30] and res.inconsistent.sum() == 1
    lo, hi = rec.X_lo[:60], rec.X_hi[:60]
    assert Record(lo, hi, y, None).misses(res.lower, res.upper).tolist() == []
