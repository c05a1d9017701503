"""Constrained zonotopes ([Scott2016]).

A constrained zonotope is

    Z = <c, G, A, b> = {c + G ξ : ‖ξ‖∞ <= 1, A ξ = b}          ([Scott2016, Definition 3])

with center ``c`` (n,), generators ``G`` (n, m), constraints ``A`` (nc, m), ``b`` (nc,). Every
convex polytope is one ([Scott2016, Theorem 1]), and unlike zonotopes they are closed under
intersection, so a set-membership filter that works with them is exact: the linear map, the
Minkowski sum and the (generalised) intersection are all exact and cheap ([Scott2016,
Proposition 1]):

* ``M Z = <M c, M G, A, b>``
* ``Z ⊕ W = <c_z + c_w, [G_z G_w], blkdiag(A_z, A_w), [b_z; b_w]>``
* ``Z ∩_R Y = <c_z, [G_z 0], [[A_z, 0], [0, A_y], [R G_z, -G_y]], [b_z; b_y; c_y - R c_z]>``

What is not cheap is asking a question of the set: its interval hull, emptiness and membership
are linear programs (:mod:`.hull`, HiGHS through :class:`ivobs.sets.lp.LinearProgram`), each
bound certified by weak duality at the solver's multipliers, so it holds whatever the solver's
tolerances.

The complexity (``m`` generators, ``nc`` constraints) grows with every Minkowski sum and
intersection; :meth:`ConstrainedZonotope.reduce` bounds it ([Scott2016, Section 4]): constraint
elimination after rescaling (:mod:`.elimination`, Section 4.2), then generator reduction of the
lifted zonotope (:mod:`.reduction`, Section 4.3). Both return a superset, their rounding
included. The array-level functions (:func:`eliminate_constraints`, :func:`reduce_generators`,
:func:`hull_certificates`) are what the estimators use; :class:`Certificates` lets the
elimination keep the LP bounds the estimator reports as tight as possible.

Modules: :mod:`.constrained` (the set and its operations), :mod:`.hull` (the LPs and their
certificates), :mod:`.elimination` and :mod:`.reduction` (the two reductions, on raw arrays),
:mod:`.tolerances`. ``UNIT_ROUNDOFF``, ``gamma`` and ``mid_rad`` (:mod:`ivobs.sets.rounding`),
``box_generators`` (:mod:`ivobs.sets.zonotope`) are re-exported for the estimators.
"""

from __future__ import annotations

from ..rounding import UNIT_ROUNDOFF, gamma, mid_rad
from ..zonotope import box_generators
from .constrained import ConstrainedZonotope
from .elimination import Reduced, eliminate_constraints, independent_constraints
from .hull import (
    Certificates,
    certified_empty,
    dual_bounds,
    hull_bounds,
    hull_certificates,
    radius_certificate,
    soften,
)
from .reduction import consolidate_small, reduce_consolidated, reduce_generators
from .tolerances import EMPTY_TOL, PIVOT_TOL, ROW_TOL, ZERO_TOL

__all__ = [
    "EMPTY_TOL",
    "PIVOT_TOL",
    "ROW_TOL",
    "UNIT_ROUNDOFF",
    "ZERO_TOL",
    "Certificates",
    "ConstrainedZonotope",
    "Reduced",
    "box_generators",
    "certified_empty",
    "consolidate_small",
    "dual_bounds",
    "eliminate_constraints",
    "gamma",
    "hull_bounds",
    "hull_certificates",
    "independent_constraints",
    "mid_rad",
    "radius_certificate",
    "reduce_consolidated",
    "reduce_generators",
    "soften",
]
