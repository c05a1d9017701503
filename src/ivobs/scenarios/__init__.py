"""The papers' example systems, ready to run: ``ivobs.scenarios.get(name)``.

The registry (:class:`Scenario`, :func:`register_scenario`, :func:`get`, :func:`names`) lives in
:mod:`ivobs.scenarios.registry`; one module per source registers its examples there:

- :mod:`~ivobs.scenarios.wang2020`: ``dinh2019`` ([Wang2020, Section 4], [Dinh2019]);
- :mod:`~ivobs.scenarios.tang2019`: ``servo-motor``, ``tang-example2`` ([Tang2019, Section VII]);
- :mod:`~ivobs.scenarios.efimov2013`: ``efimov-planar``, ``henon`` ([Efimov2013, Section IV]);
- :mod:`~ivobs.scenarios.dinh2024`: ``kkl-random8``, ``pendulum``, ``kkl-ltv-dt`` ([Dinh2024]);
- :mod:`~ivobs.scenarios.heat`: ``heat-1d`` (large sparse systems, not from a paper);
- :mod:`~ivobs.scenarios.cora`: the CORA benchmarks ``cora-*`` ([Althoff2021]);
- :mod:`~ivobs.scenarios.quadtank`: ``quadruple-tank`` ([Johansson2000]);
- :mod:`~ivobs.scenarios.uncertain`: ``servo-uncertain`` (interval matrices, docs/uncertain.md);
- :mod:`~ivobs.scenarios.nonlinear`: ``henon-nl``, ``pendulum-nl``, ``cora-tank6-nl``, ``cstr``,
  ``unicycle-range``, ``range-only``, ``chain10-nl`` (NonlinearSystem, docs/nonlinear.md).

They are imported below in that order, which is the order of :func:`names`.
"""

from __future__ import annotations

from . import registry
from .registry import _BUILDERS as _BUILDERS  # the registry's table itself (tests unregister)
from .registry import (
    DISTURBANCES,
    Scenario,
    get,
    names,
    options,
    register_scenario,
    summaries,
)

# The import order is the registration order, hence that of names(): not sorted.
# isort: off
from . import wang2020, tang2019, efimov2013, dinh2024, heat, cora, quadtank, uncertain, nonlinear
# isort: on

from .dinh2024 import kkl_ltv_A, pendulum_A
from .efimov2013 import henon_bounds
from .heat import heat_gain

# System files name these functions as ``"ivobs.scenarios:<name>"`` (``ivobs.io.callable_ref``
# writes the defining module): keep that path, stable across where the code lives.
for _fn in (henon_bounds, pendulum_A, kkl_ltv_A):
    _fn.__module__ = __name__
del _fn

__all__ = [
    "DISTURBANCES",
    "Scenario",
    "cora",
    "dinh2024",
    "efimov2013",
    "get",
    "heat",
    "heat_gain",
    "henon_bounds",
    "kkl_ltv_A",
    "names",
    "nonlinear",
    "options",
    "pendulum_A",
    "quadtank",
    "register_scenario",
    "registry",
    "summaries",
    "tang2019",
    "uncertain",
    "wang2020",
]
