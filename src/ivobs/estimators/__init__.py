"""Estimators: one module per method family, all following :class:`Estimator`.

Modules in this package register their classes with :func:`register`; every public module is
imported here, so adding a method means adding a module, nothing else.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Any

from ..errors import IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..model.statespace import is_statespace
from .base import ROUNDING, Design, Estimator, nonlinear_refusal

__all__ = ["ROUNDING", "Design", "Estimator", "get", "make_estimator", "methods", "register"]

_REGISTRY: dict[str, type[Estimator]] = {}


def register(cls: type[Estimator]) -> type[Estimator]:
    """Class decorator: make ``cls`` available to :func:`make_estimator` under ``cls.name``."""
    if not cls.name:
        raise TypeError(f"{cls.__name__} has no name")
    _REGISTRY[cls.name] = cls
    return cls


def _normalise(name: Any) -> str:
    if not isinstance(name, str):
        raise IvobsError(f"method: expected a method name (str), got {name!r}")
    return name.strip().lower().replace("_", "-")


def methods() -> list[str]:
    """Names of the available methods, in the order their classes declare (``order``: the
    papers' order), then by name."""
    return sorted(_REGISTRY, key=lambda name: (_REGISTRY[name].order, name))


def get(name: str) -> type[Estimator]:
    """The estimator class registered as ``name``."""
    key = _normalise(name)
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
    if isinstance(sys, NonlinearSystem) and not cls.supports_nonlinear:
        raise IvobsError(nonlinear_refusal(cls.name))
    allowed = cls.options()
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        raise IvobsError(
            f"options: {cls.name} does not accept {', '.join(map(repr, unknown))}; "
            f"accepted options: {', '.join(allowed) or '(none)'}"
        )
    return cls(sys, x0, **options)


def _import_all() -> None:
    for mod in pkgutil.iter_modules(__path__):
        if not mod.name.startswith("_") and mod.name != "base":
            importlib.import_module(f"{__name__}.{mod.name}")


_import_all()
