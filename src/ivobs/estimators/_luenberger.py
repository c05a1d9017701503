"""The Luenberger observer behind ``reachability`` and ``zonotope`` [Tang2019, eqs. (10), (34a)],
with a proven bound of its floating-point rounding.

With ``y = C x + D u + F d`` and the bounds of ``d`` re-centred (``d = c + δ``, ``|δ| <= r``)::

    ν[k]   = y[k] - C x̂[k] - D u[k] - F c[k]                    (innovation)
    x̂[k+1] = A x̂[k] + B u[k] + E c[k] + L ν[k]                  [Tang2019, eq. (10)]

whose error ``e = x - x̂`` obeys, in exact arithmetic, ``e+ = (A - LC) e + (E - LF) δ``
[Tang2019, eq. (15)]. The two methods differ only in the set they propagate for ``e``: the
exact interval hull of its reachable set (``reachability``) or a reduced zonotope
(``zonotope``). What they share is here: the gain (:func:`ivobs.design.hinf.designed_gain`) and
the gain of each pattern of missing outputs, the observer step with its rounding bound and the
consistency test of a measurement, the data-independent part of the bounds
(:class:`DataFreeBounds`), and the vectorised run over a record.

**Rounding** ([Higham2002]; :mod:`ivobs.sets.rounding`; the bounds themselves are in
:mod:`ivobs.estimators._observer_rounding`). The design's ``M = fl(A - L C)`` and ``G = fl(E -
L F)`` are float matrices; the exact ones differ by ``|A - LC - M| <= ΔM``, ``|E - LF - G| <=
ΔG`` (``difference``). The step computes ``ν`` and ``x̂+`` in floats; both are dot products
evaluated in some order, so ([Higham2002, eq. (3.5)])

    fl(ν) = ν + η,                          |η| <= e_ν = γ (|y| + |C| |x̂| + |D| |u| + |F| |c|)
    fl(x̂+) = A x̂ + B u + E c + L fl(ν) + ζ,  |ζ| <= ε = γ (|A| |x̂| + ... + |L| |fl(ν)|),

one linear function of the magnitudes ``z = [|x̂|, |u|, |c|, |y|, |ν|, 1]``, ``[ε; e_ν] <= W z``
(``rounding_matrix``). So the float observer's error obeys, exactly,

    e+ = M e + G δ - L η + ξ,     |ξ| <= ε + ΔM |e| + ΔG r,

two errors per step that each method propagates with its set: as generators, ``L diag(e_ν)``
and ``diag(ε + ...)`` (through ``L``: with a large gain, ``|M^i L|`` is far smaller than
``|M^i| |L|``), or, where ``M`` is the same at every step, by two scalars (``Channels``).

*The two scalars.* Let ``S = diag(s)``, ``s > 0`` powers of two that balance ``M`` (a badly
scaled plant: states of magnitudes ``1e6`` and ``1e-3`` round at those magnitudes), and
``‖v‖_s = ‖S⁻¹ v‖∞``, so that ``|v| <= ‖v‖_s s``. ``M̃ = S⁻¹ M S`` and ``L̃ = S⁻¹ L`` are
computed exactly (products by powers of two, none under- or overflowing; else ``s = 1``), and
``M^i L = S M̃^i L̃``, ``|M^i| s = S |M̃^i| 1`` exactly; so proven envelopes of the powers of
``M̃``, ``|M̃^i L̃| 1 <= ã_L λ^i`` and ``|M̃^i| 1 <= ã_x λ^i``, give

    |M^i L| 1 <= a_L λ^i,   |M^i| s <= a_x λ^i,   a_L = s ⊙ ã_L,  a_x = s ⊙ ã_x

(rounded up). The part of the error that the rounding makes, ``ω[k+1] = M ω[k] + ξ_k - L η_k``,
``ω[0] = 0``, is ``ω[k] = Σ_{j<k} M^{k-1-j} (ξ_j - L η_j)``, so

    |ω[k]| <= Σ_{j<k} (|M^{k-1-j} L| 1 ‖η_j‖∞ + |M^{k-1-j}| s ‖ξ_j‖_s)
           <= a_L Σ_{j<k} λ^{k-1-j} ‖e_ν,j‖∞ + a_x Σ_{j<k} λ^{k-1-j} ‖ξ_j‖_s.

``ξ_j`` holds ``ΔM`` acting on ``ω[j]`` itself: ``‖ξ_j‖_s <= σ_j + ‖ΔM |ω[j]|‖_s``, ``σ_j`` the
rest (``ε_j``, ``ΔG r``, ``ΔM`` on the method's own set). By induction on ``k``, ``|ω[k]| <=
a_L q_L[k] + a_x q_x[k]`` with

    q_L+ = λ q_L + ‖e_ν‖∞,     q_x+ = (λ + β_x) q_x + σ + β_L q_L,     q_L[0] = q_x[0] = 0,

``β_L = ‖ΔM a_L‖_s``, ``β_x = ‖ΔM a_x‖_s``: for ``j < k`` the hypothesis gives ``‖ΔM |ω[j]|‖_s
<= β_L q_L[j] + β_x q_x[j]``, so ``q_x[k] = Σ_{j<k} λ^{k-1-j} (σ_j + β_L q_L[j] + β_x q_x[j])``
is at least the second sum (:meth:`~ivobs.sets.rounding.DecayBound.next`, rounded up; ``λ +
β_x < 1``, else the design is refused). Its image in ``y``: ``|C ω[k]| <= c_L q_L + c_x q_x``,
``c = |C| a``. With ``s = 1`` the norm is ``‖·‖∞`` and the envelopes are those of ``M``.

The vectorised run evaluates ``x̂`` by another algorithm (a linear filter over the record) and
bounds the exact residual of the computed sequence, ``x̃[k+1] - (A x̃[k] + B u + E c + L
ν[k])``, by the same ``W`` plus the computed residual: any sequence of floats is an observer
with that error, so its bounds are proven the same way, with the same ``s``, envelopes and
recursions.

**Consistency.** A measurement is inconsistent when ``|ν_i| > ȳ_i`` for an observed output,
``ȳ`` the radius of ``y - C x̂ - D u - F c`` the model and the error set allow; it is flagged
only when ``fl(|fl(ν_i)| - e_ν,i) > ȳ_i``, i.e. proven inconsistent: an admissible sample within
rounding of its bound is never flagged.

**Missing outputs.** Keeping the gain of the outputs present can make ``A - L_S C_S`` unstable
although the plant is detectable from them; so each pattern ``S`` of observed outputs gets its
own gain (:func:`pattern_gain`), designed once when the pattern first occurs.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from ..design.hinf import designed_gain
from ..errors import DesignError, DesignWarning
from ..linalg import spectral_radius
from ..sets.rounding import enclose, mid_rad, upper
from . import _uncertain as uncertain
from ._observer_rounding import Channels, difference, rounding_matrix
from ._recursion import LinearFilter, abs_max, redo_streams
from .base import Design, Estimator

__all__ = ["DataFreeBounds", "Gain", "ObserverDesign", "ObserverEstimator", "pattern_gain"]

_ONE = np.ones(1)


@dataclass(frozen=True)
class ObserverDesign(Design):
    """``L``: observer gain; ``gamma``: its H∞ bound and ``P`` the Lyapunov matrix of
    [Tang2019, Theorem 1] (None for a user gain and the ``"radius"`` gain); ``spectral_radius``
    of ``A - LC``; ``gain``: the design (``"radius"``, ``"hinf"``, ``"hinf-lmi"``; ``"user"``
    for ``L=``); ``fallback``: None when the default's first choice designed, else which
    designs failed and why (:func:`~ivobs.design.hinf.designed_gain`; a
    :class:`~ivobs.DesignWarning` says it too)."""

    L: np.ndarray
    gamma: float | None
    P: np.ndarray | None
    spectral_radius: float
    gain: str
    fallback: str | None


def warn_fallback(who: str, used: str, why: str) -> None:
    """One line saying that the default design fell back to ``used``; ``why`` (the failures,
    ``"gain='radius': <message>; gain='hinf': ..."``) stays whole in ``design.fallback``."""
    first = why.split(";")[0]  # the first design that failed and the start of its reason
    warnings.warn(
        f"{who}: the default gain design fell back to gain={used!r} ({first}; design.fallback "
        "has every reason)",
        DesignWarning,
        # warn_fallback, _design_observer, __init__, its session-defaults wrapper
        # (estimators._overrides), make_estimator: the caller
        stacklevel=6,
    )


class Gain(NamedTuple):
    """The observer of one pattern of observed outputs: gain ``L`` (zero columns for the
    missing outputs), ``M = fl(A - L C)``, ``G = fl(E - L F)`` (``[E - LF, I, -L]`` with
    interval matrices), ``absM = |M|``, ``dM >= |A - L C - M|``, ``dG >= |E - L F - G|``
    (exact), and ``W``: the rounding bound of one observer step, ``[ε; e_ν] <= W z`` (module
    docstring)."""

    L: np.ndarray
    M: np.ndarray
    absM: np.ndarray
    G: np.ndarray
    dM: np.ndarray
    dG: np.ndarray
    W: np.ndarray


def pattern_gain(
    mats: tuple[np.ndarray, ...], L: np.ndarray, obs: np.ndarray, r: np.ndarray
) -> np.ndarray:
    """The gain for the outputs ``obs`` (the others missing): the radius gain of the system
    with those outputs alone (:mod:`ivobs.design.radius`, weights ``r`` of ``d``), whose
    ``A - L_S C_S`` is Schur whenever the pair is detectable; when it is not (no such gain),
    the one of ``L`` with the missing columns zeroed and ``0`` (prediction) that has the
    smaller spectral radius. Columns of the missing outputs are zero."""
    A, _, C, _, E, F = mats
    zeroed: np.ndarray = L * obs
    if not obs.any():
        return zeroed
    from ..design.cache import cached, fingerprint
    from ..design.radius import radius_gain

    def design() -> np.ndarray:
        try:
            Ls, _ = radius_gain(A, C[obs], E, F[obs], r)
        except DesignError:
            Ls = None
        if Ls is None or not spectral_radius(A - Ls @ C[obs]) < 1.0:
            none = np.zeros_like(L)
            return zeroed if spectral_radius(A - zeroed @ C) <= spectral_radius(A) else none
        out = np.zeros_like(L)
        out[:, obs] = Ls
        return out

    out: np.ndarray = cached(fingerprint("pattern_gain", A, C, E, F, r, L, obs), design)
    return out


class ObserverEstimator(Estimator):
    """What ``reachability`` and ``zonotope`` share (module docstring). A subclass calls
    :meth:`_design_observer` from its ``__init__`` and sets ``self._free`` (a
    :class:`DataFreeBounds`, or None when the bounds of ``d`` are not constant)."""

    proven_rounding = True
    _free: DataFreeBounds | None

    def _design_observer(self, L: Any, gain: str | None = None) -> ObserverDesign:
        """The gain (checked: ``A - LC`` Schur), the error dynamics of every pattern of observed
        outputs (built when first needed), and the decay of ``M``'s powers (the rounding ball)."""
        designed = designed_gain(self.sys, L, self.name, gain)
        Lm = designed.L
        self._mats = self.sys.matrices_at(0)
        A, B, C, D, E, F = self._mats
        self._unc = self.sys.uncertainty
        self._const: tuple[np.ndarray, np.ndarray] | None = None
        if self._unc is None and self.sys.has_constant_bounds:
            box = self.sys.d_at(0)
            self._const = mid_rad(box.lo, box.hi)  # [lo, hi] ⊆ [c - r, c + r] exactly
        self._absF = np.abs(F)
        if self._unc is not None:  # d̃ = [d; w; v]: v enters y alone
            nx, ny = A.shape[0], C.shape[0]
            self._absF = np.hstack([self._absF, np.zeros((ny, nx)), np.eye(ny)])
        self._O = np.block([[A, B, E], [C, D, F]])  # the model acting on [x̂; u; c]
        # the components of c that can be nonzero (a zero product adds no rounding)
        self._c_used = np.ones(E.shape[1]) if self._const is None else (self._const[0] != 0) * 1.0
        self._L = Lm
        self._gains: dict[bytes, Gain] = {}
        self._full = self._gain_of(Lm)
        self._gains[np.ones(C.shape[0], dtype=bool).tobytes()] = self._full
        self._channels = Channels.of(self._full.M, self._full.dM, Lm, C)
        self._gain_weights = np.ones(E.shape[1]) if self._const is None else self._const[1]
        self._filter: LinearFilter | None = None  # the vectorised run's observer
        self._refiner: LinearFilter | None = None  # and its refinement
        if designed.fallback is not None:
            warn_fallback(self.name, designed.gain, designed.fallback)
        return ObserverDesign(
            L=Lm,
            gamma=designed.gamma,
            P=designed.P,
            spectral_radius=designed.rho,
            gain=designed.gain,
            fallback=designed.fallback,
        )

    def _gain_of(self, L: np.ndarray) -> Gain:
        A, _, C, _, E, F = self._mats
        M, dM = difference(A, L, C)
        G, dG = difference(E, L, F)
        if self._unc is not None:  # e+ = M e + [G, I, -L] [δ; w; v]
            nx = A.shape[0]
            G = np.hstack([G, np.eye(nx), -L])
            dG = np.hstack([dG, np.zeros((nx, nx + L.shape[1]))])
        return Gain(L, M, np.abs(M), G, dM, dG, rounding_matrix(self._mats, L, self._c_used))

    def _gain_at(self, obs: np.ndarray) -> Gain:
        """The observer for the outputs ``obs`` (:func:`pattern_gain`; designed once)."""
        key = obs.tobytes()
        hit = self._gains.get(key)
        if hit is None:
            L = pattern_gain(self._mats, self._L, obs, self._gain_weights)
            hit = self._gains[key] = self._gain_of(L)
        return hit

    def _bounds(
        self, k: int, y_k: np.ndarray, lo: np.ndarray, hi: np.ndarray, u_k: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Centre ``c`` and radius ``r`` of the bounds of ``d[k]``, ``[lo, hi] ⊆ [c − r, c + r]``
        exactly (:func:`~ivobs.sets.rounding.mid_rad`). Interval matrices: the radius of
        ``d̃ = [d; w; v]`` (``w``, ``v`` centred at 0), ``w = ΔA x + ΔB u``, ``v = ΔC x + ΔD u``
        bounded from the box ``[lo, hi]`` of ``x[k]`` (:mod:`ivobs.estimators._uncertain`)."""
        if self._const is not None:
            return self._const
        box = self.sys.d_at(k, y_k)
        c, r = mid_rad(box.lo, box.hi)
        if self._unc is None:
            return c, r
        w, v = uncertain.terms(self._unc, lo, hi, u_k)
        return c, np.concatenate([r, w, v])

    def _observe(
        self, xh: np.ndarray, u_k: np.ndarray, y_k: np.ndarray, c: np.ndarray, ybound: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool, Gain]:
        """One step of the observer [Tang2019, eq. (10)]: ``(x̂+, ε, e_ν, inconsistent, gain)``.

        ``ybound``: an upper bound of the radius of ``y - C x̂ - D u - F c`` the model allows
        (``|C| ρ + |F| r``). ``fl(x̂+) = x̂+ + L_k η + ζ`` with ``|η| <= e_ν``, ``|ζ| <= ε`` (module
        docstring). A measurement proven inconsistent is reported and not used (no output's
        gain)."""
        nx = xh.shape[0]
        v = np.concatenate((xh, u_k, c))
        Ov = self._O @ v  # [A x̂ + B u + E c; C x̂ + D u + F c]
        s = sum(y_k.tolist())  # (NaN when an output is missing; floats: cheaper than NumPy's)
        if s == s:  # every output measured
            nu = y_k - Ov[nx:]  # ν
            gain = self._full
        else:
            obs = ~np.isnan(y_k)
            y_k = np.where(obs, y_k, 0.0)
            nu = np.where(obs, y_k - Ov[nx:], 0.0)
            gain = self._gain_at(obs)
        z = np.abs(np.concatenate((v, y_k, nu, _ONE)))
        err = gain.W @ z  # >= [ε; e_ν] (W rounded up for its own evaluation)
        e_nu = err[nx:]
        # inconsistent only when proven: |ν| - e_ν > ȳ (one rounding, monotone; a few floats)
        if any(abs(a) - e > b for a, e, b in zip(nu.tolist(), e_nu.tolist(), ybound.tolist())):
            gain = self._gain_at(np.zeros(nu.shape[0], dtype=bool))
            z[-1 - nu.shape[0] : -1] = 0.0
            return Ov[:nx], (gain.W @ z)[:nx], e_nu, True, gain
        return Ov[:nx] + gain.L @ nu, err[:nx], e_nu, False, gain  # A x̂ + B u + E c + L ν

    # -- offline, vectorised --------------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        """The record (or batch) at once, for constant bounds and complete data: the
        data-independent radii once (:class:`DataFreeBounds`), ``x̂`` by a linear filter of the
        record (:meth:`_filtered`), the exact residual of that sequence bounded a posteriori
        (module docstring) and the rounding's scalars ``q_L``, ``q_x`` by
        :meth:`~ivobs.sets.rounding.DecayBound.accumulate`. Streams of a batch with a
        measurement found inconsistent are redone by the loop."""
        free, T = self._free, y.shape[-2]
        if free is None or not T or np.isnan(y).any():
            return None
        ch, nx = self._channels, self.sys.nx
        rho_bar, yb, e_free = free.arrays(T)
        filtered = self._filtered(u, y)
        if filtered is None:
            return None
        xh, nu, res, err = filtered
        # |x̃[k+1] - x̃+_exact| <= |fl(x̃[k+1] - ...)| (one rounding) + ε: the state's channel
        np.abs(res, out=res)
        res[..., :-1, :] += err[..., :-1, :nx]
        sigma = upper(ch.norms(res[..., :-1, :]) + e_free[:-1], 3)
        mu = abs_max(err[..., :-1, nx:])
        qL = np.zeros((*sigma.shape[:-1], T))
        qx = np.zeros_like(qL)
        for idx in np.ndindex(*sigma.shape[:-1]):
            qL[idx][1:] = ch.L.accumulate(mu[idx])
            qx[idx][1:] = ch.x.accumulate(upper(sigma[idx] + ch.betaL * qL[idx][:-1], 2))
        # proven inconsistent: |ν| - e_ν > |C| ρ + |F| r (one rounding, monotone)
        nu = np.abs(nu, out=nu)
        nu -= err[..., nx:]
        qL, qx = qL[..., None], qx[..., None]
        bad = nu > upper(yb + qL * ch.cL + qx * ch.cx, 4)
        lo, hi = enclose(xh, upper(rho_bar + qL * ch.aL + qx * ch.ax, 4))
        if not bad.any():
            return lo, hi
        if y.ndim != 3:
            return None
        return redo_streams(self, u, y, t, lo, hi, bad.any(axis=(-1, -2)))

    def _filtered(
        self, u: np.ndarray, y: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """``x̃`` over the record by a linear filter (``x̃+ = M x̃ + L y + (B - LD) u + G c``),
        with ``ν = fl(y - C x̃ - D u - F c)``, the residual ``fl(x̃[k+1] - (A x̃ + B u + E c +
        L ν))`` and ``[ε; e_ν]`` of that evaluation (``rounding_matrix``). Where the filter's
        own rounding left a residual above the step's (large gains: it sums ``L y``),
        the sequence is refined once, ``x̃ -= d``, ``d+ = M d + residual``; None when its
        residual is still above ``4 ε`` (then the loop is tighter: a strongly non-normal
        ``A - LC`` amplifies the rounding of any float sequence that is not the loop's own)."""
        assert self._const is not None and self._free is not None
        c, g = self._const[0], self._full
        A, B, C, D, E, F = self._mats
        nx, nu_, nd, ny = A.shape[0], B.shape[1], E.shape[1], C.shape[0]
        if self._filter is None:
            self._filter = LinearFilter(g.M, [g.L, B - g.L @ D], E @ c - g.L @ (F @ c))
        xh = self._filter.run([y, u], x0=self._free.x0)[0]
        Oc = self._O[:, nx + nu_ :] @ c  # [E c; F c]
        W = g.W
        for refine in (True, False):
            xu = np.concatenate([xh, np.broadcast_to(u, (*xh.shape[:-1], nu_))], axis=-1)
            image = xu @ self._O[:, : nx + nu_].T  # [A x̃ + B u; C x̃ + D u]
            nu = y - image[..., nx:]
            nu -= Oc[nx:]  # ν = y - C x̃ - D u - F c
            res = image[..., :nx]
            res += Oc[:nx]
            res += nu @ g.L.T  # A x̃ + B u + E c + L ν
            np.subtract(xh[..., 1:, :], res[..., :-1, :], out=res[..., :-1, :])
            res[..., -1, :] = 0.0
            err = np.abs(xu) @ W[:, : nx + nu_].T  # >= [ε; e_ν] (the m terms in any order)
            err += np.abs(y) @ W[:, nx + nu_ + nd : nx + nu_ + nd + ny].T
            err += np.abs(nu) @ W[:, nx + nu_ + nd + ny : -1].T
            err += W[:, nx + nu_ : nx + nu_ + nd] @ np.abs(c) + W[:, -1]
            if not (np.abs(res) > 4.0 * err[..., :nx]).any():
                break
            if not refine:
                return None
            if self._refiner is None:
                self._refiner = LinearFilter(g.M, [np.eye(nx)])
            xh = xh - self._refiner.run([res])[0]  # d[k+1] = M d[k] + residual[k], d[0] = 0
        return xh, nu, res, err


class DataFreeBounds:
    """The data-independent part of the bounds: constant bounds of ``d``, every measurement
    complete and consistent. Per step ``k``: the radius ``rho[k]`` of the error set (without
    the rounding ball ``q``), ``yb[k] >= |C| ρ + |F| r`` (or ``|C H| 1 + |F| r``) its image in
    ``y``, and ``e[k]``, what the float evaluation of that set adds to the error at that step
    (an input of ``q``; 0 when the method keeps it in its set).

    A method's recursion ``advance(s) -> (rho, yb, e, s_next)`` is iterated once, as far as
    asked, and kept. It ends when it settles: ``s_next = None`` (that entry holds for every
    later step), or ``same(s_next, s_m)`` for an earlier state (a fixed point or a cycle,
    found by Brent's method: the entries from ``m`` on repeat with that period). ``keep``: the
    states are kept too while they take fewer than ``keep`` floats (:meth:`state`)."""

    def __init__(
        self,
        start: Any,
        advance: Callable[[Any], tuple[np.ndarray, np.ndarray, float, Any]],
        x0: np.ndarray,
        keep: int = 0,
        same: Callable[[Any, Any], bool] | None = None,
    ):
        self._next: Any = start
        self._advance = advance
        self._same = same
        self.x0 = x0
        self._keep = keep
        self._kept = 0
        self.states: list[Any] = []
        self.rho: list[np.ndarray] = []
        self.yb: list[np.ndarray] = []
        self.e: list[float] = []
        self._both: list[np.ndarray] = []
        self.settled: int | None = None
        self.period = 1
        self._mark: tuple[Any, int, int] = (start, 0, 1)  # Brent: state, index, power
        self._arrays: tuple[np.ndarray, ...] | None = None

    def _extend(self, n: int) -> None:
        while len(self.rho) < n and self.settled is None:
            s = self._next
            rho, yb, e, nxt = self._advance(s)
            if self._kept < self._keep and len(self.states) == len(self.rho):
                self.states.append(s)
                self._kept += int(getattr(s, "size", 1))
            self.rho.append(rho)
            self.yb.append(yb)
            self.e.append(e)
            self._both.append(np.concatenate([rho, yb]))
            n_done = len(self.rho)
            self._next = nxt
            if nxt is None:
                self.settled = n_done - 1
            elif self._same is not None:
                mark, at, power = self._mark
                if self._same(nxt, mark):  # state n_done repeats state `at`
                    self.settled, self.period = at, n_done - at
                elif n_done - at == power:
                    self._mark = (nxt, n_done, 2 * power)

    def _index(self, k: int) -> int:
        if self.settled is None or k < self.settled:
            return k
        return self.settled + (k - self.settled) % self.period

    def at(self, k: int) -> tuple[np.ndarray, float]:
        """``([rho[k]; yb[k]], e[k])``."""
        self._extend(k + 1)
        j = self._index(k)
        return self._both[j], self.e[j]

    def state(self, k: int) -> Any:
        """The recursion's state of step ``k`` when kept (the same object every time), else
        None."""
        self._extend(k + 1)
        j = self._index(k)
        return self.states[j] if j < len(self.states) else None

    def arrays(self, T: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``rho`` ``(T, nx)``, ``yb`` ``(T, ny)`` and ``e`` ``(T,)`` for steps ``0..T-1``."""
        self._extend(T)
        hit = self._arrays
        if hit is None or hit[0].shape[0] != T:
            n = len(self.rho)
            parts = tuple(np.array(a) for a in (self.rho, self.yb, self.e))
            if n < T:  # settled: the entries from `settled` on repeat with their period
                s = self.settled
                assert s is not None
                reps = -(-(T - n) // self.period)
                parts = tuple(
                    np.concatenate([p, np.tile(p[s:], (reps,) + (1,) * (p.ndim - 1))])
                    for p in parts
                )
            hit = self._arrays = tuple(p[:T] for p in parts)
        return hit[0], hit[1], hit[2]
