"""The session's defaults of the methods' options, and the one place they are applied.

:mod:`ivobs.config` fills :data:`OVERRIDES` (``set_defaults``, ``using``); every estimator class
applies them when it is built: :meth:`Estimator.__init_subclass__
<ivobs.estimators.Estimator>` wraps the ``__init__`` of each subclass with
:func:`with_overrides`, so ``make_estimator``, a class called directly, the command line and
the campaigns all get them, and no method has code of its own for it. An option passed
explicitly always wins. This module imports nothing from the methods (the base class imports
it).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any

__all__ = ["OVERRIDES", "with_overrides"]

OVERRIDES: dict[str, dict[str, Any]] = {}
"""Method name -> {option: value} set for this process (:func:`ivobs.config.set_defaults`);
options not listed keep the default of the class's signature."""


def with_overrides(init: Callable[..., None]) -> Callable[..., None]:
    """``init`` (a class's ``__init__``) that first adds the session's defaults of the method
    being built for the options not passed. Only the outermost ``__init__`` of a construction
    adds them (the class's own or the one it inherits); the ones it calls through ``super()``
    receive them as arguments. The signature, annotations and docstring stay ``init``'s
    (``Estimator.options()`` and the API reference read them)."""

    @functools.wraps(init)
    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        cls = type(self)
        session = OVERRIDES.get(cls.name)
        if session and cls.__init__ is __init__:
            kwargs = {**session, **kwargs}
        init(self, *args, **kwargs)

    return __init__
