"""Boxes never wider than the data: the box of ``x[k]`` met with the measurement strips of
``y[k]``.

Every output row of the model ([Efimov2013] (1), [Wang2020] (1))::

    y_i[k] = C_i x[k] + D_i u[k] + F_i d[k],   d[k] ∈ [d]

confines ``x[k]`` to the strip ``C_i x ∈ y_i − D_i u − F_i [d]``. A box of ``x[k]`` is
contracted by these strips, one after the other, by interval propagation
(:func:`ivobs.sets.strip.contract_box`): a state measured directly (a unit row of ``C``) is
then never wider than its sensor's band, whatever the method. The strip bounds are computed
with directed rounding (``D u`` and ``F [d]`` by :func:`ivobs.image_bounds`, each subtraction
rounded outward) and widened by the rounding of a float64 evaluation of the output equation
(``γ_N (|y_i| + |D_i||u| + |F_i| max|d| + |C_i| max(|lo|, |hi|))``, ``N = nx + nu + nd + 1``
[Higham2002, §3.1]: a record from a float64 simulation, a sample within rounding of its bound,
is admissible), so the met box still contains every state consistent with the data.

This is a step *after* the method's recursion (its state, hence its later boxes, are not
changed): the filter-form methods apply it by default (option ``strips``), the
prediction-form observers of the papers keep the box they publish unless ``strips=True``. A
strip that misses the box proves the measurement inconsistent with the model and bounds (the
step is reported like the method's own inconsistencies) and leaves the box as it was.

Applies to the outputs of a :class:`~ivobs.LinearSystem` whose rows of ``C`` and ``D`` are
exactly known (time-varying, continuous-time and bounds computed from ``y`` included; with
interval matrices, the exact rows); nonlinear models are left alone (their filter methods meet
``h`` with the data themselves).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..linalg import gamma
from ..model import LinearSystem
from ..sets import image_bounds
from ..sets.rounding import down, mid_rad, up, upper

__all__ = ["FILTERED", "MeasurementStrips"]

FILTERED: dict[str, bool] = {"strips": True}
"""The option that the comparisons (``compare``, ``ivobs compare``, ``ivobs demo``, campaigns)
and the monitor give every method unless told otherwise: boxes never wider than the data."""


class MeasurementStrips:
    """The strips of a model's outputs (:meth:`of`), applied to boxes of ``x[k]`` by
    :meth:`meet`."""

    def __init__(self, sys: LinearSystem, rows: np.ndarray):
        self.sys, self.rows = sys, rows
        self.n = sys.nx + sys.nu + sys.nd + 1
        self.lti = not sys.is_time_varying and sys.has_constant_bounds
        if self.lti:
            self.C, self.D, self.F = (M[rows] for M in (sys.C_at(0), sys.D_at(0), sys.F_at(0)))
            self.d = sys.d_at(0) if sys.nd else None

    @classmethod
    def of(cls, sys: Any) -> MeasurementStrips | None:
        """The strips of ``sys``, or None for a model they do not apply to."""
        if not isinstance(sys, LinearSystem) or sys.ny == 0:
            return None
        exact = sys.uncertainty.exact_rows() if sys.uncertainty is not None else None
        rows = np.arange(sys.ny) if exact is None else np.flatnonzero(exact)
        return cls(sys, rows) if rows.size else None

    def _strips(
        self,
        C: np.ndarray,
        D: np.ndarray,
        F: np.ndarray,
        d: Any,
        lo: np.ndarray,
        hi: np.ndarray,
        u: np.ndarray,
        y: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``|C x − t| <= σ`` (rows) enclosing ``C x ∈ y − D u − F[d]`` with the rounding of
        the data's own float64 evaluation (module docstring)."""
        g_lo, g_hi = y, y
        mag = np.abs(y)
        if self.sys.nu:
            du_lo, du_hi = image_bounds(D, u, u)
            g_lo, g_hi = down(y - du_hi), up(y - du_lo)
            mag += np.abs(u) @ np.abs(D).T
        if d is not None:
            f_lo, f_hi = image_bounds(F, d.lo, d.hi)
            g_lo, g_hi = down(g_lo - f_hi), up(g_hi - f_lo)
            mag += np.abs(F) @ np.maximum(np.abs(d.lo), np.abs(d.hi))
        with np.errstate(invalid="ignore"):
            mag += np.maximum(np.abs(lo), np.abs(hi)) @ np.abs(C).T
        w = upper(2.0 * gamma(self.n) * mag, self.n + 2)
        del mag
        return mid_rad(down(g_lo - w), up(g_hi + w))

    def meet(
        self, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, y: np.ndarray, keys: Any
    ) -> np.ndarray:
        """Contract the boxes ``lo``, ``hi`` ``(T, nx)`` in place with the strips of ``y``
        ``(T, ny)`` (NaN: missing), inputs ``u`` ``(T, nu)``; ``keys`` ``(T,)``: the steps (the
        times in continuous time). Returns the rows whose data contradict their box."""
        from ..sets.strip import contract_boxes  # compiled on first use (numba, when there)

        sys, rows = self.sys, self.rows
        if self.lti:
            t, sigma = self._strips(self.C, self.D, self.F, self.d, lo, hi, u, y[:, rows])
            return ~contract_boxes(self.C, t, sigma, lo, hi)
        bad = np.zeros(lo.shape[0], dtype=bool)
        for r, key in enumerate(keys):
            if not np.any(np.isfinite(y[r])):
                continue
            C, D, F = (M[rows] for M in (sys.C_at(key), sys.D_at(key), sys.F_at(key)))
            d = sys.d_at(key, y[r]) if sys.nd else None
            box = slice(r, r + 1)
            t, sigma = self._strips(C, D, F, d, lo[box], hi[box], u[box], y[box][:, rows])
            bad[r] = not contract_boxes(C, t, sigma, lo[box], hi[box])[0]
        return bad
