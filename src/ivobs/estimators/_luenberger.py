"""The Luenberger observer behind ``reachability`` and ``zonotope`` [Tang2019, eqs. (10), (34a)].

With ``y = C x + D u + F d`` and the bounds of ``d`` re-centred (``d = c + δ``, ``|δ| <= r``),

    x̂[k+1] = A x̂[k] + B u[k] + L (y[k] - C x̂[k] - D u[k]) + (E - L F) c[k],

whose error ``e = x - x̂`` obeys ``e+ = M e + G δ``, ``M = A - L C``, ``G = E - L F``
[Tang2019, eq. (15)]. The two methods differ only in the set they propagate for ``e``; what
they share is here: the gain (:func:`ivobs.design.hinf.observer_gain`), the gain without the
missing outputs of a step, the consistency test of a measurement, and the observer as a linear
filter of the record for the vectorised paths (:class:`ivobs._recursion.SplitFilter`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..design.hinf import observer_gain
from . import _uncertain as uncertain
from ._recursion import SplitFilter, centre_band, within_band
from .base import Design, Estimator

__all__ = [
    "ObserverDesign",
    "ObserverEstimator",
    "consistent",
    "gain_without",
    "inconsistent_steps",
    "observer_bounds",
    "observer_filter",
]


@dataclass(frozen=True)
class ObserverDesign(Design):
    """``L``: observer gain; ``gamma``: its H∞ bound and ``P`` the Lyapunov matrix of
    [Tang2019, Theorem 1] (None for a user gain and the ``"radius"`` gain); ``spectral_radius``
    of ``A - LC``; ``gain``: the design (``"radius"``, ``"hinf"``, ``"hinf-lmi"``; ``"user"``
    for ``L=``)."""

    L: np.ndarray
    gamma: float | None
    P: np.ndarray | None
    spectral_radius: float
    gain: str


class ObserverEstimator(Estimator):
    """What ``reachability`` and ``zonotope`` share: the gain ``L`` (``L=`` or a design,
    ``gain=``: :func:`ivobs.design.hinf.observer_gain`), the error dynamics ``M = A - LC``,
    ``G = E - LF``, and the bounds of ``d`` (kept when constant). A subclass calls
    :meth:`_design_observer` from its ``__init__``."""

    def _design_observer(self, L: Any, gain: str | None = None) -> ObserverDesign:
        """The gain (checked: ``A - LC`` Schur) and the matrices of the error dynamics."""
        Lm, gamma, P, rho = observer_gain(self.sys, L, self.name, gain)
        self._L = Lm
        self._mats = self.sys.matrices_at(0)
        A, _, C, _, E, F = self._mats
        self._M = A - Lm @ C
        self._G = E - Lm @ F
        self._absC, self._absF = np.abs(C), np.abs(F)
        self._const: tuple[np.ndarray, np.ndarray] | None = None
        self._unc = self.sys.uncertainty
        if self._unc is not None:  # interval matrices: d̃ = [d; w; v] with data-dependent w, v
            nx, ny = A.shape[0], C.shape[0]
            self._G = np.hstack([self._G, np.eye(nx), -Lm])
            self._absF = np.hstack([self._absF, np.zeros((ny, nx)), np.eye(ny)])
        elif self.sys.has_constant_bounds:
            box = self.sys.d_at(0)
            self._const = (box.center, box.radius)
        kind = "user" if L is not None else ("radius" if gain is None else gain)
        return ObserverDesign(L=Lm, gamma=gamma, P=P, spectral_radius=rho, gain=kind)

    def _fused_observer(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The observer and its innovation of a complete ``y[k]`` as one product (constant
        bounds): ``[x̂+; ν] = O [x̂; u; y] + o`` with ``O = [[M, B − L D, L], [−C, −D, I]]``,
        ``o = [(E − L F) c; −F c]``, ``ν = y − C x̂ − D u − F c`` ([Tang2019, eq. (10)] in the
        form of the vectorised path, :func:`observer_filter`). None without constant bounds."""
        if self._const is None:
            return None
        c = self._const[0]
        _, B, C, D, E, F = self._mats
        L, ny = self._L, C.shape[0]
        O = np.block([[self._M, B - L @ D, L], [-C, -D, np.eye(ny)]])
        return O, np.concatenate([(E - L @ F) @ c, -(F @ c)])

    def _bounds(
        self, k: int, y_k: np.ndarray, lo: np.ndarray, hi: np.ndarray, u_k: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Centre and radius of the bounds of ``d[k]`` (kept when constant). Interval matrices
        (``supports_uncertain``): the radius of ``d̃ = [d; w; v]`` (``w``, ``v`` centred at 0),
        ``w = ΔA x + ΔB u``, ``v = ΔC x + ΔD u`` bounded from the box ``[lo, hi]`` of ``x[k]``
        (:mod:`ivobs.estimators._uncertain`), which enter ``x+`` through ``[E, I, 0]`` and
        ``y`` through ``[F, 0, I]``: the error ``e+ = M e + G̃ δ̃``, ``G̃ = [E − LF, I, −L]``."""
        if self._const is not None:
            return self._const
        box = self.sys.d_at(k, y_k)
        if self._unc is None:
            return box.center, box.radius
        w, v = uncertain.terms(self._unc, lo, hi, u_k)  # centred at 0: c is that of d alone
        return box.center, np.concatenate([box.radius, w, v])

    def _gain_at(self, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(L_k, M_k, G_k)`` for the outputs observed at a step (:func:`gain_without`;
        ``G̃_k = [E − L_k F, I, −L_k]`` with interval matrices)."""
        if obs.all():
            return self._L, self._M, self._G
        Lk, Mk, Gk = gain_without(self._mats, self._L, obs)
        if self._unc is not None:
            Gk = np.hstack([Gk, np.eye(Mk.shape[0]), -Lk])
        return Lk, Mk, Gk


def observer_filter(
    M: np.ndarray, mats: tuple[np.ndarray, ...], L: np.ndarray, c: np.ndarray
) -> SplitFilter:
    """The observer of [Tang2019, eqs. (10), (34a)] as a linear filter of ``(y, u)``: state
    ``x̂`` (``x̂+ = M x̂ + L y + (B - L D) u + (E - L F) c``), outputs ``x̂`` and the innovation
    ``y - C x̂ - D u - F c``."""
    _, B, C, D, E, F = mats
    ny = C.shape[0]
    return SplitFilter(
        M,
        [L, B - L @ D],
        [np.eye(M.shape[0]), -C],
        [[None, None], [np.eye(ny), -D]],
        g=(E - L @ F) @ c,
        h=[None, -(F @ c)],
    )


def observer_bounds(
    M: np.ndarray,
    mats: tuple[np.ndarray, ...],
    L: np.ndarray,
    c: np.ndarray,
    x0: np.ndarray,
    u: np.ndarray,
    y: np.ndarray,
    rad: np.ndarray,
    yrad: np.ndarray,
    filt: SplitFilter | None = None,
    streams: bool = False,
) -> tuple[np.ndarray, ...] | None:
    """``x̂[k] ∓ rad[k]`` over a record ``(T, ·)`` or a batch ``(B, T, ·)``, with
    ``x̂+ = M x̂ + (B - L D) u + L y + (E - L F) c`` [Tang2019, eqs. (10), (34a)], ``x̂[0] = x0``;
    ``None`` when some ``|y - C x̂ - D u - F c| > yrad`` (inconsistent data: the caller falls
    back to its loop, which reports the step). ``rad`` ``(T, nx)`` and ``yrad`` ``(T, ny)`` are
    data-independent. One pass of :class:`ivobs._recursion.SplitFilter` (``filt``, from
    :func:`observer_filter`): the part of ``x̂`` shared by a batch's streams (``x0``, ``c``, a
    common input) is folded into the offsets ``shared ∓ rad``. With ``streams=True`` a batch
    with inconsistent streams gives ``(lo, hi, bad)``, ``bad`` the streams to redo (loop)."""
    if filt is None:
        filt = observer_filter(M, mats, L, c)
    nx = M.shape[0]
    hi = np.empty((*y.shape[:-1], nx))
    (xh, innov), shared = filt.run([y, u], x0=x0, out=[hi, None], temp=[1])
    s_x, s_i = (None, None) if shared is None else shared
    # consistent() allows 1e-9 (1 + |innov| + |y| + yrad) of excess: a narrower band first
    bad: np.ndarray | None = None
    if not within_band(innov, s_i, yrad + 1e-9 * (1.0 + yrad)):
        if s_i is not None:
            innov = innov + s_i
        fail = inconsistent_steps(innov, yrad, y)
        if fail.any():
            if not streams or y.ndim != 3:
                return None
            bad = np.asarray(fail.any(axis=-1))
    del innov
    lo, xh = centre_band(xh, rad, s_x)
    return (lo, xh) if bad is None else (lo, xh, bad)


def gain_without(
    mats: tuple[np.ndarray, ...], L: np.ndarray, obs: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``L_k`` (columns of missing outputs zeroed), ``M_k = A - L_k C``, ``G_k = E - L_k F``."""
    A, _, C, _, E, F = mats
    Lk = L * obs
    return Lk, A - Lk @ C, E - Lk @ F


def inconsistent_steps(innov: np.ndarray, bound: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``(..., T)`` mask of the steps :func:`consistent` rejects (complete measurements)."""
    excess = np.abs(innov) - bound
    tol = 1e-9 * (1.0 + np.abs(innov) + np.abs(y) + bound)
    mask: np.ndarray = (excess > tol).any(axis=-1)
    return mask


def consistent(innov: np.ndarray, bound: np.ndarray, y: np.ndarray, obs: np.ndarray | None) -> bool:
    """``|innov| <= bound`` (up to a rounding tolerance) where observed (``obs``; all if None).

    ``innov = y - C x̂ - D u - F c`` and ``bound`` its radius implied by the model and the set
    estimate (a measurement outside is inconsistent: a fault under the model's assumptions).
    """
    excess = np.abs(innov)
    excess -= bound
    if obs is not None and not obs.all():
        excess = np.where(obs, excess, -np.inf)
    if not (excess > 0.0).any():
        return True
    y0 = np.where(np.isnan(y), 0.0, y)
    tol = 1e-9 * (1.0 + np.abs(innov) + np.abs(y0) + bound)
    return not (excess > tol).any()
