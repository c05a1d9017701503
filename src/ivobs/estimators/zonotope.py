"""Zonotope-based set-membership estimation [Tang2019, Section IV, Proposition 1, eqs. (33)-(35)]
(the zonotopic observer of [Combastel2015]), with the reduction operator of [Tang2019, Remark 2].
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._validate import as_int, as_matrix
from ..errors import DesignError, DesignWarning, IvobsError
from ..linalg import UNIT_ROUNDOFF, spectral_radius
from ..model import LinearSystem
from ..sets import Box, Zonotope, box_generators
from ..sets.rounding import enclose, mid_rad, product_error, upper
from . import register
from ._luenberger import DataFreeBounds, Gain, ObserverDesign, ObserverEstimator, warn_fallback
from .base import check_size
from .state import OnlineState, Step, evolve

__all__ = ["ZonotopeDesign", "ZonotopeEstimator", "ZonotopeState"]

ORDER_PER_STATE = 10
"""Default order ``q = ORDER_PER_STATE * nx`` (generators kept by the reduction)."""

SETTLE_STEPS = 2000
"""Steps of the generator recursion (34b) iterated at design (more when ``A - LC`` is slow)."""

SEQUENCE_FLOATS = 1 << 21
"""Most floats kept of the data-independent generators (34b) for ``step()``."""

WIDTH_STEPS = 60
"""Steps of (34b) over which the default gain is chosen when the reduction can grow (at least;
more for a slowly contracting ``A - LC``, see :meth:`ZonotopeEstimator._gain_by_width`)."""

MAX_WIDTH_STEPS = 4000
"""At most this many steps for that comparison."""

SETTLE_WORK = 2e9
"""Budget (multiply-adds) of that iteration: larger systems are iterated for fewer steps."""

DECAY_TOL = 1e-2
"""A generator of (34b) matters while ``‖M^i g‖ >= DECAY_TOL max_j ‖g_j‖`` (see ``order``)."""

SLOW_STEPS = 50
"""``A - LC`` contracts slowly when ``ρ^k`` needs this many steps to fall below
:data:`DECAY_TOL` (``ρ >= 0.912``): only then is an explicit order checked for tightness."""


def generators_that_matter(M: np.ndarray, GR: np.ndarray, W: np.ndarray | None) -> int | None:
    """How many generators of the exact zonotope (34b) (without reduction) are at least
    :data:`DECAY_TOL` times the largest new one, ``‖M^i g_j‖_W >= DECAY_TOL max_j ‖g_j‖_W`` over
    the ages ``i >= 0`` and the columns ``g_j`` of ``G diag r`` (``‖h‖_W² = hᵀ W h``, the norm
    the reduction sorts by). With ``ρ(M)`` close to 1 the error decays slowly and this is large:
    an order below ``nx +`` this count boxes generators that still matter, and the boxed part
    propagates like ``|M|``. None when ``M`` is not Schur or the count exceeds the work budget
    :data:`SETTLE_WORK`."""
    rho = spectral_radius(M)
    if not 0.0 < rho < 1.0 or not GR.size:
        return None

    def norms(X: np.ndarray) -> np.ndarray:
        out: np.ndarray = np.sqrt(np.einsum("ij,ij->j", X, X if W is None else W @ X))
        return out

    X = GR
    tol = DECAY_TOL * float(norms(X).max())
    if not tol > 0.0:
        return None
    # the transient of a non-normal M may exceed ρ^i: the ages are counted until M^i G R is
    # below the tolerance for good, at most a few times the decay time of ρ^i
    steps = int(4 * np.log(DECAY_TOL) / np.log(rho)) + 10
    if steps * M.shape[0] ** 2 * GR.shape[1] > SETTLE_WORK:
        return None
    count = 0
    for _ in range(steps):
        n = norms(X)
        big = int((n >= tol).sum())
        if not big:
            return count
        count += big
        X = M @ X
    return count


@dataclass(frozen=True)
class ZonotopeDesign(ObserverDesign):
    """The observer's design (:class:`~ivobs.estimators._luenberger.ObserverDesign`);
    ``order``: ``q`` of ``↓_{q,W}``; ``weight``: ``W`` [Tang2019, Remark 2]."""

    order: int
    weight: np.ndarray | None


@dataclass(frozen=True)
class ZonotopeState(OnlineState):
    """``x[k] ∈ <p, H> ⊕ Box(a_L qL + a_x qx)``: centre ``p`` (nx,) and generators ``H``
    (nx, ·) of [Tang2019, eq. (34)], and the centre's rounding so far, ``qL``, ``qx``
    (:class:`~ivobs.estimators._observer_rounding.Channels`)."""

    p: np.ndarray
    H: np.ndarray
    qL: float
    qx: float


@register
class ZonotopeEstimator(ObserverEstimator):
    """Zonotope set-membership estimator [Tang2019, Proposition 1, eq. (34)], with the
    reduction of [Tang2019, Remark 2].

    With ``y = C x + D u + F d``, adding ``L (y - C x - D u - F d) = 0`` to the state equation
    [Tang2019, eq. (33)] and re-centring ``d ∈ [c - r, c + r]`` (``d = c + diag(r) b``,
    ``|b| <= 1``)::

        p[k+1] = A p[k] + B u[k] + E c[k] + L (y[k] - C p[k] - D u[k] - F c[k])     (34a)
        H[k+1] = [ (A - LC) ↓_{q,W} H[k],  (E - LF) diag(r[k]) ]                      (34b)

    ((34a) is [Tang2019]'s ``(A - LC) p + B u + L (y - D u) + (E - LF) c`` written as the
    observer of eq. (10).) ``x[0] ∈ <p0, H0>`` with ``p0 = center(x0)``, ``H0 =
    diag(radius(x0))``. [Tang2019]'s (34b) writes ``E, -LF`` without the bounds' scaling (it
    takes ``W = <0, Dw>``, ``V = <0, Dv>``); the generators must be scaled by the bounds, as
    above. The box of ``x[k]`` is the interval hull ``p[k] ± |H[k]| 1`` [Tang2019, eq. (35),
    Property 4]. ``↓_{q,W}`` sorts generators by ``hᵀ W h``, keeps the ``q - nx`` largest and
    encloses the rest in a box (:meth:`ivobs.Zonotope.reduce`), so ``H`` has at most
    ``q + nx + nd`` columns (the ``nx`` of a box of rounding, below).

    **Rounding, proven.** (34b) is evaluated with the set verbs, each containing its exact
    result: the reduction rounds its box up, ``M @ Z`` appends the box of its product's
    rounding (:meth:`ivobs.Zonotope.linear_map`); the exact ``A - LC`` and ``E - LF`` differ from
    the float ``M``, ``G`` by ``ΔM``, ``ΔG`` (:mod:`~ivobs.estimators._luenberger`), which
    appends the box ``ΔM |H| 1 + ΔG r`` (and the rounding of ``G diag r``). The centre's
    rounding (the observer's, :mod:`~ivobs.estimators._luenberger`) is the ball ``q`` of
    :class:`~ivobs.sets.rounding.DecayBound` for the powers of ``M``: ``x[k] ∈ <p, H> ⊕
    Ball∞(q)``, the box ``p ± (|H| 1 + q)`` rounded outward. At a step with another gain (a
    missing or inconsistent measurement) the ball joins the generators (``[H, q I]``) and that
    step's rounding is a box of generators too.

    **Data used (prediction form):** the box of ``x[k]`` uses ``u[0..k-1]``, ``y[0..k-1]``.

    **Missing samples** (NaN components of ``y[k]``): that step uses the gain of the outputs
    present (:func:`~ivobs.estimators._luenberger.pattern_gain`: ``A - L_k C`` Schur whenever
    those outputs detect the plant; designed once per pattern), and (34) uses ``A - L_k C``,
    ``E - L_k F``: the set is still an outer bound and stays bounded. **Time-varying /
    measurement-dependent bounds:** ``c[k], r[k]`` at each step. **Inconsistent data:** ``y[k]``
    is inconsistent when ``|y - C p - D u - F c| > |C H| 1 + |C| 1 q + |F| r`` (proven, its
    rounding included); it is then reported and treated as missing.

    **Interval matrices** (``supports_uncertain``; docs/uncertain.md): the gain is designed for
    the nominal matrices and the matrix uncertainty is a generator term. The plant is the
    nominal one plus ``w = ΔA x + ΔB u`` in the state and ``v = ΔC x + ΔD u`` in the output,
    so the error obeys ``e+ = M e + G δ + w − L v``: (34b) appends ``[diag(w̄), −L diag(v̄)]``
    with ``w̄ >= |w|``, ``v̄ >= |v|`` bounded from the box of ``x[k]``
    (:mod:`ivobs.estimators._uncertain`, rounded upwards), and the consistency test widens by
    ``v̄``. Every step is the loop (the term depends on the box).

    **Constant bounds, complete data:** ``H[k]`` does not depend on the data, so its radii are
    computed once, as far as a run needs them, until (34b) reaches a fixed point
    (:class:`~ivobs.estimators._luenberger.DataFreeBounds`); ``step()`` takes them from there
    and :meth:`run` computes ``p[k]`` by a vectorised recursion (batches ``(B, T, n)`` too).

    Parameters
    ----------
    sys : time-invariant discrete-time :class:`~ivobs.LinearSystem`
    x0 : Box, prior box on ``x[0]``
    L : (nx, ny) observer gain, ``A - LC`` Schur, optional (default: designed, see ``gain``;
        e.g. the paper's ``L1`` for [Tang2019, Theorem 6]: the reachability box is inside this
        one with the same gain)
    gain : ``"radius"`` (the gain minimising the steady-state box, :mod:`ivobs.design.radius`),
        ``"hinf"`` (the H∞ gain of [Tang2019, Theorem 1, problem (20)] by Riccati equations) or
        ``"hinf-lmi"`` (the same problem by its LMI, as the paper): the design when ``L`` is not
        given (docs/gains.md). Default: the radius gain, or the H∞ gain when ``|A - LC|`` is not
        Schur and the H∞ gain's reduced zonotope is narrower over :data:`WIDTH_STEPS` steps of
        (34b) (more when ``A - LC`` contracts slowly)
    order : ``q >= nx``, generators kept by the reduction (default ``10 nx``: on the paper's
        servo motor the widths are within a few per mille of much larger orders from ``q = 10 nx``
        on, while the cost per step grows with ``q``). Larger ``q`` approaches Algorithm 1
        ([Tang2019, Theorem 6]: it is never tighter). The part the reduction boxes is
        propagated like ``|A - LC|``: when ``|A - LC|`` is Schur every order keeps the widths
        bounded; otherwise a small order may not (the servo motor with ``q = 4``: summed width
        44.7 at k = 50, 1,518 at k = 2,000). So, for constant bounds, the design iterates
        (34b) as the run computes it (:data:`SETTLE_STEPS` steps, more when ``A - LC``
        converges slowly, within :data:`SETTLE_WORK`) and accepts ``q`` when ``H`` repeats an
        earlier value (the recursion then repeats itself forever) or its widths stopped growing
        (a sign, not a proof); otherwise it raises ``DesignError`` naming the next order that
        settles. ``q = nx`` is refused when ``|A - LC|`` is not Schur. An explicit order (not the
        default) that boxes generators that still matter (:func:`generators_that_matter`, when
        ``A - LC`` contracts slowly) gets a :class:`~ivobs.DesignWarning` naming the order that
        keeps them
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
        self._p0, h0 = mid_rad(self.x0.lo, self.x0.hi)
        self._H0 = np.diag(h0)
        observer = self._design_observer(L, gain)
        self.design = ZonotopeDesign(**observer.as_dict(), order=q, weight=W)
        if L is None and gain is None and self._const is not None:
            self._gain_by_width()
        absM = self._full.absM
        if q == nx and spectral_radius(absM) >= 1.0:
            raise DesignError(
                f"order: q = nx = {nx} boxes the set at every step, so the boxes grow like "
                f"|A - LC|^k, whose spectral radius is {spectral_radius(absM):.4g} "
                ">= 1 (they would diverge); use order > nx (default 10 nx)"
            )
        self._free = None
        if self._const is not None:
            self._check_bounded()
            if order is not None:
                self._check_order_tightness()
            self._free = self._free_bounds(SEQUENCE_FLOATS)

    # -- (34b) --------------------------------------------------------------------------------
    def _predict(
        self,
        H: np.ndarray,
        gain: Gain,
        r: np.ndarray,
        rad: np.ndarray,
        rounding: np.ndarray | None = None,
    ) -> np.ndarray:
        """``H[k+1] = [M_k ↓_{q,W} H, G_k diag r]`` [Tang2019, eq. (34b)] with the boxes of its
        rounding (class docstring); ``rad >= |H| 1`` (the bound of the error the matrices' own
        difference acts on); ``rounding``: generators of the centre's rounding at this step
        (``[L_k diag e_ν, diag ε]``), appended."""
        reduced = Zonotope._trusted(np.zeros(H.shape[0]), H).reduce(
            self.design.order, self.design.weight
        )
        image = reduced._map(gain.M, gain.absM)  # M ↓H and the box of its rounding
        GR = gain.G * r
        n = H.shape[0] + r.shape[0]
        if rounding is not None:
            GR = np.concatenate([GR, rounding], axis=1)
        box = gain.dM @ rad + gain.dG @ r + product_error(np.abs(GR).sum(axis=1), GR.shape[1])
        return np.concatenate([image.G, box_generators(upper(box, n + 3)), GR], axis=1)

    def _output_radius(self, H: np.ndarray, rad: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``>= |C H| 1 + |F| r``: the radius of ``y - C p - D u - F c`` (rounding included)."""
        C = self._mats[2]
        CH = C @ H
        s = np.abs(CH).sum(axis=1) + product_error(np.abs(C) @ rad, C.shape[1])
        out: np.ndarray = upper(s + self._absF @ r, CH.shape[1] + r.shape[0] + 2)
        return out

    def _free_step(self, H: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, Any]:
        """One step of (34b) without data (constant bounds, the full gain): the radius ``|H| 1``,
        its image in ``y``, and ``H[k+1]`` (None at a fixed point)."""
        r = self._const[1]  # type: ignore[index]
        rad = upper(np.abs(H).sum(axis=1), H.shape[1])
        H_next = self._predict(H, self._full, r, rad)
        return rad, self._output_radius(H, rad, r), 0.0, None if _same(H_next, H) else H_next

    def _free_bounds(self, keep: int = 0) -> DataFreeBounds:
        """(34b) without data from ``H[0]``, iterated as far as asked until it repeats an earlier
        value (a fixed point or a cycle: then it repeats itself forever)."""
        return DataFreeBounds(self._H0, self._free_step, self._p0, keep=keep, same=_same)

    def _settled(self, steps: int) -> tuple[int | None, np.ndarray]:
        """The step at which (34b) without data repeats an earlier value within ``steps`` steps
        (None if it does not), and its summed widths ``2 Σ |H[k]| 1`` (rounded up), ``k <=
        steps``."""
        free = self._free_bounds()
        rad = free.arrays(steps + 1)[0]
        at = None if free.settled is None else free.settled + free.period
        return at, 2.0 * rad.sum(axis=1)

    # -- design checks --------------------------------------------------------------------------
    def _gain_by_width(self) -> None:
        """Default gain: the radius gain minimises the box of Algorithm 1, which the zonotope
        reaches only up to its reduction; when ``|A - LC|`` is not Schur the boxed part of the
        reduction can grow (``order``), and another gain may give the narrower zonotope. Then
        the radius gain and the H∞ gain are both run through the data-independent recursion
        (34b) for :data:`WIDTH_STEPS` steps and the one with the smaller mean radius over the
        second half is kept (``design.gain`` says which). The steps are at least
        :data:`WIDTH_STEPS` and twice the time the slower gain's error takes to decay to
        :data:`DECAY_TOL` (``ρ^k``, at most :data:`MAX_WIDTH_STEPS`): before that the boxed
        part is still growing, and a slow H∞ gain would look narrower than it stays (a sampled
        cart-pole, ``ρ = 0.993``: narrower at 60 steps, 40 times wider at 600). If the H∞ gain
        cannot be designed the radius gain stands (``design.fallback``, a warning)."""
        per_step = self.sys.nx**2 * (self.design.order + self.sys.nd)
        if spectral_radius(self._full.absM) < 1.0 or WIDTH_STEPS * per_step > SETTLE_WORK:
            return  # bounded for every order; or too large to compare
        if self.design.gain != "radius":
            return  # the default already fell back (it warned)
        try:
            hinf = self._design_observer(None, "hinf")  # cached: no second design
        except DesignError as exc:
            # the comparison is an improvement over the radius gain, never a condition
            note = f"gain='hinf' (compared with the radius gain over (34b)): {exc}"
            self.design = replace(self.design, fallback=note)
            warn_fallback(self.name, "radius", note)
            return
        rho = max(hinf.spectral_radius, self.design.spectral_radius)
        slow = min(int(2 * np.log(DECAY_TOL) / np.log(rho)) + 1, MAX_WIDTH_STEPS)
        T = max(WIDTH_STEPS, min(slow, int(SETTLE_WORK // per_step)))
        widths = {}
        for gain in ("hinf", "radius"):  # the radius gain last: kept on a tie
            observer = self._design_observer(None, gain)
            self.design = replace(self.design, **observer.as_dict())
            widths[gain] = float(self._free_bounds().arrays(T)[0][T // 2 :].mean())
        if widths["hinf"] < widths["radius"]:
            observer = self._design_observer(None, "hinf")
            self.design = replace(self.design, **observer.as_dict())

    def _check_order_tightness(self) -> None:
        """Warn (:class:`~ivobs.DesignWarning`) when an explicit order boxes generators that still
        matter (:func:`generators_that_matter`), naming the order that keeps them; the default
        order is not changed by it (a larger order costs more per step on every system)."""
        nx, q = self.sys.nx, self.design.order
        rho = self.design.spectral_radius
        if not rho**SLOW_STEPS > DECAY_TOL:
            return  # a fast observer: the generators the reduction boxes were small already
        M, G, r = self._full.M, self._full.G, self._const[1]  # type: ignore[index]
        count = generators_that_matter(M, G * r, self.design.weight)
        if count is None or q >= nx + count:
            return
        warnings.warn(
            f"order: q = {q} keeps {q - nx} generators, but A - LC contracts slowly (spectral "
            f"radius {rho:.4g}) and {count} generators of the error's zonotope stay above "
            f"{DECAY_TOL:g} of the largest new one; the reduction boxes the others, so the "
            f"widths can be far above Algorithm 1's: order={nx + count} keeps them (the cost "
            "per step grows with the order)",
            DesignWarning,
            # _check_order_tightness, __init__, its session-defaults wrapper
            # (estimators._overrides), make_estimator: the caller
            stacklevel=5,
        )

    def _check_bounded(self) -> None:
        """Refuse an order whose reduced recursion (34b) is not shown bounded (see ``order``)."""
        M, r = self._full.M, self._const[1]  # type: ignore[index]
        nx, q = self.sys.nx, self.design.order
        rho = spectral_radius(M)
        slow = int(30 * 37 / -np.log(rho)) if 0.0 < rho < 1.0 else 0
        steps = min(max(SETTLE_STEPS, slow), 20 * SETTLE_STEPS)
        absM = self._full.absM
        if spectral_radius(absM) < 1.0 or steps * nx * nx * (q + r.shape[0]) > SETTLE_WORK:
            return  # |A - LC| Schur: bounded for every order (docs); too large: not checked
        at, sums = self._settled(steps)
        if at is not None or sums[-1] <= sums[steps // 4 : steps // 2 + 1].max() * (1.0 + 1e-9):
            return
        hint = ""
        design = self.design
        try:
            for q2 in range(q + 1, min(q + 8, ORDER_PER_STATE * nx) + 1):
                self.design = replace(design, order=q2)
                at2, _ = self._settled(steps)
                if at2 is not None:
                    hint = f" (order = {q2} settles at k = {at2})"
                    break
        finally:
            self.design = design
        k50 = min(50, steps)
        raise DesignError(
            f"order: q = {q} keeps {q - nx} generator(s) of the zonotope and boxes the others at "
            f"every step; the boxed part is propagated like |A - LC| (spectral radius "
            f"{spectral_radius(absM):.4g} >= 1), and iterating the reduced recursion "
            f"(34b) (it does not depend on the data) for {steps} steps it neither settled nor "
            f"stopped growing: summed width {sums[k50]:.4g} at k = {k50}, "
            f"{sums[steps // 2]:.4g} at k = {steps // 2}, {sums[-1]:.4g} at k = {steps}; ivobs "
            f"cannot show that the boxes stay bounded: use a larger order{hint}"
        )

    # -- online --------------------------------------------------------------------------------
    def _initial_state(self) -> ZonotopeState:
        H0 = self._free.state(0) if self._free is not None else self._H0.copy()
        return ZonotopeState(p=self._p0.copy(), H=H0, qL=0.0, qx=0.0)

    def _step(
        self, state: ZonotopeState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ZonotopeState]:
        p, H, k, ch = state.p, state.H, state.k, self._channels
        Hk = self._free.state(k) if self._free is not None else None  # H[k] without data
        free = Hk is not None and (Hk is H or _same(Hk, H))  # (restored: the same values)
        nx = p.shape[0]
        if free:  # [|H| 1; |C H| 1 + |F| r] of the data-free sequence, and the rounding so far
            stacked = self._free.at(k)[0]  # type: ignore[union-attr]
            widened = ch.widen(stacked, state.qL, state.qx)
            radH, rad, ybound = stacked[:nx], widened[:nx], widened[nx:]
            c, r = self._const  # type: ignore[misc]
        else:
            radH = upper(np.abs(H).sum(axis=1), H.shape[1])
            rad = ch.widen(radH, state.qL, state.qx)  # [Tang2019, eq. (35)], rounding too
            c, r = self._bounds(k, y_k, *enclose(p, rad), u_k)
            ybound = ch.widen(np.concatenate([radH, self._output_radius(H, radH, r)]),
                              state.qL, state.qx)[nx:]  # fmt: skip
        lo, hi = enclose(p, rad)
        p_next, eps, e_nu, inconsistent, gain = self._observe(p, u_k, y_k, c, ybound)
        if gain is self._full:  # (34a) with L; its rounding joins q_L, q_x
            H_next = self._free.state(k + 1) if free else None  # type: ignore[union-attr]
            if H_next is None:
                H_next = self._predict(H, gain, r, radH)  # (34b)
            qL = ch.L.next(state.qL, max(e_nu.tolist()))
            sigma = (ch.norm(eps) + ch.betaL * state.qL) * (1.0 + 4.0 * UNIT_ROUNDOFF)
            new = evolve(state, p=p_next, H=H_next, qL=qL, qx=ch.x.next(state.qx, sigma))
            return Step(new, lo, hi, inconsistent)
        # another gain: the rounding so far becomes a box of generators, this step's too
        Hq = np.concatenate([H, box_generators(ch.widen(np.zeros(nx), state.qL, state.qx))], 1)
        H_next = self._predict(Hq, gain, r, rad, np.concatenate([gain.L * e_nu, np.diag(eps)], 1))
        new = evolve(state, p=p_next, H=H_next, qL=0.0, qx=0.0)
        return Step(new, lo, hi, inconsistent)


def _same(H1: np.ndarray, H2: np.ndarray) -> bool:
    """The same generators, bit for bit (the recursion (34b) then repeats itself)."""
    return H1.shape == H2.shape and bool(np.array_equal(H1, H2))
