"""Zonotopic set-membership filter with strip intersection [Alamo2005].

**Intersection with a strip [Alamo2005].** For a zonotope ``<p, H>`` and a strip
``S = {x : |hᵀx - t| <= σ}``, every ``λ`` gives a zonotope containing ``<p, H> ∩ S``::

    X(λ) = <p + λ (t - hᵀp), [(I - λ hᵀ) H, σ λ]>

and the one with the smallest Frobenius radius ``‖·‖_F`` of its generator matrix has the closed
form ``λ* = H Hᵀ h / (hᵀ H Hᵀ h + σ²)``.

**Correlated disturbance.** ``d`` enters both ``x+ = A x + B u + E d`` and
``y = C x + D u + F d``, so the filter works on the pair ``(x_k, d_k)``: the joint zonotope
``<(p, c_d), blkdiag(H, R)>`` (``d = c_d + R δ``), each measured component ``i`` is the
hyperplane ``C_i x + F_i d = y_i - D_i u`` in the joint space (the measurement noise is the
``F d`` part of the joint set; its half-width is only the rounding level, see below), and the
prediction maps the intersected joint set with ``[A E]``. This is exact for the correlation, and
reduces to the classical strip ``σ_i = Σ_j |F_ij| r_j`` when the noise components enter one
output and not the state. The components of ``y_k`` are intersected one after the other.

**Rounding.** ``y`` is a float64 record (possibly a float64 simulation of the model) and every
update is rounded, so component ``i`` is intersected as the strip of half-width (``h = (C_i,
F_i)``, ``t = y_i - D_i u``, ``w̄`` a bound on ``|(x, d)|`` from the joint box,
``γ_n = n u / (1 - n u)`` [Higham2002, Section 3.1])::

    σ_i = 2 γ_{nz+nu+2} (|y_i| + |D_i| |u| + |h|ᵀ w̄) + γ_{nz+1} (|t| + |h|ᵀ |z|)
          + γ_{nz} |h|ᵀ |H_z| 1                                                        (8)

which certainly holds ``(x_k, d_k)``, not as the hyperplane ``σ = 0``: with ``σ = 0`` the gain
``λ* = H s / sᵀs`` grows like ``1 / ‖s‖`` once the set is thin along ``h`` and ``eps |y|`` moved
the set off the state (a miss of 0.22 at ``|x| ~ 3e4``); (8) bounds it. The rounding of the
updates (``z + λ e``, ``H - λ sᵀ``) is accumulated in a box kept aside,
``(x_k, d_k) ∈ <z, H_z> ⊕ box(acc)``, which the prediction appends as generators together with
the rounding of ``M z + B u`` and ``M H``. A measurement is reported inconsistent only when the
strip certainly misses the zonotope: ``|t - hᵀz| > (‖s‖₁ + σ_z) (1 + γ)`` (``σ_z``: (8) widened
by the box aside).

**Boxes.** The box of ``x[k]`` is the interval hull of the filtered zonotope, intersected with
two cheap exact enclosures computed at each strip before the zonotope update: the interval hull
of ``(current zonotope) ∩ (hyperplane)`` per coordinate (the Lagrangian dual of the LP
``max x_j``, a one-dimensional convex piecewise-linear function minimised at its breakpoints: no
solver), and constraint propagation of the hyperplane over the box of ``(x, d)``. When every
state is measured the box is therefore the measurement box whenever the prediction is wider.

**Order reduction.** After the prediction the zonotope keeps at most ``order`` generators.
The default (``reduction="parallelotope"``) absorbs the generators to remove into a basis of
``nx`` large, independent ones (the parallelotope rule of [Chisci1998];
:func:`ivobs.sets.zonotope.reduce_parallelotope`), on the steps where that basis is well
conditioned, and otherwise encloses them in Girard's box ([Girard2005], CORA's default,
``reduction="girard"``): a basis picked among the generators can become nearly dependent, and
without the check the boxes diverged (CORA's tank30 at ``order = 2 nx``: radius 10⁷).
``reduction="box"`` is the box of [Combastel2015] ([Tang2019, Remark 2]).

**Work per step.** Only the components of ``d`` that enter a measurement are in the joint set
(the others are added at the prediction, exactly); the per-coordinate hull sorts the
breakpoints once (``O(nx m log m)`` per strip, ``m`` the generators); the model's structure is
derived once for a time-invariant system. The two box enclosures are in
``estimators/_strip_hull.py``, each bound pair computed by stacked ``(2, ·)`` array
operations, and the large per-strip temporaries (``|H_z|``, ``λ sᵀ``, the hull's spread) are
computed in place in scratch arrays (issue 17). With numba (``pip install ivobs[fast]``) the
whole step runs as one compiled call (:mod:`._strip_kernel`), tested bound for bound against
this module, which is its reference and the fallback.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._validate import as_int, as_matrix
from ..errors import IvobsError
from ..linalg import UNIT_ROUNDOFF, gamma
from ..model import LinearSystem
from ..sets import Box, Zonotope
from ..sets.rounding import mid_rad
from ..sets.zonotope import box_generators, reduce_girard, reduce_parallelotope
from . import _strip_kernel, register
from . import _uncertain as uncertain
from ._strip_hull import _add, _max, propagate_strip, section_hull
from ._strip_hull import propagate_hyperplane as _propagate_hyperplane
from ._strip_hull import section_hull as _section_hull
from .base import Design, Estimator, check_size
from .state import OnlineState, Step

__all__ = [
    "REDUCTIONS",
    "StripDesign",
    "StripEstimator",
    "StripState",
    "_propagate_hyperplane",
    "_section_hull",
]

REDUCTIONS = ("parallelotope", "girard", "box")


@dataclass(frozen=True)
class StripDesign(Design):
    """``order``: generators kept by the reduction (the zonotope order ``q`` of [Tang2019,
    Remark 2]); ``reduction``: ``"parallelotope"`` or ``"box"``; ``weight``: the weight ``W`` of
    the box reduction (identity when None)."""

    order: int
    reduction: str
    weight: np.ndarray | None


@dataclass(frozen=True)
class StripState(OnlineState):
    """``x[k] ∈ <p, H> ⊕ box(e)``: the zonotope of ``x[k]`` predicted from ``y[0..k-1]``
    (centre ``p``, generators ``H``) and ``e``, the box of the rounding of the last reduction,
    kept aside until the next prediction."""

    p: np.ndarray
    H: np.ndarray
    e: np.ndarray


@dataclass(frozen=True)
class _Structure:
    """What the step needs of the model at one ``k``, derived once for a time-invariant system:
    ``jc``, the components of ``d`` that enter a measurement (``F`` column nonzero) and so
    are part of the joint set; ``pc``, those that enter only the state equation: the strips
    never touch them (their entries of ``s = H_zᵀ h`` and ``λ`` are zero), so they are added at
    the prediction, ``E_pc <c_d, R>``, exactly as in the joint set; ``mc``, the columns of
    ``M = [A E_jc]`` that are nonzero; ``h[i] = (C_i, F_i,jc)``; the absolute values
    ``|h|, |M|, |E_pc|, |B|, |D|`` of the rounding bounds; ``hnz[i]``: where ``h[i] != 0``."""

    A: np.ndarray
    B: np.ndarray
    D: np.ndarray
    jc: np.ndarray
    pc: np.ndarray
    Ep: np.ndarray
    M: np.ndarray
    mc: np.ndarray
    h: np.ndarray
    ah: np.ndarray
    aM: np.ndarray
    aEp: np.ndarray
    aB: np.ndarray
    aD: np.ndarray
    all_mc: bool
    hnz: tuple[np.ndarray, ...]


def _structure(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray, E: np.ndarray,
               F: np.ndarray) -> _Structure:  # fmt: skip
    f_used = np.any(F != 0, axis=0)
    jc = np.flatnonzero(f_used)
    pc = np.flatnonzero(~f_used & np.any(E != 0, axis=0))
    M = np.hstack([A, E[:, jc]])
    mc = np.flatnonzero(np.any(M != 0, axis=0))
    h = np.hstack([C, F[:, jc]])
    Ep, Mc = E[:, pc], M[:, mc]
    return _Structure(
        A,
        B,
        D,
        jc,
        pc,
        Ep,
        Mc,
        mc,
        h,
        np.abs(h),
        np.abs(Mc),
        np.abs(Ep),
        np.abs(B),
        np.abs(D),
        mc.size == M.shape[1],
        tuple(np.flatnonzero(row) for row in h),
    )


@dataclass
class _Joint:
    """The pair ``(x_k, d_jc)`` during the measurement update of one step: in the zonotope
    ``<z, Hz[:, :m]>`` up to the rounding box ``acc`` kept aside, and in the box ``box = [lo;
    hi]`` (shape ``(2, nz)``; the exact enclosures of the module docstring). ``Hz`` has room
    for the column each strip appends. Local to a step, updated strip by strip."""

    z: np.ndarray
    Hz: np.ndarray
    m: int
    box: np.ndarray
    acc: np.ndarray
    work: np.ndarray  # scratch of the shape of Hz: |Hz| and λ sᵀ without a new array each

    def intersect(
        self, h: np.ndarray, ah: np.ndarray, t: float, y_i: float, du: float, g_meas: float,
        nx: int, v_i: float = 0.0, hnz: np.ndarray | None = None,
    ) -> bool:  # fmt: skip
        """Intersect with the strip ``|hᵀ(x, d) - t| <= σ`` of one measured component
        (``t = y_i - D_i u``, ``du = |D_i| |u|``, ``ah = |h|``; ``v_i`` widens it by the
        interval matrices' ``|ΔC_i x + ΔD_i u|``); False when it certainly misses the set
        (inconsistent: the set is left as it was). ``hnz``: where ``h != 0``, when known."""
        z, acc, m = self.z, self.acc, self.m
        Hz = self.Hz[:, :m]
        nz = z.shape[0]
        work = self.work[:, :m]
        rows = _add(np.abs(Hz, out=work), axis=1)
        s = h @ Hz
        e = float(t - h @ z)
        a_z = np.abs(z)
        # the half-width of the strip that certainly holds (x_k, d_k): eq. (8) of the module
        # docstring with the rounding of y, of t, of e and of s ([Higham2002]'s γ_n bounds)
        wmax = _max(np.abs(self.box), axis=0)
        sigma = (
            g_meas * (abs(y_i) + du + ah @ wmax)
            + gamma(nz + 1) * (abs(t) + ah @ a_z)
            + gamma(nz) * float(ah @ rows)
            + v_i
        ) * (1.0 + 4.0 * UNIT_ROUNDOFF)
        # the point of <z, Hz> that is (x_k, d_k) minus the rounding: in a wider strip
        sigma_z = (sigma + ah @ acc) * (1.0 + gamma(nz + 2))
        s1 = float(_add(np.abs(s)))
        if abs(e) > (s1 + sigma_z) * (1.0 + gamma(m + 2)):
            return False  # the strip misses the zonotope: certain
        box = propagate_strip(h, t, self.box, sigma, hnz)
        if box is None:
            return False
        lo_j, hi_j = section_hull(z[:nx], Hz[:nx], s, e, sigma_z, rows[:nx])
        pad = acc[:nx] * (1.0 + 2.0 * UNIT_ROUNDOFF)
        np.maximum(box[0, :nx], lo_j - pad, out=box[0, :nx])
        np.minimum(box[1, :nx], hi_j + pad, out=box[1, :nx])
        self.box = box
        den = float(s @ s) + sigma_z * sigma_z
        if s1 == 0.0 or not den > 0.0:
            return True
        lam = Hz @ s / den  # the F-radius optimal λ* of [Alamo2005] (joint space)
        al = np.abs(lam)
        # rounding of z + λ e and of H - λ sᵀ, σ λ: added to the box aside
        self.acc = acc + gamma(3) * (a_z + al * abs(e) + rows + al * (s1 + sigma_z))
        self.z = z + lam * e
        Hz -= np.multiply(lam[:, None], s, out=work)  # in place: the room in self.Hz
        self.Hz[:, m] = sigma_z * lam
        self.m = m + 1
        return True


@register
class StripEstimator(Estimator):
    """Zonotopic filter with strip intersection and F-radius gain [Alamo2005].

    Uses ``u[0..k]`` and ``y[0..k]``: the box at step ``k`` is the filtered set, after the
    intersection with the strips of ``y[k]``. Needs the prior box ``x0``. Per step: ``ny``
    closed-form intersections and one order reduction, no optimisation; the cost is bounded by
    ``order``.

    Parameters
    ----------
    sys : LinearSystem (discrete time; matrices and bounds may vary with ``k``)
    x0 : Box, the prior box on ``x[0]``
    order : int, optional
        Generators kept between steps (default ``10 nx``; at least ``nx``). More generators
        give tighter boxes at a cost per step growing with ``order`` (``O(ny nx order log
        order)``).
    reduction : ``"parallelotope"`` (default), ``"girard"`` or ``"box"``
        Order reduction: the parallelotope absorption of [Chisci1998] with a conditioned basis
        (Girard's box on the steps where the basis is ill-conditioned), the box of
        [Girard2005] (CORA's default) or the box of [Combastel2015]. The two boxes refuse
        ``order < 2 nx`` (they diverge there) and can diverge above it where ``|A|`` expands
        (a random 7-state system at ``2 nx``): the default is the one that stayed bounded on
        every system tried.
    weight : (nx, nx) array, optional
        Positive definite weight of the box reduction (which generators are kept).

    Notes
    -----
    **Interval matrices** (``supports_uncertain``; docs/uncertain.md): the plant is the nominal
    one plus ``w = ΔA x + ΔB u`` in the state and ``v = ΔC x + ΔD u`` in the output. Each strip
    is that of the nominal row widened by ``v̄_i >= |v_i|`` (bounded from the predicted box of
    ``x[k]``), and the prediction adds the box ``diag(w̄)`` (``w̄ >= |w|`` from the filtered box)
    as generators, which later strips can contract: :mod:`ivobs.estimators._uncertain`, rounded
    upwards.
    """

    name = "strip"
    order = 80
    summary = "zonotopic set-membership filter, strip intersection"
    reference = "[Alamo2005]"
    data_used = "filter"
    supports_time_varying = True
    supports_uncertain = True  # see "Interval matrices" in the docstring
    design: StripDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        order: int | None = None,
        reduction: str = "parallelotope",
        weight: Any = None,
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        check_size(
            self.name,
            sys.nx,
            "multiplies and reduces a dense nx x q generator matrix "
            "(q = 10 nx by default, O(nx^3) work)",
        )
        if reduction not in REDUCTIONS:
            raise IvobsError(
                f"reduction: expected one of {', '.join(map(repr, REDUCTIONS))}, got {reduction!r}"
            )
        q = 10 * sys.nx if order is None else as_int("order", order, 1)
        if q < sys.nx:
            raise IvobsError(
                f"order: the reduction keeps at least nx = {sys.nx} generators, got {q}"
            )
        if reduction != "parallelotope" and q < 2 * sys.nx:
            raise IvobsError(
                f"order: the {reduction!r} reduction needs order >= 2 nx = {2 * sys.nx}, got "
                f"{q}: with fewer than nx generators kept beside its box the boxes diverge "
                "(a kept generator is never reduced and Alamo's update does not keep it "
                "bounded: CORA's vehicle6 at order nx + 1 reached 1e16; a plain box, "
                "order = nx, grows like |A| where the strips do not cut it: 1e82 on a random "
                "system); use reduction='parallelotope'"
            )
        W = None
        if weight is not None:
            W = as_matrix("weight", weight, sys.nx, sys.nx)
            if not np.allclose(W, W.T) or np.min(np.linalg.eigvalsh(0.5 * (W + W.T))) <= 0:
                raise IvobsError("weight: expected a symmetric positive definite matrix")
        if W is not None and reduction != "box":
            raise IvobsError("weight: only the 'box' reduction takes a weight")
        self.design = StripDesign(order=q, reduction=reduction, weight=W)
        self._lti = None if sys.is_time_varying else _structure(*sys.matrices_at(0))
        self._d_cache: tuple[tuple[bytes, bytes], tuple[np.ndarray, np.ndarray]] | None = None
        # the compiled step when numba is there (_strip_kernel: this file is its reference)
        plain = reduction == "box" or sys.uncertainty is not None
        self._kernel = None if plain else _strip_kernel.load()
        self._kst = None if self._lti is None else _strip_kernel.kernel_structure(self._lti)

    # -- online --------------------------------------------------------------------------------
    def _initial_state(self) -> StripState:
        assert self.x0 is not None
        p, r = mid_rad(self.x0.lo, self.x0.hi)
        return StripState(p=p, H=np.diag(r)[:, r > 0], e=np.zeros(self.sys.nx))

    def _step(
        self, state: StripState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[StripState]:
        k = state.k
        st = self._lti if self._lti is not None else _structure(*self.sys.matrices_at(k))
        dbox = self.sys.d_at(k, y_k)
        cd, rd = self._d_radius(dbox)
        if self._kernel is not None:
            return self._kernel_step(state, st, u_k, y_k, dbox, cd, rd)
        y_list = y_k.tolist()
        measured = [i for i, y_i in enumerate(y_list) if y_i == y_i]  # not NaN
        joint = self._joint(state, st, dbox, cd, rd, len(measured))
        nx, nu = self.sys.nx, u_k.shape[0]
        g_meas = 2.0 * gamma(nx + cd.shape[0] + nu + 2)
        t_all, du_all = (y_k - st.D @ u_k).tolist(), (st.aD @ np.abs(u_k)).tolist()
        inconsistent = False
        unc = self.sys.uncertainty  # interval matrices: |v| <= v̄ widens each strip (class doc)
        v = (
            None
            if unc is None
            else uncertain.terms(unc, joint.box[0, :nx], joint.box[1, :nx], u_k)[1]
        )
        for i in measured:
            v_i = 0.0 if v is None else float(v[i])
            args = (t_all[i], y_list[i], du_all[i], g_meas, nx, v_i)
            if not joint.intersect(st.h[i], st.ah[i], *args, st.hnz[i]):
                inconsistent = True
        acc = joint.acc * (1.0 + gamma(y_k.shape[0] + 1))  # the rounding of acc's sums
        Hz = joint.Hz[:, : joint.m]
        rows = _add(np.abs(Hz), axis=1)
        r = rows[:nx] + acc[:nx]
        lo = np.maximum(joint.z[:nx] - r, joint.box[0, :nx])
        hi = np.minimum(joint.z[:nx] + r, joint.box[1, :nx])
        hi = np.maximum(hi, lo)  # equal up to rounding when a state is pinned down exactly
        w = None if unc is None else uncertain.terms(unc, lo, hi, u_k)[0]  # |w| <= w̄
        p, H, e = self._predict(k, st, joint.z, Hz, rows, acc, u_k, cd, rd, w)
        # a new state built directly (dataclasses.replace costs as much as a strip's update)
        new = StripState(p=p, H=H, e=e, k=state.k, scale=state.scale)
        return Step(new, lo, hi, inconsistent)

    def _kernel_step(
        self, state: StripState, st: _Structure, u_k: np.ndarray, y_k: np.ndarray, dbox: Box,
        cd: np.ndarray, rd: np.ndarray,
    ) -> Step[StripState]:  # fmt: skip
        """:meth:`_step` as one compiled call (:mod:`._strip_kernel`)."""
        kst = self._kst if self._kst is not None else _strip_kernel.kernel_structure(st)
        c, kernel = _strip_kernel.as_c, self._kernel
        assert kernel is not None
        p, H, e, lo, hi, inconsistent, finite = kernel(
            c(state.p), c(state.H), c(state.e), c(u_k), c(y_k), cd, rd, c(dbox.lo), c(dbox.hi),
            kst, self.design.order, self.design.reduction == "girard",
        )  # fmt: skip
        if not finite:
            self._check_overflow(state.k + 1, p, H)
        return Step(StripState(p=p, H=H, e=e, k=state.k, scale=state.scale), lo, hi, inconsistent)

    def _d_radius(self, dbox: Box) -> tuple[np.ndarray, np.ndarray]:
        """:func:`mid_rad` of the box of ``d[k]``, kept for the next step while the bounds
        are the same numbers (a time-invariant ``d``: the same box every step)."""
        key = (dbox.lo.tobytes(), dbox.hi.tobytes())
        if self._d_cache is None or self._d_cache[0] != key:
            self._d_cache = (key, mid_rad(dbox.lo, dbox.hi))
        return self._d_cache[1]

    def _joint(
        self, state: StripState, st: _Structure, dbox: Box, cd: np.ndarray, rd: np.ndarray,
        room: int,
    ) -> _Joint:  # fmt: skip
        """The joint zonotope of ``(x_k, d_jc)`` (with ``room`` free generator columns for
        the strips) and its box (the rounding of ``|H| 1`` and the box aside added)."""
        nx = self.sys.nx
        p, H = state.p, state.H
        jc = st.jc
        nh = H.shape[1]
        cols = np.flatnonzero(rd[jc] > 0)
        nz, m = nx + jc.size, nh + cols.size
        z = np.concatenate([p, cd[jc]])
        Hz = np.zeros((nz, m + room))
        Hz[:nx, :nh] = H
        Hz[nx + cols, nh + np.arange(cols.size)] = rd[jc[cols]]
        r0 = np.abs(H).sum(axis=1)
        pad = gamma(nh + 2) * (np.abs(p) + r0) + state.e * (1.0 + gamma(2))
        box = np.empty((2, nz))
        box[0, :nx] = p - r0 - pad
        box[1, :nx] = p + r0 + pad
        box[0, nx:] = dbox.lo[jc]
        box[1, nx:] = dbox.hi[jc]
        acc = np.zeros(nz)
        acc[:nx] = state.e
        return _Joint(z=z, Hz=Hz, m=m, box=box, acc=acc, work=np.empty_like(Hz))

    def _predict(
        self,
        k: int,
        st: _Structure,
        z: np.ndarray,
        Hz: np.ndarray,
        rows: np.ndarray,
        acc: np.ndarray,
        u_k: np.ndarray,
        cd: np.ndarray,
        rd: np.ndarray,
        w: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(p, H, e)`` of ``x[k+1]``: the joint set mapped by ``M = [A E_jc]`` plus
        ``E_pc <c_d, R>``, then reduced. A box covers the rounding of ``M z + E_pc c_d + B u``,
        of ``M H`` and ``E_pc R`` and of the plant's own float64 arithmetic, the image of the
        box aside, and ``w̄`` (interval matrices)."""
        nx = self.sys.nx
        mc, M, Ep = st.mc, st.M, st.Ep
        if not st.all_mc:
            z, Hz, rows, acc = z[mc], Hz[mc], rows[mc], acc[mc]
        cp, rp = cd[st.pc], rd[st.pc]
        p_next = M @ z + Ep @ cp + st.B @ u_k
        n_terms = mc.size + cp.size + u_k.shape[0] + 1
        err = 2.0 * gamma(n_terms) * (
            st.aM @ (np.abs(z) + rows + acc) + st.aEp @ (np.abs(cp) + rp) + st.aB @ np.abs(u_k)
        ) + (st.aM @ acc) * (1.0 + gamma(mc.size + 1))
        if w is not None:  # the interval matrices' w = ΔA x + ΔB u: generators of the box
            err = np.nextafter(err + w, np.inf)
        live = rp > 0
        H_next = np.hstack([M @ Hz, Ep[:, live] * rp[live], box_generators(err)])
        used = np.any(H_next != 0, axis=0)
        if not used.all():  # a copy only when a column is zero
            H_next = H_next[:, used]
        self._check_overflow(k + 1, p_next, H_next)
        e_next = np.zeros(nx)
        q = self.design.order
        if self.design.reduction == "parallelotope":
            H_next, e_next = reduce_parallelotope(H_next, q)
        elif self.design.reduction == "girard":
            H_next = reduce_girard(H_next, q)
        else:
            m = H_next.shape[1]
            zp = Zonotope._trusted(p_next, H_next).reduce(q, self.design.weight)
            p_next, H_next = zp.c, zp.G
            if m > q:  # the box of the removed generators: a rounded sum
                H_next[:, -nx:] *= 1.0 + gamma(m + 1)
        # C order, as after a state() / restore() round trip (BLAS results depend on layout)
        return p_next, np.ascontiguousarray(H_next), e_next
