"""The data scale ``s_k`` of the rounding margin (:mod:`ivobs.estimators.rounding`).

``s_k`` is the running maximum, over steps ``j <= k``, of the magnitudes of the data terms of a
step: ``|y_j|``, ``g_i |u_j,i|`` (``g_i`` the largest entry of column ``i`` of ``|B|`` and
``|D|``) and the disturbance terms ``|E| |d|``, ``|F| |d|`` (0 for bounds computed from ``y``);
for a nonlinear model, ``|u_j|`` and the largest bound of its unknowns ``w``.
The online path (one step) and the record path (a whole record or batch) give the same numbers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..sets import Box

__all__ = ["SHORT", "DataScale"]

SHORT = 32
"""Vectors up to this length are handled as Python floats in one step (a NumPy call on a short
vector costs more than the arithmetic; the operations, ``abs``, ``*`` and ``max``, are exact or
rounded alike, so the numbers are the same bit for bit)."""


class DataScale:
    """The data-scale terms of one model (cached when they do not depend on the step)."""

    def __init__(self, sys: Any):
        self.sys = sys
        self._steady: tuple[np.ndarray, float] | None = None
        self._steady_list: tuple[list[float], float] | None = None
        """``(g, c)`` with ``g`` as a list: the one-step path of short vectors in floats."""

    def terms(self, k: Any) -> tuple[np.ndarray, float]:
        """``(g, c)`` at step (or time) ``k``: the input gains ``g`` and the disturbance term
        ``c`` (see the module docstring)."""
        if self._steady is not None:
            return self._steady
        sys = self.sys
        if not hasattr(sys, "matrices_at"):  # a nonlinear model: |u| and the bounds of w
            box = sys.w_box
            c = float(np.max(np.maximum(np.abs(box.lo), np.abs(box.hi)), initial=0.0))
            self._steady = (np.ones(sys.nu), c)
            return self._steady
        _A, B, _C, D, E, F = sys.matrices_at(k)
        g = np.max(np.abs(np.vstack([B, D])), axis=0) if sys.nu else np.zeros(0)
        c = 0.0
        if sys.nd and isinstance(sys.d, Box):
            box = sys.d_at(int(k) if sys.is_discrete else 0)
            md = np.maximum(np.abs(box.lo), np.abs(box.hi))
            c = float(max(np.max(np.abs(E) @ md, initial=0.0), np.max(np.abs(F) @ md, initial=0.0)))
        out = (g, c)
        if not sys.is_time_varying and sys.has_constant_bounds:
            self._steady = out
            self._steady_list = (g.tolist(), c)
        return out

    def steady_list(self) -> tuple[list[float], float] | None:
        """The constant terms ``(g, c)`` with ``g`` as a list, or None when they vary."""
        self.terms(0)
        return self._steady_list

    def of_step(self, k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> float:
        """The magnitude of the data terms of one step (its running maximum is ``s_k``)."""
        if self._steady_list is not None and y_k.size + u_k.size <= SHORT:
            return _of_short_step(*self._steady_list, u_k.tolist(), y_k.tolist())
        g, c = self.terms(k if t_k is None else t_k)
        a = c
        if y_k.size:
            m = np.fmax.reduce(np.abs(y_k))
            if m == m:  # not all missing
                a = max(a, float(m))
        if u_k.size:
            a = max(a, float(np.max(np.abs(u_k) * g)))
        return a

    def of_record(self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> np.ndarray:
        """``s_k`` over a record or batch, ``(..., T)``: the running maximum of
        :meth:`of_step` (the same numbers as the online path)."""
        T = y.shape[-2]
        a = np.zeros(y.shape[:-1])
        for i in range(y.shape[-1]):  # columns: a reduction over a short last axis is slow
            np.fmax(a, np.abs(y[..., i]), out=a)  # fmax: a missing sample (NaN) counts as 0
        sys = self.sys
        if not sys.is_time_varying and sys.has_constant_bounds:
            g, c = self.terms(0 if t is None else t[0])
            G, cs = g, np.full(T, c)
        else:
            terms = [self.terms(k if t is None else t[k]) for k in range(T)]
            G = np.array([gc[0] for gc in terms]).reshape(T, sys.nu)
            cs = np.array([gc[1] for gc in terms])
        if sys.nu:
            if u.ndim == 3 and u.strides[0] == 0:
                au = np.max(np.abs(u[0]) * G, axis=-1)  # one input for the whole batch
            else:
                au = np.max(np.abs(u) * G, axis=-1)
            np.maximum(a, au, out=a)
        np.maximum(a, cs, out=a)
        return np.asarray(np.maximum.accumulate(a, axis=-1))


def _of_short_step(g: list[float], c: float, u: list[float], y: list[float]) -> float:
    """:meth:`DataScale.of_step` on short vectors (:data:`SHORT`): the same numbers, in floats;
    a missing sample (NaN) counts as 0 as in ``np.fmax``."""
    a = c
    ya = [abs(v) for v in y if v == v]
    if ya:
        a = max(a, max(ya))
    if u:
        a = max(a, max([abs(v) * gi for v, gi in zip(u, g)]))
    return a
