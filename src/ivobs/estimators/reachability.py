"""Interval estimation by reachability analysis of an H∞ observer's error (paper 002, Section III).

Paper: Tang, Wang, Wang, Raïssi, Shen, *Interval estimation methods for discrete-time LTI
systems*, IEEE TAC 2019 (``seeds/002_b3ef6f5573cb68d4.txt``): Algorithm 1, Theorem 2,
eqs. (10), (13), (21)-(26); gain by Theorem 1 / problem (20) (:mod:`ivobs.design.hinf`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._recursion import SplitFilter, redo_streams, within_band
from .._validate import as_int
from ..design.hinf import observer_gain
from ..model import LinearSystem
from ..sets import Box
from . import register
from .base import Design, Estimator, check_size

__all__ = ["Reachability", "ReachabilityDesign"]

TAIL = 1e-3
"""Default memory: the smallest ``K`` with ``‖ |(A - LC)^K| ‖∞ <= TAIL`` (see ``memory``)."""

MAX_MEMORY = 500
"""Upper limit of the default memory (slowly converging gains)."""

_CHUNK = 1 << 21
"""Floats per block when the data-independent radius sequence is computed (memory bound)."""


@dataclass(frozen=True)
class ReachabilityDesign(Design):
    """``L``: observer gain; ``gamma``: its H∞ bound (None for a user gain); ``P``: the LMI's
    Lyapunov matrix (None for a user gain); ``spectral_radius`` of ``A - LC``; ``memory``: ``K``,
    the window of exactly propagated terms for time-varying bounds and missing samples."""

    L: np.ndarray
    gamma: float | None
    P: np.ndarray | None
    spectral_radius: float
    memory: int


def default_memory(M: np.ndarray, tail: float = TAIL, cap: int = MAX_MEMORY) -> int:
    """Smallest ``K >= 1`` with ``max row sum |M^K| <= tail`` (at most ``cap``)."""
    P = M.copy()
    for K in range(1, cap + 1):
        if np.abs(P).sum(axis=1).max(initial=0.0) <= tail:
            return K
        P = M @ P
    return cap


@register
class Reachability(Estimator):
    """Reachability-based interval estimation (002 Algorithm 1, Theorem 2).

    Observer (002 eq. 10), with ``d ∈ [c - r, c + r]`` re-centred (``G = E - L F``)::

        x̂[k+1] = A x̂[k] + B u[k] + L (y[k] - C x̂[k] - D u[k]) + G c[k],   x̂[0] = center(x0)

    Its error ``e = x - x̂`` obeys ``e+ = M e + G δ``, ``M = A - L C``, ``|δ| <= r``, so (eqs.
    21-26, Algorithm 1) ``x[k] ∈ x̂[k] ± ρ[k]`` with the exact interval hull of the reachable set

        ρ[k] = |M^k| h0 + Σ_{i<k} |M^i G| r[k-1-i],        h0 = radius(x0)   (H0 = diag h0)

    (Property 4: ``Box(<0, X>)`` has radius ``|X| 1``; ``|·|`` elementwise). Over-approximation
    happens only in these Box operations (002 Remark 1).

    **Data used (prediction form):** the box of ``x[k]`` uses ``u[0..k-1]``, ``y[0..k-1]``
    (the paper's convention); ``y[k]`` enters the box of ``x[k+1]``.

    **Gain.** By default the H∞ gain of Theorem 1 / problem (20); ``L=`` gives it explicitly (the
    papers' comparisons "with the same gain"); ``A - LC`` must be Schur.

    **Constant bounds, no missing sample:** Algorithm 1 exactly (``ρ`` by the running sums of
    ``|M^i G| r``; with :meth:`run` the whole sequence is computed once, data-independent, and
    ``x̂`` by a vectorised recursion; batches ``(B, T, n)`` too).

    **Time-varying or measurement-dependent bounds ``r[k]``, missing samples:** the sum is a
    convolution and, with missing components of ``y[k]`` (gain column set to zero at that step:
    ``L_k``, ``M_k = A - L_k C``, ``G_k = E - L_k F``), the error dynamics become time-varying.
    Sound finite-memory form: with ``Φ(k, j) = M_{k-1} ... M_j`` and any ``j <= k``,

        Ω_k ⊆ Φ(k, j) Box(Ω_j) ⊕ ⊕_{j<=i<k} Φ(k, i+1) G_i <0, diag r_i>,

    so ``ρ[k] <= |Φ(k, j) diag ρ[j]| 1 + Σ_{j<=i<k} |Φ(k, i+1) G_i diag r_i| 1`` for every ``j``.
    The last ``K = memory`` steps are kept as matrices propagated with the *actual* ``M_i``
    (``Φ(k, j) diag ρ[j]`` and ``Φ(k, i+1) G_i diag r_i``) and ``ρ[k]`` is the elementwise
    minimum of these bounds over the window (for constant ``M`` this is at least as tight as
    ``ρ_k <= Σ_{i<K} |M^i G| r_{k-1-i} + |M^K| ρ_{k-K}``). Older terms are boxed (``Box(Ω_j)``)
    before being propagated, which loses at most ``|Φ(k, k-K)|``-small amounts. The exact
    Algorithm 1 state is kept until the first missing sample; the switch keeps ``M^k H0`` and
    boxes the accumulated disturbance part (``<0, [M^k H0, diag s_k]>``, ``s_k`` its exact
    interval hull radius) and continues with the window.

    **Inconsistent data:** ``y[k]`` is consistent only if
    ``|y[k] - C x̂[k] - D u[k] - F c[k]| <= |C| ρ[k] + |F| r[k]``; otherwise it is reported and
    treated as missing.

    Parameters
    ----------
    sys : time-invariant discrete-time :class:`~ivobs.LinearSystem`
    x0 : Box, prior box on ``x[0]`` (002: ``x0 ∈ <p0, H0>``)
    L : (nx, ny) observer gain, optional (default: H∞ gain, 002 Theorem 1, problem (20))
    memory : window ``K`` for time-varying bounds / missing samples (default: smallest ``K``
        with ``‖ |M^K| ‖∞ <= 1e-3``, at most 500)
    """

    name = "reachability"
    order = 20
    summary = "H∞ observer + exact interval hull of the error's reachable set (002 Alg. 1)"
    reference = "002 Tang et al., IEEE TAC 2019: Algorithm 1, Theorem 2, eqs. (10), (13), (21)"

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        memory: int | None = None,
        **base: Any,
    ):
        super().__init__(sys, x0, **base)
        check_size(
            self.name,
            sys.nx,
            "propagates the exact interval hull of the error's "
            "reachable set, nx x (nx + nd) matrices (O(nx^3) work)",
        )
        K = None if memory is None else as_int("memory", memory, 1)
        Lm, gamma, P, rho = observer_gain(sys, L, self.name)
        self._mats = sys.matrices_at(0)
        A, _, C, _, E, F = self._mats
        self._M = A - Lm @ C
        self._G = E - Lm @ F
        self._absC, self._absF = np.abs(C), np.abs(F)
        K = default_memory(self._M) if K is None else K
        self.design = ReachabilityDesign(L=Lm, gamma=gamma, P=P, spectral_radius=rho, memory=K)
        assert self.x0 is not None
        self._xc = self.x0.center.copy()
        self._h0 = self.x0.radius.copy()
        self._const: tuple[np.ndarray, np.ndarray] | None = None
        if sys.has_constant_bounds:
            box = sys.d_at(0)
            self._const = (box.center, box.radius)

    # -- helpers -------------------------------------------------------------------------------
    def _bounds(self, k: int, y_k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centre and radius of the bounds of ``d[k]`` (cached when constant)."""
        if self._const is not None:
            return self._const
        box = self.sys.d_at(k, y_k)
        return box.center, box.radius

    # -- online --------------------------------------------------------------------------------
    def _initial_state(self) -> dict[str, Any]:
        nx, nd = self.sys.nx, self.sys.nd
        if self._const is not None:  # exact Algorithm 1: X = [M^k H0, M^k G diag r]
            X = np.hstack([np.diag(self._h0), self._G * self._const[1]])
            Z = np.zeros((nx, 0))
        else:
            X, Z = np.zeros((nx, 0)), np.diag(self._h0)
        return {
            "xh": self._xc.copy(),
            "mode": 0 if self._const is not None else 1,
            "X": X,
            "s": np.zeros(nx),  # Σ_{i<k} |M^i G| r
            # window: Z = Φ(k, k0) Z0 while complete; slot j = [Φ(k, j) diag ρ_j,
            # Φ(k, j+1) G_j diag r_j] for the last K steps j (oldest first)
            "Z": Z,
            "slots": np.zeros((0, nx, nx + nd)),
        }

    def _window_radius(self, state: dict[str, Any]) -> np.ndarray:
        nx = self.sys.nx
        S = np.abs(state["slots"])
        g = S[:, :, nx:].sum(axis=2)  # (n_s, nx)
        suffix = np.cumsum(g[::-1], axis=0)[::-1]  # Σ over slots j' >= j
        cand = S[:, :, :nx].sum(axis=2) + suffix
        if not state["Z"].shape[1]:
            return cand.min(axis=0)
        z = np.abs(state["Z"]).sum(axis=1) + (suffix[0] if suffix.shape[0] else 0.0)
        return np.minimum(z, cand.min(axis=0)) if cand.shape[0] else z

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        nx = self.sys.nx
        xh = state["xh"]
        exact = state["mode"] == 0
        if exact:
            rho = np.abs(state["X"][:, :nx]).sum(axis=1) + state["s"]
        else:
            rho = self._window_radius(state)
        lo, hi = xh - rho, xh + rho

        A, B, C, D, E, F = self._mats
        c, r = self._bounds(k, y_k)
        obs = ~np.isnan(y_k)
        full = bool(obs.all())
        innov = (y_k if full else np.where(obs, y_k, 0.0)) - C @ xh - D @ u_k - F @ c
        if (full or obs.any()) and not consistent(
            innov, self._absC @ rho + self._absF @ r, y_k, obs
        ):
            state["_inconsistent"] = True
            obs, full = np.zeros_like(obs), False
        if full:
            Lk, Mk, Gk = self.design.L, self._M, self._G
            state["xh"] = A @ xh + B @ u_k + E @ c + Lk @ innov
        else:
            Lk, Mk, Gk = gain_without(self._mats, self.design.L, obs)
            state["xh"] = A @ xh + B @ u_k + E @ c + Lk @ np.where(obs, innov, 0.0)

        if exact and full:
            X = state["X"]
            state["s"] = state["s"] + np.abs(X[:, nx:]).sum(axis=1)
            state["X"] = Mk @ X
            return lo, hi
        if exact:  # first missing sample: box the disturbance part, continue with the window
            state["mode"] = 1
            state["Z"] = np.hstack([state["X"][:, :nx], np.diag(state["s"])])
            state["X"] = np.zeros((nx, 0))
            state["s"] = np.zeros(nx)
        slots = np.concatenate([state["slots"], np.zeros((1, nx, nx + self.sys.nd))])
        slots[-1, :, :nx] = np.diag(rho)
        slots = Mk @ slots
        slots[-1, :, nx:] = Gk * r  # d[k] enters e[k+1] unpropagated
        Z = Mk @ state["Z"]
        if slots.shape[0] > self.design.memory:  # oldest slot leaves: Z loses a term
            slots = slots[1:]
            Z = np.zeros((nx, 0))
        state["slots"], state["Z"] = slots, Z
        return lo, hi

    # -- offline, vectorised --------------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        if not self.sys.has_constant_bounds or not y.shape[-2] or np.isnan(y).any():
            return None  # (an empty record: the loop)
        assert self._const is not None
        c, r = self._const
        T = y.shape[-2]
        cached = self.__dict__.get("_vec")
        if cached is None or cached[0] != T:
            rho = radius_sequence(self._M, np.diag(self._h0), self._G * r, T)
            yrad = rho @ self._absC.T + self._absF @ r  # |C| ρ + |F| r: consistency of y
            filt = (
                cached[3]
                if cached is not None
                else observer_filter(self._M, self._mats, self.design.L, c)
            )
            cached = self.__dict__["_vec"] = (T, rho, yrad, filt)
        _, rho, yrad, filt = cached
        out = observer_bounds(
            self._M, self._mats, self.design.L, c, self._xc, u, y, rho, yrad, filt, streams=True
        )
        if out is None or len(out) == 2:
            return out
        return redo_streams(self, u, y, t, *out)


def observer_filter(
    M: np.ndarray, mats: tuple[np.ndarray, ...], L: np.ndarray, c: np.ndarray
) -> SplitFilter:
    """The observer of 002 eqs. (10)/(34a) as a linear filter of ``(y, u)``: state ``x̂``
    (``x̂+ = M x̂ + L y + (B - L D) u + (E - L F) c``), outputs ``x̂`` and the innovation
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
    ``x̂+ = M x̂ + (B - L D) u + L y + (E - L F) c`` (002 eqs. 10 / 34a), ``x̂[0] = x0``;
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
    bad = None
    if not within_band(innov, s_i, yrad + 1e-9 * (1.0 + yrad)):
        if s_i is not None:
            innov = innov + s_i
        fail = inconsistent_steps(innov, yrad, y)
        if fail.any():
            if not streams or y.ndim != 3:
                return None
            bad = fail.any(axis=-1)
    del innov
    lo = np.empty_like(hi)
    if s_x is None:
        np.subtract(xh, rad, out=lo)
        xh += rad
    else:
        np.add(xh, s_x - rad, out=lo)
        xh += s_x + rad
    return (lo, xh) if bad is None else (lo, xh, bad)


def radius_sequence(M: np.ndarray, H0: np.ndarray, GR: np.ndarray, T: int) -> np.ndarray:
    """``ρ[k] = |M^k H0| 1 + Σ_{i<k} |M^i GR| 1`` for ``k < T`` (002 eq. 21), shape ``(T, nx)``.

    Data-independent. The powers ``M^i [H0 GR]`` are built by doubling (``M^(s..2s-1) X =
    M^s M^(0..s-1) X``), then block by block; once a block is exactly zero (the powers of a
    Schur ``M`` underflow) the terms stop and ``ρ`` stays constant.
    """
    nx = M.shape[0]
    X = np.hstack([H0, GR])
    a = np.zeros((T, nx))  # |M^k H0| 1
    b = np.zeros((T, nx))  # |M^k GR| 1
    limit = max(1, _CHUNK // max(X.size, 1))
    blk = X[None]
    Mp = M.copy()
    while blk.shape[0] < min(T, limit):
        new = (Mp @ blk)[: T - blk.shape[0]]
        blk = np.concatenate([blk, new])
        if not new.any():
            break
        Mp = Mp @ Mp
    step = np.linalg.matrix_power(M, blk.shape[0])
    start = 0
    while start < T:
        n = min(blk.shape[0], T - start)
        absb = np.abs(blk[:n])
        a[start : start + n] = absb[:, :, :nx].sum(axis=2)
        b[start : start + n] = absb[:, :, nx:].sum(axis=2)
        if not blk[n - 1].any():
            break
        start += n
        blk = step @ blk
    rho = a
    rho[1:] += np.cumsum(b[:-1], axis=0)
    return rho


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
    return (excess > tol).any(axis=-1)


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
