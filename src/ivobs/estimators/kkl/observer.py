"""What every KKL recursion shares: the bounds ``z̲ <= T x <= z̄`` as online state, the
recovery of the box of ``x`` ([Dinh2024, eqs. (3.c-d), (10.d), (15.d)]), the prior box at the
first step and the consistency test of a measurement against the box.

A mode (discrete-time time-invariant, discrete-time time-varying, continuous time) is one
subclass of :class:`Observer`, chosen once when the estimator is built; the estimator hands each
step to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Generic, NamedTuple, TypeVar

import numpy as np

from ...model import LinearSystem
from ...sets import Box, image_bounds
from ..state import OnlineState, Step
from .design import KKLDesign, OutputRows, Transform, every, finite, output_rows

__all__ = ["Measured", "Observer", "Setting", "ZState", "prior_box"]

EPS = float(np.finfo(float).eps)
PATTERNS = 256
"""Patterns of observed components whose output rows a time-invariant observer keeps."""


@dataclass(frozen=True)
class ZState(OnlineState):
    """``z̲ <= z[k] = T[k] x[k] <= z̄`` (``zlo``, ``zhi``, shape ``(n_z,)``): the bounds of
    observers (3), (10) and (15)."""

    zlo: np.ndarray
    zhi: np.ndarray

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("zlo", "zhi"),)


S = TypeVar("S", bound=OnlineState)


class Measured(NamedTuple):
    """One pattern of observed components of ``y``: its output rows, whether it is complete
    and, for constant bounds of ``d``, the terms ``F_o d_c`` and ``|F_o| d_r`` of the
    consistency test (None: computed at each step from the bounds of the step)."""

    rows: OutputRows
    full: bool
    Fdc: np.ndarray | None
    Fdr: np.ndarray | None


@dataclass(frozen=True)
class Setting:
    """What every observer of a design works with: the model, the prior box on ``x[0]``, the
    design, the threshold of left-invertibility and ``rec``, the relative rounding margin of
    the recovery ``x = T⁺ z``: ``16 (n_z + n_x) ε`` (discrete time; linear recursions, the base
    margin covers the rest), plus ``100 rtol`` in continuous time (the integration error of the
    flows, covered heuristically)."""

    sys: LinearSystem
    x0: Box | None
    design: KKLDesign
    max_cond: float
    rec: float


def prior_box(x0: Box | None, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At ``k = 0`` the prior box itself is known: intersect (sound, never looser)."""
    if x0 is None:
        return lo, hi
    return np.maximum(lo, x0.lo), np.minimum(hi, x0.hi)


class Observer(Generic[S]):
    """One mode of the KKL observer: its online state and its step, written once."""

    def __init__(self, setting: Setting):
        self.sys = setting.sys
        self.x0 = setting.x0
        self.design = setting.design
        self.max_cond = setting.max_cond
        self.rec = setting.rec
        sys = setting.sys
        # constant bounds of d (or none): the same box at every step
        self._dfix = sys.d_at(0) if sys.has_constant_bounds else None
        # constant (C, D, F): the rows of each pattern of observed components, kept
        self._patterns: dict[bytes, Measured] | None = None if sys.is_time_varying else {}

    def initial_state(self) -> S:
        raise NotImplementedError

    def step(self, state: S, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> Step[S]:
        raise NotImplementedError

    def initial_z(self) -> tuple[np.ndarray, np.ndarray]:
        """``z̲[0], z̄[0]``: ``T[0] [x̲0, x̄0]`` by Lemma 1 ((3.b)/(10.c)/(15.c)); ``z[0] = 0``
        exactly when ``T[0] = 0`` and no prior is given."""
        if self.x0 is not None:
            return image_bounds(self.design.T, self.x0.lo, self.x0.hi)
        nz = self.design.n_z
        return np.zeros(nz), np.zeros(nz)

    def initial_x(self) -> tuple[np.ndarray, np.ndarray]:
        """The prior box on ``x[0]`` (infinite without one)."""
        if self.x0 is not None:
            return self.x0.lo.copy(), self.x0.hi.copy()
        nx = self.sys.nx
        return np.full(nx, -np.inf), np.full(nx, np.inf)

    def recover(
        self, tr: Transform, zlo: np.ndarray, zhi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(3.c-d)/(15.d): bounds of ``x = T⁺ z`` plus the rounding margin of the recovery,
        ``rec cond(T) |T⁺| (|z_c| + z_r)``."""
        zc, zr = 0.5 * (zlo + zhi), 0.5 * (zhi - zlo)
        aP = tr.absP
        xr = aP @ zr + (self.rec * tr.cond) * (aP @ (np.abs(zc) + zr))
        xc = tr.P @ zc
        return xc - xr, xc + xr

    def first_box(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return prior_box(self.x0, lo, hi)

    def bounds_d(self, k: int, y_k: np.ndarray) -> Box:
        """The bounds of ``d[k]`` (constant ones kept)."""
        return self._dfix if self._dfix is not None else self.sys.d_at(k, y_k)

    def measured(self, CDF: tuple[np.ndarray, ...], obs: np.ndarray) -> Measured:
        """:class:`Measured` for the observed components ``obs`` (kept per pattern when
        ``(C, D, F)`` are constant)."""
        cache = self._patterns
        if cache is None:
            return self._measure(CDF, obs)
        key = obs.tobytes()
        m = cache.get(key)
        if m is None:
            if len(cache) >= PATTERNS:
                cache.clear()
            m = cache[key] = self._measure(CDF, obs)
        return m

    def _measure(self, CDF: tuple[np.ndarray, ...], obs: np.ndarray) -> Measured:
        r = output_rows(CDF, obs)
        d = self._dfix
        if d is None:
            return Measured(r, every(obs), None, None)
        return Measured(r, every(obs), r.F @ (0.5 * (d.lo + d.hi)), r.absF @ (0.5 * (d.hi - d.lo)))

    def usable(
        self,
        y_k: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        CDF: tuple[np.ndarray, ...],
        u_k: np.ndarray,
        d: Box,
    ) -> tuple[np.ndarray, bool]:
        """The observed components of ``y[k]`` and whether ``y[k]`` contradicts the box
        ``[lo, hi]`` of ``x[k]`` (then none is used): ``|y - C x_c - D u - F d_c| <= |C| x_r +
        |F| d_r`` up to rounding on the observed rows."""
        obs = ~np.isnan(y_k)
        width = hi - lo
        # a non-finite width: lo or hi not finite, or (lo, hi finite) a width beyond the float
        # range, whose test below could not fail: nothing to test either way
        if not np.count_nonzero(obs) or not finite(width):
            return obs, False
        m = self.measured(CDF, obs)
        r = m.rows
        Fdc, Fdr = m.Fdc, m.Fdr
        if Fdc is None or Fdr is None:
            Fdc, Fdr = r.F @ (0.5 * (d.lo + d.hi)), r.absF @ (0.5 * (d.hi - d.lo))
        yc = r.C @ (0.5 * (lo + hi)) + Fdc + r.D @ u_k
        yr = r.absC @ (0.5 * width) + Fdr
        yo = y_k if m.full else y_k[obs]
        if np.count_nonzero(np.abs(yo - yc) > yr + 1e-9 * (1.0 + np.abs(yc) + yr)):
            return np.zeros_like(obs), True
        return obs, False
