"""Set-membership filter with constrained zonotopes [Scott2016].

[Scott2016, Section 5]: prediction and measurement update are exact in constrained-zonotope
form; only the reduction [Scott2016, Section 4] over-approximates.

The disturbance ``d`` enters both equations (``x+ = A x + B u + E d``, ``y = C x + D u + F d``),
so the update is done on the pair ``(x_k, d_k)``, never on separate process and measurement noise:
with ``X_k = <c, G, A_c, b>`` the set of ``x[k]`` predicted from ``y[0..k-1]`` and
``d_k = c_d + R δ``, ``‖δ‖∞ <= 1`` (bounds re-centred, ``R = diag(radius)``),

* measurement update (the measured components of ``y_k``; the generalised intersection of
  [Scott2016, Proposition 1] with a point ``Y``)::

      X_k|k × D_k = <(c, c_d), [G 0; 0 R], [A_c 0; C G  F R], [b; y_k - D u_k - C c - F c_d]>

* box: the interval hull of the ``x`` part, by LP (HiGHS, warm-started from objective to
  objective), each bound certified by duality;
* prediction (linear map and Minkowski sum, [Scott2016, Proposition 1]):
  ``X_{k+1} = <A c + B u_k + E c_d, [A G, E R], ..., ...>``;
* reduction [Scott2016, Section 4]: at most ``max_constraints`` constraints (rescaling +
  elimination, Section 4.2), then at most ``max_generators`` generators (lifted zonotope,
  Section 4.3, with the parallelotope enclosure of [Chisci1998]).

Which factor to eliminate is not chosen by the paper's shape heuristic (an estimate of the
Hausdorff distance) but by what the box needs: the LPs of the box give dual certificates of its
``2 nx`` bounds and of the ``2 nx`` bounds of the prediction ``[A G, E R]`` (without these, a
factor free for the box of ``x[k]`` could triple a predicted width: cora-vehicle6; on large
sets most of the latter are combinations of the box's certificates, solved for only where
that combination is not within a few percent of their optimum), the
prediction keeps the same factors, and every elimination changes the certificates in closed
form; the factor whose elimination loosens the certified bounds least (relative to the widths)
is eliminated, the Hausdorff estimate breaking ties
(:class:`ivobs.czonotope.Certificates`; ``elimination="hausdorff"`` restores the paper's
rule). With ``2 nx`` constraints this keeps the box within a few percent of the exact hull on
random systems, where the shape heuristic alone loses 30 % on some.

Without reduction (``reduce=False``) the box is the exact hull of the states consistent with the
data (the ``exact`` method's answer, to LP tolerance), at a cost that grows with the horizon.
With it, the per-step cost is bounded by the two limits.

An empty measurement update (no state, disturbance and initial condition explain ``y_k``) is a
fault: it is reported (``Estimate.inconsistent``) and the step is predicted without ``y_k``,
only with a certificate (:func:`ivobs.czonotope.certified_empty`: a dual ray, checked in floating
point, proving that even the factor box ``‖ξ‖∞ <= 1 + EMPTY_TOL`` misses the constraints). When
HiGHS calls a thin set infeasible without one, the box is that of the softened set (a superset).

**Rounding (proof).** The state is ``x[k] ∈ <c, G, A, b> ⊕ box(e)`` with the arrays read as
exact numbers; every floating-point step keeps that true by adding the proven bound of its
error ([Higham2002, Lemma 3.1]: a computed sum of ``n`` products is within
``γ_n Σ |a_i| |b_i|`` of the exact one; :func:`~ivobs.sets.rounding.product_error` evaluates
such a bound so that it is one, rounding included), so the base class adds no margin
(``proven_rounding``):

* ``d[k] ∈ c_d ± r_d`` exactly (:func:`~ivobs.sets.rounding.mid_rad`); ``E R``, ``F R`` are
  one product per entry;
* measurement rows: the right-hand side ``y − D u − C c − F c_d`` and the row ``[C G, F R]``
  at ``|ξ| <= 1`` are dot products of at most ``n = nx + m + nu + nd`` terms. Their errors,
  and that of the data itself (a float64 record ``y = fl(C x + D u + F d)`` of an admissible
  ``x``, ``d``, also within ``γ_n`` of the terms), are bounded by
  ``ρ = product_error(|y| + |D| |u| + |C| x̄ + |F| d̄, 2n + 3)`` (``x̄ = |c| + |G| 1 + e`` bounds
  ``|x|``, ``d̄ = |c_d| + r_d``), and the box aside enters as ``|C| e``: each row gets a slack
  factor of that size. New rows are scaled by powers of two (exact);
* the box: each hull bound is proven by weak duality (:func:`ivobs.czonotope.dual_bounds`),
  then ``∓ e``, rounded outward;
* prediction: ``A c + B u + E c_d``, ``A G`` and the image ``|A| e`` of the box aside, with the
  float64 plant's own rounding, likewise: one box of generators
  ``product_error(|A| x̄ + |B| |u| + |E| d̄, 2n + 3) + |A| e``;
* the elimination and the generator reduction return supersets of what they are given, their
  rounding included (:mod:`ivobs.sets.czonotope.elimination`,
  :mod:`ivobs.sets.czonotope.reduction`); the elimination runs in coordinates centred at
  ``c`` and its rounding box joins ``e``, with the rounding ``u |c + shift|`` of the re-centring;
* a softened set (:func:`ivobs.czonotope.hull_certificates`) is rescaled with the rounding of
  that product in ``e`` and a slack per constraint.

A measurement is therefore never found inconsistent when the data are a float64 record of an
admissible trajectory, whatever the magnitudes. Tiny generators are consolidated into one box
per step (:data:`CONSOLIDATE_X`, :data:`CONSOLIDATE_C`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._validate import as_bool, as_int
from ..errors import IvobsError
from ..model import LinearSystem
from ..sets import Box
from ..sets.czonotope import (
    EMPTY_TOL,
    Certificates,
    box_generators,
    certified_empty,
    eliminate_constraints,
    hull_certificates,
    independent_constraints,
    mid_rad,
    reduce_consolidated,
    soften,
)
from ..sets.rounding import UNIT_ROUNDOFF, down, product_error, up, upper
from . import _uncertain as uncertain
from . import register
from .base import Design, Estimator, check_size
from .state import OnlineState, Step

__all__ = ["ConstrainedZonotopeDesign", "ConstrainedZonotopeEstimator", "ConstrainedZonotopeState"]


CONSOLIDATE_X = 1e-13
CONSOLIDATE_C = 1e-9
"""Generators whose ``x`` part is below ``CONSOLIDATE_X (1 + |c|)`` (rounding level against the
state) and whose constraint part is below ``CONSOLIDATE_C`` times the largest (normalised)
coefficient are replaced, after each reduction, by one box in ``x`` and one slack per
constraint (:func:`ivobs.czonotope.consolidate_small`, a superset): the rounding slacks of
the measurement rows and of the elimination, and the rounding boxes of the prediction, would
otherwise pile up in the set (a few per step) until the generator limit. Larger thresholds
cost tightness where the state is pinned down by more outputs than disturbances
(``kkl-random8``); on other sets these generators are negligible either way."""
TOLS = (CONSOLIDATE_X, CONSOLIDATE_C)
"""Both, for :func:`~ivobs.sets.czonotope.reduce_consolidated`."""


def _measurement_update(
    Ac: np.ndarray, b: np.ndarray, CG: np.ndarray, FR: np.ndarray, rhs: np.ndarray,
    rho: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, int, str, tuple[np.ndarray, np.ndarray]]:  # fmt: skip
    """Constraints after the measurement: the old ones (padded with the new factors) and
    ``[C G, F R, diag(ρ)] (ξ, δ, τ) = y - D u - C c - F c_d`` for the measured components
    (NaN: missing); ``τ_i`` is the slack factor of the rounding bound ``ρ_i`` of row ``i``.

    Returns ``(A, b, p, status, full)``, ``p`` the number of new factors (``δ`` and slacks);
    ``status`` is ``"ok"``, ``"empty"`` (certainly inconsistent) or ``"check"`` (implied
    constraints were dropped that the kept ones do not quite satisfy: the caller decides with
    :func:`ivobs.czonotope.certified_empty` on ``full``, the system before dropping)."""
    obs = ~np.isnan(rhs)
    rows, rhs, rho = np.concatenate([CG[obs], FR[obs]], axis=1), rhs[obs], rho[obs]
    live = np.flatnonzero(rho > 0)
    slack = np.zeros((rows.shape[0], live.size))
    slack[live, np.arange(live.size)] = rho[live]
    rows = np.concatenate([rows, slack], axis=1)
    # a row of negligible coefficients is dropped (normalising it would amplify rounding; a
    # superset); it certainly cannot hold when |rhs| exceeds what the factor box reaches
    absr = np.abs(rows)
    zero = absr.max(axis=1, initial=0.0) <= 1e-9 * (1.0 + np.abs(rhs))
    reach = upper(absr[zero].sum(axis=1) * (1.0 + EMPTY_TOL), rows.shape[1] + 1)
    consistent = bool(np.all(np.abs(rhs[zero]) <= reach))
    # each kept row (and its right-hand side) scaled by a power of two, its largest coefficient
    # in [1, 2): the same constraints, exactly (the kept rows are far from the underflow range)
    d = np.ldexp(1.0, 1 - np.frexp(absr[~zero].max(axis=1))[1])
    rows, rhs = rows[~zero] * d[:, None], rhs[~zero] * d
    p = FR.shape[1] + live.size
    A_all = np.concatenate([np.concatenate([Ac, np.zeros((Ac.shape[0], p))], axis=1), rows])
    b_all = np.concatenate([b, rhs])
    if not consistent:
        return A_all, b_all, p, "empty", (A_all, b_all)
    A_new, b_new, implied_ok = _drop_implied(A_all, b_all)
    return A_new, b_new, p, "ok" if implied_ok else "check", (A_all, b_all)


def _drop_implied(A: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
    """Drop constraints that are linear combinations of the others (more outputs than
    disturbances over-determine the set; HiGHS handles such degenerate programs badly): a
    superset. Returns False when a dropped row does not hold where the kept ones do
    (least-squares residual above ``1e-7``): the data may contradict each other, which the
    caller decides with a certificate."""
    keep = independent_constraints(A)
    if np.all(keep):
        return A, b, True
    xi = np.linalg.lstsq(A[keep], b[keep], rcond=None)[0]
    resid = np.abs(A[~keep] @ xi - b[~keep])
    ok = bool(np.all(resid <= 1e-7 * (1.0 + np.abs(b[~keep]) + np.abs(xi).max(initial=0.0))))
    return A[keep], b[keep], ok


@dataclass(frozen=True)
class ConstrainedZonotopeDesign(Design):
    """Complexity limits of the constrained zonotope [Scott2016, Section 4].

    ``max_constraints`` (``n_c``) and ``max_generators`` (``n_g``) bound the set kept between
    steps; ``0`` means no limit (``reduce=False``: the exact filter). ``elimination``: how the
    factor to eliminate is chosen (``"certificates"`` or the paper's ``"hausdorff"``)."""

    max_constraints: int
    max_generators: int
    elimination: str = "certificates"


def default_limits(nx: int) -> tuple[int, int]:
    """Default ``(max_constraints, max_generators) = (2 nx, 16 nx)``: on random stable systems
    (2-6 states, 1-3 outputs, vertex disturbances) the mean widths stay within a few percent of
    the exact hull; fewer generators cost less and lose more, more approach the exact hull; with
    certificate-guided elimination, constraints beyond ``2 nx`` buy little."""
    return 2 * nx, 16 * nx


@dataclass(frozen=True)
class ConstrainedZonotopeState(OnlineState):
    """``x[k] ∈ <c, G, A, b> ⊕ box(e)``: the constrained zonotope of ``x[k]`` predicted from
    ``y[0..k-1]`` (centre ``c``, generators ``G``, constraints ``A ξ = b``) and ``e``, the box
    of the rounding of the last reduction, kept aside until the next prediction."""

    c: np.ndarray
    G: np.ndarray
    A: np.ndarray
    b: np.ndarray
    e: np.ndarray


@dataclass(frozen=True)
class _StepData:
    """What a step knows before its measurement update: the model at ``k``, the bounds of
    ``d[k] = c_d + r_d δ``, the columns ``E R``, ``F R`` of the disturbance factors, bounds
    ``xmag >= |x_k|`` and ``dmag >= |d_k|``, ``n`` (the length of the sums of a step) and, for
    interval matrices, ``v >= |ΔC x + ΔD u|``."""

    mats: tuple[np.ndarray, ...]
    u: np.ndarray
    cd: np.ndarray
    ER: np.ndarray
    FR: np.ndarray
    xmag: np.ndarray
    dmag: np.ndarray
    n: int
    v: np.ndarray | None = None


@dataclass(frozen=True)
class _Filtered:
    """The set after the measurement update of a step: the box ``[lo, hi]`` of ``x[k]``, the
    generators ``G`` (the state's, padded for the new factors), constraints ``A ξ = b``, ``ER``
    padded likewise, ``e`` (the box aside, grown if the set was softened), ``er_err`` (the
    rounding of ``E R`` if it was softened), the certificates of the box (None for the paper's
    rule) and whether ``y[k]`` was inconsistent (not used)."""

    lo: np.ndarray
    hi: np.ndarray
    G: np.ndarray
    A: np.ndarray
    b: np.ndarray
    ER: np.ndarray
    e: np.ndarray
    er_err: np.ndarray
    cert: Certificates | None
    inconsistent: bool


@register
class ConstrainedZonotopeEstimator(Estimator):
    """Constrained-zonotope set-membership filter [Scott2016, Section 5].

    Uses ``u[0..k]`` and ``y[0..k]``: the box at step ``k`` is the filtered set, after the
    measurement update with ``y[k]`` (before reduction). Needs the prior box ``x0``.

    Parameters
    ----------
    sys : LinearSystem (discrete time; matrices and bounds may vary with ``k``)
    x0 : Box, the prior box on ``x[0]``
    max_constraints : int, optional
        Constraints kept between steps (default ``2 nx``; :func:`default_limits`; at least 1:
        with none, the widths diverge on marginally stable plants). Raise it when the boxes
        are far from the ``exact`` hull on your system; each constraint costs a factor in
        every LP.
    max_generators : int, optional
        Generators kept between steps (default ``16 nx``; never fewer than the rank of the
        lifted generators, ``nx`` plus the constraints). Raise it for tighter boxes (towards
        the exact hull), lower it for cheaper steps.
    reduce : bool
        ``False`` keeps every constraint and generator: the exact filter, whose cost grows
        with the horizon (for short records and as a reference).
    elimination : ``"certificates"`` (default) or ``"hausdorff"``
        How the factor to eliminate is chosen: the least loss of the LP-certified box bounds
        (see the module docstring), or [Scott2016]'s smallest Hausdorff-error estimate (to
        reproduce the paper's filter as published; looser).

    Notes
    -----
    **Interval matrices** (``supports_uncertain``; docs/uncertain.md): the plant is the nominal
    one plus ``w = ΔA x + ΔB u`` in the state and ``v = ΔC x + ΔD u`` in the output. Each
    measured row's slack ``ρ_i`` grows by ``v̄_i >= |v_i|`` (from the predicted set's box), and
    the prediction adds the box ``diag(w̄)`` (``w̄ >= |w|`` from the certified box of ``x[k]``)
    as generators: :mod:`ivobs.estimators._uncertain`, rounded upwards.
    """

    name = "constrained-zonotope"
    order = 90
    summary = "set-membership filter in constrained-zonotope form, hull by LP"
    reference = "[Scott2016, Sections 4-5]"
    data_used = "filter"
    supports_time_varying = True
    supports_uncertain = True  # see "Interval matrices" in the docstring
    proven_rounding = True  # see "Rounding (proof)" in the module docstring
    design: ConstrainedZonotopeDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        max_constraints: int | None = None,
        max_generators: int | None = None,
        reduce: bool = True,
        elimination: str = "certificates",
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        check_size(
            self.name,
            sys.nx,
            "reduces a dense constrained zonotope and solves LPs over its generators",
        )
        reduce = as_bool("reduce", reduce)
        if elimination not in ("certificates", "hausdorff"):
            raise IvobsError(
                f"elimination: expected 'certificates' or 'hausdorff', got {elimination!r}"
            )
        nc_def, ng_def = default_limits(sys.nx)
        nc = nc_def if max_constraints is None else as_int("max_constraints", max_constraints, 0)
        if nc == 0 and reduce:
            raise IvobsError(
                "max_constraints: expected >= 1, got 0: with no constraint kept, a measurement "
                "acts only through its elimination, and the widths grow without bound on "
                "marginally stable plants (CORA's pedestrian double integrator: 3x wider after "
                "240 steps, 7x the exact hull); for a zonotope filter use the 'zonotope' or "
                "'strip' method"
            )
        ng = ng_def if max_generators is None else as_int("max_generators", max_generators, 1)
        if not reduce:
            nc, ng = 0, 0
        self.design = ConstrainedZonotopeDesign(
            max_constraints=nc, max_generators=ng, elimination=elimination
        )

    # -- online -------------------------------------------------------------------------------
    def _initial_state(self) -> ConstrainedZonotopeState:
        assert self.x0 is not None
        c, r = mid_rad(self.x0.lo, self.x0.hi)
        G = np.diag(r)[:, r > 0]
        return ConstrainedZonotopeState(
            c=c, G=G, A=np.zeros((0, G.shape[1])), b=np.zeros(0), e=np.zeros(self.sys.nx)
        )

    def _step(
        self, state: ConstrainedZonotopeState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ConstrainedZonotopeState]:
        k = state.k
        mats = self.sys.matrices_at(k)
        E, F = mats[4], mats[5]
        dbox = self.sys.d_at(k, y_k)
        cd, rd = mid_rad(dbox.lo, dbox.hi)
        cols = (rd > 0) & ((E != 0).any(axis=0) | (F != 0).any(axis=0))
        xmag = upper(np.abs(state.c) + np.abs(state.G).sum(axis=1) + state.e, state.G.shape[1] + 2)
        data = _StepData(
            mats=mats,
            u=u_k,
            cd=cd,
            ER=E[:, cols] * rd[cols],
            FR=F[:, cols] * rd[cols],
            xmag=xmag,
            dmag=up(np.abs(cd) + rd),
            n=state.G.shape[0] + state.G.shape[1] + u_k.shape[0] + dbox.dim,
        )
        if self.sys.uncertainty is not None:  # from the predicted box |x| <= xmag
            data = replace(data, v=uncertain.terms(self.sys.uncertainty, -xmag, xmag, u_k)[1])
        upd = self._update(state, data, y_k)
        c, G, A, b, e = self._predict(k, state, data, upd)
        new = replace(state, c=c, G=G, A=A, b=b, e=e)
        return Step(new, upd.lo, upd.hi, upd.inconsistent)

    def _update(
        self, state: ConstrainedZonotopeState, data: _StepData, y_k: np.ndarray
    ) -> _Filtered:
        """Measurement update on ``(x_k, d_k)`` (``C x + F d = y - D u`` up to the rounding
        bound ``ρ`` of each row, module docstring), then the certified box of ``x[k]``."""
        _, _, C, D, _, F = data.mats
        c, G, Ac, b, e = state.c, state.G, state.A, state.b, state.e
        nx, m = G.shape
        rhs = y_k - D @ data.u - C @ c - F @ data.cd
        aC = np.abs(C)
        terms = np.abs(y_k) + np.abs(D) @ np.abs(data.u) + aC @ data.xmag + np.abs(F) @ data.dmag
        rho = upper(product_error(terms, 2 * data.n + 3) + aC @ e, nx + 1)
        if data.v is not None:
            rho = up(rho + data.v)
        A_new, b_new, p, status, full = _measurement_update(Ac, b, C @ G, data.FR, rhs, rho)
        if status == "check" and certified_empty(*full):
            status = "empty"
        ER = np.concatenate([data.ER, np.zeros((nx, p - data.ER.shape[1]))], axis=1)  # slacks
        G_aug = np.concatenate([G, np.zeros((nx, p))], axis=1)
        # the certificates also keep the hull of the prediction x[k+1] = A x[k] + E d[k] (same
        # factors): the box of x[k] alone lets an elimination blow up a predicted coordinate
        pred = None
        if self.design.elimination != "hausdorff":
            pred = np.concatenate([data.mats[0] @ G, ER], axis=1)
        pmap = data.mats[0]  # pred = A G + (E R on the new factors)
        hull = None if status == "empty" else hull_certificates(c, G_aug, A_new, b_new, pred, pmap)
        inconsistent = hull is None
        if hull is None:  # certainly inconsistent: report, predict without y_k
            A_new, b_new = np.concatenate([Ac, np.zeros((Ac.shape[0], p))], axis=1), b
            hull = hull_certificates(c, G_aug, A_new, b_new, pred, pmap)
        cert: Certificates | None = None
        er_err = np.zeros(nx)
        if hull is None:  # pragma: no cover - the prior set is never certainly empty
            r = upper(np.abs(G).sum(axis=1), m)
            lo, hi = down(c - r), up(c + r)
        else:
            lo, hi, cert = hull
            if cert.softened:  # see hull_certificates: keep the larger set
                pad = np.concatenate([np.zeros((nx, m)), ER], axis=1)  # E R on the new factors
                GE, A_new, err = soften(
                    np.concatenate([G_aug, pad]), A_new, cert.radius, cert.slack
                )
                G_aug, ER, e, er_err = GE[:nx], GE[nx:, m:], up(e + err[:nx]), err[nx:]
                cert = None  # certificates of the softened set: not worth rescaling
        lo, hi = down(lo - e), up(hi + e)
        if self.design.elimination == "hausdorff":
            cert = None
        return _Filtered(lo, hi, G_aug, A_new, b_new, ER, e, er_err, cert, inconsistent)

    def _predict(
        self, k: int, state: ConstrainedZonotopeState, data: _StepData, upd: _Filtered
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(c, G, A, b, e)`` of ``x[k+1]``: the prediction (same factors, so the
        certificates still apply) plus the box of its rounding (module docstring), then the
        reduction [Scott2016, Section 4]."""
        A, B, _, _, E, _ = data.mats
        c, m, n = state.c, state.G.shape[1], data.n
        c_next = A @ c + B @ data.u + E @ data.cd
        aA = np.abs(A)
        terms = aA @ data.xmag + np.abs(B) @ np.abs(data.u) + np.abs(E) @ data.dmag
        err = upper(product_error(terms, 2 * n + 3) + aA @ upd.e + upd.er_err, c.shape[0] + 2)
        if self.sys.uncertainty is not None:  # w = ΔA x + ΔB u from the certified box of x[k]
            err = up(err + uncertain.terms(self.sys.uncertainty, upd.lo, upd.hi, data.u)[0])
        box = box_generators(err)
        G_next = np.concatenate([A @ upd.G[:, :m], upd.ER, box], axis=1)
        self._check_overflow(k + 1, c_next, G_next)
        A_next = np.concatenate([upd.A, np.zeros((upd.A.shape[0], box.shape[1]))], axis=1)
        if self.design.max_generators <= 0:
            return c_next, G_next, A_next, upd.b, np.zeros(c.shape[0])
        cert = upd.cert
        if cert is not None:
            cert.pad(box.shape[1])
        # in coordinates centred at c_next, so that the rounding of the reduction is relative to
        # the set, not to |x|; the shift is added once, its rounding u |c + shift| aside
        out = eliminate_constraints(
            np.zeros_like(c_next), G_next, A_next, upd.b, self.design.max_constraints, cert
        )
        if out is None:  # numerically empty: restart from the box of x[k] (sound, not a fault)
            c_next, G, A_c, b = self._restart(data, upd)
            e = np.zeros_like(c_next)
        else:
            c_next = c_next + out.c
            G, A_c, b, e = out.G, out.A, out.b, up(out.e + UNIT_ROUNDOFF * np.abs(c_next))
        c_next, G, A_c, b = reduce_consolidated(c_next, G, A_c, b, self.design.max_generators, TOLS)
        # row-major, as a restored state is: BLAS sums in an order that depends on the layout,
        # and a restored estimator must continue as the saved one would have
        return c_next, np.ascontiguousarray(G), np.ascontiguousarray(A_c), b, e

    def _restart(
        self, data: _StepData, upd: _Filtered
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The prediction of the box ``[lo, hi]`` of ``x[k]``: ``A m + B u + E c_d``,
        ``[A diag(r), E R]`` and the box of its rounding (as in :meth:`_predict`)."""
        A, B, _, _, E, _ = data.mats
        mid, r = mid_rad(upd.lo, upd.hi)
        aA = np.abs(A)
        terms = aA @ (np.abs(mid) + r) + np.abs(B) @ np.abs(data.u) + np.abs(E) @ data.dmag
        err = product_error(terms, 2 * data.n + 3)
        if self.sys.uncertainty is not None:
            err = up(err + uncertain.terms(self.sys.uncertainty, upd.lo, upd.hi, data.u)[0])
        G = np.concatenate([A * r, data.ER, box_generators(err)], axis=1)
        return A @ mid + B @ data.u + E @ data.cd, G, np.zeros((0, G.shape[1])), np.zeros(0)
