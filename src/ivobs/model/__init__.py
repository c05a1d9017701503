"""Models: :class:`LinearSystem` and the protocols estimators depend on.

* :mod:`.linear`: :class:`LinearSystem` (``x+ = A x + B u + E d``, ``y = C x + D u + F d``),
  constant, time-varying (stacked or callable matrices) or sparse; discrete or continuous time.
* :mod:`.protocol`: :class:`SystemModel` (dimensions, time base, disturbance bounds: what every
  model answers) and :class:`LinearModel` (its matrices at each step), the members an estimator
  may use, so that a nonlinear model sits beside :class:`LinearSystem`.
* :mod:`.nonlinear`: :class:`NonlinearSystem` (``x+ = f(x, u, p, d)``, ``y = h(x, u, p, d)``,
  expressions or traced callables) and its generated guaranteed interval functions.
"""

from __future__ import annotations

from .linear import LinearSystem
from .nonlinear import NonlinearSystem
from .protocol import BoundsLike, LinearModel, SystemModel

__all__ = ["BoundsLike", "LinearModel", "LinearSystem", "NonlinearSystem", "SystemModel"]
