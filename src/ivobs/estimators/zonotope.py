"""Zonotope-based set-membership estimation [Tang2019, Section IV, Proposition 1, eqs. (33)-(35)]
(the zonotopic observer of [Combastel2015]), with the reduction operator of [Tang2019, Remark 2].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from typing import Any

import numpy as np

from .._validate import as_int, as_matrix
from ..errors import DesignError, IvobsError
from ..linalg import spectral_radius
from ..model import LinearSystem
from ..sets import Box, Zonotope
from . import register
from ._luenberger import ObserverDesign, ObserverEstimator, consistent, observer_bounds
from .base import check_size
from .state import OnlineState, Step, evolve

__all__ = ["ZonotopeDesign", "ZonotopeEstimator", "ZonotopeState"]

ORDER_PER_STATE = 10
"""Default order ``q = ORDER_PER_STATE * nx`` (generators kept by the reduction)."""

SETTLE_STEPS = 2000
"""Steps of the generator recursion (34b) iterated at design (more when ``A - LC`` is slow)."""

SEQUENCE_FLOATS = 1 << 21
"""Most floats kept of the data-independent generator sequence (34b) for ``step()``."""

WIDTH_STEPS = 60
"""Steps of (34b) over which the default gain is chosen when the reduction can grow."""

SETTLE_WORK = 2e9
"""Budget (multiply-adds) of that iteration: larger systems are iterated for fewer steps."""


def settle(
    M: np.ndarray, GR: np.ndarray, H0: np.ndarray, reduce: Any, steps: int
) -> tuple[int | None, np.ndarray]:
    """Iterate ``H[k+1] = [M ↓H[k], GR]`` ([Tang2019, eq. (34b)], constant bounds: no data) for
    at most ``steps`` steps, exactly as the estimator computes it. Returns the step at which
    ``H`` repeats an earlier value bitwise (a fixed point or a cycle, found by Brent's method:
    from then on the recursion repeats itself, so its widths are bounded by those seen) or
    ``None``, and the summed widths ``2 Σ |H[k]| 1`` of the steps iterated."""
    H, mark, power, lam = H0, H0, 1, 0
    sums = np.empty(steps + 1)
    sums[0] = 2.0 * np.abs(H0).sum()
    for k in range(1, steps + 1):
        H = np.hstack([M @ reduce(H), GR])
        sums[k] = 2.0 * np.abs(H).sum()
        lam += 1
        if H.shape == mark.shape and np.array_equal(H, mark):
            return k, sums[: k + 1]
        if lam == power:  # Brent: move the mark every power of two
            mark, power, lam = H, 2 * power, 0
    return None, sums


@dataclass(frozen=True)
class ZonotopeDesign(ObserverDesign):
    """The observer's design (:class:`~ivobs.estimators._luenberger.ObserverDesign`);
    ``order``: ``q`` of ``↓_{q,W}``; ``weight``: ``W`` [Tang2019, Remark 2]."""

    order: int
    weight: np.ndarray | None


@dataclass(frozen=True)
class ZonotopeState(OnlineState):
    """``x[k] ∈ <p, H>``: centre ``p`` (nx,) and generators ``H`` (nx, ·) of [Tang2019,
    eq. (34)]."""

    p: np.ndarray
    H: np.ndarray


@register
class ZonotopeEstimator(ObserverEstimator):
    """Zonotope set-membership estimator [Tang2019, Proposition 1, eq. (34)], with the
    reduction of [Tang2019, Remark 2].

    With ``y = C x + D u + F d``, adding ``L (y - C x - D u - F d) = 0`` to the state equation
    [Tang2019, eq. (33)] and re-centring ``d ∈ [c - r, c + r]`` (``d = c + diag(r) b``,
    ``|b| <= 1``)::

        p[k+1] = (A - LC) p[k] + B u[k] + L (y[k] - D u[k]) + (E - LF) c[k]          (34a)
        H[k+1] = [ (A - LC) ↓_{q,W} H[k],  (E - LF) diag(r[k]) ]                      (34b)

    ``x[0] ∈ <p0, H0>`` with ``p0 = center(x0)``, ``H0 = diag(radius(x0))``. [Tang2019]'s (34b)
    writes ``E, -LF`` without the bounds' scaling (it takes ``W = <0, Dw>``, ``V = <0, Dv>``);
    the generators must be scaled by the bounds, as above. The box of ``x[k]`` is the interval
    hull ``p[k] ± |H[k]| 1`` [Tang2019, eq. (35), Property 4]. ``↓_{q,W}`` sorts generators by
    ``hᵀ W h``, keeps the ``q - nx`` largest and encloses the rest in a box
    (:meth:`ivobs.Zonotope.reduce`), so ``H`` has at most ``q + nd`` columns.

    **Data used (prediction form):** the box of ``x[k]`` uses ``u[0..k-1]``, ``y[0..k-1]``.

    **Gain.** ``gain=``: ``"radius"`` (default; the gain minimising the steady-state box,
    :mod:`ivobs.design.radius`), ``"hinf"`` (the H∞ gain of [Tang2019, Theorem 1, problem
    (20)] by Riccati equations), ``"hinf-lmi"`` (the same problem by its LMI, as the paper);
    docs/gains.md. Or ``L=`` explicitly
    (e.g. the paper's ``L1`` for [Tang2019, Theorem 6]: the reachability box is inside this one
    with the same gain); ``A - LC`` must be Schur.

    **Missing samples** (NaN components of ``y[k]``): the gain columns of the missing outputs are
    zero at that step, ``L_k``, and (34) uses ``A - L_k C``, ``E - L_k F``: the set is still an
    outer bound. **Time-varying / measurement-dependent bounds:** ``c[k], r[k]`` at each step.
    **Inconsistent data:** ``y[k]`` must satisfy ``|y - C p - D u - F c| <= |C H| 1 + |F| r``;
    otherwise it is reported and treated as missing.

    **Interval matrices** (``supports_uncertain``; docs/uncertain.md): the gain is designed for
    the nominal matrices and the matrix uncertainty is a generator term. The plant is the
    nominal one plus ``w = ΔA x + ΔB u`` in the state and ``v = ΔC x + ΔD u`` in the output,
    so the error obeys ``e+ = M e + G δ + w − L v``: (34b) appends ``[diag(w̄), −L diag(v̄)]``
    with ``w̄ >= |w|``, ``v̄ >= |v|`` bounded from the box of ``x[k]``
    (:mod:`ivobs.estimators._uncertain`, rounded upwards), and the consistency test widens by
    ``v̄``. Every step is the loop (the term depends on the box).

    **Vectorised run** (constant bounds, no missing sample): ``H[k]`` does not depend on the
    data, so its radii are computed once (stopping at a fixed point of (34b)) and ``p[k]`` by a
    vectorised recursion; batches ``(B, T, n)`` share them.

    Parameters
    ----------
    sys : time-invariant discrete-time :class:`~ivobs.LinearSystem`
    x0 : Box, prior box on ``x[0]``
    L : (nx, ny) observer gain, optional (default: designed, see ``gain``)
    gain : ``"radius"``, ``"hinf"`` or ``"hinf-lmi"``: the design when ``L`` is not given
        (docs/gains.md). Default: the radius gain, or the H∞ gain when ``|A - LC|`` is not
        Schur and the H∞ gain's reduced zonotope is narrower over 60 steps of (34b)
    order : ``q >= nx``, generators kept by the reduction (default ``10 nx``: on the paper's
        servo motor the widths are within a few per mille of much larger orders from ``q = 10 nx``
        on, while the cost per step grows with ``q``). Larger ``q`` approaches Algorithm 1
        ([Tang2019, Theorem 6]: it is never tighter). The part the reduction boxes is
        propagated like ``|A - LC|``: when ``|A - LC|`` is Schur every order keeps the widths
        bounded; otherwise a small order may not (the servo motor with ``q = 4``: summed width
        44.7 at k = 50, 1,518 at k = 2,000). So, for constant bounds, the design iterates the
        data-independent recursion (34b), exactly as the run computes it, for 2,000 steps (up
        to 40,000 when ``A - LC`` converges slowly; systems too large for 2e9 multiply-adds are
        not checked) and accepts ``q`` when ``H`` repeats an earlier value (a fixed point or a
        cycle: the recursion then repeats itself forever) or its widths stopped growing (the
        last no larger than the largest of the second quarter: a sign, not a proof); otherwise
        it raises ``DesignError`` with the widths seen and the next order that settles.
        ``q = nx`` (a box at every step, propagated by ``|A - LC|``) is refused when
        ``|A - LC|`` is not Schur
    weight : (nx, nx) positive definite ``W`` of the reduction (default identity)
    """

    name = "zonotope"
    order = 30
    summary = "zonotope set-membership observer with order reduction"
    reference = "[Tang2019, Proposition 1, eqs. (33)-(35), Remark 2]; [Combastel2015]"
    data_used = "prediction"
    supports_uncertain = True  # see "Interval matrices" in the docstring
    design: ZonotopeDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        order: int | None = None,
        weight: Any = None,
        gain: str | None = None,
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        nx = sys.nx
        check_size(
            self.name,
            nx,
            "multiplies an nx x q generator matrix (q >= nx) and sorts its columns (O(nx^3) work)",
        )
        q = ORDER_PER_STATE * nx if order is None else as_int("order", order)
        if q < nx:
            raise IvobsError(
                f"order: expected q >= nx = {nx} generators ([Tang2019, Remark 2]), got {q}"
            )
        W = None
        if weight is not None:
            W = as_matrix("weight", weight, nx, nx)
            if not np.allclose(W, W.T) or np.linalg.eigvalsh(0.5 * (W + W.T)).min() <= 0:
                raise IvobsError("weight: expected a symmetric positive definite matrix W")
        assert self.x0 is not None
        self._p0 = self.x0.center.copy()
        self._H0 = np.diag(self.x0.radius)
        observer = self._design_observer(L, gain)
        self.design = ZonotopeDesign(**observer.as_dict(), order=q, weight=W)
        if L is None and gain is None and self._const is not None:
            self._gain_by_width()
        if q == nx and spectral_radius(np.abs(self._M)) >= 1.0:
            raise DesignError(
                f"order: q = nx = {nx} boxes the set at every step, so the boxes grow like "
                f"|A - LC|^k, whose spectral radius is {spectral_radius(np.abs(self._M)):.4g} "
                ">= 1 (they would diverge); use order > nx (default 10 nx)"
            )
        if self._const is not None:
            self._check_bounded()
        self._fused = self._fused_observer()
        self._gens: GeneratorSequence | None = None
        if self._fused is not None and self._const is not None:  # (34b) is data-independent
            C, GR = self._mats[2], self._G * self._const[1]
            self._gens = GeneratorSequence(
                self._H0.copy(), self._M, GR, C, self._absF @ self._const[1], self._reduce
            )

    def _gain_by_width(self) -> None:
        """Default gain: the radius gain minimises the box of Algorithm 1, which the zonotope
        reaches only up to its reduction; when ``|A - LC|`` is not Schur the boxed part of the
        reduction can grow (``order``), and another gain may give the narrower zonotope. Then
        the radius gain and the H∞ gain are both run through the data-independent recursion
        (34b) for :data:`WIDTH_STEPS` steps and the one with the smaller mean radius over the
        second half is kept (``design.gain`` says which)."""
        C, r, T = self._mats[2], self._const[1], WIDTH_STEPS  # type: ignore[index]
        work = T * self.sys.nx**2 * (self.design.order + self.sys.nd)
        if spectral_radius(np.abs(self._M)) < 1.0 or work > SETTLE_WORK:
            return
        widths = {}
        for gain in ("hinf", "radius"):  # the radius gain last: kept on a tie
            observer = self._design_observer(None, gain)  # cached: no second design
            self.design = replace(self.design, **observer.as_dict())
            widths[gain] = float(self._generator_radii(C, self._G * r, T)[0][T // 2 :].mean())
        if widths["hinf"] < widths["radius"]:
            observer = self._design_observer(None, "hinf")
            self.design = replace(self.design, **observer.as_dict())

    def _check_bounded(self) -> None:
        """Refuse an order whose reduced recursion (34b) is not shown bounded (see ``order``)."""
        M, GR = self._M, self._G * self._const[1]  # type: ignore[index]
        nx, q = self.sys.nx, self.design.order
        rho = spectral_radius(M)
        slow = int(30 * 37 / -np.log(rho)) if 0.0 < rho < 1.0 else 0
        steps = min(max(SETTLE_STEPS, slow), 20 * SETTLE_STEPS)
        if spectral_radius(np.abs(M)) < 1.0 or steps * nx * nx * (q + GR.shape[1]) > SETTLE_WORK:
            return  # |A - LC| Schur: bounded for every order (docs); too large: not checked
        at, sums = settle(M, GR, self._H0, self._reduce, steps)
        if at is not None or sums[-1] <= sums[steps // 4 : steps // 2 + 1].max() * (1.0 + 1e-9):
            return
        hint = ""
        for q2 in range(q + 1, min(q + 8, ORDER_PER_STATE * nx) + 1):
            at2, _ = settle(
                M, GR, self._H0, partial(_reduce, design=replace(self.design, order=q2)), steps
            )
            if at2 is not None:
                hint = f" (order = {q2} settles at k = {at2})"
                break
        k50 = min(50, steps)
        raise DesignError(
            f"order: q = {q} keeps {q - nx} generator(s) of the zonotope and boxes the others at "
            f"every step; the boxed part is propagated like |A - LC| (spectral radius "
            f"{spectral_radius(np.abs(M)):.4g} >= 1), and iterating the reduced recursion "
            f"(34b) (it does not depend on the data) for {steps} steps it neither settled nor "
            f"stopped growing: summed width {sums[k50]:.4g} at k = {k50}, "
            f"{sums[steps // 2]:.4g} at k = {steps // 2}, {sums[-1]:.4g} at k = {steps}; ivobs "
            f"cannot show that the boxes stay bounded: use a larger order{hint}"
        )

    def _reduce(self, H: np.ndarray) -> np.ndarray:
        """``↓_{q,W} H`` [Tang2019, Remark 2]."""
        return _reduce(H, self.design)

    # -- online --------------------------------------------------------------------------------
    def _initial_state(self) -> ZonotopeState:
        H0 = self._gens.seq[0][0] if self._gens else self._H0.copy()  # never modified: shared
        return ZonotopeState(p=self._p0.copy(), H=H0)

    def _step(
        self, state: ZonotopeState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ZonotopeState]:
        if self._fused is not None:
            fast = self._fast_step(state, u_k, y_k)
            if fast is not None:
                return fast
        p, H = state.p, state.H
        rad = np.abs(H).sum(axis=1)
        lo, hi = p - rad, p + rad
        A, B, C, _, E, _ = self._mats
        c, r = self._bounds(state.k, y_k, lo, hi, u_k)
        obs = ~np.isnan(y_k)
        p_full, innov = self._innovation(p, u_k, y_k, obs, c)
        inconsistent = False
        if obs.any():
            bound = np.abs(C @ H).sum(axis=1) + self._absF @ r
            if not consistent(innov, bound, y_k, obs):
                inconsistent = True
                obs, p_full = np.zeros_like(obs), None
        Lk, Mk, Gk = self._gain_at(obs)
        if p_full is not None:  # (34a), complete y: the product of the fast step
            p_next = p_full
        else:  # (34a) without the missing outputs
            p_next = A @ p + B @ u_k + E @ c + Lk @ np.where(obs, innov, 0.0)
        H_next = np.hstack([Mk @ self._reduce(H), Gk * r])  # (34b)
        return Step(replace(state, p=p_next, H=H_next), lo, hi, inconsistent)

    def _innovation(
        self, p: np.ndarray, u_k: np.ndarray, y_k: np.ndarray, obs: np.ndarray, c: np.ndarray
    ) -> tuple[np.ndarray | None, np.ndarray]:
        """``(p+, ν)``: (34a) and the innovation ``ν = y − C p − D u − F c`` of a complete
        ``y`` by the one product of :meth:`_fused_observer` (constant bounds), as the fast
        step; else ``(None, ν)`` with missing outputs read as 0."""
        _, _, C, D, _, F = self._mats
        if self._fused is not None and obs.all():
            O, o = self._fused
            out = O.dot(np.concatenate((p, u_k, y_k)))
            out += o
            return out[: p.shape[0]], out[p.shape[0] :]
        return None, np.where(obs, y_k, 0.0) - C @ p - D @ u_k - F @ c

    def _fast_step(
        self, state: ZonotopeState, u_k: np.ndarray, y_k: np.ndarray
    ) -> Step[ZonotopeState] | None:
        """:meth:`_step` with constant bounds and a complete ``y[k]`` inside its bounds: the
        generators from the kept sequence (:class:`GeneratorSequence`), (34a) as one product
        (:meth:`_fused_observer`); None (the general step) otherwise."""
        gen = None if self._gens is None else self._gens.at(state.k, state.H)
        if gen is None:
            return None
        rad, ybound, H_next = gen
        O, o = self._fused  # type: ignore[misc]
        p = state.p
        nx = p.shape[0]
        out = O.dot(np.concatenate((p, u_k, y_k)))  # as _innovation
        out += o
        excess = np.abs(out[nx:])  # |y - C p - D u - F c| - (|C H| 1 + |F| r)
        excess -= ybound
        for v in excess.tolist():
            if v > 0.0 or v != v:  # maybe inconsistent (or NaN): the general step decides
                return None
        return Step(evolve(state, p=out[:nx], H=H_next), p - rad, p + rad, False)

    # -- offline, vectorised --------------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        if self._const is None or np.isnan(y).any():
            return None
        c, r = self._const
        rad, crad = self._generator_radii(self._mats[2], self._G * r, y.shape[-2])
        yrad = crad + self._absF @ r  # |C H| 1 + |F| r: consistency of y
        return observer_bounds(self._M, self._mats, self._L, c, self._p0, u, y, rad, yrad)

    def _generator_radii(
        self, C: np.ndarray, GR: np.ndarray, T: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """``|H[k]| 1`` and ``|C H[k]| 1`` for ``k < T``: data-independent for constant bounds
        ([Tang2019, eq. (34b)]). A fixed point ``H[k+1] = H[k]`` ends the loop early."""
        rad = np.empty((T, self.sys.nx))
        crad = np.empty((T, self.sys.ny))
        H = self._H0.copy()
        for k in range(T):
            rad[k] = np.abs(H).sum(axis=1)
            crad[k] = np.abs(C @ H).sum(axis=1)
            H_next = np.hstack([self._M @ self._reduce(H), GR])
            if H_next.shape == H.shape and np.array_equal(H_next, H):
                rad[k + 1 :] = rad[k]
                crad[k + 1 :] = crad[k]
                break
            H = H_next
        return rad, crad


class GeneratorSequence:
    """The generators ``H[k]`` of (34b) from ``H0`` with constant bounds and complete data (they
    do not depend on the data), each with ``|H| 1`` and ``|C H| 1 + |F| r``, computed once by
    ``step()`` and kept up to their fixed point (:data:`SEQUENCE_FLOATS` at most)."""

    def __init__(
        self, H0: np.ndarray, M: np.ndarray, GR: np.ndarray, C: np.ndarray, Fr: np.ndarray,
        reduce: Callable[[np.ndarray], np.ndarray],
    ):  # fmt: skip
        self.M, self.GR, self.C, self.Fr, self.reduce = M, GR, C, Fr, reduce
        self.seq = [self.entry(H0)]
        self.fixed = False

    def entry(self, H: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return H, np.abs(H).sum(axis=1), np.abs(self.C @ H).sum(axis=1) + self.Fr

    def at(self, k: int, H: np.ndarray) -> tuple[np.ndarray, ...] | None:
        """``(|H| 1, |C H| 1 + |F| r, H[k+1])`` when ``H`` is this sequence's ``H[k]`` (the
        same object), else None."""
        seq = self.seq
        j = min(k, len(seq) - 1)
        if seq[j][0] is not H:
            return None
        _, rad, ybound = seq[j]
        if j + 1 < len(seq):
            return rad, ybound, seq[j + 1][0]
        if self.fixed:
            return rad, ybound, H
        if j != k:
            return None
        H_next = np.hstack([self.M @ self.reduce(H), self.GR])  # (34b), as _step
        if H_next.shape == H.shape and np.array_equal(H_next, H):
            self.fixed = True
            return rad, ybound, H
        if len(seq) * H.size < SEQUENCE_FLOATS:
            seq.append(self.entry(H_next))
        return rad, ybound, H_next


def _reduce(H: np.ndarray, design: ZonotopeDesign) -> np.ndarray:
    """``↓_{q,W} H`` [Tang2019, Remark 2] with the design's ``q`` and ``W``."""
    z = Zonotope._trusted(np.zeros(H.shape[0]), H)
    return z.reduce(design.order, design.weight).G
