"""What every KKL recursion shares: the bounds ``z̲ <= T x <= z̄`` as online state, the
recovery of the box of ``x`` ([Dinh2024, eqs. (3.c-d), (10.d), (15.d)]) with its proven
rounding, and the prior box at the first step.

A mode (discrete time, continuous time) is one subclass of :class:`Observer`, chosen once when
the estimator is built; the estimator hands each step to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import inf, nan, nextafter
from typing import ClassVar, Generic, TypeVar

import numpy as np

from ...model import LinearSystem
from ...sets import Box, image_bounds
from ..state import OnlineState, Step
from .design import KKLDesign, Transform
from .terms import Consistency, consistency

__all__ = ["PATTERNS", "Observer", "ZState", "prior_box", "recover"]

PATTERNS = 256
"""Patterns of observed outputs whose matrices an observer keeps."""


@dataclass(frozen=True)
class ZState(OnlineState):
    """``z̲ <= z[k] = T[k] x[k] <= z̄`` (``zlo``, ``zhi``, shape ``(n_z,)``): the bounds of
    observers (3), (10) and (15)."""

    zlo: np.ndarray
    zhi: np.ndarray

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("zlo", "zhi"),)


S = TypeVar("S", bound=OnlineState)


def prior_box(x0: Box | None, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """At ``k = 0`` the prior box itself is known: intersect (sound, never looser)."""
    if x0 is None:
        return lo, hi
    return np.maximum(lo, x0.lo), np.minimum(hi, x0.hi)


def recover(
    tr: Transform, zlo: np.ndarray, zhi: np.ndarray, zabs: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(3.c-d)/(10.d)/(15.d): a box certain to contain ``x`` when ``z̲ <= T x <= z̄``.

    ``P`` is a float left inverse of ``T``, not an exact one: ``x = P (T x) + (I - P T) x``.
    The first term lies in the Lemma-1 image ``P⁺ z̲ - P⁻ z̄ <= P z <= P⁺ z̄ - P⁻ z̲``, evaluated
    in floats with error at most ``γ_{2 n_z} |P| |z|`` (each bound a sum of ``2 n_z`` products,
    [Higham2002, Lemma 3.1]); the second is at most ``max r ‖x‖∞`` per component, ``r`` the
    row sums of ``|I - P T|`` (``tr.resid``), with ``‖x‖∞ <= ‖|P| |z|‖∞ / (1 - max r)``. Both are
    added (constants of :class:`~.design.Transform` with the slack that covers the rounding
    of this sum), then each bound is rounded outward by one ulp (the exact result of its last
    operation lies within half an ulp). ``|z| <= zabs = max(|z̲|, |z̄|)`` componentwise."""
    if zabs is None:
        zabs = np.maximum(np.abs(zlo), np.abs(zhi))
    nx = tr.P.shape[0]
    r = tr.W.dot(np.concatenate((zlo, zhi, zabs))).tolist()
    s = r[2 * nx :]
    # r_i ‖x‖∞ <= max r ‖x‖∞ (NaN-propagating maximum: a NaN in s gives NaN bounds)
    smax = max(s) if sum(s) == sum(s) else nan
    wide = smax * tr.c_resid + tr.eta
    lo, hi = [0.0] * nx, [0.0] * nx  # in Python floats: the same IEEE operations, cheaper
    for i in range(nx):
        err = tr.c_err * s[i] + wide
        lo[i], hi[i] = nextafter(r[i] - err, -inf), nextafter(r[nx + i] + err, inf)
    return np.array(lo), np.array(hi)


class Observer(Generic[S]):
    """One mode of the KKL observer: its online state and its step, written once."""

    def __init__(self, sys: LinearSystem, x0: Box | None, design: KKLDesign, max_cond: float):
        self.sys = sys
        self.x0 = x0
        self.design = design
        self.max_cond = max_cond
        # constant bounds of d (or none): the same box at every step
        self._dfix = sys.d_at(0) if sys.has_constant_bounds else None
        # the consistency test of each pattern of observed outputs, kept while (C, D, F) are
        self._checks: dict[bytes, tuple[tuple[np.ndarray, ...], Consistency]] = {}

    def initial_state(self) -> S:
        raise NotImplementedError

    def step(self, state: S, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> Step[S]:
        raise NotImplementedError

    def initial_z(self) -> tuple[np.ndarray, np.ndarray]:
        """``z̲[0], z̄[0]``: ``T[0] [x̲0, x̄0]`` by Lemma 1 ((3.b)/(10.c)/(15.c), proven
        rounding); ``z[0] = 0`` exactly when ``T[0] = 0`` and no prior is given."""
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

    def check(self, CDF: tuple[np.ndarray, ...], obs: np.ndarray) -> Consistency:
        """The consistency test of the observed outputs ``obs`` (kept while ``C, D, F`` are the
        same)."""
        key = obs.tobytes()
        hit = self._checks.get(key)
        if hit is not None and all(np.array_equal(a, b) for a, b in zip(hit[0], CDF)):
            return hit[1]
        if len(self._checks) >= PATTERNS:
            self._checks.clear()
        C, D, F = (M[obs] for M in CDF)
        d = (self._dfix.lo, self._dfix.hi) if self._dfix is not None else None
        check = consistency(C, D, F, d)
        self._checks[key] = (CDF, check)
        return check

    def bounds_d(self, k: int, y_k: np.ndarray) -> Box:
        """The bounds of ``d[k]`` (constant ones kept)."""
        return self._dfix if self._dfix is not None else self.sys.d_at(k, y_k)
