"""Tools to check guaranteed estimators, ivobs' own and yours.

* :mod:`.systems`: random observable systems and adversarial (vertex-disturbance) trajectories.
* :mod:`.exact`: exact trajectories of a linear model (integers over a power of two), so that a
  soundness check relies on no rounding margin.
* :func:`check_estimator` (:mod:`.conformance`): the checks every registered method passes —
  containment at every step under vertex disturbances on the exact trajectory (``run``,
  ``step`` and ``step`` with state round trips), missing samples, no admissible sample flagged
  inconsistent, bad input refused; run it on a method of your own.
"""

from __future__ import annotations

from .conformance import check_estimator, conformance_plants
from .exact import ExactLinear, ExactStates, exact_misses, exact_run
from .systems import adversarial_run, assert_contains, random_system

__all__ = [
    "ExactLinear",
    "ExactStates",
    "adversarial_run",
    "assert_contains",
    "check_estimator",
    "conformance_plants",
    "exact_misses",
    "exact_run",
    "random_system",
]
