"""Exceptions raised by ivobs.

Every rejected input raises a subclass of :class:`IvobsError` (itself a ``ValueError``) whose
message names the argument, what was expected, what was received, and what to do about it.
"""

from __future__ import annotations


class IvobsError(ValueError):
    """Bad input to ivobs: the message names the argument, the expectation and what came."""


class DesignError(IvobsError):
    """An offline design could not be met (infeasible LMI, no nonnegative ``A - LC``, ...).

    The message says which condition failed and, where there is one, what to try instead.
    """


class DesignWarning(UserWarning):
    """A design succeeded other than asked or expected: the default gain fell back to another
    design (``design.fallback`` says why), or an option will make the estimate needlessly wide
    (e.g. a zonotope order too low for a slowly contracting observer). The message names what
    was used and what to pass instead."""


class DivergenceError(IvobsError):
    """The model could not be evaluated over the current box: a validated flow found no a
    priori enclosure (the solution may escape within the period, or the box grew too wide for
    the sampling period). ``run()`` stops there and returns the steps before it."""


class InconsistentDataError(IvobsError):
    """Measurements that no state, disturbance and initial condition of the model can explain.

    Under the model's assumptions this is a fault (sensor, actuator or model), never a reason to
    return an empty or inverted box. ``step`` is the first step at which it was detected.
    """

    def __init__(self, message: str, step: int | None = None):
        super().__init__(message)
        self.step = step
