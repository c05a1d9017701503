"""Tightness, long runs, saved states and options of the LP-based methods
(``constrained-zonotope``, ``exact``, ``dual-window``).

* Ratio of the mean width to the full-horizon ``exact`` hull over 300 steps (vertex
  disturbances) on the servo motor and on a random 4-state system: ``constrained-zonotope``
  within 1 % (measured 1.0001 and 1.0008), ``dual-window`` (a 20-step window) within 60 %
  (measured 1.20 and 1.43).
* Every accepted option keeps the widths bounded over long runs.
* ``state()`` through JSON and ``restore()`` continue identically, at states near 1e7 too.
* Bad options are refused with a message naming the option.
"""

from __future__ import annotations

import json
from functools import cache

import numpy as np
import pytest

import ivobs
from ivobs.testing import adversarial_run
from test_set_membership_soundness import random_plant


@cache
def servo(T: int) -> tuple[ivobs.LinearSystem, ivobs.Box, ivobs.Trajectory]:
    sc = ivobs.scenarios.get("servo-motor", horizon=T)
    return sc.system, sc.x0, sc.simulate("vertex", seed=0)


@cache
def plant(T: int, scale: float = 1.0) -> tuple[ivobs.LinearSystem, ivobs.Box, ivobs.Trajectory]:
    sys, _, x0 = random_plant(3, scale)
    return sys, x0, adversarial_run(sys, x0, T, seed=4)


def _case(name: str, T: int) -> tuple[ivobs.LinearSystem, ivobs.Box, ivobs.Trajectory]:
    return servo(T) if name == "servo" else plant(T)


@cache
def mean_width(name: str, method: str, T: int, **options: object) -> float:
    sys, x0, tr = _case(name, T)
    res = ivobs.make_estimator(method, sys, x0=x0, **options).run(tr.u, tr.y)
    assert res.contains(tr.x).all()
    return float((res.upper - res.lower)[10:].mean())


@pytest.mark.slow
@pytest.mark.parametrize("name", ["servo", "random"])
def test_ratio_to_the_exact_hull_over_300_steps(name: str) -> None:
    exact = mean_width(name, "exact", 300, progress=False)
    cz = mean_width(name, "constrained-zonotope", 300) / exact
    dw = mean_width(name, "dual-window", 300) / exact
    assert 1.0 - 1e-6 <= cz <= 1.01, cz  # measured: servo 1.0001, random 1.0008
    assert 1.0 - 1e-6 <= dw <= 1.6, dw  # the 20-step window forgets: servo 1.20, random 1.43


OPTIONS = [
    ("constrained-zonotope", {"max_constraints": 1, "max_generators": 1}),
    ("constrained-zonotope", {"max_constraints": 2, "max_generators": 4}),
    ("constrained-zonotope", {"max_constraints": 6, "max_generators": 8}),
    ("constrained-zonotope", {"elimination": "hausdorff"}),
    ("exact", {"window": 1, "progress": False}),
    ("exact", {"window": 6, "progress": False}),
    ("dual-window", {"window": 1, "cache": 1, "refresh": 1}),
    ("dual-window", {"window": 40, "cache": 2, "refresh": 500, "refresh_tol": None}),
]


@pytest.mark.slow
@pytest.mark.parametrize(("method", "options"), OPTIONS)
def test_every_accepted_option_keeps_the_widths_bounded(method: str, options: dict) -> None:
    sys, x0, tr = servo(1200)
    res = ivobs.make_estimator(method, sys, x0=x0, **options).run(tr.u, tr.y)
    assert res.contains(tr.x).all()
    w = (res.upper - res.lower).mean(axis=1)
    assert np.isfinite(w).all()
    assert w[800:].max() <= 1.5 * w[200:400].max()  # no drift
    assert w[800:].mean() <= 10.0 * mean_width("servo", "exact", 300, progress=False)


@pytest.mark.parametrize("scale", [1.0, 1e7])
@pytest.mark.parametrize(
    "method", ["constrained-zonotope", "exact", "dual-window", "nl-constrained-zonotope"]
)
def test_state_round_trip_through_json_continues_identically(method: str, scale: float) -> None:
    sys, x0, tr = plant(40, scale)
    options = {"window": 8, "progress": False} if method == "exact" else {}
    whole = ivobs.make_estimator(method, sys, x0=x0, **options)
    ref = [whole.step(tr.u[k], tr.y[k]) for k in range(40)]
    first = ivobs.make_estimator(method, sys, x0=x0, **options)
    for k in range(25):
        first.step(tr.u[k], tr.y[k])
    saved = json.loads(json.dumps(first.state()))
    again = ivobs.make_estimator(method, sys, x0=x0, **options)
    again.restore(saved)
    for k in range(25, 40):
        box = again.step(tr.u[k], tr.y[k])
        np.testing.assert_array_equal(box.lo, ref[k].lo)
        np.testing.assert_array_equal(box.hi, ref[k].hi)


BAD = [
    ("constrained-zonotope", {"max_constraints": 0}, "max_constraints"),
    ("constrained-zonotope", {"max_generators": 0}, "max_generators"),
    ("constrained-zonotope", {"reduce": "yes"}, "reduce"),
    ("constrained-zonotope", {"elimination": "random"}, "elimination"),
    ("exact", {"window": 0}, "window"),
    ("exact", {"progress": "yes"}, "progress"),
    ("dual-window", {"window": 0}, "window"),
    ("dual-window", {"cache": 0}, "cache"),
    ("dual-window", {"refresh": 0}, "refresh"),
    ("nl-constrained-zonotope", {"max_generators": 0}, "max_generators"),
    ("nl-constrained-zonotope", {"hull_lp": "block"}, "hull_lp"),
]


@pytest.mark.parametrize(("method", "options", "name"), BAD)
def test_bad_options_are_refused_by_name(method: str, options: dict, name: str) -> None:
    sys, x0, _ = servo(10)
    with pytest.raises(ivobs.IvobsError, match=name):
        ivobs.make_estimator(method, sys, x0=x0, **options)
