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
are linear programs (solved with HiGHS). Each bound is certified by
LP duality: for any multiplier ``μ``, ``min {gᵀξ : Aξ = b, |ξ| <= 1} >= μᵀb - ‖g - Aᵀμ‖₁``; the
returned bound is this expression at HiGHS' multipliers, so it is a valid bound whatever the
solver's tolerances (it equals the optimum when ``μ`` is optimal).

The complexity (``m`` generators, ``nc`` constraints) grows with every Minkowski sum and
intersection; :meth:`ConstrainedZonotope.reduce` bounds it ([Scott2016, Section 4]): constraint
elimination after rescaling (Section 4.2), then generator reduction of the lifted zonotope
(Section 4.3). Both return a superset. The array-level functions (:func:`eliminate_constraints`,
:func:`reduce_generators`, :func:`hull_certificates`) are what the ``constrained-zonotope``
estimator uses; :class:`Certificates` lets the elimination keep the LP bounds the estimator
reports as tight as possible (see its docstring).

Rounding. Constraints are normalised (largest coefficient 1); constraints made of rounding noise
(all coefficients below :data:`ROW_TOL` after cancellation or rescaling) and linearly dependent
constraints are dropped (a superset); propagated factor bounds are widened by ``1e-10``
(relative); a set counts as empty only beyond :data:`EMPTY_TOL`.

Modules: :mod:`.constrained` (the set and its exact operations), :mod:`.hull` (the LPs and their
certificates), :mod:`.elimination` and :mod:`.reduction` (the two reductions, on raw arrays).
``UNIT_ROUNDOFF``, ``gamma`` (:mod:`ivobs.linalg`) and ``mid_rad``, ``box_generators``
(:mod:`ivobs.sets.zonotope`) are re-exported here for the estimators' rounding terms.
"""

from __future__ import annotations

from ...linalg import UNIT_ROUNDOFF, gamma
from ..rounding import mid_rad
from ..zonotope import box_generators
from ._tolerances import EMPTY_TOL, PIVOT_TOL, ROW_TOL, ZERO_TOL
from .constrained import ConstrainedZonotope
from .elimination import eliminate_constraints, independent_constraints
from .hull import (
    Certificates,
    certified_empty,
    hull_bounds,
    hull_certificates,
    radius_certificate,
)
from .reduction import consolidate_small, reduce_consolidated, reduce_generators

__all__ = [
    "EMPTY_TOL",
    "PIVOT_TOL",
    "ROW_TOL",
    "UNIT_ROUNDOFF",
    "ZERO_TOL",
    "Certificates",
    "ConstrainedZonotope",
    "box_generators",
    "certified_empty",
    "consolidate_small",
    "eliminate_constraints",
    "gamma",
    "hull_bounds",
    "hull_certificates",
    "independent_constraints",
    "mid_rad",
    "radius_certificate",
    "reduce_consolidated",
    "reduce_generators",
]
