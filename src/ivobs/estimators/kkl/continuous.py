"""Continuous-time KKL observers of [Dinh2024] (Sections 2 and 3.1) with sampled measurements.

Between samples only ``y[k]`` is known, and observers (3)/(10) integrate ``B_z y(t)``. ivobs runs
their *sampled-data* form, which is exact for any ``y(t)``: the measurement enters at the sample
instants,

    T(t_k+) = T(t_k-) + h_k B_z C(t_k),   z(t_k+) = z(t_k-) + h_k B_z (y_k - D u_k - F d(t_k))

(``h_k = t_k - t_{k-1}``, the rectangle rule of ``∫ B_z y``; ``y_0`` gets weight 0), and between
samples ``Ṫ = A_z T - T A(t)`` (eq. 10.b without the ``B_z C`` term) and the bounds (10.a)
without ``B_z y``: ``dz̄/dt = A_z z̄ + T B u + (T E)⁺ d̄ - (T E)⁻ d̲`` (``A_z`` Metzler:
comparison principle). Then ``z(t) = T(t) x(t)`` holds exactly whatever ``y`` does between
samples; as the sampling period tends to 0 this is observer (3)/(10). ``T(0)`` is the solution of
(4) (time-invariant) or of (4) frozen at ``t = 0`` (time-varying), so the bounds hold from the
first sample given ``x0`` (``valid_from = 0``).

What is guaranteed. The measurement jump, the recovery and the consistency test bound their
floating-point error by a proven model, as in discrete time (:func:`.observer.recover`,
:class:`.terms.Consistency`). The flows between samples are not proven: they are integrated
numerically (time-varying: SciPy DOP853, ``rtol=1e-10``, ``atol=1e-12``,
:class:`ContinuousLTV`) or evaluated by matrix exponentials (time-invariant, closed forms,
:class:`~ivobs.estimators.kkl.sampled.ContinuousLTI`), and that error is covered by a stated
margin: ``z`` bounds widened by ``10 (atol + rtol |z|)`` per interval (time-varying) and the
recovery by ``100 rtol cond(T) |P| |z|`` (:meth:`ContinuousObserver.recover_box`).
Assumptions between samples: ``u``
follows ``input_hold`` (``"zero"``-order hold by default, as a digital controller and
:func:`ivobs.simulate` with array inputs do; ``"linear"`` interpolation of the samples; or a
callable ``t -> u(t)``, integrated by 8-point Gauss-Legendre per interval (time-invariant) or by
the ODE solver (time-varying)); the bounds of ``d`` are the hull of their values at the two ends
of the interval (exact for constant bounds). Nothing is assumed about ``y`` between samples.

Data used: the box at ``t_k`` uses ``y`` up to ``t_k``. Missing samples: the missing rows are
left out of the jump (``T`` and ``z`` jump by ``h B_o C_o``, ``h B_o y_o`` only), which is exact.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple, TypeVar

import numpy as np

from ...errors import DesignError, IvobsError
from ...model import LinearSystem
from ...sets import Box
from ...sets.rounding import down, product_error, up
from ..state import Step
from .design import KKLDesign, Transform, every, finite, left_inverse
from .observer import Observer, ZState, recover
from .terms import Consistency, consistency

__all__ = ["ContinuousLTV", "ContinuousObserver", "ContinuousState", "Flowed", "InputHold", "Span"]

InputHold = str | Callable[[float], Any]
"""``u`` between samples: ``"zero"``-order hold, ``"linear"`` interpolation or ``t -> u(t)``."""


@dataclass(frozen=True)
class ContinuousState(ZState):
    """Observer (10) in sampled-data form at ``t_(k-1)+``: ``z̲ <= T x <= z̄`` with ``T`` itself
    (``T(t)`` moves between samples), and the previous sample: its time ``t_prev`` (None before
    the first), input ``u_prev`` and bounds ``[dlo_prev, dhi_prev]`` of ``d``."""

    T: np.ndarray
    t_prev: float | None
    u_prev: np.ndarray
    dlo_prev: np.ndarray
    dhi_prev: np.ndarray

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (
        ("zlo", "zhi"),
        ("dlo_prev", "dhi_prev"),
    )


S = TypeVar("S", bound=ContinuousState)


class Span(NamedTuple):
    """One interval between samples: its ends, the inputs there and the hull of the bounds of
    ``d`` at the two ends."""

    t0: float
    t1: float
    u0: np.ndarray
    u1: np.ndarray
    dlo: np.ndarray
    dhi: np.ndarray


class Flowed(NamedTuple):
    """``T(t_k-)``, ``z̲, z̄`` at ``t_k-``, the constant-``T`` data used (time-invariant regular
    grid, else None) and the model's prediction of the previous box (time-invariant, else
    None)."""

    T: np.ndarray
    zlo: np.ndarray
    zhi: np.ndarray
    anchor: Any
    model: tuple[np.ndarray, np.ndarray] | None


class ContinuousObserver(Observer[S]):
    """The sampled-data step, written once: the flow from the previous sample (subclasses), the
    measurement jump, and the recovery of the box."""

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None,
        design: KKLDesign,
        max_cond: float,
        hold: InputHold,
        rtol: float,
        atol: float,
    ):
        super().__init__(sys, x0, design, max_cond)
        self.hold = hold
        self.rtol, self.atol = rtol, atol
        # constant (C, D, F): the consistency test of each pattern of observed outputs, kept
        self._checks: dict[bytes, Consistency] | None = None if sys.is_time_varying else {}

    def check(self, CDF: tuple[np.ndarray, ...], obs: np.ndarray) -> Consistency:
        """The consistency test of the observed outputs ``obs`` (kept per pattern)."""
        d = (self._dfix.lo, self._dfix.hi) if self._dfix is not None else None
        if self._checks is None:
            C, D, F = (M[obs] for M in CDF)
            return consistency(C, D, F, d)
        key = obs.tobytes()
        c = self._checks.get(key)
        if c is None:
            if len(self._checks) >= 256:
                self._checks.clear()
            C, D, F = (M[obs] for M in CDF)
            c = self._checks[key] = consistency(C, D, F, d)
        return c

    def recover_box(
        self, tr: Transform, zlo: np.ndarray, zhi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(3.c-d)/(10.d) (:func:`.observer.recover`, proven rounding), widened by the margin
        of the flows' integration, ``100 rtol cond(T) |P| |z|``."""
        return recover(tr, zlo, zhi, margin=100.0 * self.rtol * tr.cond)

    def initial_fields(self) -> dict[str, Any]:
        """The fields of :class:`ContinuousState` at step 0."""
        zlo, zhi = self.initial_z()  # (3.b)/(10.c)
        nu, nd = self.sys.nu, self.sys.nd
        return {
            "zlo": zlo,
            "zhi": zhi,
            "T": self.design.T.copy(),
            "t_prev": None,
            "u_prev": np.zeros(nu),
            "dlo_prev": np.zeros(nd),
            "dhi_prev": np.zeros(nd),
        }

    def flow(self, state: S, span: Span) -> Flowed:
        """From ``t_(k-1)+`` to ``t_k-``."""
        raise NotImplementedError

    def kept(self, lo: np.ndarray, hi: np.ndarray) -> dict[str, Any]:
        """Fields of the next state that keep the box of ``x[k]`` (time-invariant: the box the
        model predicts the next one from)."""
        return {}

    def step(self, state: S, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> Step[S]:
        assert t_k is not None
        k = state.k
        _, _, C, D, _, F = self.sys.matrices_at(t_k)
        d = self.bounds_d(k, y_k)
        fl = Flowed(state.T, state.zlo, state.zhi, None, None)
        h = 0.0
        if state.t_prev is not None:
            t0 = float(state.t_prev)
            h = t_k - t0
            if not h > 0:
                raise IvobsError(f"t: sample times must increase; got t = {t_k} after {t0}")
            dlo = np.minimum(state.dlo_prev, d.lo)
            dhi = np.maximum(state.dhi_prev, d.hi)
            fl = self.flow(state, Span(t0, t_k, state.u_prev, u_k, dlo, dhi))
        T, zlo, zhi, an, model = fl
        bad = False
        if h > 0 and np.count_nonzero(np.isnan(y_k)) < y_k.size:  # sampled B_z y in (3)/(10)
            T, zlo, zhi, bad = self.jump(h, fl, y_k, u_k, d, (C, D, F))
        tr = an.tr if an is not None and T is an.T else left_inverse(T, self.max_cond)
        box, crossed = self.x_box(tr, zlo, zhi, model)
        if box is None:
            raise DesignError(
                f"kkl: T(t) lost left-invertibility at t = {t_k} (cond {tr.cond:.3e} > max_cond "
                f"= {self.max_cond:.0e}); choose faster target dynamics (larger ell) or another "
                "A_z, B_z ([Dinh2024, Propositions 1, 3])"
            )
        lo, hi = box
        if k == 0:
            lo, hi = self.first_box(lo, hi)
        new = type(state)(
            T=T,
            zlo=zlo,
            zhi=zhi,
            t_prev=float(t_k),
            u_prev=u_k.copy(),
            dlo_prev=d.lo.copy(),
            dhi_prev=d.hi.copy(),
            k=k,
            scale=state.scale,
            inconsistent=state.inconsistent,
            **self.kept(lo, hi),
        )
        return Step(new, lo, hi, bad or crossed)

    def jump(
        self,
        h: float,
        fl: Flowed,
        y_k: np.ndarray,
        u_k: np.ndarray,
        d: Box,
        CDF: tuple[np.ndarray, np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """``T(t_k+)``, ``z̲, z̄`` at ``t_k+`` and whether ``y_k`` contradicted the box at
        ``t_k-`` (then it is not used)."""
        T, zlo, zhi, an, model = fl
        tr = an.trm if an is not None else left_inverse(T, self.max_cond)
        box, bad = self.x_box(tr, zlo, zhi, model)
        obs = ~np.isnan(y_k)
        if box is not None and np.count_nonzero(obs):
            lo, hi = box
            xabs = np.maximum(np.abs(lo), np.abs(hi))
            if finite(xabs):
                y_o = y_k[obs]
                if self.check(CDF, obs).contradicts(
                    y_o, u_k, lo, hi, xabs, np.abs(u_k), d.lo, d.hi
                ):
                    obs, bad = np.zeros_like(obs), True
        full = every(obs)
        Co, Do, Fo = (M[obs] for M in CDF)
        Bo = h * self.design.B_z[:, obs]
        if an is not None and full:
            T = an.T  # = T(t_k-) + h B_z C exactly (see ContinuousLTI.anchor)
        else:
            T = T + Bo @ Co
        # z jumps by h B_o (y_o - D_o u - F_o d): the Lemma-1 bounds of the d term, and the
        # proven bound of the evaluation (a sum of n_o (n_u + 1) + 1 products per entry)
        yo = y_k if full else y_k[obs]
        v = Bo @ (yo - Do @ u_k)
        BF = Bo @ Fo
        dc, dr = 0.5 * (d.lo + d.hi), 0.5 * (d.hi - d.lo)
        v = v - BF @ dc
        gr = np.abs(BF) @ dr
        mag = np.abs(Bo) @ (np.abs(yo) + np.abs(Do) @ np.abs(u_k) + np.abs(Fo) @ np.abs(dc))
        n = Bo.shape[1] * (2 + Do.shape[1] + Fo.shape[1]) + 4
        e = up(product_error(mag + gr, n) + gr * (1.0 + 1e-15))
        return T, down(zlo + v - e), up(zhi + v + e), bad

    def x_box(
        self,
        tr: Transform,
        zlo: np.ndarray,
        zhi: np.ndarray,
        model: tuple[np.ndarray, np.ndarray] | None,
    ) -> tuple[tuple[np.ndarray, np.ndarray] | None, bool]:
        """The box from ``z`` (3.c-d)/(10.d), intersected with the model prediction ``model`` of
        the previous box (time-invariant; both are sound); the prediction alone while ``T`` is
        not left-invertible (e.g. right after a long gap); None if neither is available.

        An empty intersection beyond rounding means the data contradict the model: reported as
        an inconsistency (the flag returned); each crossed coordinate then keeps the hull of the
        two crossed ends.
        """
        if not tr.ok:
            return model, False
        lo, hi = self.recover_box(tr, zlo, zhi)
        if model is None:
            return (lo, hi), False
        lo, hi = np.maximum(lo, model[0]), np.minimum(hi, model[1])
        cross = lo > hi
        bad = False
        if np.count_nonzero(cross):
            bad = bool(np.any(lo - hi > 1e-9 * (1.0 + np.abs(lo) + np.abs(hi))))
            lo, hi = np.where(cross, hi, lo), np.where(cross, lo, hi)
        return (lo, hi), bad


class ContinuousLTV(ContinuousObserver[ContinuousState]):
    """Time-varying: ``Ṫ = A_z T - T A(t)`` and the bounds (10.a) without ``B_z y`` integrated
    by SciPy's DOP853 on each interval."""

    def initial_state(self) -> ContinuousState:
        return ContinuousState(**self.initial_fields())

    def flow(self, state: ContinuousState, span: Span) -> Flowed:
        from scipy.integrate import solve_ivp

        t0, t1, u0, u1, dlo, dhi = span
        T = state.T
        Az = self.design.A_z
        nz, nx = T.shape
        nT = nz * nx
        A_t, B_t, E_t = (_accessor(M) for M in (self.sys.A, self.sys.B, self.sys.E))
        dc, dr = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo)
        hold, du = self.hold, (u1 - u0) / (t1 - t0)

        def rhs(t: float, Y: np.ndarray) -> np.ndarray:
            # centre/radius form of (10.a): (TE)⁺ d̄ - (TE)⁻ d̲ = TE d_c + |TE| d_r
            Tm = Y[:nT].reshape(nz, nx)
            TE = Tm @ E_t(t)
            uu = hold(t) if callable(hold) else (u0 if hold == "zero" else u0 + (t - t0) * du)
            base = Tm @ (B_t(t) @ np.asarray(uu, dtype=float)) + TE @ dc
            rad = np.abs(TE) @ dr
            out = np.empty_like(Y)
            out[:nT] = (Az @ Tm - Tm @ A_t(t)).ravel()
            out[nT : nT + nz] = Az @ Y[nT : nT + nz] + base - rad
            out[nT + nz :] = Az @ Y[nT + nz :] + base + rad
            return out

        Y0 = np.concatenate([T.ravel(), state.zlo, state.zhi])
        sol = solve_ivp(
            rhs, (t0, t1), Y0, method="DOP853", rtol=self.rtol, atol=self.atol, first_step=t1 - t0
        )
        if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
            raise IvobsError(f"kkl: integration failed on [{t0}, {t1}]: {sol.message}")
        Y = sol.y[:, -1]
        nlo, nhi = Y[nT : nT + nz], Y[nT + nz :]
        pad = 10 * (self.atol + self.rtol * np.maximum(np.abs(nlo), np.abs(nhi)))
        return Flowed(Y[:nT].reshape(nz, nx), nlo - pad, nhi + pad, None, None)


def _accessor(M: Any) -> Callable[[float], np.ndarray]:
    """``t -> M(t)`` without per-call validation (the model validated ``M`` at construction)."""
    if callable(M):
        return lambda t: np.asarray(M(t), dtype=float)
    Mc = np.asarray(M, dtype=float)
    return lambda t: Mc
