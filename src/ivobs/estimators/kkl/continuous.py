"""Continuous-time KKL observers of [Dinh2024] (Sections 2 and 3.1) with sampled measurements.

Between samples only ``y[k]`` is known, and observers (3)/(10) integrate ``B_z y(t)``. ivobs runs
their *sampled-data* form, which is exact for any ``y(t)``: the measurement enters at the sample
instants, ``T ← T + h_k B_z C(t_k)``, ``z ← z + h_k B_z (y_k − D u_k − F d(t_k))`` (the
rectangle rule of ``∫ B_z y``, ``h_k = t_k − t_(k−1)``; ``y_0`` gets weight 0), and between
samples ``T`` follows ``Ṫ = A_z T − T A(t)`` (eq. 10.b without ``B_z C``), so that
``d(T x)/dt = A_z T x + T B u + T E d``. As the sampling period tends to 0 this is observer
(3)/(10). ``T(0)`` solves (4) (time-invariant) or (4) frozen at ``t = 0`` (time-varying), and
``z(0)`` is bounded from ``x0`` by (3.b)/(10.c) (``valid_from = 0``).

**The identity each interval rests on.** ``T`` (at ``t0+``) and ``T'`` (at ``t1−``) are float
matrices, and for every trajectory of the plant, with ``Φ = Φ(t1, t0)`` its transition matrix,

    T' x(t1) = e^{A_z h} (T x(t0)) + (T' Φ − e^{A_z h} T) x(t0)
               + T' ∫_{t0}^{t1} Φ(t1, s) (B u + E d)(s) ds                         (flow)

exactly, whatever ``T'`` is. ivobs takes ``T' = fl(e^{A_z h} T Φ⁻¹)`` (the flow of ``T``
computed in floats) or, on a regular grid, the constant of :mod:`.sampled`; the second term is
then rounding-sized and bounded on the box of ``x(t0)``. At ``t1`` the jump, with
``B_o = fl(h B_z[:, o])`` on the observed outputs and ``T'' = fl(T' + B_o C_o)``:

    T'' x = T' x + B_o (y_o − D_o u − F_o d) + (T'' − T' − B_o C_o) x               (jump)

again exact; the last term is bounded on the box at ``t1−``. Every matrix of the flow is an
interval matrix that contains the exact one (:mod:`.flow`: validated exponentials and Van Loan
blocks for time-invariant systems, the interval Taylor method for time-varying ones). Since
``e^{A_z h} >= 0`` (``A_z`` Metzler), ``e^{A_z h} z̲ <= e^{A_z h} T x(t0) <= e^{A_z h} z̄``;
the disturbance term is bounded by ``M ∫ Φ E ds d_c ± ∫ |M Φ E| ds d_r`` ([Dinh2024, Lemma 1]
under the integral). Each bound is one float sum whose rounding is bounded by ``γ_n`` times its
terms' magnitudes ([Higham2002, Lemma 3.1]) and rounded outward. The box of ``x`` is recovered
from ``z`` by :func:`.observer.recover` (proven rounding) and intersected with the model's
prediction of the previous box, ``x(t1) ∈ Φ [x̲, x̄] + ∫ Φ (B u + E d)`` (same enclosures).
The consistency test treats ``y_k`` as the double nearest to the exact output (half an ulp).

**Assumptions between samples.** ``u`` follows ``input_hold``: ``"zero"``-order hold (as a
digital controller and :func:`ivobs.simulate` with array inputs), ``"linear"`` interpolation, or
a callable ``t -> u(t)`` (traced, :mod:`.traced`: enclosed on sub-intervals). ``d(t)`` is any
measurable signal within the hull of its bounds at the two ends of the interval (constant bounds:
exactly its bounds); nothing is assumed about ``y`` between samples. Time-varying ``A``, ``B``,
``E`` are functions of ``t`` written with :mod:`ivobs.nlmath` (traced); ``C``, ``D``, ``F`` are
used at the sample times as their callables return them.

Data used: the box at ``t_k`` uses ``y`` up to ``t_k``. Missing samples: the missing rows are
left out of the jump, which is exact.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ...errors import DesignError, IvobsError
from ...linalg import gamma
from ...model import LinearSystem
from ...sets import Box
from ...sets.expm import IntervalMatrix, interval_product
from ...sets.rounding import ETA, UNIT_ROUNDOFF, down, mid_rad, product_error, up, upper
from ..state import Step
from .design import KKLDesign, Transform, left_inverse
from .flow import K, Passage, ltv_passage, minus, target_exponential
from .observer import Observer, ZState, prior_box, recover
from .periods import mismatch, period_key
from .traced import TimeFunction, trace

__all__ = ["ContinuousLTV", "ContinuousObserver", "ContinuousState", "Forcing", "InputHold"]

InputHold = str | Callable[[float], Any]
"""``u`` between samples: ``"zero"``-order hold, ``"linear"`` interpolation or ``t -> u(t)``."""


@dataclass(frozen=True)
class ContinuousState(ZState):
    """Observer (10) in sampled-data form at ``t_(k-1)+``: ``z̲ <= T x <= z̄`` with ``T`` itself
    (``T(t)`` moves between samples), the box ``[xlo, xhi]`` of ``x`` there, and the previous
    sample: its time ``t_prev`` (None before the first), input ``u_prev`` and bounds
    ``[dlo_prev, dhi_prev]`` of ``d``."""

    T: np.ndarray
    t_prev: float | None
    u_prev: np.ndarray
    dlo_prev: np.ndarray
    dhi_prev: np.ndarray
    xlo: np.ndarray
    xhi: np.ndarray

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (
        ("zlo", "zhi"),
        ("dlo_prev", "dhi_prev"),
        ("xlo", "xhi"),
    )


@dataclass(frozen=True)
class Span:
    """One interval between samples: its ends, the inputs there and the hull of the bounds of
    ``d`` at the two ends as centre and radius (``d ∈ [dc − dr, dc + dr]``)."""

    t0: float
    t1: float
    u0: np.ndarray
    u1: np.ndarray
    dc: np.ndarray
    dr: np.ndarray


@dataclass(frozen=True)
class Forcing:
    """``M ∫_{t0}^{t1} Φ(t1, s) (B u + E d)(s) ds`` of one interval for a float ``M`` (the
    identity when None), as the linear form of the step: it lies within ``L v ± R [|v|; u_r;
    d_r]`` where ``v`` holds the inputs of the hold (zero-order: ``u0``; linear: ``u0, u1``;
    callable: the centres of the ranges of ``u`` on the sub-intervals, ``u_r`` their radii)
    and ``d_c``. ``L`` is a float matrix within ``Lr`` of the exact one (interval products),
    ``Lu`` bounds the exact matrix applied to ``u_r`` and ``W >= ∫ |M Φ E|``; the rounding of
    ``L v`` itself is added where the step sums it (:func:`flow_matrices`)."""

    L: np.ndarray
    Lr: np.ndarray
    Lu: np.ndarray
    W: np.ndarray


def forcing(ps: Passage, M: np.ndarray | None, hold: str) -> Forcing:
    """The :class:`Forcing` of ``M`` (None: the identity) over the passage ``ps`` for the input
    hold ``hold`` (``"zero"``, ``"linear"``, ``"callable"``)."""

    def times(G: IntervalMatrix) -> IntervalMatrix:
        return G if M is None else interval_product(M, None, *G)

    parts = []
    rows = ps.GE[0].shape[0] if M is None else M.shape[0]
    Lu = np.zeros((rows, 0))
    if hold == "zero":
        parts.append(times(ps.G0))
    elif hold == "linear":  # u(s) = u0 + (s − t0)/h (u1 − u0): (G0 − G1) u0 + G1 u1
        parts += [times(minus(ps.G0, ps.G1)), times(ps.G1)]
    else:  # Σ over the sub-intervals of (∫ Φ B) times the range of u there
        assert ps.kB is not None
        pc, pr = ps.kB.times(M).subintegrals()  # (P, q, rows, nu)
        pc = np.moveaxis(pc, 2, 0).reshape(rows, -1)
        pr = np.moveaxis(pr, 2, 0).reshape(rows, -1)
        parts.append((pc, pr))
        Lu = up(np.abs(pc) + pr)
    parts.append(times(ps.GE))
    L = np.concatenate([c for c, _ in parts], axis=1)
    Lr = np.concatenate([r for _, r in parts], axis=1)
    return Forcing(L, Lr, Lu, ps.kE.times(M).abs_integral())


@dataclass(frozen=True)
class FlowMatrices:
    """The step (flow) of one interval for one ``T'`` as two products: ``Z [z̲; z̄; v]`` gives
    the centres of ``[z̲'; z̄']`` and ``Ze [|z̲|; |z̄|; |x|; |v|; u_r; d_r]`` their error bounds
    (module docstring: ``e^{A_z h} >= 0`` on ``[z̲, z̄]``, its radius, ``|X| |x|``, the forcing,
    and ``2 γ_{n+2}`` times the magnitudes of the ``n`` terms of each centre for its rounding);
    likewise ``Z [x̲; x̄; v]`` and ``Ze [|x|; |v|; u_r; d_r]`` (one error row per state, for
    both bounds) for the model's prediction of the box (the Lemma-1 image of ``Φ``)."""

    Z: np.ndarray
    Ze: np.ndarray

    def apply(
        self, lo: np.ndarray, hi: np.ndarray, v: np.ndarray, mags: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The centres ``Z [lo; hi; v]`` less/plus the error bound of ``Ze mags`` (rounded up),
        rounded outward."""
        n = lo.size
        out = self.Z @ np.concatenate((lo, hi, v))
        err = upper(self.Ze @ mags, self.Ze.shape[1])
        return down(out[:n] - err[:n]), up(out[n:] + err[-n:])


def flow_matrices(ps: Passage, Xmag: np.ndarray, f: Forcing) -> FlowMatrices:
    """:class:`FlowMatrices` of ``T'`` (forcing ``f``, ``Xmag >= |T' Φ − e^{A_z h} T|``)."""
    P, RP = ps.Phiz
    nz, nv = P.shape[0], f.L.shape[1]
    fac = 2.0 * gamma(nz + nv + 2)
    Z = np.zeros((2 * nz, 2 * nz + nv))
    Z[:nz, :nz], Z[nz:, nz : 2 * nz] = P, P
    Z[:, 2 * nz :] = np.vstack((f.L, f.L))
    A1 = up(RP + fac * np.abs(P))
    rest = np.concatenate((Xmag, up(f.Lr + fac * np.abs(f.L)), f.Lu, f.W), axis=1)
    Ze = np.zeros((2 * nz, 2 * nz + rest.shape[1]))
    Ze[:nz, :nz], Ze[nz:, nz : 2 * nz] = A1, A1
    Ze[:, 2 * nz :] = np.vstack((rest, rest))
    return FlowMatrices(Z, Ze)


def model_matrices(ps: Passage, f: Forcing) -> FlowMatrices:
    """:class:`FlowMatrices` of the model's prediction ``x(t1) ∈ Φ [x̲, x̄] + ∫ Φ (B u + E d)``
    (the identity's forcing ``f``)."""
    Phi, RPhi = ps.Phi
    n, nv = Phi.shape[0], f.L.shape[1]
    fac = 2.0 * gamma(2 * n + nv + 2)
    Pp, Pn = np.maximum(Phi, 0.0), np.maximum(-Phi, 0.0)
    Mx = np.block([[Pp, -Pn, f.L], [-Pn, Pp, f.L]])
    Me = np.concatenate(
        (up(RPhi + fac * np.abs(Phi)), up(f.Lr + fac * np.abs(f.L)), f.Lu, f.W), axis=1
    )
    return FlowMatrices(Mx, Me)


@dataclass(frozen=True)
class JumpMatrices:
    """The jump (module docstring) for one pattern of observed outputs: ``T''`` and its left
    inverse (None: computed), and ``z`` moves by ``Lj [y_o; u; d_c]`` within ``Kj [|y_o|;
    |u|; |d_c|; d_r; s; |x|]`` (``s``: half an ulp of ``y_o``; the last columns ``|T'' − T' −
    B_o C_o|`` bounded)."""

    T: np.ndarray
    tr: Transform | None
    Lj: np.ndarray
    Kj: np.ndarray


def jump_matrices(
    Tp: np.ndarray,
    Tn: np.ndarray,
    tr: Transform | None,
    Bo: np.ndarray,
    CDF: tuple[np.ndarray, ...],
) -> JumpMatrices:
    """:class:`JumpMatrices` from ``T'``, ``T''``, ``B_o`` and the observed rows ``(C_o, D_o,
    F_o)``: ``z`` jumps by ``B_o (y_o − D_o u − F_o d)``; the exact ``B_o D_o``, ``B_o F_o``
    lie within the radii of their interval products, and ``T'' − T' − B_o C_o`` within
    ``|fl(fl(T'' − T') − fl(B_o C_o))|`` plus the rounding of the three operations."""
    Co, Do, Fo = CDF
    J = Bo @ Co
    Dd = Tn - Tp
    Y = np.abs(Dd - J)
    no = Bo.shape[1]
    Ymag = upper(Y + product_error(np.abs(Bo) @ np.abs(Co) + np.abs(Dd) + Y, no + 2), 2)
    BD, BDr = interval_product(Bo, None, Do, None)
    BF, BFr = interval_product(Bo, None, Fo, None)
    Lj = np.concatenate((Bo, -BD, -BF), axis=1)
    fac = 2.0 * gamma(Lj.shape[1] + 2)
    aL = fac * np.abs(Lj)
    Kj = np.concatenate(
        (
            aL[:, :no],
            up(aL[:, no : no + BD.shape[1]] + BDr),
            up(aL[:, no + BD.shape[1] :] + BFr),
            up(np.abs(BF) + BFr),
            np.abs(Bo),
            Ymag,
        ),
        axis=1,
    )
    return JumpMatrices(Tn, tr, Lj, up(Kj))


class ContinuousObserver(Observer[ContinuousState]):
    """The sampled-data step, written once: the flow from the previous sample, the measurement
    jump, and the recovery of the box. Subclasses give the :class:`~.flow.Passage` of each
    interval and may keep ``T`` constant (:mod:`.sampled`)."""

    def __init__(
        self, sys: LinearSystem, x0: Box | None, design: KKLDesign, max_cond: float, hold: InputHold
    ):
        super().__init__(sys, x0, design, max_cond)
        self.hold = "callable" if callable(hold) else str(hold)
        self.u_fn: TimeFunction | None = (
            trace("input_hold", hold, (sys.nu,), 0) if callable(hold) else None
        )
        self._Phiz: dict[float, tuple[tuple[float, float], IntervalMatrix]] = {}
        self._dmr = mid_rad(self._dfix.lo, self._dfix.hi) if self._dfix is not None else None

    # -- what subclasses choose ----------------------------------------------------------------
    def passage(self, span: Span) -> Passage:
        """The enclosures of the interval ``span``."""
        raise NotImplementedError

    def next_transform(
        self, state: ContinuousState, ps: Passage
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any]:
        """``(T, z̲, z̄)`` at ``t0+`` (possibly moved onto another ``T``), ``T'`` at ``t1−`` and
        a tag for :meth:`matrices`, :meth:`after_jump` (None: ``T'`` is the flow of ``T``)."""
        return self.propagate(state.T, state.zlo, state.zhi, ps)

    def propagate(
        self, T: np.ndarray, zlo: np.ndarray, zhi: np.ndarray, ps: Passage
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any]:
        """:meth:`next_transform` with ``T' = fl(e^{A_z h} T Φ⁻¹)``, the flow of ``T``."""
        Phiz, Phi = ps.Phiz[0], ps.Phi[0]
        Tp = np.linalg.solve(Phi.T, (Phiz @ T).T).T
        return T, zlo, zhi, Tp, None

    def matrices(self, ps: Passage, T: np.ndarray, Tp: np.ndarray, tag: Any) -> FlowMatrices:
        """The :class:`FlowMatrices` of ``T'``."""
        f = forcing(ps, Tp, self.hold)
        return flow_matrices(ps, mismatch(Tp, ps, T), f)

    def model(self, ps: Passage) -> FlowMatrices:
        """The model's prediction matrices of ``ps`` (kept with it)."""
        m: FlowMatrices | None = ps.kept.get("model")
        if m is None:
            m = ps.kept["model"] = model_matrices(ps, forcing(ps, None, self.hold))
        return m

    def transform_at(self, T: np.ndarray, tag: Any) -> Transform:
        """The left inverse of ``T'`` (at ``t1−``)."""
        return left_inverse(T, self.max_cond)

    def after_jump(
        self,
        ps: Passage,
        Tp: np.ndarray,
        h: float,
        obs: np.ndarray,
        CDF: tuple[np.ndarray, ...],
        tag: Any,
    ) -> JumpMatrices:
        """The :class:`JumpMatrices` with ``B_o = fl(h B_z[:, o])`` and ``T'' = fl(T' + B_o
        C_o)``."""
        Bo = h * self.design.B_z[:, obs]
        rows = tuple(M[obs] for M in CDF)
        return jump_matrices(Tp, Tp + Bo @ rows[0], None, Bo, rows)

    # -- pieces --------------------------------------------------------------------------------
    def target_exponential(self, h: float) -> tuple[tuple[float, float], IntervalMatrix]:
        """``e^{A_z τ}`` for an interval of lengths around ``h`` (kept by period)."""
        key, H = period_key(h)
        got = self._Phiz.get(key)
        if got is None:
            if len(self._Phiz) >= 256:
                self._Phiz.clear()
            got = self._Phiz[key] = (H, target_exponential(self.design.A_z, H))
        return got

    def inputs(self, ps: Passage, span: Span) -> tuple[np.ndarray, np.ndarray]:
        """``(v, u_r)`` of :class:`Forcing` for the input hold: for a callable input the ranges
        of ``u`` on the sub-intervals of the kernel of ``B`` (sub-interval ``s`` of piece ``p``
        covers ``σ = t1 − t`` in ``[(p + s/q) ℓ, (p + (s+1)/q) ℓ]``), in the order of
        :func:`forcing`."""
        if self.hold == "zero":
            return np.concatenate((span.u0, span.dc)), np.zeros(0)
        if self.hold == "linear":
            return np.concatenate((span.u0, span.u1, span.dc)), np.zeros(0)
        assert ps.kB is not None and self.u_fn is not None
        w = ps.kB.w
        P, q = ps.kB.P, w.sub[0].shape[0]
        ell = w.ell
        cs, rs = [], []
        for p in range(P):
            for j in range(q):
                slo = float(down(down((p + j / q) * ell[0]) * (1 - 4 * UNIT_ROUNDOFF)))
                shi = float(up(up((p + (j + 1) / q) * ell[1]) * (1 + 4 * UNIT_ROUNDOFF)))
                tl = max(float(down(span.t1 - shi)), float(down(span.t0)))
                th = min(float(up(span.t1 - slo)), float(up(span.t1)))
                c, r = self.u_fn.coefficients(min(tl, th), th)
                cs.append(c[0])
                rs.append(r[0])
        uc, ur = np.array(cs).T.ravel(), np.array(rs).T.ravel()  # (nu, P q) as in forcing
        return np.concatenate((uc, span.dc)), ur

    def initial_state(self) -> ContinuousState:
        zlo, zhi = self.initial_z()  # (3.b)/(10.c)
        xlo, xhi = self.initial_x()
        nu, nd = self.sys.nu, self.sys.nd
        return ContinuousState(
            zlo=zlo, zhi=zhi, T=self.design.T.copy(), t_prev=None, u_prev=np.zeros(nu),
            dlo_prev=np.zeros(nd), dhi_prev=np.zeros(nd), xlo=xlo, xhi=xhi, k=0,
        )  # fmt: skip

    # -- the step ------------------------------------------------------------------------------
    def flow(
        self, state: ContinuousState, ps: Passage, span: Span
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[np.ndarray, np.ndarray], Any]:
        """From ``t0+`` to ``t1−`` (module docstring, (flow)): ``T'``, ``z̲, z̄`` at ``t1−``,
        the model's prediction of the box, and the tag of ``T'``."""
        T, zlo, zhi, Tp, tag = self.next_transform(state, ps)
        fm = self.matrices(ps, T, Tp, tag)
        xlo, xhi = state.xlo, state.xhi
        xabs = np.maximum(np.abs(xlo), np.abs(xhi))
        v, ur = self.inputs(ps, span)
        mags = np.concatenate((np.abs(v), ur, span.dr))
        # T' x(t1) = e^{A_z h} z + X x(t0) + T' ∫ Φ (B u + E d)
        zabs = np.concatenate((np.abs(zlo), np.abs(zhi), xabs, mags))
        zlo1, zhi1 = fm.apply(zlo, zhi, v, zabs)
        # the model: x(t1) ∈ Φ [x̲, x̄] + ∫ Φ (B u + E d)
        model = self.model(ps).apply(xlo, xhi, v, np.concatenate((xabs, mags)))
        return Tp, zlo1, zhi1, model, tag

    def step(
        self, state: ContinuousState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ContinuousState]:
        assert t_k is not None
        k = state.k
        _, _, C, D, _, F = self.sys.matrices_at(t_k)
        d = self.bounds_d(k, y_k)
        T, zlo, zhi = state.T, state.zlo, state.zhi
        model: tuple[np.ndarray, np.ndarray] | None = None
        bad = False
        if state.t_prev is None:  # the first sample: z from x0, no interval yet
            tr = left_inverse(T, self.max_cond)
        else:
            t0 = float(state.t_prev)
            if not t_k - t0 > 0:
                raise IvobsError(f"t: sample times must increase; got t = {t_k} after {t0}")
            if self._dmr is not None:
                dc, dr = self._dmr
            else:
                dc, dr = mid_rad(np.minimum(state.dlo_prev, d.lo), np.maximum(state.dhi_prev, d.hi))
            span = Span(t0, float(t_k), state.u_prev, u_k, dc, dr)
            ps = self.passage(span)
            Tp, zlo, zhi, model, tag = self.flow(state, ps, span)
            tr = self.transform_at(Tp, tag)
            box, bad = self.x_box(tr, zlo, zhi, model)
            T = Tp
            obs = ~np.isnan(y_k)
            if box is not None and np.count_nonzero(obs):  # the sampled B_z y of (3)/(10)
                jumped = self.jump(ps, t_k - t0, Tp, zlo, zhi, box, y_k, u_k, d, (C, D, F), tag)
                if jumped is None:
                    bad = True  # y_k contradicts the box: not used
                else:
                    T, zlo, zhi, trn = jumped
                    tr = trn if trn is not None else left_inverse(T, self.max_cond)
                    model = box
            elif box is not None:
                model = box
        box, crossed = self.x_box(tr, zlo, zhi, model)
        if box is None:
            raise DesignError(
                f"kkl: T(t) lost left-invertibility at t = {t_k} (cond {tr.cond:.3e} > max_cond "
                f"= {self.max_cond:.0e}); choose faster target dynamics (larger ell) or another "
                "A_z, B_z ([Dinh2024, Propositions 1, 3])"
            )
        lo, hi = box
        if k == 0:
            lo, hi = prior_box(self.x0, lo, hi)
        new = ContinuousState(
            T=T, zlo=zlo, zhi=zhi, t_prev=float(t_k), u_prev=u_k.copy(), dlo_prev=d.lo.copy(),
            dhi_prev=d.hi.copy(), xlo=lo.copy(), xhi=hi.copy(), k=k,
            inconsistent=state.inconsistent,
        )  # fmt: skip
        return Step(new, lo, hi, bad or crossed)

    def jump(
        self,
        ps: Passage,
        h: float,
        Tp: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        box: tuple[np.ndarray, np.ndarray],
        y_k: np.ndarray,
        u_k: np.ndarray,
        d: Box,
        CDF: tuple[np.ndarray, np.ndarray, np.ndarray],
        tag: Any,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, Transform | None] | None:
        """(jump) of the module docstring: ``T''``, ``z̲, z̄`` at ``t1+`` and the left inverse of
        ``T''`` if known; None when ``y_k`` contradicts the box at ``t1−`` (it is not used)."""
        obs = ~np.isnan(y_k)
        lo, hi = box
        xabs = np.maximum(np.abs(lo), np.abs(hi))
        if not np.isfinite(xabs).all():
            return None
        y_o = y_k[obs]
        slack = up(UNIT_ROUNDOFF * np.abs(y_o) + ETA)  # y_o: the double nearest to the exact
        uabs = np.abs(u_k)
        if self.check(CDF, obs).contradicts(y_o, u_k, lo, hi, xabs, uabs, d.lo, d.hi, slack=slack):
            return None
        jm = self.after_jump(ps, Tp, h, obs, CDF, tag)
        dc, dr = self._dmr if self._dmr is not None else mid_rad(d.lo, d.hi)
        c = jm.Lj @ np.concatenate((y_o, u_k, dc))
        mags = np.concatenate((np.abs(y_o), uabs, np.abs(dc), dr, slack, xabs))
        e = upper(jm.Kj @ mags, mags.size)
        return jm.T, down(down(zlo + c) - e), up(up(zhi + c) + e), jm.tr

    def x_box(
        self,
        tr: Transform,
        zlo: np.ndarray,
        zhi: np.ndarray,
        model: tuple[np.ndarray, np.ndarray] | None,
    ) -> tuple[tuple[np.ndarray, np.ndarray] | None, bool]:
        """The box from ``z`` (3.c-d)/(10.d), intersected with the model's prediction ``model``
        (both are sound); the prediction alone while ``T`` is not left-invertible (e.g. right
        after a long gap); None if neither is available.

        An empty intersection beyond rounding means the data contradict the model: reported as
        an inconsistency (the flag returned); each crossed coordinate then keeps the hull of the
        two crossed ends.
        """
        if not tr.ok:
            return model, False
        lo, hi = recover(tr, zlo, zhi)
        if model is None:
            return (lo, hi), False
        lo, hi = np.maximum(lo, model[0]), np.minimum(hi, model[1])
        cross = lo > hi
        bad = False
        if np.count_nonzero(cross):
            bad = bool(np.any(lo - hi > 1e-9 * (1.0 + np.abs(lo) + np.abs(hi))))
            lo, hi = np.where(cross, hi, lo), np.where(cross, lo, hi)
        return (lo, hi), bad


class ContinuousLTV(ContinuousObserver):
    """Time-varying: the passage of every interval by the interval Taylor method
    (:func:`.flow.ltv_passage`) on the traced ``A(t)``, ``B(t)``, ``E(t)``."""

    def __init__(
        self, sys: LinearSystem, x0: Box | None, design: KKLDesign, max_cond: float, hold: InputHold
    ):
        super().__init__(sys, x0, design, max_cond, hold)
        self.A = _traced("A", sys.A, (sys.nx, sys.nx), K)
        self.B = _traced("B", sys.B, (sys.nx, sys.nu), K + 1)
        self.E = _traced("E", sys.E, (sys.nx, sys.nd), K + 1)

    def passage(self, span: Span) -> Passage:
        H, Phiz = self.target_exponential(span.t1 - span.t0)
        h = (float(down(span.t1 - span.t0)), float(up(span.t1 - span.t0)))
        if not (H[0] <= h[0] and h[1] <= H[1]):
            Phiz = target_exponential(self.design.A_z, h)
        A = self.A if isinstance(self.A, TimeFunction) else _Constant(self.A)
        return ltv_passage(A, self.B, self.E, span.t0, span.t1, Phiz, self.hold == "callable")


class _Constant:
    """A constant matrix with the interface of :class:`~.traced.TimeFunction`."""

    def __init__(self, M: np.ndarray):
        self.shape = M.shape
        self._c = np.zeros((K + 1, *M.shape))
        self._c[0] = M
        self._r = np.zeros_like(self._c)

    def coefficients(self, tl: float, th: float) -> tuple[np.ndarray, np.ndarray]:
        return self._c, self._r


def _traced(name: str, M: Any, shape: tuple[int, int], order: int) -> Any:
    """A time-varying matrix of a continuous-time model traced as a function of ``t`` (a
    constant one as it is)."""
    if callable(M):
        return trace(name, M, shape, order)
    arr = np.asarray(M, dtype=float)
    if arr.ndim == 3:
        raise IvobsError(
            f"{name}: stacked matrices are steps of a discrete-time model; a continuous-time "
            f"model takes a function of t"
        )
    return arr.reshape(shape)
