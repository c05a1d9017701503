"""The continuous-time time-invariant KKL observer between samples, in closed form.

On an interval of length ``h`` (the sampled-data form of :mod:`.continuous`) the flow's
matrices are validated exponentials and Van Loan blocks (:func:`.periods.lti_passage`), kept per
sampling period. On a regular grid the observer keeps ``T`` constant at the samples
(:meth:`ContinuousLTI.anchor`): ``T' = T_h − h B_z C`` and ``T'' = T_h`` every interval, so the
matrices of the step are computed once per period.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...design.sylvester import flow_gap
from ...errors import DesignError
from ...model import LinearSystem
from ...sets import Box, image_bounds
from ...sets.rounding import down, product_error, up, upper
from .continuous import (
    ContinuousObserver,
    ContinuousState,
    FlowMatrices,
    InputHold,
    JumpMatrices,
    Span,
    flow_matrices,
    forcing,
    jump_matrices,
)
from .design import KKLDesign, Transform, left_inverse
from .flow import Passage
from .periods import Anchor, lti_passage, make_anchor, period_key

__all__ = ["ContinuousLTI"]

ANCHOR_TOL = 1e-9
"""Relative distance of ``T`` to the constant ``T_h`` of a regular grid below which the state is
moved onto ``T_h`` (the cost is ``|T_h − T| |x|``, see :meth:`ContinuousLTI.to_anchor`)."""
CACHE_SIZE = 256
"""Sampling periods whose interval matrices are kept."""


class ContinuousLTI(ContinuousObserver):
    """Time-invariant: closed-form flows, a constant ``T`` on regular grids."""

    def __init__(
        self, sys: LinearSystem, x0: Box | None, design: KKLDesign, max_cond: float, hold: InputHold
    ):
        super().__init__(sys, x0, design, max_cond, hold)
        self._periods: dict[float, Passage] = {}
        # a target slower than a plant mode ([Dinh2024, Proposition 1] allows it): the flow of T
        # between samples is unstable, so T is brought back onto T_h from the last box
        self._restart = flow_gap(self.design.A_z, self.sys.A_at(0)) >= 0.0

    def passage(self, span: Span) -> Passage:
        """The passage of one sampling interval (kept by period, with the period's anchor)."""
        h = span.t1 - span.t0
        key, H = period_key(h)
        exact = (float(down(h)), float(up(h)))  # the exact t1 − t0 lies in it
        if not (H[0] <= exact[0] and exact[1] <= H[1]):
            return lti_passage(self.sys, self.design.A_z, exact, self.hold == "callable")
        ps = self._periods.get(key)
        if ps is None:
            if len(self._periods) >= CACHE_SIZE:  # irregular grids: one entry per period
                self._periods.clear()
            ps = lti_passage(self.sys, self.design.A_z, H, self.hold == "callable")
            ps.kept["h"] = key
            self._periods[key] = ps
        return ps

    def anchor(self, ps: Passage, first: bool = False) -> Anchor | None:
        """The constant ``T`` of a regular grid of period ``h`` (kept with the period).

        With every output observed, one interval maps ``T(t_k+)`` to
        ``e^{A_z h} T e^{-A h} + h B_z C``; its fixed point ``T_h`` solves the Sylvester equation
        (eq. 4 of the sampled system, solved once per period)::

            T_h e^{A h} - e^{A_z h} T_h = h B_z C e^{A h}

        (``T_h → T`` of (4) as ``h → 0``). Started at ``T_h`` (:meth:`to_anchor`), ``T`` is
        constant at the samples: ``T' = T_h − h B_z C`` at ``t_k−``, and the mismatch
        ``T' Φ − e^{A_z h} T_h`` of the identity (flow) is bounded once. ``None`` when ``T_h``
        is singular or ill-conditioned (then ``T`` is propagated); on the first interval
        (``first``) that is a :class:`DesignError`: the target modes are too fast for the
        sampling period (rows of ``T`` with ``|a_i| h >> 1`` are forgotten between samples and
        become ``h b_i C``).
        """
        data = ps.kept
        if "anchor" not in data:
            if "h" not in data:  # an interval of its own (lengths beyond a kept period)
                return None
            data["anchor"], data["T_h"] = make_anchor(
                ps, self.design.B_z, self.sys.C_at(0), data["h"], self.max_cond
            )
        an: Anchor | None = data["anchor"]
        if an is None and first:
            Th = data["T_h"]
            cond = left_inverse(Th, self.max_cond).cond if Th is not None else float("inf")
            a = float(np.min(np.linalg.eigvals(self.design.A_z).real))
            h = data["h"]
            raise DesignError(
                f"kkl: sampling period h = {h:g}: the transformation at the samples "
                f"(T_h, fixed point of T -> e^(A_z h) T e^(-A h) + h B_z C) has cond {cond:.3e} > "
                f"max_cond = {self.max_cond:.0e}; target modes much faster than 1/h are forgotten "
                f"between samples (fastest eigenvalue of A_z: {a:.4g}, a h = {a * h:.3g}): "
                "pass A_z, B_z with slower eigenvalues (still faster than every mode of A) or "
                "sample faster"
            )
        return an

    def next_transform(
        self, state: ContinuousState, ps: Passage
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, Any]:
        k = state.k
        an = self.anchor(ps, first=k == 1)
        T, zlo, zhi = state.T, state.zlo, state.zhi
        if an is not None:
            T, zlo, zhi = self.to_anchor(an, k, T, zlo, zhi, (state.xlo, state.xhi))
            if T is an.T:  # constant T: the anchored step
                return T, zlo, zhi, an.Tm, an
        return self.propagate(T, zlo, zhi, ps)

    def matrices(self, ps: Passage, T: np.ndarray, Tp: np.ndarray, tag: Any) -> FlowMatrices:
        if not isinstance(tag, Anchor):
            return super().matrices(ps, T, Tp, tag)
        fm: FlowMatrices | None = ps.kept.get("anchored")
        if fm is None:  # T' = T_h − h B_z C every interval: kept with the period
            fm = ps.kept["anchored"] = flow_matrices(ps, tag.Xmag, forcing(ps, Tp, self.hold))
        return fm

    def transform_at(self, T: np.ndarray, tag: Any) -> Transform:
        return tag.trm if isinstance(tag, Anchor) else super().transform_at(T, tag)

    def after_jump(
        self,
        ps: Passage,
        Tp: np.ndarray,
        h: float,
        obs: np.ndarray,
        CDF: tuple[np.ndarray, ...],
        tag: Any,
    ) -> JumpMatrices:
        if not (isinstance(tag, Anchor) and obs.all()):
            return super().after_jump(ps, Tp, h, obs, CDF, tag)
        jm: JumpMatrices | None = ps.kept.get("anchored jump")
        if jm is None:  # B_o = fl(h B_z) of the period, T'' = T_h = fl(T' + B_o C) (make_anchor)
            Bo = ps.kept["h"] * self.design.B_z
            jm = ps.kept["anchored jump"] = jump_matrices(Tp, tag.T, tag.tr, Bo, CDF)
        return jm

    def to_anchor(
        self,
        an: Anchor,
        k: int,
        T: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        box: tuple[np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Switch the state ``(T, z̲, z̄)`` at ``t_(k-1)+`` to ``T_h`` when that costs nothing.

        ``T = T_h`` already (bitwise; after a JSON round trip too): nothing to do. First
        interval (``k = 1``, nothing measured yet): ``z`` is re-initialised from ``x0`` by (3.b)
        with ``T_h``. ``T`` within ``1e-9`` (relative) of ``T_h`` (back after missing samples or a
        change of period, the flow being stable), or, when the flow of ``T`` is unstable (a
        target mode slower than a plant mode, which [Dinh2024, Proposition 1] allows: the
        deviation of ``T`` from ``T_h`` would grow): ``T_h x`` bounded by :meth:`retarget`.
        Otherwise the state is returned unchanged.
        """
        Th = an.T
        if np.array_equal(T, Th):
            return Th, zlo, zhi
        if k == 1 and self.x0 is not None:
            zl, zh = image_bounds(Th, self.x0.lo, self.x0.hi)
            return Th, zl, zh
        close = np.max(np.abs(T - Th)) <= ANCHOR_TOL * np.max(np.abs(Th))
        if (close or self._restart) and np.all(np.isfinite(box[0] + box[1])):
            return (Th, *self.retarget(Th, T, zlo, zhi, box))
        return T, zlo, zhi

    def retarget(
        self,
        Th: np.ndarray,
        T: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        box: tuple[np.ndarray, np.ndarray],
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``T_h x`` from ``z̲ <= T x <= z̄`` and the box of ``x``: (3.b) with ``T_h``
        on the box, intersected (when ``T`` is left-invertible, ``P`` a float left inverse)
        with ``T_h x = T x + Δ x``, ``Δ = T_h − T = Δ̂ + δ`` (``Δ̂ = fl(T_h − T)``, ``|δ| <= u |Δ̂|``)
        and ``Δ̂ x = Δ̂ P (T x) + Δ̂ (I − P T) x``: the Lemma-1 image of ``M̂ = fl(I + Δ̂ P)`` on
        ``[z̲, z̄]``, plus ``|M − M̂| |z|``, ``|Δ̂| r ‖x‖∞`` (``r`` the row sums of ``|I − P T|``,
        :class:`~.design.Transform`) and ``u |Δ̂| |x|``."""
        lo, hi = image_bounds(Th, box[0], box[1])
        tr = left_inverse(T, self.max_cond)
        if tr.ok:
            nz = T.shape[0]
            Dh = Th - T
            aD = np.abs(Dh)
            M = np.eye(nz) + Dh @ tr.P
            eM = product_error(aD @ tr.absP + np.eye(nz), nz + 1)
            clo, chi = image_bounds(M, zlo, zhi)
            xabs = np.maximum(np.abs(box[0]), np.abs(box[1]))
            zabs = np.maximum(np.abs(zlo), np.abs(zhi))
            s = eM @ zabs + (aD @ tr.resid) * float(np.max(xabs)) + product_error(aD @ xabs, 1)
            m = upper(s, 2 * nz + 4)
            nlo, nhi = np.maximum(lo, down(clo - m)), np.minimum(hi, up(chi + m))
            ok = nlo <= nhi  # crossed only on data inconsistent with the model: keep (3.b)
            lo, hi = np.where(ok, nlo, lo), np.where(ok, nhi, hi)
        return lo, hi
