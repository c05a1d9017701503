"""The continuous-time time-invariant KKL observer between samples, in closed form.

On an interval of length ``h`` (the sampled-data form of :mod:`.continuous`) ``T`` and the ``u``
term are exact (``expm``, Van Loan's block exponential); the ``d`` integral is enclosed by
midpoint sums plus a rigorous bound of their variation (not a quadrature). On a regular grid the
observer keeps ``T`` constant at the samples (:meth:`ContinuousLTI.anchor`), so nothing about it
is propagated; the box from ``z`` is intersected with the model's prediction of the previous box.
The matrices of one sampling period are computed once per period (:class:`PeriodData`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..._validate import as_vector
from ...design.sylvester import flow_gap
from ...errors import DesignError
from ...linalg import gamma
from ...model import LinearSystem
from ...sets import Box, image_bounds
from .continuous import ContinuousObserver, ContinuousState, Flowed, InputHold, Span
from .design import KKLDesign, left_inverse
from .periods import Anchor, PeriodData, make_anchor, period_data

__all__ = ["ContinuousLTI", "ContinuousLTIState"]

ANCHOR_TOL = 1e-9
"""Relative distance of ``T`` to the constant ``T_h`` of a regular grid below which the state is
moved onto ``T_h`` (the cost is ``|T_h - T| |x|``, see :meth:`ContinuousLTI.to_anchor`)."""
CACHE_SIZE = 256
"""Sampling periods whose interval matrices are kept."""


@dataclass(frozen=True)
class ContinuousLTIState(ContinuousState):
    """:class:`~ivobs.estimators.kkl.continuous.ContinuousState` and the previous box
    ``[xlo, xhi]`` of ``x``, whose prediction through the model bounds the next one too."""

    xlo: np.ndarray
    xhi: np.ndarray

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (
        ("zlo", "zhi"),
        ("dlo_prev", "dhi_prev"),
        ("xlo", "xhi"),
    )


class ContinuousLTI(ContinuousObserver[ContinuousLTIState]):
    """Time-invariant: closed-form flows, a constant ``T`` on regular grids, and the model's
    prediction of the previous box."""

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
        super().__init__(sys, x0, design, max_cond, hold, rtol, atol)
        self._periods: dict[float, PeriodData] = {}
        # a target slower than a plant mode ([Dinh2024, Proposition 1] allows it): the flow of T
        # between samples is unstable, so T is brought back onto T_h from the last box
        self._restart = flow_gap(self.design.A_z, self.sys.A_at(0)) >= 0.0

    def initial_state(self) -> ContinuousLTIState:
        xlo, xhi = self.initial_x()
        return ContinuousLTIState(**self.initial_fields(), xlo=xlo, xhi=xhi)

    def kept(self, lo: np.ndarray, hi: np.ndarray) -> dict[str, Any]:
        return {"xlo": lo.copy(), "xhi": hi.copy()}

    def period(self, h: float) -> PeriodData:
        """The matrices of one sampling interval of length ``h`` (kept by ``h``)."""
        # keyed (and computed) by h rounded to 1e-12, so that a grid such as np.arange(0, 10, .01)
        # (steps differing by 1e-17) reuses one set, the same whatever step comes first
        h = key = round(float(h), 12)
        cache = self._periods
        if key in cache:
            return cache[key]
        if len(cache) >= CACHE_SIZE:  # irregular grids: one entry per distinct period
            cache.clear()
        data = period_data(self.sys, self.design.A_z, h, callable(self.hold))
        cache[key] = data
        return data

    def flow(self, state: ContinuousLTIState, span: Span) -> Flowed:
        k = state.k
        T, zlo, zhi = state.T, state.zlo, state.zhi
        c = self.period(span.t1 - span.t0)
        an = self.anchor(c, first=k == 1)
        model = self.predict_box(c, state.xlo, state.xhi, span)
        if an is not None:
            T, zlo, zhi = self.to_anchor(an, k, T, zlo, zhi, (state.xlo, state.xhi))
        if an is not None and T is an.T:  # constant T: nothing propagated
            return Flowed(*self.flow_anchored(c, an, zlo, zhi, span), an, model)
        return Flowed(*self.flow_exact(T, zlo, zhi, span), None, model)

    def u_between(self, t: float, span: Span) -> Any:
        t0, t1, u0, u1 = span.t0, span.t1, span.u0, span.u1
        if callable(self.hold):
            return as_vector("input_hold(t)", self.hold(t), self.sys.nu)
        if self.hold == "zero":
            return u0
        s = (t - t0) / (t1 - t0)
        return u0 + s * (u1 - u0)

    def input_integral(
        self,
        c: PeriodData,
        span: Span,
        mats: tuple[Any, np.ndarray, np.ndarray] | None = None,
    ) -> Any:
        """``M ∫ e^{A(h-s)} B u(t0 + s) ds`` over one interval, for the input hold: zero-order
        (``G0 u0``), linear (``G0 u0 + G1 (u1 - u0)``) or a callable (Gauss–Legendre nodes).
        ``mats = (nodes, G0, G1)`` already multiplied by ``M`` (default: those of ``c``,
        ``M = I``)."""
        if mats is None:
            mats = (c.gl[2] if c.gl is not None else None, c.G0, c.G1)
        nodes, G0, G1 = mats
        u0, u1 = span.u0, span.u1
        if callable(self.hold):
            assert c.gl is not None and nodes is not None
            sg, wg, _ = c.gl
            return sum(
                w * (nb @ self.u_between(span.t0 + s, span)) for s, w, nb in zip(sg, wg, nodes)
            )
        if self.hold == "zero":
            return G0 @ u0
        return G0 @ u0 + G1 @ (u1 - u0)

    def flow_exact(
        self, T: np.ndarray, zlo: np.ndarray, zhi: np.ndarray, span: Span
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact flow: ``T(t1-) = e^{A_z h} T e^{-A h}``,
        ``z(t1-) = e^{A_z h} z + T(t1-) ∫ e^{A(h-s)} (B u + E d) ds``; the ``d`` integral bounded by
        midpoint sums of ``|T(t1-) e^{A(h-s)} E|`` plus a bound of their variation on each
        sub-interval (rigorous, not a quadrature)."""
        h = span.t1 - span.t0
        c = self.period(h)
        Tn = c.Phi_z @ T @ c.Psi
        xu = self.input_integral(c, span)
        dc, dr = 0.5 * (span.dlo + span.dhi), 0.5 * (span.dhi - span.dlo)
        rad = (h / c.N) * np.abs(Tn @ c.nodesE).sum(axis=0) @ dr
        rad = rad + np.linalg.norm(Tn, axis=1) * float(c.var @ dr)
        mid = Tn @ (xu + c.GE @ dc)
        return Tn, c.Phi_z @ zlo + mid - rad, c.Phi_z @ zhi + mid + rad

    def anchor(self, c: PeriodData, first: bool = False) -> Anchor | None:
        """The constant ``T`` of a regular grid of period ``h`` (kept with the period's data).

        With every output observed, one interval maps ``T(t_k+)`` to
        ``e^{A_z h} T e^{-A h} + h B_z C``; its fixed point ``T_h`` solves the Sylvester equation
        (eq. 4 of the sampled system, solved once per period)::

            T_h e^{A h} - e^{A_z h} T_h = h B_z C e^{A h}

        (``T_h → T`` of (4) as ``h → 0``). Started at ``T_h`` (:meth:`to_anchor`), ``T`` is
        constant at the samples and nothing about it is propagated: ``T(t_k-) = T_h - h B_z C``,
        and the ``d`` radius of an interval is one matrix. ``D = e^{A_z h} T_h - T(t_k-) e^{A h}``
        (the computed residual) enters the radius as ``|D T_h⁻¹| max(|z̲|, |z̄|)``. ``None`` when
        ``T_h`` is singular or ill-conditioned (then ``T`` is propagated by :meth:`flow_exact`);
        on the first interval (``first``) that is a :class:`DesignError`: the target modes are
        too fast for the sampling period (rows of ``T`` with ``|a_i| h >> 1`` are forgotten
        between samples and become ``h b_i C``).
        """
        if not c.anchor_done:
            c.anchor, c.T_h = make_anchor(c, self.design.B_z, self.sys.C_at(0), self.max_cond)
            c.anchor_done = True
        if c.anchor is None and first:
            Th = c.T_h
            cond = left_inverse(Th, self.max_cond).cond if Th is not None else float("inf")
            a = float(np.min(np.linalg.eigvals(self.design.A_z).real))
            raise DesignError(
                f"kkl: sampling period h = {c.h:g}: the transformation at the samples "
                f"(T_h, fixed point of T -> e^(A_z h) T e^(-A h) + h B_z C) has cond {cond:.3e} > "
                f"max_cond = {self.max_cond:.0e}; target modes much faster than 1/h are forgotten "
                f"between samples (fastest eigenvalue of A_z: {a:.4g}, a h = {a * c.h:.3g}): "
                "pass A_z, B_z with slower eigenvalues (still faster than every mode of A) or "
                "sample faster"
            )
        return c.anchor

    def to_anchor(
        self,
        an: Anchor,
        k: int,
        T: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        box: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Switch the state ``(T, z̲, z̄)`` at ``t_(k-1)+`` to ``T_h`` when that costs nothing.

        ``T = T_h`` already (bitwise; after a JSON round trip too): nothing to do. First
        interval (``k = 1``, nothing measured yet): ``z`` is re-initialised from ``x0`` by (3.b)
        with ``T_h``. ``T`` within ``1e-9`` (relative) of ``T_h`` (back after missing samples or a
        change of period, the flow being stable): ``T_h x = z + (T_h - T) T⁻¹ z``, bounded by
        Lemma 1. Otherwise, when the flow of ``T`` is unstable (a target mode slower than a
        plant mode, which [Dinh2024, Proposition 1] allows: the deviation of ``T`` from ``T_h``
        would grow), ``z`` is re-initialised from the last box ``box`` of ``x`` by (3.b) with
        ``T_h``; else the state is returned unchanged.
        """
        Th = an.T
        if T is Th:
            return T, zlo, zhi
        if np.array_equal(T, Th):
            return Th, zlo, zhi
        if k == 1 and self.x0 is not None:
            zl, zh = image_bounds(Th, self.x0.lo, self.x0.hi)
            return Th, zl, zh
        if np.max(np.abs(T - Th)) <= ANCHOR_TOL * np.max(np.abs(Th)):
            tr = left_inverse(T, self.max_cond)
            if tr.ok:
                clo, chi = image_bounds((Th - T) @ tr.P, zlo, zhi)
                return Th, zlo + clo, zhi + chi
        if self._restart and box is not None and np.all(np.isfinite(box[0] + box[1])):
            return (Th, *self.restart(Th, T, zlo, zhi, box))
        return T, zlo, zhi

    def restart(
        self,
        Th: np.ndarray,
        T: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        box: tuple[np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``T_h x`` from ``z̲ <= T x <= z̄`` and the box of ``x``: (3.b) with ``T_h``
        on the box, intersected (when ``T`` is left-invertible, ``P T = I``) with
        ``T_h x = (I + (T_h - T) P) T x`` by Lemma 1, plus ``|T_h - T| |P T - I| |x|`` for the
        rounding of ``P`` (its residual bounded with ``γ_n``, [Higham2002, Lemma 3.1])."""
        lo, hi = image_bounds(Th, box[0], box[1])
        tr = left_inverse(T, self.max_cond)
        if tr.ok:
            n = T.shape[1]
            M = np.eye(T.shape[0]) + (Th - T) @ tr.P
            clo, chi = image_bounds(M, zlo, zhi)
            res = np.abs(tr.P @ T - np.eye(n)) + gamma(n + 2) * (np.abs(tr.P) @ np.abs(T))
            xabs = np.maximum(np.abs(box[0]), np.abs(box[1]))
            m = np.abs(Th - T) @ (res @ xabs) * (1.0 + gamma(2 * n + 2))
            nlo, nhi = np.maximum(lo, clo - m), np.minimum(hi, chi + m)
            ok = nlo <= nhi  # crossed only on data inconsistent with the model: keep (3.b)
            lo, hi = np.where(ok, nlo, lo), np.where(ok, nhi, hi)
        return lo, hi

    def flow_anchored(
        self, c: PeriodData, an: Anchor, zlo: np.ndarray, zhi: np.ndarray, span: Span
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`flow_exact` from ``T(t0+) = T_h``: the same formulas with the matrices of
        :meth:`anchor`, plus the residual term of ``T_h``."""
        mid = self.input_integral(c, span, (an.TgB, an.TG0, an.TG1))
        dc, dr = 0.5 * (span.dlo + span.dhi), 0.5 * (span.dhi - span.dlo)
        mid = mid + an.TGE @ dc
        rad = an.rad @ dr + an.res @ np.maximum(np.abs(zlo), np.abs(zhi))
        Phi = c.Phi_z
        return an.Tm, Phi @ zlo + mid - rad, Phi @ zhi + mid + rad

    def predict_box(
        self, c: PeriodData, xlo: np.ndarray, xhi: np.ndarray, span: Span
    ) -> tuple[np.ndarray, np.ndarray]:
        """``x(t1) ∈ e^{A h}[x̲, x̄] + ∫ e^{A(h-s)} (B u + E d) ds`` (Lemma 1 and the enclosures
        of :meth:`flow_exact` with ``T = I``)."""
        radI, abs_eA = c.identity_radius()
        xc, xr = 0.5 * (xlo + xhi), 0.5 * (xhi - xlo)
        mid = self.input_integral(c, span)
        dc, dr = 0.5 * (span.dlo + span.dhi), 0.5 * (span.dhi - span.dlo)
        mid = mid + c.eA @ xc + c.GE @ dc
        rad = abs_eA @ xr + radI @ dr
        return mid - rad, mid + rad
