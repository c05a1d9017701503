"""Interval estimation by reachability analysis of an H∞ observer's error [Tang2019, Section III].

[Tang2019, Algorithm 1, Theorem 2, eqs. (10), (13), (21)-(26)]; the gain by [Tang2019,
Theorem 1, problem (20)] (:mod:`ivobs.design.hinf`) or the radius gain
(:mod:`ivobs.design.radius`). The observer itself, its rounding bound and what
``reachability`` shares with ``zonotope`` are in :mod:`ivobs.estimators._luenberger`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_int
from ..linalg import UNIT_ROUNDOFF
from ..model import LinearSystem
from ..sets import Box
from ..sets.rounding import enclose, mid_rad, product_error, up, upper
from . import register
from ._luenberger import DataFreeBounds, Gain, ObserverDesign, ObserverEstimator
from .base import check_size
from .state import OnlineState, Step, evolve

__all__ = ["Reachability", "ReachabilityDesign", "ReachabilityState"]

TAIL = 1e-3
"""Default memory: the smallest ``K`` with ``‖ |(A - LC)^K| ‖∞ <= TAIL`` (see ``memory``)."""

MAX_MEMORY = 500
"""Upper limit of the default memory (slowly converging gains)."""

SETTLED = 2.0**-40
"""Algorithm 1's data-free radius is computed until ``‖ |M^k [H0, G R]| 1 ‖∞`` falls below this
fraction of ``‖s_k‖∞``; what is left is bounded as rounding (a rounding-level widening)."""

MAX_TERMS = 1 << 16
"""At most this many steps of that radius are computed (slowly converging gains); the rest is
bounded as rounding too (sound, wider)."""

EXACT, WINDOW = 0, 1
"""Modes of :class:`ReachabilityState`: Algorithm 1's exact state, or the finite-memory window."""


@dataclass(frozen=True)
class ReachabilityDesign(ObserverDesign):
    """The observer's design (:class:`~ivobs.estimators._luenberger.ObserverDesign`) and
    ``memory``: ``K``, the window of exactly propagated terms for time-varying bounds and
    missing samples."""

    memory: int


@dataclass(frozen=True)
class ReachabilityState(OnlineState):
    """``x[k] ∈ x̂[k] ± ρ[k]``: the observer's state ``xh`` (``x̂[k]``) and what gives ``ρ[k]``.

    ``mode``: :data:`EXACT` (constant bounds, every measurement used so far): ``ρ[k]`` is
    Algorithm 1's data-free radius plus the rounding so far, ``a_L qL + a_x qx``
    (:class:`~ivobs.estimators._observer_rounding.Channels`); then :data:`WINDOW`: ``slots``
    ``(n_s, nx, 2 nx + nd + ny)``, slot ``j`` is ``[Φ(k, j) diag ρ_j, Φ(k, j+1) [G_j diag r_j,
    L_j diag e_ν, diag ξ_j]]`` for the last ``K`` steps ``j`` (oldest first), ``err``
    ``(n_s, 2, nx)`` bounds the rounding of their row sums (both parts)."""

    xh: np.ndarray
    qL: float
    qx: float
    mode: int
    slots: np.ndarray
    err: np.ndarray


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

    Observer [Tang2019, eq. (10)] (:mod:`~ivobs.estimators._luenberger`), ``d ∈ [c - r, c + r]``::

        x̂[k+1] = A x̂[k] + B u[k] + E c[k] + L (y[k] - C x̂[k] - D u[k] - F c[k]),
        x̂[0] = center(x0)

    Its error ``e = x - x̂`` obeys ``e+ = M e + G δ``, ``M = A - L C``, ``G = E - L F``,
    ``|δ| <= r``, so [Tang2019, eqs. (21)-(26), Algorithm 1] ``x[k] ∈ x̂[k] ± ρ[k]`` with the
    exact interval hull of the reachable set::

        ρ[k] = |M^k| h0 + Σ_{i<k} |M^i G| r,           h0 = radius(x0)

    ([Tang2019, Property 4]: ``Box(<0, X>)`` has radius ``|X| 1``; ``|·|`` elementwise), from
    ``X_k = M^k [H0, G diag r]`` and the running sum ``s_k = Σ_{i<k} |M^i G| r``:
    ``ρ[k] = |X_k^H| 1 + s_k``. It does not depend on the data: it is computed once, as far as
    a run needs it, until ``X_k`` is negligible, and then stays constant.

    **Rounding, proven** (the observer's: :mod:`~ivobs.estimators._luenberger`). ``X_{k+1} =
    fl(M X_k)`` differs from ``M X_k`` by ``E_k``, ``|E_k| <= product_error(|M| |X_k|)``. Those
    errors enter the error set as ``Σ_j M^{k-1-j} ξ_j`` with ``‖ξ_j‖_s <= ‖|E_j^H| 1‖_s +
    Σ_{i<j} ‖|E_i^G| 1‖_s`` (a term ``|M^a G R|`` of the sum is computed with ``a`` roundings; the
    ones of the same age are the same matrix), plus the exact matrices' difference
    ``ΔM ρ + ΔG r``, plus the observer's rounding ``ε``; ``‖v‖_s = ‖S⁻¹ v‖∞`` is the scaled norm
    of :class:`~ivobs.estimators._observer_rounding.Channels`. Their sum is its ball ``a_L q_L +
    a_x q_x`` (``|M^i| s <= a_x λ^i``, the exact powers of the float ``M``): ``x[k] ∈ x̂[k] ±
    (ρ[k] + a_L q_L[k] + a_x q_x[k])``, every sum rounded up. Where ``X_k`` is dropped
    (negligible), its remainder ``M X_k`` is one more such ``E_k``.

    **Data used (prediction form):** the box of ``x[k]`` uses ``u[0..k-1]``, ``y[0..k-1]``
    (the paper's convention); ``y[k]`` enters the box of ``x[k+1]``.

    **Time-varying or measurement-dependent bounds ``r[k]``, missing samples:** with missing
    components of ``y[k]`` the step uses the gain of the outputs present
    (:func:`~ivobs.estimators._luenberger.pattern_gain`: ``L_k``, ``M_k = A - L_k C``,
    ``G_k = E - L_k F``), so the error dynamics become time-varying. Sound finite-memory form:
    with ``Φ(k, j) = M_{k-1} ... M_j`` and any ``j <= k``,

        e_k ∈ Φ(k, j) Box(ρ_j) ⊕ ⊕_{j<=i<k} Φ(k, i+1) (G_i <0, diag r_i> ⊕ Box(ξ_i)),

    ``ξ_i`` the step's rounding (above), so ``ρ[k]`` is bounded by every ``j`` of the window of
    the last ``K = memory`` steps, each term propagated with the *actual* ``M_i``; ``ρ[k]`` is
    the elementwise minimum of these bounds (for constant ``M`` at least as tight as
    ``ρ_k <= Σ_{i<K} |M^i G| r_{k-1-i} + |M^K| ρ_{k-K}``). Their float products carry their
    rounding bounds (``|M_i|`` times the previous bound plus ``product_error``; a bound that
    grows makes its term lose the minimum, never the containment). Algorithm 1's state is kept
    until the first missing (or inconsistent) sample; then ``ρ[k]`` starts the window.

    **Interval matrices** (``supports_uncertain``; docs/uncertain.md): the gain is designed for
    the nominal matrices; the plant adds ``w = ΔA x + ΔB u`` to the state and ``v = ΔC x +
    ΔD u`` to the output, so ``e+ = M e + G δ + w − L v``: a disturbance ``[d; w; v]`` through
    ``[G, I, −L]`` whose radii ``w̄``, ``v̄`` come from the box of ``x[k]`` at each step
    (:mod:`ivobs.estimators._uncertain`, rounded upwards). Time-varying radii are what the
    finite-memory form handles (sound for every window): it runs from the first step.

    **Inconsistent data:** ``y[k]`` is inconsistent when
    ``|y[k] - C x̂[k] - D u[k] - F c[k]| > |C| ρ[k] + |F| r[k]`` (proven, its rounding
    included); it is then reported and treated as missing.

    Parameters
    ----------
    sys : time-invariant discrete-time :class:`~ivobs.LinearSystem`
    x0 : Box, prior box on ``x[0]`` ([Tang2019]: ``x0 ∈ <p0, H0>``)
    L : (nx, ny) observer gain, ``A - LC`` Schur, optional (the papers' comparisons "with the
        same gain"; default: designed, see ``gain``)
    gain : ``"radius"`` (default; the gain minimising the steady-state box,
        :mod:`ivobs.design.radius`), ``"hinf"`` (the H∞ gain of [Tang2019, Theorem 1, problem
        (20)] by Riccati equations) or ``"hinf-lmi"`` (the same problem by its LMI, as the
        paper): the design when ``L`` is not given (docs/gains.md)
    memory : window ``K`` for time-varying bounds / missing samples (default: smallest ``K``
        with ``‖ |M^K| ‖∞ <= 1e-3``, at most 500). Larger: tighter after a missing sample for a
        slowly converging gain, at ``O(K nx^2 (nx + nd))`` work per step
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
        K = default_memory(self._full.M) if K is None else K
        self.design = ReachabilityDesign(**observer.as_dict(), memory=K)
        assert self.x0 is not None
        self._xc, self._h0 = mid_rad(self.x0.lo, self.x0.hi)
        self._free = None
        if self._const is not None:
            r = self._const[1]
            X0 = np.hstack([np.diag(self._h0), self._full.G * r])
            rows = upper(np.abs(X0[:, self.sys.nx :]).sum(axis=1), 2)
            e0 = float(up(UNIT_ROUNDOFF * self._channels.norm(rows)))
            start = (X0, np.zeros(self.sys.nx), e0, 0)  # (X_k, s_k, Σ_{i<k} ‖E_i^G‖_s, k)
            self._free = DataFreeBounds(start, self._algorithm1, self._xc)

    def _algorithm1(self, state: Any) -> tuple[np.ndarray, np.ndarray, float, Any]:
        """One step of [Tang2019, Algorithm 1] without data: ``ρ[k] = |X_k^H| 1 + s_k``,
        ``yb = |C| ρ + |F| r`` and the rounding ``e[k]`` it adds (class docstring), then
        ``X_{k+1} = M X_k``, ``s_{k+1} = s_k + |X_k^G| 1``."""
        X, s, cum, k = state
        g, r, ch = self._full, self._const[1], self._channels  # type: ignore[index]
        C, nx, nd = self._mats[2], self.sys.nx, r.shape[0]
        aH = upper(np.abs(X[:, :nx]).sum(axis=1), nx)
        aG = upper(np.abs(X[:, nx:]).sum(axis=1), nd)
        rho = up(aH + s)  # [Tang2019, eq. (21)]
        yb = upper(np.abs(C) @ rho + self._absF @ r, nx + nd)
        mismatch = ch.norm(upper(g.dM @ rho + g.dG @ r, nx + nd))  # (A - LC - M) e, ...
        if not X.any():  # M^k X0 is gone: ρ stays
            return rho, yb, float(upper(cum + mismatch, 2)), None
        X_next = g.M @ X
        eH = product_error(g.absM @ aH, nx)  # fl(M X) - M X
        eG = product_error(g.absM @ aG, nx)
        left = upper(np.abs(X_next).sum(axis=1), nx + nd)
        s_next = up(s + aG)
        if left.max() <= SETTLED * s_next.max() or k + 1 >= MAX_TERMS:
            eH = eH + upper(np.abs(X_next[:, :nx]).sum(axis=1), nx)  # dropped: M X_k is its error
            eG = eG + upper(np.abs(X_next[:, nx:]).sum(axis=1), nd)
            X_next = np.zeros_like(X)
        e = float(upper(ch.norm(upper(eH, 2)) + cum + mismatch, 3))
        return rho, yb, e, (X_next, s_next, float(up(cum + ch.norm(upper(eG, 2)))), k + 1)

    # -- online --------------------------------------------------------------------------------
    def _initial_state(self) -> ReachabilityState:
        nx, ng = self.sys.nx, self._full.G.shape[1]  # G̃ = [G, I, -L] with interval matrices
        ny = self.sys.ny
        return ReachabilityState(
            xh=self._xc.copy(),
            qL=0.0,
            qx=0.0,
            mode=EXACT if self._free is not None else WINDOW,
            slots=np.zeros((0, nx, 2 * nx + ng + ny)),
            err=np.zeros((0, 2, nx)),
        )

    def _step(
        self, state: ReachabilityState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ReachabilityState]:
        xh, ch = state.xh, self._channels
        if state.mode == EXACT:  # Algorithm 1: ρ[k] data-free, plus the rounding so far
            free, e = self._free.at(state.k)  # type: ignore[union-attr]
            both = ch.widen(free, state.qL, state.qx)  # [ρ; |C| ρ + |F| r]
            rho, ybound = both[: xh.shape[0]], both[xh.shape[0] :]
            c, r = self._const  # type: ignore[misc]
        else:
            rho = self._window_radius(state)
            c, r = self._bounds(state.k, y_k, *enclose(xh, rho), u_k)
            ybound = upper(np.abs(self._mats[2]) @ rho + self._absF @ r, rho.shape[0] + r.shape[0])
        lo, hi = enclose(xh, rho)
        xh_next, eps, e_nu, inconsistent, gain = self._observe(xh, u_k, y_k, c, ybound)
        if state.mode == EXACT and gain is self._full:  # the rounding joins q_L, q_x
            qL = ch.L.next(state.qL, max(e_nu.tolist()))
            sigma = (ch.norm(eps) + e + ch.betaL * state.qL) * (1.0 + 4.0 * UNIT_ROUNDOFF)
            return Step(evolve(state, xh=xh_next, qL=qL, qx=ch.x.next(state.qx, sigma)), lo, hi)
        xi = upper(eps + gain.dM @ rho + gain.dG @ r, rho.shape[0] + r.shape[0] + 2)
        rounding = np.hstack([gain.L * e_nu, np.diag(xi)])  # L_k η + ξ_k
        new = self._window_step(state, xh_next, rho, r, gain, rounding)
        return Step(new, lo, hi, inconsistent)

    def _window_radius(self, state: ReachabilityState) -> np.ndarray:
        """``ρ[k]``: the smallest bound of the window (class docstring)."""
        if not state.slots.shape[0]:  # step 0 of a run that starts windowed
            return self._h0
        nx = self.sys.nx
        S = np.abs(state.slots)
        h = S[:, :, :nx].sum(axis=2) + state.err[:, 0]
        g = S[:, :, nx:].sum(axis=2) + state.err[:, 1]
        suffix = np.cumsum(g[::-1], axis=0)[::-1]  # Σ over the slots j' >= j
        rho: np.ndarray = upper(h + suffix, S.shape[2] + S.shape[0] + 2).min(axis=0)
        return rho

    def _window_step(
        self,
        state: ReachabilityState,
        xh_next: np.ndarray,
        rho: np.ndarray,
        r: np.ndarray,
        gain: Gain,
        rounding: np.ndarray,
    ) -> ReachabilityState:
        """The window moves on by one step with ``M_k`` (class docstring); a new slot
        ``[M_k diag ρ_k, G_k diag r_k, L_k diag e_ν, diag ξ_k]`` (the disturbance and rounding
        of step ``k`` enter ``e[k+1]`` unpropagated)."""
        nx = self.sys.nx
        slots, err = state.slots, state.err
        if state.mode == EXACT:  # the first missing sample: ρ_k (ball included) starts it
            slots, err = slots[:0], err[:0]
        S = np.abs(slots)
        w = S.shape[2]
        rows = np.stack([S[:, :, :nx].sum(axis=2), S[:, :, nx:].sum(axis=2)], axis=1)
        err = upper(err @ gain.absM.T + product_error(upper(rows, w) @ gain.absM.T, nx), nx + 2)
        G = np.hstack([gain.G * r, rounding])  # (L_k diag e_ν: products, rounded)
        new = np.hstack([gain.M * rho, G])
        new_err = np.stack(
            [product_error(gain.absM @ rho, 1), product_error(np.abs(G).sum(axis=1), G.shape[1])]
        )
        slots = np.concatenate([gain.M @ slots, new[None]])
        err = np.concatenate([err, new_err[None]])
        if slots.shape[0] > self.design.memory:  # the oldest term leaves
            slots, err = slots[1:], err[1:]
        return evolve(state, xh=xh_next, qL=0.0, qx=0.0, mode=WINDOW, slots=slots, err=err)
