"""Boxes never wider than the data: the box of ``x[k]`` met with the measurement strips of
``y[k]``.

Every output row of the model ([Efimov2013] (1), [Wang2020] (1))::

    y_i[k] = C_i x[k] + D_i u[k] + F_i d[k],   d[k] ∈ [d]

confines ``x[k]`` to the strip ``C_i x ∈ y_i − D_i u − F_i [d]``. A box of ``x[k]`` is
contracted by these strips, one after the other, by interval propagation
(:func:`ivobs.sets.strip.meet_strips`): a state measured directly (a unit row of ``C``) is then
never wider than its sensor's band, whatever the method.

**The strip, proven.** The data may be a float64 evaluation of the output equation (a
simulation, a sample within rounding of its bound: admissible), which adds at most
``ρ_i = 2 γ_N (|y_i| + |D_i||u| + |F_i| max|d| + |C_i| m)``, ``m = max(|lo|, |hi|)`` for ``x``
in the box, ``N = nx + nu + nd + 1`` ([Higham2002, §3.1]). ``F_i [d]`` is enclosed once by
:func:`ivobs.image_bounds` (rounding included) and re-centred, ``F_i [d] ⊆ [f_i − φ_i, f_i +
φ_i]`` exactly (:func:`~ivobs.sets.rounding.mid_rad`). So ``|C_i x − τ_i| <= φ_i + ρ_i`` with
``τ_i = y_i − D_i u − f_i``, and its float evaluation ``t_i``, a sum of ``nu + 2`` terms in
some order, is within ``γ_{nu+2} (|y_i| + |D_i||u| + |f_i|) + (nu + 2) η`` of ``τ_i``. Hence
``|C_i x − t_i| <= σ_i`` with

    σ_i = a (|y_i| + |D_i||u|) + b |C_i| m + κ_i,     a = 2 γ_N + γ_{nu+2},   b = 2 γ_N,
    κ_i = φ_i + 2 γ_N |F_i| max|d| + γ_{nu+2} |f_i| + (nu + 2) η,

``a``, ``b`` and ``κ`` rounded up once (:func:`~ivobs.sets.rounding.upper`, which covers
their own evaluation), and ``σ_i`` evaluated per step and rounded up for its own rounding
(:func:`ivobs.sets.strip.meet_strips`). So the met box still contains every state consistent
with the data.

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
from ..sets.rounding import ETA, mid_rad, upper

__all__ = ["FILTERED", "MeasurementStrips"]

FILTERED: dict[str, bool] = {"strips": True}
"""The option that the comparisons (``compare``, ``ivobs compare``, ``ivobs demo``, campaigns)
and the monitor give every method unless told otherwise: boxes never wider than the data."""


_KERNEL: Any = None


def _kernel() -> Any:
    """:func:`ivobs.sets.strip.meet_strips`, imported on first use (numba compiles it then,
    when installed; ``import ivobs`` does not import numba)."""
    global _KERNEL
    if _KERNEL is None:
        from ..sets.strip import meet_strips

        _KERNEL = meet_strips
    return _KERNEL


class MeasurementStrips:
    """The strips of a model's outputs (:meth:`of`), applied to boxes of ``x[k]`` by
    :meth:`meet`."""

    def __init__(self, sys: LinearSystem, rows: np.ndarray):
        self.sys, self.rows = sys, rows
        self.nx, self.nu, self.every_row = sys.nx, sys.nu, rows.shape[0] == sys.ny
        n = sys.nx + sys.nu + sys.nd + 1
        m = sys.nu + 2  # the terms of t_i = y_i - D_i u - f_i
        self.a = float(upper(2.0 * gamma(n) + gamma(m), 4))
        self.b = float(upper(2.0 * gamma(n), 4))
        self._g = (2.0 * gamma(n), gamma(m))
        lti = not sys.is_time_varying and sys.has_constant_bounds
        self.P: np.ndarray | None = self.coefficients(0, None) if lti else None

    @classmethod
    def of(cls, sys: Any) -> MeasurementStrips | None:
        """The strips of ``sys``, or None for a model they do not apply to."""
        if not isinstance(sys, LinearSystem) or sys.ny == 0:
            return None
        exact = sys.uncertainty.exact_rows() if sys.uncertainty is not None else None
        rows = np.arange(sys.ny) if exact is None else np.flatnonzero(exact)
        return cls(sys, rows) if rows.size else None

    def coefficients(self, key: Any, y: np.ndarray | None) -> np.ndarray:
        """``P = [C, D, f, κ]`` (the rows of the strips) at step ``key`` (the time in
        continuous time; ``y``: the sample, for bounds computed from it); module docstring."""
        sys, rows = self.sys, self.rows
        C, D, F = (M[rows] for M in (sys.C_at(key), sys.D_at(key), sys.F_at(key)))
        f = phi = fmag = np.zeros(rows.shape[0])
        if sys.nd:
            d = sys.d_at(key, y)
            f, phi = mid_rad(*image_bounds(F, d.lo, d.hi))  # F [d] ⊆ [f - φ, f + φ]
            fmag = np.abs(F) @ np.maximum(np.abs(d.lo), np.abs(d.hi))
        g_n, g_m = self._g
        kappa = upper(phi + g_n * fmag + g_m * np.abs(f), sys.nd + 6) + (sys.nu + 2) * ETA
        return np.ascontiguousarray(np.column_stack([C, D, f, kappa]), dtype=np.float64)

    def meet(
        self, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, y: np.ndarray, keys: Any
    ) -> np.ndarray:
        """Contract the boxes ``lo``, ``hi`` ``(T, nx)`` in place with the strips of ``y``
        ``(T, ny)`` (NaN: missing), inputs ``u`` ``(T, nu)``; ``keys`` ``(T,)``: the steps (the
        times in continuous time). Returns the rows whose data contradict their box."""
        meet_strips = _KERNEL or _kernel()
        nx, nu = self.nx, self.nu
        ys = y if self.every_row else y[:, self.rows]
        if self.P is not None:
            ok: np.ndarray = meet_strips(self.P, nx, nu, self.a, self.b, lo, hi, u, ys)
            return ~ok
        bad = np.zeros(lo.shape[0], dtype=bool)
        for r, key in enumerate(keys):
            if not np.any(np.isfinite(ys[r])):
                continue
            P = self.coefficients(key, y[r])
            box = slice(r, r + 1)
            bad[r] = not meet_strips(P, nx, nu, self.a, self.b, lo[box], hi[box], u[box],
                                     ys[box])[0]  # fmt: skip
        return bad
