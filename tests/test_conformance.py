"""Every registered method passes the public conformance checks (ivobs.testing.check_estimator):
containment of the exact state through run(), step() and state round trips, on stable,
unstable, badly scaled and asymmetric plants; missing samples; no admissible sample flagged
inconsistent; bad input refused; metadata."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import ivobs
from ivobs.testing import check_estimator


@pytest.mark.parametrize("method", ivobs.methods())
def test_every_method_passes_the_conformance_checks(method):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        report = check_estimator(method, steps=80)
    assert report.checked and report.steps >= 80 * 3


def test_a_method_that_misses_is_caught():
    """The kit fails a method whose boxes are too narrow (it cannot pass everything)."""
    from ivobs.estimators import get

    class Narrow(get("interval-split")):  # type: ignore[misc, valid-type]
        name = "narrow-test"

        def _step(self, state, u_k, y_k, t_k):
            step = super()._step(state, u_k, y_k, t_k)
            mid = (np.asarray(step.lo) + np.asarray(step.hi)) / 2
            return step._replace(lo=mid, hi=mid)

    with pytest.raises(AssertionError, match="narrow-test .* miss"):
        check_estimator(Narrow, steps=40)
