"""Data rounded to doubles are never a fault (issue of the monitor's false alarm at step 0).

One state on the corner of its prior box, the noise on its bound: ``y = -0.1 + -0.005`` is the
double ``-0.10500000000000001``, about 4e-18 beyond the exact set's end ``-0.105``. The recorded
double stands for the real number it rounds, so no method may flag it, and no monitor may raise
an alarm on a fault-free record.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import ivobs
from ivobs.monitor import Monitor

X0 = ivobs.Box([-0.1], [0.1])


def linear() -> ivobs.LinearSystem:
    """``x+ = 0.5 x + w``, ``y = x + v``, ``|w| <= 0.01``, ``|v| <= 0.005``."""
    return ivobs.LinearSystem(
        [[0.5]], None, [[1.0]], E=[[1.0, 0.0]], F=[[0.0, 1.0]],
        d=ivobs.Box([-0.01, -0.005], [0.01, 0.005]),
    )  # fmt: skip


def nonlinear() -> ivobs.NonlinearSystem:
    return ivobs.NonlinearSystem(
        states=["x"], f=["0.5*x + w"], h=["x + v"], d={"w": (-0.01, 0.01), "v": (-0.005, 0.005)}
    )


def record() -> tuple[np.ndarray, np.ndarray]:
    """States on the corners and the noise on its bounds: every sum rounded to a double."""
    x = [-0.1, 0.5 * -0.1 + -0.01]
    x.append(0.5 * x[1] + -0.01)
    y = [[v + -0.005] for v in x]
    assert y[0][0] == -0.10500000000000001  # 4e-18 beyond the exact -0.105
    return np.array(x)[:, None], np.array(y)


@pytest.mark.parametrize("method", ivobs.methods())
def test_a_sample_within_rounding_of_its_bound_is_consistent(method: str) -> None:
    xs, ys = record()
    models = [linear()] + ([nonlinear()] if method.startswith("nl-") else [])
    for sys in models:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # an inconsistency report is a warning
            res = ivobs.make_estimator(method, sys, x0=X0).run(y=ys)
        assert not np.any(res.inconsistent), (method, type(sys).__name__)
        # the true states are the doubles above, within rounding of the exact corner states
        valid = np.all(np.isfinite(res.lower), axis=1)
        assert valid[-1] and np.all(res.contains(xs, tol=1e-17)[valid])


@pytest.mark.parametrize("method", ["reachability", "constrained-zonotope", "nl-interval"])
def test_the_monitor_raises_no_alarm_on_rounded_data(method: str) -> None:
    _, ys = record()
    out = Monitor(linear(), method, x0=X0).run(y=ys)
    assert not np.any(out.alarm)
