"""The discrete-time KKL observers of [Dinh2024]: observers (3) (time-invariant) and (15)
(time-varying), one step, written once.

Time-invariant systems ([Dinh2024, Section 2]). ``T`` solves ``T A = A_z T + B_z C`` (eq. 4), so
``z = T x`` obeys, with the feedthrough and the shared disturbance of the ivobs model,

    z[k+1] = A_z z[k] + B_z y[k] + (T B - B_z D) u[k] + (T E - B_z F) d[k]          (eq. 5)

and, ``A_z`` being nonnegative, observer (3.a) ``z̄+ = A_z z̄ + B_z y + (TB - B_zD) u + ḡ``
(``ḡ``, ``g̲`` the Lemma-1 bounds of ``(T E - B_z F) d``; one matrix for the correlated ``d``)
keeps ``z̲ <= T x <= z̄``; (3.c-d) give ``x = T⁻¹ z``. Observer (6) of the paper is the same
bounds written in ``x̂ = T⁻¹ z``: ivobs runs (3).

Time-varying systems ([Dinh2024, Section 3.2]). ``T[k+1] = (A_z T[k] + B_z C[k]) A[k]⁻¹``
(eq. 15.b, needs invertible ``A[k]``), ``A_z = gamma Ã``, ``B_z = B̃`` block-diagonal with one
block per output of size the observability index ``m_i`` (eq. 16.a), ``n_z = Σ m_i``; the
bounds (15.a) with ``T[k+1]`` in place of ``T``, and ``x`` recovered by the pseudo-inverse
(15.d) once ``T[k]`` is left-invertible. ``T[k]`` does not depend on the data, so
``valid_from`` is decided offline: the first ``k`` with ``cond(N T[k]) <= max_cond``, ``N`` the
positive diagonal scaling that gives ``T[k]`` unit rows. The default ``T0 = 0`` makes ``z[0] =
0`` exactly: no prior on ``x[0]`` is needed ([Dinh2024, Example 3]: ``valid_from = 2``).

What is guaranteed: the exact sets, every floating-point error bounded: the step's terms and
their rounding (:mod:`.terms`), the recovery (:func:`.observer.recover`), the transformation
(time-invariant: the float ``T`` is the observer's exact transformation, its residual in (4)
bounded on the box of ``x``; time-varying: the exact sequence (15.b), within ``τ[k]`` of the
float one, :class:`~.design.TransformSequence`).

Data used: the box at ``k`` comes from ``z[k]``, which uses ``y[0..k-1]`` (prediction form, as in
the paper); ``y[k]`` is used for the step to ``k+1`` and is checked against the box at ``k`` (a
measurement certainly outside the set the model allows is reported and not used).

Missing samples. ``B_m y_m = B_m (C_m x + D_m u + F_m d)`` is bounded on the box of ``x``
(:mod:`.terms`). That alone can let the widths grow while outputs are missing (the interval
image of ``B_m C_m`` on the box of ``x = T⁺ z`` is not a contraction), so from a missing sample
on the observer also carries the model's one-step prediction of the box, ``x[k+1] ∈ A [x̲, x̄] +
B u + E [d̲, d̄]``, and intersects: the box of ``x`` with it, and ``z`` with ``T[k+1]`` times it
(Lemma 1). Both are sound, so the result is; the prediction is carried until the box from
``z`` alone lies inside it (then it no longer helps). Time-varying systems always carry it
(before ``T[k]`` is left-invertible it is the only box).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ...errors import IvobsError
from ...model import LinearSystem
from ...sets import Box, image_bounds
from ...sets.rounding import down, up, upper
from ..state import Step, evolve
from .design import KKLDesign, Transform, TransformSequence, left_inverse
from .observer import PATTERNS, Observer, ZState, prior_box, recover
from .terms import Terms, combination, make_terms

__all__ = ["Discrete", "DiscreteState"]


@dataclass(frozen=True)
class DiscreteState(ZState):
    """Observers (3)/(15): ``z̲ <= T[k] x[k] <= z̄`` and, when ``carried``, the model's
    prediction ``[xlo, xhi]`` of the box of ``x[k]`` (zeros otherwise: every entry of a saved
    state is finite)."""

    xlo: np.ndarray
    xhi: np.ndarray
    carried: bool

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("zlo", "zhi"), ("xlo", "xhi"))


class Discrete(Observer[DiscreteState]):
    """Observer (3) (``seq`` None: one ``T``) or (15) (the sequence ``T[k]`` of (15.b))."""

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None,
        design: KKLDesign,
        max_cond: float,
        seq: TransformSequence | None = None,
    ):
        super().__init__(sys, x0, design, max_cond)
        self.seq = seq
        self._tr = left_inverse(design.T, max_cond) if seq is None else None
        self._patterns: dict[bytes, tuple[Terms, Terms | None]] = {}
        nx = sys.nx
        self._none = (np.full(nx, -np.inf), np.full(nx, np.inf))
        self._zero = np.zeros(nx)

    # -- the design at step k -------------------------------------------------------------
    def transform(self, k: int) -> Transform:
        """``T[k]`` with its left inverse."""
        if self._tr is not None:
            return self._tr
        assert self.seq is not None
        return self.seq.at(k)

    def terms(self, k: int, obs: np.ndarray) -> tuple[Terms, Terms | None]:
        """:class:`~.terms.Terms` of step ``k`` for the observed outputs ``obs`` and, with
        missing outputs and a left-invertible ``T[k]``, those that bound them through ``z``
        (kept per pattern for a time-invariant system)."""
        if self.seq is None:
            key = obs.tobytes()
            hit = self._patterns.get(key)
            if hit is None:
                if len(self._patterns) >= PATTERNS:
                    self._patterns.clear()
                hit = self._patterns[key] = self._terms(k, obs)
            return hit
        return self._terms(k, obs)

    def _terms(self, k: int, obs: np.ndarray) -> tuple[Terms, Terms | None]:
        A, B, C, D, E, F = self.sys.matrices_at(k)
        Az, Bz = self.design.A_z, self.design.B_z
        Bo, Bm = Bz[:, obs], Bz[:, ~obs]
        Co, Cm, Do, Fo = C[obs], C[~obs], D[obs], F[obs]
        d = (self._dfix.lo, self._dfix.hi) if self._dfix is not None else None
        nu = B.shape[1]
        BE, DF = np.hstack((B, E)), np.hstack((Do, Fo))
        if self.seq is None:  # (4) for the float T: its residual X is bounded on the box
            T = self.design.T
            LG = combination((T, BE), (-Bo, DF))
            X = combination((T, A), (-Az, T), (-Bo, Co))
        else:  # (15.b), exact: T̂[k+1] within τ[k+1]; X = B_m C_m
            Tn, tau = self.seq.at(k + 1).T, self.seq.tau(k + 1)
            LG = _plus_tau(combination((Tn, BE), (-Bo, DF)), tau, BE)
            X = combination((Bm, Cm))
        L = (LG[0][:, :nu], LG[1][:, :nu])
        G = (LG[0][:, nu:], LG[1][:, nu:])
        check = self.check((C, D, F), obs)
        terms = make_terms(obs, Az, Bz, L, G, X, (C, D, F), d, check=check)
        tr = self.transform(k)
        if terms.full or not tr.ok:
            return terms, None
        through = (tr.P, tr.resid, tr.T)
        return terms, make_terms(obs, Az, Bz, L, G, X, (C, D, F), d, through, check)

    # -- the step -------------------------------------------------------------------------
    def initial_state(self) -> DiscreteState:
        zlo, zhi = self.initial_z()  # (3.b)/(15.c); z[0] = 0 exactly for T0 = 0
        xlo, xhi = self.initial_x()  # the prior (time-varying: the box until T is invertible)
        carried = self.seq is not None and self.x0 is not None
        if not carried:
            xlo = xhi = self._zero
        return DiscreteState(zlo=zlo, zhi=zhi, xlo=xlo, xhi=xhi, carried=carried)

    def box(
        self, state: DiscreteState, k: int, tr: Transform, zabs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, bool]:
        """The box of ``x[k]``: (3.c-d)/(15.d), intersected with the prediction when one is
        carried (and with the prior at ``k = 0``); whether the prediction cut it."""
        if tr.ok:
            lo, hi = recover(tr, state.zlo, state.zhi, zabs)
        else:  # T[k] not left-invertible (time-varying): the prediction alone
            lo, hi = self._none
        if k == 0:
            lo, hi = prior_box(self.x0, lo, hi)
        plo, phi = state.xlo, state.xhi
        cut = state.carried and bool(np.count_nonzero(plo > lo) or np.count_nonzero(phi < hi))
        if cut:
            nlo, nhi = np.maximum(lo, plo), np.minimum(hi, phi)
            if np.count_nonzero(nlo > nhi):  # data contradicting the model: keep (3.c-d)
                return lo, hi, False
            lo, hi = nlo, nhi
        if not tr.ok and k >= self.design.k_star and not np.isfinite((lo, hi)).all():
            raise IvobsError(
                f"kkl: T[{k}] is not left-invertible (cond {tr.cond:.2e}) and no finite "
                "prior is available; pass x0 so the observer can bridge such steps"
            )
        return lo, hi, cut

    def step(
        self, state: DiscreteState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[DiscreteState]:
        k = state.k
        zabs = np.maximum(np.abs(state.zlo), np.abs(state.zhi))
        lo, hi, cut = self.box(state, k, self.transform(k), zabs)  # (3.c-d)/(15.d)
        d = self.bounds_d(k, y_k)
        xabs = np.maximum(np.abs(lo), np.abs(hi))
        uabs = np.abs(u_k)
        # (time-invariant: always bounded, the prior box is required)
        bounded = self.seq is None or bool(xabs.max() < np.inf) if xabs.size else True
        obs = y_k == y_k  # the components measured (not NaN)
        terms, via_z = self.terms(k, obs)
        y_o = y_k if terms.full else y_k[obs]
        bad = False
        if bounded and y_o.size:  # a measurement the box contradicts is not used
            bad = terms.check.contradicts(y_o, u_k, lo, hi, xabs, uabs, d.lo, d.hi)
            if bad:
                obs = np.zeros_like(obs)
                (terms, via_z), y_o = self.terms(k, obs), y_k[obs]
        if not terms.full and not bounded:
            raise IvobsError(
                f"y: measurement missing at step {k}, before T[k] is left-invertible, and "
                "no prior box on x[0]: pass x0 to predict through missing samples there"
            )
        args = (state.zlo, state.zhi, zabs, y_o, u_k, uabs, lo, hi, xabs, d.lo, d.hi)
        zlo, zhi = terms.advance(*args)  # (3.a)/(15.a)
        if via_z is not None:  # missing outputs: also bounded through z; both are sound
            zlo2, zhi2 = via_z.advance(*args)
            zlo, zhi = _meet(zlo, zhi, zlo2, zhi2)
        plo = phi = self._zero
        carried = False
        if bounded and (self.seq is not None or not terms.full or cut):
            plo, phi = self.predict(k, lo, hi, u_k, d)
            carried = True
            zlo, zhi = self.intersect_z(k, zlo, zhi, plo, phi)
        new = evolve(state, zlo=zlo, zhi=zhi, xlo=plo, xhi=phi, carried=carried)
        return Step(new, lo, hi, bad)

    def predict(
        self, k: int, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, d: Box
    ) -> tuple[np.ndarray, np.ndarray]:
        """``x[k+1] ∈ [A B E] [[x̲, x̄]; u; [d̲, d̄]]`` (Lemma 1: the proven image of
        :func:`~ivobs.sets.image_bounds`, its rounding included)."""
        A, B, _, _, E, _ = self.sys.matrices_at(k)
        M = np.hstack((A, B, E))
        return image_bounds(M, np.concatenate((lo, u, d.lo)), np.concatenate((hi, u, d.hi)))

    def intersect_z(
        self, k: int, zlo: np.ndarray, zhi: np.ndarray, plo: np.ndarray, phi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``z[k+1] = T[k+1] x[k+1]`` also lies in ``T[k+1]`` times the prediction (Lemma 1;
        time-varying: the exact ``T[k+1]`` within ``τ[k+1]`` of the float one)."""
        if self.seq is None:
            T, tau = self.design.T, None
        else:
            T, tau = self.seq.at(k + 1).T, self.seq.tau(k + 1)
        tlo, thi = image_bounds(T, plo, phi)
        if tau is not None and np.any(tau):
            e = upper(tau @ np.maximum(np.abs(plo), np.abs(phi)), T.shape[1])
            tlo, thi = down(tlo - e), up(thi + e)
        return _meet(zlo, zhi, tlo, thi)


def _meet(
    lo: np.ndarray, hi: np.ndarray, lo2: np.ndarray, hi2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The intersection of two enclosures of the same vector (the first where they do not
    meet: data contradicting the model)."""
    nlo, nhi = np.maximum(lo, lo2), np.minimum(hi, hi2)
    if np.count_nonzero(nlo > nhi):
        return lo, hi
    return nlo, nhi


def _plus_tau(
    coef: tuple[np.ndarray, np.ndarray], tau: np.ndarray, M: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A coefficient ``T[k+1] M - ...`` computed with ``T̂[k+1]``: its error bound plus
    ``τ |M|``."""
    if not np.any(tau) or M.shape[1] == 0:
        return coef
    return coef[0], up(coef[1] + upper(tau @ np.abs(M), tau.shape[1]))
