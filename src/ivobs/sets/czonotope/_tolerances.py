"""Tolerances of the constrained-zonotope operations ([Scott2016]); each is relative to the
largest coefficient it is compared with, so scaling a set does not change what it means."""

from __future__ import annotations

__all__ = ["EMPTY_TOL", "PIVOT_TOL", "ROW_TOL", "ZERO_TOL"]

EMPTY_TOL = 1e-7
"""A constrained zonotope counts as empty when its constraints need ``‖ξ‖∞ > 1 + EMPTY_TOL``."""

ZERO_TOL = 1e-13  # relative size below which a generator or constraint entry counts as zero
ROW_TOL = 1e-9
"""A constraint whose coefficients are all below this (relative) is dropped (a superset): after
cancellation or rescaling it carries rounding noise, which row normalisation would amplify."""
PIVOT_TOL = 1e-6  # smallest pivot (constraints normalised to a largest coefficient of 1)
