"""Sets that every method speaks: boxes, zonotopes and constrained zonotopes.

All three answer the same verbs, as CORA's ``@interval`` and ``@zonotope`` do: linear map
(``M @ S``), Minkowski sum (``S1 + S2``; a box or zonotope on either side, a vector translates),
``interval_hull()`` and ``contains``. Zonotopes and constrained zonotopes also ``reduce``; boxes
and constrained zonotopes ``intersect``; constrained zonotopes also ``intersect_strip``.

* :mod:`.box`: ``Box(lo, hi)`` ([Tang2019, Definition 1]), possibly time-varying, and the interval
  image :func:`image_bounds` of a box (``M⁺``, ``M⁻``: :func:`pos`, :func:`neg`).
* :mod:`.zonotope`: ``Zonotope(c, G) = <c, G>`` ([Tang2019, Definition 3]), order reduction
  ([Combastel2015]).
* :mod:`.czonotope`: ``ConstrainedZonotope(c, G, A, b)`` ([Scott2016]), its hull LPs certified by
  duality, constraint elimination and generator reduction on raw arrays (what the
  ``constrained-zonotope`` and ``strip`` estimators use).

SciPy is imported only where a linear program or a QR factorisation is computed.
"""

from __future__ import annotations

from .box import Box, image_bounds, neg, pos
from .czonotope import (
    EMPTY_TOL,
    Certificates,
    ConstrainedZonotope,
    certified_empty,
    consolidate_small,
    eliminate_constraints,
    hull_bounds,
    hull_certificates,
    independent_constraints,
    radius_certificate,
    reduce_generators,
)
from .rounding import mid_rad
from .zonotope import Zonotope, box_generators

__all__ = [
    "EMPTY_TOL",
    "Box",
    "Certificates",
    "ConstrainedZonotope",
    "Zonotope",
    "box_generators",
    "certified_empty",
    "consolidate_small",
    "eliminate_constraints",
    "hull_bounds",
    "hull_certificates",
    "image_bounds",
    "independent_constraints",
    "mid_rad",
    "neg",
    "pos",
    "radius_certificate",
    "reduce_generators",
]
