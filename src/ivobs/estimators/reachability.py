"""Interval estimation by reachability analysis of an H∞ observer's error [Tang2019, Section III].

[Tang2019, Algorithm 1, Theorem 2, eqs. (10), (13), (21)-(26)]; the gain by [Tang2019,
Theorem 1, problem (20)] (:mod:`ivobs.design.hinf`). The observer itself and what
``reachability`` shares with ``zonotope`` are in :mod:`ivobs.estimators._luenberger`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._validate import as_int
from ..model import LinearSystem
from ..sets import Box
from . import register
from ._luenberger import (
    ObserverDesign,
    ObserverEstimator,
    consistent,
    observer_bounds,
    observer_filter,
)
from ._recursion import SplitFilter, redo_streams
from .base import check_size
from .state import OnlineState, Step, evolve

__all__ = ["Reachability", "ReachabilityDesign", "ReachabilityState", "radius_sequence"]

TAIL = 1e-3
"""Default memory: the smallest ``K`` with ``‖ |(A - LC)^K| ‖∞ <= TAIL`` (see ``memory``)."""

MAX_MEMORY = 500
"""Upper limit of the default memory (slowly converging gains)."""

EXACT, WINDOW = 0, 1
"""Modes of :class:`ReachabilityState`: Algorithm 1's exact state, or the finite-memory window."""

_CHUNK = 1 << 21
"""Floats per block when the data-independent radius sequence is computed (memory bound)."""


@dataclass(frozen=True)
class ReachabilityDesign(ObserverDesign):
    """The observer's design (:class:`~ivobs.estimators._luenberger.ObserverDesign`) and
    ``memory``: ``K``, the window of exactly propagated terms for time-varying bounds and
    missing samples."""

    memory: int


@dataclass(frozen=True)
class ReachabilityState(OnlineState):
    """``x[k] ∈ x̂[k] ± ρ[k]``: the observer's state ``xh`` (``x̂[k]``) and what gives ``ρ[k]``.

    ``mode``: :data:`EXACT` (constant bounds, no missing sample yet): Algorithm 1's
    ``X = [M^k H0, M^k G diag r]`` and ``s = Σ_{i<k} |M^i G| r``; then :data:`WINDOW`:
    ``Z = Φ(k, k0) Z0`` while complete (no columns once its oldest term left), and ``slots``
    ``(n_s, nx, nx + nd)``: slot ``j`` is ``[Φ(k, j) diag ρ_j, Φ(k, j+1) G_j diag r_j]`` for the
    last ``K`` steps ``j`` (oldest first)."""

    xh: np.ndarray
    mode: int
    X: np.ndarray
    s: np.ndarray
    Z: np.ndarray
    slots: np.ndarray


def default_memory(M: np.ndarray, tail: float = TAIL, cap: int = MAX_MEMORY) -> int:
    """Smallest ``K >= 1`` with ``max row sum |M^K| <= tail`` (at most ``cap``)."""
    P = M.copy()
    for K in range(1, cap + 1):
        if np.abs(P).sum(axis=1).max(initial=0.0) <= tail:
            return K
        P = M @ P
    return cap


@register
class Reachability(ObserverEstimator):
    """Reachability-based interval estimation [Tang2019, Algorithm 1, Theorem 2].

    Observer [Tang2019, eq. (10)], with ``d ∈ [c - r, c + r]`` re-centred (``G = E - L F``)::

        x̂[k+1] = A x̂[k] + B u[k] + L (y[k] - C x̂[k] - D u[k]) + G c[k],   x̂[0] = center(x0)

    Its error ``e = x - x̂`` obeys ``e+ = M e + G δ``, ``M = A - L C``, ``|δ| <= r``, so
    [Tang2019, eqs. (21)-(26), Algorithm 1] ``x[k] ∈ x̂[k] ± ρ[k]`` with the exact interval hull
    of the reachable set::

        ρ[k] = |M^k| h0 + Σ_{i<k} |M^i G| r[k-1-i],        h0 = radius(x0)   (H0 = diag h0)

    ([Tang2019, Property 4]: ``Box(<0, X>)`` has radius ``|X| 1``; ``|·|`` elementwise).
    Over-approximation happens only in these Box operations [Tang2019, Remark 1].

    **Data used (prediction form):** the box of ``x[k]`` uses ``u[0..k-1]``, ``y[0..k-1]``
    (the paper's convention); ``y[k]`` enters the box of ``x[k+1]``.

    **Gain.** ``gain=``: ``"radius"`` (default; the gain minimising the steady-state box,
    :mod:`ivobs.design.radius`), ``"hinf"`` (the H∞ gain of [Tang2019, Theorem 1, problem
    (20)] by Riccati equations), ``"hinf-lmi"`` (the same problem by its LMI, as the paper);
    docs/gains.md. Or ``L=`` gives it
    explicitly (the papers' comparisons "with the same gain"); ``A - LC`` must be Schur.

    **Constant bounds, no missing sample:** Algorithm 1 exactly (``ρ`` by the running sums of
    ``|M^i G| r``; with :meth:`run` the whole sequence is computed once, data-independent
    (:func:`radius_sequence`), and ``x̂`` by the shared linear-filter kernel; batches
    ``(B, T, n)`` too).

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

    **Interval matrices** (``supports_uncertain``; docs/uncertain.md): the gain is designed for
    the nominal matrices; the plant adds ``w = ΔA x + ΔB u`` to the state and ``v = ΔC x +
    ΔD u`` to the output, so ``e+ = M e + G δ + w − L v``: a disturbance ``[d; w; v]`` through
    ``[G, I, −L]`` whose radii ``w̄``, ``v̄`` come from the box of ``x[k]`` at each step
    (:mod:`ivobs.estimators._uncertain`, rounded upwards). Time-varying radii are what the
    finite-memory form handles (sound for every window): it runs from the first step.

    **Inconsistent data:** ``y[k]`` is consistent only if
    ``|y[k] - C x̂[k] - D u[k] - F c[k]| <= |C| ρ[k] + |F| r[k]``; otherwise it is reported and
    treated as missing.

    Parameters
    ----------
    sys : time-invariant discrete-time :class:`~ivobs.LinearSystem`
    x0 : Box, prior box on ``x[0]`` ([Tang2019]: ``x0 ∈ <p0, H0>``)
    L : (nx, ny) observer gain, optional (default: designed, see ``gain``)
    gain : ``"radius"`` (default), ``"hinf"`` or ``"hinf-lmi"``: the design when ``L`` is not
        given (docs/gains.md)
    memory : window ``K`` for time-varying bounds / missing samples (default: smallest ``K``
        with ``‖ |M^K| ‖∞ <= 1e-3``, at most 500)
    """

    name = "reachability"
    order = 20
    summary = "Luenberger observer + exact interval hull of the error's reachable set"
    reference = "[Tang2019, Algorithm 1, Theorems 1-2, eqs. (10), (13), (21)-(26)]"
    data_used = "prediction"
    supports_uncertain = True  # see "Interval matrices" in the docstring
    design: ReachabilityDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        memory: int | None = None,
        gain: str | None = None,
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        check_size(
            self.name,
            sys.nx,
            "propagates the exact interval hull of the error's "
            "reachable set, nx x (nx + nd) matrices (O(nx^3) work)",
        )
        K = None if memory is None else as_int("memory", memory, 1)
        observer = self._design_observer(L, gain)
        K = default_memory(self._M) if K is None else K
        self.design = ReachabilityDesign(**observer.as_dict(), memory=K)
        assert self.x0 is not None
        self._xc = self.x0.center.copy()
        self._h0 = self.x0.radius.copy()
        self._vec: tuple[int, np.ndarray, np.ndarray, SplitFilter] | None = None
        self._fast = self._fast_operators()

    def _fast_operators(self) -> tuple[np.ndarray, ...] | None:
        """Design-time constants of the common step (constant bounds, complete ``y``): the
        observer and its innovation as one product (:meth:`_fused_observer`), the selector
        ``Σ`` giving both row sums of ``|X| = |[M^k H0, M^k G diag r]|`` in one product, and
        ``|F| r`` (a list of floats: the fast step tests in floats). None when the bounds are
        not constant (the general step)."""
        fused = self._fused_observer()
        if fused is None or self._const is None:
            return None
        nx = self._M.shape[0]
        sel = np.zeros((nx + self._G.shape[1], 2))
        sel[:nx, 0] = 1.0
        sel[nx:, 1] = 1.0
        return *fused, sel, (self._absF @ self._const[1]).tolist()

    # -- online --------------------------------------------------------------------------------
    def _initial_state(self) -> ReachabilityState:
        nx, nd = self.sys.nx, self._G.shape[1]  # d̃ = [d; w; v] with interval matrices
        if self._const is not None:  # exact Algorithm 1: X = [M^k H0, M^k G diag r]
            X = np.hstack([np.diag(self._h0), self._G * self._const[1]])
            Z = np.zeros((nx, 0))
        else:
            X, Z = np.zeros((nx, 0)), np.diag(self._h0)
        return ReachabilityState(
            xh=self._xc.copy(),
            mode=EXACT if self._const is not None else WINDOW,
            X=X,
            s=np.zeros(nx),
            Z=Z,
            slots=np.zeros((0, nx, nx + nd)),
        )

    def _radius(self, state: ReachabilityState) -> np.ndarray:
        """``ρ[k]``: Algorithm 1's running sum while exact, else the window's bound."""
        nx = self.sys.nx
        if state.mode == EXACT:
            rho: np.ndarray = np.abs(state.X[:, :nx]).sum(axis=1) + state.s
            return rho
        S = np.abs(state.slots)
        g = S[:, :, nx:].sum(axis=2)  # (n_s, nx)
        suffix = np.cumsum(g[::-1], axis=0)[::-1]  # Σ over slots j' >= j
        cand = S[:, :, :nx].sum(axis=2) + suffix
        if not state.Z.shape[1]:
            window: np.ndarray = cand.min(axis=0)
            return window
        z: np.ndarray = np.abs(state.Z).sum(axis=1) + (suffix[0] if suffix.shape[0] else 0.0)
        return np.minimum(z, cand.min(axis=0)) if cand.shape[0] else z

    def _step(
        self, state: ReachabilityState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ReachabilityState]:
        if self._fast is not None and state.mode == EXACT:
            fast = self._fast_step(state, u_k, y_k)
            if fast is not None:
                return fast
        xh = state.xh
        rho = self._radius(state)
        lo, hi = xh - rho, xh + rho

        A, B, C, D, E, F = self._mats
        c, r = self._bounds(state.k, y_k, lo, hi, u_k)
        obs = ~np.isnan(y_k)
        full = bool(obs.all())
        if full and self._fast is not None:  # the product of the fast step
            out = self._fast[0].dot(np.concatenate((xh, u_k, y_k)))
            out += self._fast[1]
            innov = out[xh.shape[0] :]
        else:
            innov = (y_k if full else np.where(obs, y_k, 0.0)) - C @ xh - D @ u_k - F @ c
        inconsistent = False
        if (full or obs.any()) and not consistent(
            innov, self._absC @ rho + self._absF @ r, y_k, obs
        ):
            inconsistent = True
            obs, full = np.zeros_like(obs), False
        Lk, Mk, Gk = self._gain_at(obs)
        if full and self._fast is not None:
            xh_next = out[: xh.shape[0]]
        elif full:  # [Tang2019, eq. (10)]
            xh_next = A @ xh + B @ u_k + E @ c + Lk @ innov
        else:
            xh_next = A @ xh + B @ u_k + E @ c + Lk @ np.where(obs, innov, 0.0)

        if state.mode == EXACT and full:  # Algorithm 1
            nx = self.sys.nx
            new = replace(
                state, xh=xh_next, s=state.s + np.abs(state.X[:, nx:]).sum(axis=1), X=Mk @ state.X
            )
        else:
            new = self._window_step(state, xh_next, rho, r, Mk, Gk)
        return Step(new, lo, hi, inconsistent)

    def _fast_step(
        self, state: ReachabilityState, u_k: np.ndarray, y_k: np.ndarray
    ) -> Step[ReachabilityState] | None:
        """Algorithm 1 with constant bounds and a complete, consistent ``y[k]``: the same
        recursion as :meth:`_step` in a few fused products (:meth:`_fast_operators`); ``None``
        (the general step) for a missing or inconsistent measurement."""
        O, o, sel, Fr = self._fast  # type: ignore[misc]
        xh = state.xh
        nx = xh.shape[0]
        sums = np.abs(state.X).dot(sel)  # |M^k H0| 1 and |M^k G diag r| 1
        rho = sums[:, 0] + state.s
        out = O.dot(np.concatenate((xh, u_k, y_k)))
        out += o
        innov = out.tolist()[nx:]  # |y - C x̂ - D u - F c| - (|C| ρ + |F| r), in floats
        for i, b, f in zip(innov, self._absC.dot(rho).tolist(), Fr):
            if not abs(i) - (b + f) <= 0.0:  # maybe inconsistent (or NaN): the general step
                return None
        new = evolve(state, xh=out[:nx], X=self._M.dot(state.X), s=state.s + sums[:, 1])
        lo, hi = [], []  # (a loop: cheaper than comprehensions on three numbers)
        for a, b in zip(xh.tolist(), rho.tolist()):
            lo.append(a - b)
            hi.append(a + b)
        return Step(new, lo, hi, False)

    def _window_step(
        self,
        state: ReachabilityState,
        xh_next: np.ndarray,
        rho: np.ndarray,
        r: np.ndarray,
        Mk: np.ndarray,
        Gk: np.ndarray,
    ) -> ReachabilityState:
        """The finite-memory bound (class docstring): the window moves on by one step."""
        nx = self.sys.nx
        if state.mode == EXACT:  # first missing sample: box the disturbance part, go on windowed
            state = replace(
                state,
                mode=WINDOW,
                Z=np.hstack([state.X[:, :nx], np.diag(state.s)]),
                X=np.zeros((nx, 0)),
                s=np.zeros(nx),
            )
        slots = np.concatenate([state.slots, np.zeros((1, nx, nx + self._G.shape[1]))])
        slots[-1, :, :nx] = np.diag(rho)
        slots = Mk @ slots
        slots[-1, :, nx:] = Gk * r  # d[k] enters e[k+1] unpropagated
        Z = Mk @ state.Z
        if slots.shape[0] > self.design.memory:  # oldest slot leaves: Z loses a term
            slots = slots[1:]
            Z = np.zeros((nx, 0))
        return replace(state, xh=xh_next, slots=slots, Z=Z)

    # -- offline, vectorised --------------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        """Algorithm 1 over a record or a batch: ``ρ`` once (:func:`radius_sequence`, kept for
        the record length), ``x̂`` by the shared linear-filter kernel; streams of a batch with
        an inconsistent measurement are redone by the loop."""
        if self._const is None or not y.shape[-2] or np.isnan(y).any():
            return None  # (an empty record: the loop)
        c, r = self._const
        T = y.shape[-2]
        if self._vec is None or self._vec[0] != T:
            rho = radius_sequence(self._M, np.diag(self._h0), self._G * r, T)
            yrad = rho @ self._absC.T + self._absF @ r  # |C| ρ + |F| r: consistency of y
            filt = (
                self._vec[3]
                if self._vec is not None
                else observer_filter(self._M, self._mats, self._L, c)
            )
            self._vec = (T, rho, yrad, filt)
        _, rho, yrad, filt = self._vec
        out = observer_bounds(
            self._M, self._mats, self._L, c, self._xc, u, y, rho, yrad, filt, streams=True
        )
        if out is None or len(out) == 2:
            return out
        return redo_streams(self, u, y, t, *out)


def radius_sequence(M: np.ndarray, H0: np.ndarray, GR: np.ndarray, T: int) -> np.ndarray:
    """``ρ[k] = |M^k H0| 1 + Σ_{i<k} |M^i GR| 1`` for ``k < T`` [Tang2019, eq. (21)], shape
    ``(T, nx)``.

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
