"""Tolerances of the constrained-zonotope operations ([Scott2016]). None of them is needed for
soundness (every rounding is bounded where it occurs); each says when a number is treated as
noise, relative to the largest coefficient it is compared with, so scaling a set does not change
what it means."""

from __future__ import annotations

__all__ = ["EMPTY_TOL", "PIVOT_TOL", "ROW_TOL", "ZERO_TOL"]

EMPTY_TOL = 1e-7
"""A constrained zonotope counts as empty (a measurement as inconsistent) only when even the
factor box ``‖ξ‖∞ <= 1 + EMPTY_TOL`` misses its constraints, certainly: a set that is empty by
less is treated as thin (its hull is that of the slightly larger set)."""

ZERO_TOL = 1e-13
"""A normalised constraint coefficient below this gives no bound on its factor when
propagating (dividing by it would)."""

ROW_TOL = 1e-9
"""A constraint whose coefficients are all below this (relative) is dropped (a superset): after
cancellation or rescaling it carries rounding noise, which row normalisation would amplify."""

PIVOT_TOL = 1e-6
"""Smallest pivot of an elimination (constraints normalised to a largest coefficient near 1):
solving a constraint for a factor with a smaller coefficient would amplify rounding."""
