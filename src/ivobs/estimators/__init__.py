"""Estimators: one module per method family, all following :class:`Estimator`.

The built-in methods are listed in :data:`METHODS` (name -> module, class, position), so that
``import ivobs`` imports none of them: a method's module (and the solvers it needs) is imported
the first time the method is asked for (:func:`get`, :func:`make_estimator`). Modules register
their classes with :func:`register`; a method defined outside ivobs registers itself the same
way. tests/test_registry.py checks :data:`METHODS` against the classes, so adding a built-in
method means adding its module and its line in :data:`METHODS`.
"""

from __future__ import annotations

import importlib
from typing import Any, NamedTuple

from ..errors import IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..model.statespace import is_statespace
from . import base
from ._inputs import check_option_types
from .base import Design, Estimator

__all__ = [
    "METHODS",
    "Design",
    "Entry",
    "Estimator",
    "checked_options",
    "get",
    "make_estimator",
    "methods",
    "register",
]


class Entry(NamedTuple):
    """Where a built-in method lives: its module (relative to this package), its class and its
    ``order`` (the class's position in :func:`methods`)."""

    module: str
    cls: str
    order: int


METHODS: dict[str, Entry] = {
    "fixed-time": Entry("fixed_time.estimator", "FixedTimeEstimator", 10),
    "reachability": Entry("reachability", "Reachability", 20),
    "zonotope": Entry("zonotope", "ZonotopeEstimator", 30),
    "interval": Entry("interval.observers", "IntervalObserver", 40),
    "interval-transformed": Entry("interval.observers", "TransformedIntervalObserver", 50),
    "interval-split": Entry("interval.observers", "SplitIntervalObserver", 60),
    "kkl": Entry("kkl.estimator", "KKL", 70),
    "strip": Entry("strip.estimator", "StripEstimator", 80),
    "ellipsoid": Entry("ellipsoid", "EllipsoidEstimator", 85),
    "constrained-zonotope": Entry("constrained_zonotope", "ConstrainedZonotopeEstimator", 90),
    "exact": Entry("exact.estimator", "Exact", 100),
    "dual-window": Entry("dual_window.estimator", "DualWindow", 105),
    "intersect": Entry("intersect", "Intersect", 110),
    "nl-interval": Entry("nonlinear.interval", "NonlinearIntervalEstimator", 900),
    "nl-zonotope": Entry("nonlinear.zonotope", "NonlinearZonotopeEstimator", 910),
    "nl-constrained-zonotope": Entry(
        "nonlinear.czonotope", "NonlinearConstrainedZonotopeEstimator", 920
    ),
    "nl-horizon": Entry("nonlinear.horizon", "NonlinearHorizonEstimator", 930),
}
"""The built-in methods, imported on first use (see the module docstring)."""

_REGISTRY: dict[str, type[Estimator]] = {}
"""The classes registered so far (built-in methods whose module was imported, and methods
registered from outside)."""


def register(cls: type[Estimator]) -> type[Estimator]:
    """Class decorator: make ``cls`` available to :func:`make_estimator` under ``cls.name``."""
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name")
    _REGISTRY[cls.name] = cls
    return cls


def methods() -> list[str]:
    """Names of the available methods, in the order their classes declare (``order``: the
    papers' order), then by name."""
    order = {
        **{n: e.order for n, e in METHODS.items()},
        **{n: c.order for n, c in _REGISTRY.items()},
    }
    return sorted(order, key=lambda name: (order[name], name))


def get(name: str) -> type[Estimator]:
    """The estimator class registered as ``name`` (its module is imported here the first
    time)."""
    if not isinstance(name, str):
        raise IvobsError(f"method: expected a method name (str), got {name!r}")
    key = name.strip().lower().replace("_", "-")
    if key not in _REGISTRY and key in METHODS:
        importlib.import_module(f"{__name__}.{METHODS[key].module}")
    if key not in _REGISTRY:
        raise IvobsError(
            f"method: unknown method {name!r}; known methods: {', '.join(methods()) or '(none)'}"
        )
    return _REGISTRY[key]


def make_estimator(
    name: str, sys: LinearSystem | NonlinearSystem, x0: Any = None, **options: Any
) -> Estimator:
    """Build the estimator ``name`` for ``sys`` (design happens here, once).

    ``x0`` is the prior box on ``x[0]`` (methods that need it); ``options`` are the method's
    design options (an explicit gain ``L``, a transformation, ``s``, ...): see each method's
    docstring, or ``ivobs.estimators.get(name).options()``. ``sys`` may be a python-control
    ``StateSpace`` (all its inputs known; for disturbance inputs use
    :meth:`LinearSystem.from_statespace` with ``disturbances=`` and ``d=``).
    """
    cls = get(name)
    if is_statespace(sys):  # every input of a StateSpace is then a known input u
        sys = LinearSystem.from_statespace(sys)
    return cls(sys, x0, **checked_options(cls, options))


def checked_options(cls: type[Estimator], options: dict[str, Any]) -> dict[str, Any]:
    """``options`` of ``cls``: every name one of its options (an error listing the accepted
    ones otherwise), one-value options not arrays (NumPy scalars as Python ones); the values
    themselves are the method's to check when it is built."""
    allowed = cls.options()
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise IvobsError(
            f"options: {cls.name} does not accept {', '.join(map(repr, unknown))}; "
            f"accepted options: {', '.join(allowed) or '(none)'}"
        )
    return check_option_types(cls, options)


def _methods_with(flag: str) -> list[str]:
    """Names of the methods whose class flag is true (imports every built-in method: used for
    error messages only)."""
    return [name for name in methods() if getattr(get(name), flag)]


base.methods_with = _methods_with
