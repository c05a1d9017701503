"""Interval estimation for nonlinear systems: inclusion functions and contractors
([Jaulin2001, Ch. 4 and 6], the mean-value form of [Moore2009, Ch. 6]).

For ``x[k+1] = f(x[k], u[k], w[k])``, ``y[k] = h(x[k], u[k], w[k])`` with ``w = (unknown
parameters, d)`` in the constant box ``[w]`` (:class:`~ivobs.NonlinearSystem`), one step from
the predicted box ``[x]_k^-`` of ``x[k]``:

1. **Correction** (forward-backward contractor, HC4-revise [Jaulin2001, Ch. 4]): contract
   ``([x]_k^-, [w])`` with ``h(x, u_k, w) ∈ [y_k]`` -> ``([x]_k, [w]_k)``;
2. **One step back** (``lag=1``): contract ``([x]_{k-1}, [w]_{k-1}, [w]_k)`` with
   ``h(f(x', u_{k-1}, w'), u_k, w) ∈ [y_k]``, then ``([x]_{k-1}, [w]_{k-1})`` with
   ``f(x', u_{k-1}, w') ∈ [x]_k`` by the centred form (below), then ``[x]_k <- [x]_k ∩
   F([x]_{k-1}, u_{k-1}, [w]_{k-1})`` and contract with ``[y_k]`` again. This bounds states
   the output sees only through the dynamics (the Hénon map with ``y = x2``: ``x1[k-1] =
   x2[k]/b``);
3. **Prediction**: ``[x]_{k+1}^- = F([x]_k, u_k, [w]_k)`` with ``F`` the natural inclusion
   intersected with the mean-value form ``f(c) + J([x],[w]) ([x, w] - c)`` (with the
   window-centred form, step 4, from its own linearisation of ``f`` over the same box:
   :func:`~ivobs.estimators.nonlinear.window.centred`, one evaluation of ``f`` and its
   Jacobian for both).

2'. **Further back** (``lag = L >= 2``, in place of step 2): the boxes of ``(x[j], w[j])``
   for the ``L`` steps ``j = k-L..k-1`` are kept; each is contracted with ``f(x[j], u[j],
   w[j]) ∈ [x]_{j+1}`` (one contractor for all the states, :meth:`~ivobs.NonlinearSystem.
   f_contractor`, then the centred form) and with its own measurement ``h(x[j], u[j], w[j]) ∈
   [y_j]``, newest first,
   then ``[x]_{j+1} <- [x]_{j+1} ∩ F([x]_j, u_j, [w]_j)`` and the measurement of ``j + 1``
   again, oldest first: the contractor network of the last ``L`` steps [Jaulin2001, Ch. 4
   and 6]. What ``y_k`` says about earlier states thus reaches ``x[k]`` through them. Its
   newest step does the work of step 2 (``[x]_k``, contracted by ``[y_k]``, narrows
   ``(x[k-1], w[k-1])`` through ``f``), so step 2 is skipped: through ``h∘f`` it narrowed no
   more on the scenarios measured (BENCHMARKS.md), for a second set of contractors per sweep.

**The centred form back through f.** The forward-backward contractors (HC4-revise) give
the hull of a row's constraint where each variable occurs once in its expression; where one
occurs twice they lose (CORA's tanks: ``x1 + Ts (u - k sqrt(x1))``, each occurrence bounded
as if it were another variable). On the rows of ``f`` where a state or unknown occurs more
than once (:meth:`~ivobs.NonlinearSystem.f_repeated_rows`), ``(x[j], w[j])`` is also
contracted with ``f ∈ [x]_{j+1}`` through the mean-value form of ``f`` over its box
(:func:`~ivobs.estimators.nonlinear.meanvalue.contract_centred`; codac's ``CtcInverse`` has
the same centred form), which sees the two occurrences as one. Not for validated flows (their
Jacobian is a flow of its own).

After step 1, step 2 or 2' (each ends with the contraction by ``[y_k]``) repeats, starting
from the boxes the last sweep left, until a sweep narrows no state's width by
:data:`FIXPOINT_GAIN` of itself (at most :data:`MAX_SWEEPS`): the contractor network of the last
steps iterated to its fixpoint (to within that share) [Jaulin2001, Ch. 4]. Step 1 is done once,
before the sweeps: its gain does not count (the rule measures what the steps back add, so one
sweep that adds nothing ends the contraction). The rule is per state, not on the summed width,
which a wide state that nothing bounds well would dominate, stopping the sweeps while the
well-measured states still narrow (CORA's six tanks; BENCHMARKS.md has the figures). Without a
step back (``lag=0``, or the first step) step 1 repeats under the same rule.

4. **Window-centred form** (``window = M >= 1``; :mod:`~ivobs.estimators.nonlinear.window`):
   each of the last ``M`` steps ``j`` keeps, from the mean-value forms of ``f`` and ``h`` over
   its corrected box of ``ζ_j = (x[j], w[j])`` and a gain ``L_j``, the affine enclosure
   ``x[j+1] = f(ζ_j) + L_j (y_j - h(ζ_j)) ∈ b_j + F_j x[j] + Fw_j (w[j] - cw_j) ± n_j``
   (exact for every ``L_j``: ``y_j = h(ζ_j)``). With the filter form of step ``k``,
   ``x[k] = x[k] + K (y_k - h(ζ_k)) ∈ a + G x[k] ± r``, and the transitions substituted
   backwards, ``x[k] ∈ m_j + Φ_j x[j] ± R_j`` with ``Φ_j = G F_{k-1} ⋯ F_j`` carried as a
   matrix; then, after the sweeps,

       [x]_k <- [x]_k ∩ ⋂_j (m_j + Φ_j [x]_j ± R_j)      (j = k-M..k, [x]_j the kept boxes)

   and ``[x]_k`` is contracted with ``[y_k]`` once more. This is the centred form
   [Moore2009, Ch. 6] composed over the window in the coordinates of an observer (a Luenberger
   correction of the interval observer of [Jaulin2001, Ch. 6]); the gains ``K``, ``L`` come
   from a Kalman filter on the same linearisations with the boxes' squared radii as variances
   [Kalman1960] (any gains are sound; these make the form tight).

``[y_k]`` is the measurement interval ``[down(y_k), up(y_k)]``: the reals the recorded double
stands for (:func:`~ivobs.estimators.nonlinear.meanvalue.measurement`), so a sample within
rounding of its bound is consistent.

**Rounding (proof).** Every bound is computed by the model's generated interval code, which
rounds each operation outward (:mod:`ivobs.model.nonlinear`: ``+ - * /`` and powers by one
ulp with ``nextafter``, elementary functions by their documented libm error): each returned
box contains the exact image of the exact boxes it was computed from, at every magnitude.
The contractors only remove points that cannot explain ``[y_k]``, and intersections of such
enclosures are exact operations. The window-centred form's hulls enclose the exact ones,
every rounding of its linearisations, products and sums bounded
(:mod:`~ivobs.estimators.nonlinear.window`, [Higham2002, Lemma 3.1]) and its bounds rounded
outward. By induction the box of ``x[k]`` contains the true state
whenever the plant follows the model with ``w[k] ∈ [w]`` and ``y[k]`` is its output rounded
to a double; no margin is added (``proven_rounding``).

**Wrapping.** Boxes are not closed under rotation: a map that contracts (``ρ(J) < 1``) can
still grow a box when ``ρ(|J|) > 1``: on random stable linear plants the box form alone (steps
1-3, ``window=0``) reaches 1e12-1e126 times the exact hull's width after 400 steps. The
window-centred form does not wrap: its dependence on the box ``j`` steps back is ``|Φ_j| r_j``
with ``Φ_j`` the product of the observer's matrices, which decays like ``(A - L C)^(k-j)`` on a
linear plant (where the box form grows like ``|A|^(k-j)``), and the remainders of the other
steps enter through the same products. On those plants it stays within 1.07-1.68 times the
exact hull (BENCHMARKS.md), about what nl-zonotope reaches (1.05-1.35). It costs
``M`` small matrix products and two linearisations per step, so by default (``window=None``)
it is used where the model's boxes would wrap: where the Jacobian ``J`` of ``f`` in ``x`` at
the centre of the prior box and of the unknowns' box has ``ρ(|J|) > (1 + WRAP_MARGIN) ρ(J)``
(a rotation, or a coupling of mixed signs: the pendulum, not the Hénon map or the tanks, whose
Jacobians there are similar to nonnegative matrices). Where the summed width still passes
:data:`WRAP_GROWTH` times the prior's (the model expands in directions the outputs do not see,
or ``window=0``), a warning says so once, with the two spectral radii at the box's centre, and
names the methods whose sets rotate with the map.

The box of ``x[k]`` uses ``u[0..k]``, ``y[0..k]`` (``data_used = "filter"``). A missing output
component is skipped; a measurement that no point of the box can produce (an empty
contraction) is reported inconsistent and not used: the step continues from the prediction.
"""

from __future__ import annotations

import hashlib
import math
import warnings
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple

import numpy as np

from ..._validate import as_int
from ...errors import IvobsError
from ...model import NonlinearSystem
from ...model.nonlinear.flow import FlowSystem
from ...sets import Box
from .. import register
from ..base import Design, Estimator
from ..state import OnlineState, Step, evolve
from . import window as wf
from .meanvalue import Linearisation, contract_centred, linearise, measurement

__all__ = [
    "WINDOW",
    "WRAP_GROWTH",
    "NonlinearIntervalDesign",
    "NonlinearIntervalEstimator",
    "NonlinearIntervalState",
]

MAX_SWEEPS = 8
"""Most sweeps of the steps back (each ending with the contraction by ``y[k]``) of one step."""

FIXPOINT_GAIN = 0.01
"""A sweep that narrows no state's width by this share of itself ends the step's contraction
(the fixpoint, to within it)."""

WRAP_GROWTH = 1e6
"""Growth of the summed width over the prior's (or the unknowns' box, or 1) that is reported
as wrapping."""


_STEP_FIELDS = wf.Transition._fields
"""The fields of a kept transition, each stored in the state as ``win_<field>``."""

MAX_LAG = 10
"""Most steps of the window contracted back (``lag``)."""

WINDOW = 20
"""Steps kept by the window-centred form (``window``; module docstring)."""

MAX_WINDOW = 100
"""Most steps of the window-centred form."""

WRAP_MARGIN = 0.01
"""How much faster than the map (``ρ(|J|)`` over ``ρ(J)``) boxes must grow under it for the
window-centred form to be used by default (``window=None``)."""


@dataclass(frozen=True)
class NonlinearIntervalDesign(Design):
    """``lag``: steps back through the model at each correction (0 to :data:`MAX_LAG`);
    ``window``: steps of the window-centred form (0: none); ``w_lo``, ``w_hi``: the box
    ``[w]`` of the per-step unknowns."""

    lag: int
    window: int
    w_lo: np.ndarray
    w_hi: np.ndarray
    model: int
    """A hash of the model's expressions and names (in the state's fingerprint: a state
    restores only into an estimator of the same model)."""


def _empty() -> np.ndarray:
    return np.zeros(0)


@dataclass(frozen=True)
class NonlinearIntervalState(OnlineState):
    """``lo``, ``hi``: the predicted box ``[x]_k^-``; ``prev_lo``, ``prev_hi``: the corrected
    box of ``(x[k-1], w[k-1])``, ``prev_u`` = ``u[k-1]`` and ``prev_y`` = ``y[k-1]`` (NaN:
    missing or not used), for the step back (``back`` says whether there is one);
    ``hist_lo``, ``hist_hi`` (·, nx + nw), ``hist_u``, ``hist_y``: the same for the steps
    before ``k - 1`` kept by ``lag >= 2``, oldest first. The window-centred form
    (``window >= 1``): ``win_lo``, ``win_hi`` the boxes of ``x[j]`` of the kept steps ``j``
    (oldest first, the last ``k - 1``) and their transitions ``j -> j + 1`` (``win_b``,
    ``win_F``, ``win_Fw``, ``win_n``, ``win_e``, ``win_dw``, ``win_eta``:
    :class:`~ivobs.estimators.nonlinear.window.Transition`); ``cov``: the prior covariance of
    the gains' Riccati recursion."""

    lo: np.ndarray
    hi: np.ndarray
    prev_lo: np.ndarray
    prev_hi: np.ndarray
    prev_u: np.ndarray
    back: bool = False
    prev_y: np.ndarray = field(default_factory=_empty)
    hist_lo: np.ndarray = field(default_factory=_empty)
    hist_hi: np.ndarray = field(default_factory=_empty)
    hist_u: np.ndarray = field(default_factory=_empty)
    hist_y: np.ndarray = field(default_factory=_empty)
    win_lo: np.ndarray = field(default_factory=_empty)
    win_hi: np.ndarray = field(default_factory=_empty)
    win_b: np.ndarray = field(default_factory=_empty)
    win_F: np.ndarray = field(default_factory=_empty)
    win_Fw: np.ndarray = field(default_factory=_empty)
    win_n: np.ndarray = field(default_factory=_empty)
    win_e: np.ndarray = field(default_factory=_empty)
    win_dw: np.ndarray = field(default_factory=_empty)
    win_eta: np.ndarray = field(default_factory=_empty)
    cov: np.ndarray = field(default_factory=_empty)
    bounds: ClassVar[tuple[tuple[str, str], ...]] = (
        ("lo", "hi"),
        ("prev_lo", "prev_hi"),
        ("hist_lo", "hist_hi"),
        ("win_lo", "win_hi"),
    )


@register
class NonlinearIntervalEstimator(Estimator):
    """Interval observer for nonlinear systems: natural ∩ mean-value prediction and
    forward-backward contraction by the measurement, one step back through ``h∘f``, and a
    window-centred form that keeps boxes from wrapping (module docstring).

    Parameters
    ----------
    sys : :class:`~ivobs.NonlinearSystem` (a time-invariant discrete-time
        :class:`~ivobs.LinearSystem` with constant bounds is converted)
    x0 : prior box of ``x[0]`` (required)
    lag : 1 (default) to contract one step back through ``h∘f``; 0 not to: when every state
        is seen by the outputs of its own step, or when ``h∘f`` is costly (a validated flow of
        a continuous-time plant steps back through its Jacobian; docs/nonlinear.md); ``L >= 2``
        (up to :data:`MAX_LAG`) to contract the last ``L`` steps as one network through ``f``
        and each step's ``h``, in place of the step through ``h∘f`` (tighter where the
        outputs see a state only through several steps of the dynamics, at about ``L`` times
        the cost of a step back; not for sampled continuous-time plants)
    window : steps ``M`` of the window-centred form (0 to :data:`MAX_WINDOW`; 0: none, the box
        form alone); None (default): :data:`WINDOW` where the model's boxes would wrap (module
        docstring, "Wrapping"), else 0
    """

    name = "nl-interval"
    order = 900
    summary = (
        "nonlinear systems: natural ∩ mean-value inclusion, forward-backward contraction by "
        "y, one step back through h∘f, and a window-centred form that does not wrap"
    )
    reference = "[Jaulin2001, Ch. 4], [Moore2009, Ch. 6]"
    data_used = "filter"
    needs_x0 = True
    supports_nonlinear = True
    proven_rounding = True
    design: NonlinearIntervalDesign

    def __init__(
        self,
        sys: Any,
        x0: Box | None = None,
        *,
        lag: int = 1,
        window: int | None = None,
        **options: Any,
    ):
        super().__init__(sys, x0, **options)
        sys = self.model  # (a linear model converted: Estimator.__init__)
        lag = as_int("lag", lag, minimum=0)
        if lag > MAX_LAG:
            raise IvobsError(f"lag: expected 0 to {MAX_LAG} steps back, got {lag}")
        if window is None:
            window = _auto_window(sys, self.x0)
        else:
            window = as_int("window", window, minimum=0)
            if window > MAX_WINDOW:
                raise IvobsError(f"window: expected 0 to {MAX_WINDOW} steps, got {window}")
            if window and _jacobian_at_prior(sys, self.x0) is None:
                raise IvobsError(
                    "window: the window-centred form linearises f, whose Jacobian this model "
                    "does not give (a validated flow of a non-smooth f); use window=0"
                )
        self._fc = sys.f_contractor() if lag > 1 else None
        w = sys.w_box
        digest = hashlib.sha256(repr(sorted(sys.spec().items())).encode()).hexdigest()
        self.design = NonlinearIntervalDesign(
            lag=lag, window=window, w_lo=w.lo.copy(), w_hi=w.hi.copy(), model=int(digest[:12], 16)
        )
        self._flow = isinstance(sys, FlowSystem)
        # the centred form back through f, on the rows where HC4 is not already the tightest
        self._fb_rows = sys.f_repeated_rows() if lag and not self._flow else []
        self._f_evals = sys.evaluators("f") if window or self._fb_rows else None
        self._h_evals = sys.evaluators("h") if window and sys.ny else None
        self._wl, self._wh = w.lo.tolist(), w.hi.tolist()
        self._hf = sys.hf_contractors() if lag == 1 and sys.ny else None
        # growth that says the interval form wraps (module docstring, "Wrapping")
        prior = float(np.sum(self.x0.hi - self.x0.lo)) if self.x0 is not None else 0.0
        self._wrap_limit = WRAP_GROWTH * max(prior, float(np.sum(w.hi - w.lo)), 1.0)
        self._wrapping_said = False

    def _say_wrapping(self, k: int, lo: list[float], hi: list[float], u: list[float]) -> None:
        """Warn once that the boxes grew past :data:`WRAP_GROWTH` times the prior's width,
        with the spectral radii of the Jacobian at the box's centre and of its magnitude."""
        self._wrapping_said = True
        width = sum(hi) - sum(lo)
        why = ""
        if all(np.isfinite(lo)) and all(np.isfinite(hi)):
            c = [0.5 * a + 0.5 * b for a, b in zip(lo, hi)]
            wc = [0.5 * a + 0.5 * b for a, b in zip(self._wl, self._wh)]
            radii = _radii(_jacobian(self.model, c, u, wc))
            if radii is not None:
                rho, rho_abs = radii
                why = (
                    f"the Jacobian at the box's centre has spectral radius {rho:.3g}, its "
                    f"magnitude {rho_abs:.3g}"
                )
                if rho < 1.0 <= rho_abs:
                    why = (
                        f": the interval form wraps ({why}: boxes of a map that rotates or "
                        "couples its states grow even where the map contracts); it stays sound "
                        "but says little. nl-zonotope or nl-constrained-zonotope keep such "
                        "plants bounded"
                    )
                else:
                    why = f" ({why}): the outputs do not bound what the model lets grow"
        warnings.warn(
            f"{self.name}: the box grew to a width of {width:.3g} by step {k + 1}, more than "
            f"{WRAP_GROWTH:.0e} times the prior's{why}",
            stacklevel=4,
        )

    def _initial_state(self) -> NonlinearIntervalState:
        assert self.x0 is not None
        m = self.model
        extra: dict[str, np.ndarray] = {}  # the window of lag >= 2, the window-centred form
        if self._fc is not None:
            extra = {
                "prev_y": np.full(m.ny, np.nan),
                "hist_lo": np.zeros((0, m.nx + m.nw)),
                "hist_hi": np.zeros((0, m.nx + m.nw)),
                "hist_u": np.zeros((0, m.nu)),
                "hist_y": np.zeros((0, m.ny)),
            }
        state = NonlinearIntervalState(
            lo=self.x0.lo.copy(),
            hi=self.x0.hi.copy(),
            prev_lo=np.zeros(m.nx + m.nw),
            prev_hi=np.zeros(m.nx + m.nw),
            prev_u=np.zeros(m.nu),
        )
        if self.design.window:
            nx, nw = m.nx, m.nw
            r = 0.5 * self.x0.hi - 0.5 * self.x0.lo
            extra.update(
                win_lo=np.zeros((0, nx)),
                win_hi=np.zeros((0, nx)),
                win_b=np.zeros((0, nx)),
                win_F=np.zeros((0, nx, nx)),
                win_Fw=np.zeros((0, nx, nw)),
                win_n=np.zeros((0, nx)),
                win_e=np.zeros((0, nx)),
                win_dw=np.zeros((0, nw)),
                win_eta=np.zeros(0),
                cov=np.diag(r * r),
            )
        return evolve(state, **extra) if extra else state

    def _step(
        self, state: NonlinearIntervalState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[NonlinearIntervalState]:
        sys, nx = self.model, self.model.nx
        u = u_k.tolist()
        # the joint box (x[k], w[k]) as lists: the generated contractors narrow it in place
        vl, vh = state.lo.tolist() + self._wl, state.hi.tolist() + self._wh
        inconsistent = False
        ylo, yhi = measurement(y_k)
        chain = self._chain(state)
        seen = any(v == v for v in ylo)
        prev = None
        if seen:
            ok = sys.contract_lists(vl, vh, u, ylo, yhi)  # 1. correction
            back = (self._hf is not None or self._fc is not None) and state.back
            for _ in range(MAX_SWEEPS):  # to a fixpoint: until a sweep gains < FIXPOINT_GAIN
                if not ok:
                    break
                before = [b - a for a, b in zip(vl[:nx], vh[:nx])]
                if not back:  # the correction again (HC4 is not idempotent)
                    ok = sys.contract_lists(vl, vh, u, ylo, yhi)
                elif chain:  # 2'. the steps back (lag >= 2), k - 1 the newest
                    ok = self._window(chain, vl, vh, u, ylo, yhi)
                    prev = (chain[-1].lo, chain[-1].hi)
                else:  # 2. the step back (each ends with the correction)
                    ok, prev = self._back(state, vl, vh, u, ylo, yhi, prev)
                if not ok or not _gained(before, vl, vh):
                    break
            if not ok:  # y_k contradicts the model: not used
                inconsistent = True
        hist: dict[str, np.ndarray] = {}
        pred = None
        with np.errstate(all="ignore"):  # the window-centred form checks what is not finite
            win: _Form | None = None
            if self.design.window and not inconsistent:  # 4. the window-centred form
                win = self._form(state, vl, vh, u_k, y_k, ylo, yhi, seen, chain, prev)
                if win is None:  # empty: y_k contradicts the model and the window
                    inconsistent = True
                elif seen and win.narrowed and not sys.contract_lists(vl, vh, u, ylo, yhi):
                    inconsistent = True
            if inconsistent:
                vl, vh = state.lo.tolist() + self._wl, state.hi.tolist() + self._wh
                chain = self._chain(state)
                win = None
                if self.design.window:
                    win = self._form(state, vl, vh, u_k, y_k, ylo, yhi, False, chain, None)
            if self.design.window and win is None:  # the model contradicted: start again
                rows = self._rows(state, [], None).empty()
                win = _Form(rows, None, None, state.cov, None, False)
            prev_lo, prev_hi = np.array(vl, dtype=float), np.array(vh, dtype=float)
            if self._fc is not None:
                hist = self._history(chain, y_k, inconsistent)
            if win is not None:
                slid, pred = self._slide(win, prev_lo, prev_hi, u_k, len(y_k))
                hist.update(slid)
        if pred is None:  # 3. prediction: natural ∩ mean-value form
            f = sys._f
            pl, ph = sys._call(f.tight, f.sites, vl[:nx], vh[:nx], u, vl[nx:], vh[nx:])
        else:  # (from step 4's linearisation of f)
            pl, ph = pred[0].tolist(), pred[1].tolist()
        if not self._wrapping_said and sum(ph) - sum(pl) > self._wrap_limit:
            self._say_wrapping(state.k, pl, ph, u)
        new = evolve(  # a new object (cheaper than the constructor): the base sets k
            state,
            lo=np.array(pl, dtype=float),
            hi=np.array(ph, dtype=float),
            prev_lo=prev_lo,
            prev_hi=prev_hi,
            prev_u=u_k.copy(),
            back=True,
            **hist,
        )
        return Step(new, prev_lo[:nx], prev_hi[:nx], inconsistent)

    def _form(
        self,
        st: NonlinearIntervalState,
        vl: list[float],
        vh: list[float],
        u_k: np.ndarray,
        y_k: np.ndarray,
        ylo: list[float],
        yhi: list[float],
        seen: bool,
        chain: list[_Link],
        prev: tuple[list[float], list[float]] | None,
    ) -> _Form | None:
        """Step 4 of the module docstring on the box ``vl, vh`` of ``(x[k], w[k])`` (narrowed
        in place): the filter form of ``y_k`` (when ``seen``) composed with the kept
        transitions, intersected over the kept boxes; None when the intersection is empty."""
        nx = self.model.nx
        lo, hi = np.array(vl, dtype=float), np.array(vh, dtype=float)
        lh: Linearisation | None = None
        g: wf.Gains | None = None
        dw = None
        if seen and self._h_evals is not None and np.isfinite(lo).all() and np.isfinite(hi).all():
            lh = wf.affine(self._h_evals, lo, hi, u_k, nx)
            if np.isfinite(lh.J).all() and np.isfinite(lh.rho).all():
                dw = wf.radius(lo[nx:], hi[nx:], lh.c[nx:])
                g = wf.filter_gain(st.cov, lh, ~np.isnan(y_k), dw, nx)
            else:
                lh = None
        K = np.zeros((nx, len(y_k))) if g is None else g.K
        meas = wf.measured(y_k, ylo, yhi)
        start = wf.filter_start(lh, K, dw, lo[:nx], hi[:nx], meas, nx)
        rows = self._rows(st, chain, prev)
        cl, ch = wf.hull(start, lo[:nx], hi[:nx], rows)
        nl = np.fmax(lo[:nx], np.fmax.reduce(cl, axis=0))
        nh = np.fmin(hi[:nx], np.fmin.reduce(ch, axis=0))
        if (nl > nh).any():
            return None
        narrowed = bool((nl > lo[:nx]).any() or (nh < hi[:nx]).any())
        vl[:nx], vh[:nx] = nl.tolist(), nh.tolist()
        return _Form(rows, lh, g, st.cov, meas, narrowed)

    def _rows(
        self,
        st: NonlinearIntervalState,
        chain: list[_Link],
        prev: tuple[list[float], list[float]] | None,
    ) -> wf.Rows:
        """The kept steps of the window-centred form, their boxes narrowed by what this step's
        contraction back (``prev``, ``chain``) found."""
        nx = self.model.nx
        lo, hi = st.win_lo, st.win_hi
        boxes = [(c.lo, c.hi) for c in chain] if chain else ([prev] if prev is not None else [])
        if boxes and lo.shape[0]:
            lo, hi = lo.copy(), hi.copy()
            for i, (bl, bh) in enumerate(boxes[-lo.shape[0] :][::-1]):
                j = lo.shape[0] - 1 - i
                lo[j] = np.maximum(lo[j], bl[:nx])
                hi[j] = np.minimum(hi[j], bh[:nx])
        return wf.Rows(lo, hi, wf.Transition(*(getattr(st, f"win_{f}") for f in _STEP_FIELDS)))

    def _slide(
        self, win: _Form, lo: np.ndarray, hi: np.ndarray, u_k: np.ndarray, ny: int
    ) -> tuple[dict[str, np.ndarray], tuple[np.ndarray, np.ndarray] | None]:
        """The window-centred form's part of the next state: the box of ``x[k]`` and the
        transition ``k -> k + 1`` appended (the oldest dropped past ``window`` steps), and the
        next prior covariance. A transition that is not finite empties the window. Also the
        prediction (step 3) from the same linearisation of ``f``: the natural inclusion met
        with the centred form, as ``F`` (None for a validated flow, whose own ``F`` is used,
        or without a linearisation)."""
        nx = self.model.nx
        assert self._f_evals is not None
        rows, P = win.rows, None
        tr: wf.Transition | None = None
        pred = None
        if win.meas is not None and np.isfinite(lo).all() and np.isfinite(hi).all():
            lf = wf.affine(self._f_evals, lo, hi, u_k, nx)
            delta = wf.radius(lo, hi, lf.c)
            if not self._flow:
                pred = wf.centred(lf, delta)
            L, P = wf.predictor(win.P, win.g, lf.J, lf.rho, delta[nx:], nx, ny)
            tr = wf.transition(lf, win.lh, L, delta, win.meas, nx)
            total = tr.b.sum() + tr.F.sum() + tr.Fw.sum() + tr.n.sum() + tr.e.sum() + tr.dw.sum()
            if not math.isfinite(float(total) + tr.eta):  # (a sum that overflows counts too)
                tr = None
        if P is None or not float(np.max(np.abs(P), initial=0.0)) < 1e150:  # (NaN: not <)
            r = np.where(np.isfinite(hi - lo), 0.5 * hi - 0.5 * lo, 1.0)[:nx]
            P = np.diag(np.minimum(r * r, 1e150))
        if tr is None:  # the chain of transitions breaks: start again
            rows = rows.empty()
            steps = dict(zip(_STEP_FIELDS, rows.steps))
        else:
            keep = max(rows.lo.shape[0] - (self.design.window - 1), 0)

            def add(old: np.ndarray, row: Any) -> np.ndarray:
                return np.concatenate([old[keep:], np.asarray(row, dtype=float)[None]])

            rows = wf.Rows(add(rows.lo, lo[:nx]), add(rows.hi, hi[:nx]), rows.steps)
            steps = {f: add(old, new) for f, old, new in zip(_STEP_FIELDS, rows.steps, tr)}
        return {
            "win_lo": rows.lo,
            "win_hi": rows.hi,
            **{f"win_{f}": a for f, a in steps.items()},
            "cov": P,
        }, pred

    def _chain(self, st: NonlinearIntervalState) -> list[_Link]:
        """The kept steps ``k-L..k-1`` as boxes to contract (copies), oldest first; empty
        unless ``lag >= 2`` and there is a step back."""
        if self._fc is None or not st.back:
            return []
        links = [
            _Link(lo.tolist(), hi.tolist(), u.tolist(), y, *measurement(y))
            for lo, hi, u, y in zip(st.hist_lo, st.hist_hi, st.hist_u, st.hist_y)
        ]
        y = st.prev_y
        links.append(_Link(st.prev_lo.tolist(), st.prev_hi.tolist(), st.prev_u.tolist(), y,
                           *measurement(y)))  # fmt: skip
        return links

    def _history(self, chain: list[_Link], y_k: np.ndarray, dropped: bool) -> dict[str, np.ndarray]:
        """The state's window after step ``k``: the contracted boxes of the steps before ``k``
        (the last ``L - 1``) and ``y[k]`` (NaN if it was not used)."""
        keep = self.design.lag - 1
        m = self.model
        links = chain[-keep:] if chain else []
        y = np.full(m.ny, np.nan) if dropped else np.array(y_k, dtype=float)
        width = m.nx + m.nw

        def rows(values: list[Any], n: int) -> np.ndarray:
            return np.array(values, dtype=float).reshape(len(values), n)

        return {
            "prev_y": y,
            "hist_lo": rows([c.lo for c in links], width),
            "hist_hi": rows([c.hi for c in links], width),
            "hist_u": rows([c.u for c in links], m.nu),
            "hist_y": rows([c.y for c in links], m.ny),
        }

    def _window(
        self,
        chain: list[_Link],
        vl: list[float],
        vh: list[float],
        u: list[float],
        ylo: list[float],
        yhi: list[float],
    ) -> bool:
        """Step 2' of the module docstring on the kept steps ``chain`` and the box ``vl, vh``
        of ``(x[k], w[k])`` (all in place): backward through the ``f`` contractors and each
        step's measurement, then forward through the inclusion of ``f``. False when the boxes
        become empty (``y[k]`` contradicts the window)."""
        sys, nx = self.model, self.model.nx
        assert self._fc is not None
        (fc, sites), f = self._fc, sys._f
        for j in range(len(chain) - 1, -1, -1):  # newest first
            c = chain[j]
            tl, th = (vl, vh) if j == len(chain) - 1 else (chain[j + 1].lo, chain[j + 1].hi)
            if not sys._call(fc, sites, c.lo, c.hi, c.u, tl, th):  # f(x[j], ·) ∈ [x]_{j+1}
                return False
            if not self._centred_back(c.lo, c.hi, c.u, tl[:nx], th[:nx]):
                return False
            if any(v == v for v in c.ylo) and not sys.contract_lists(c.lo, c.hi, c.u, c.ylo, c.yhi):
                return False
        for j, c in enumerate(chain):  # oldest first
            last = j == len(chain) - 1
            nl, nh = (vl, vh) if last else (chain[j + 1].lo, chain[j + 1].hi)
            fl, fh = sys._call(f.tight, f.sites, c.lo[:nx], c.hi[:nx], c.u, c.lo[nx:], c.hi[nx:])
            if not _meet(nl, nh, fl, fh):
                return False
            ml, mh = (ylo, yhi) if last else (chain[j + 1].ylo, chain[j + 1].yhi)
            nu = u if last else chain[j + 1].u
            if any(v == v for v in ml) and not sys.contract_lists(nl, nh, nu, ml, mh):
                return False
        return True

    def _centred_back(
        self, zl: list[float], zh: list[float], u: list[float], tl: list[float], th: list[float]
    ) -> bool:
        """The box ``[zl, zh]`` of ``(x[j], w[j])`` contracted in place with ``f(x[j], u[j],
        w[j]) ∈ [tl, th]`` by the centred form of ``f`` over it
        (:func:`~.meanvalue.contract_centred`); False when it becomes empty."""
        if not self._fb_rows or not all(map(math.isfinite, zl + zh)):
            return True
        assert self._f_evals is not None
        c = np.array([0.5 * a + 0.5 * b for a, b in zip(zl, zh)])
        lin = linearise(self._f_evals, zl, zh, c, np.array(u, dtype=float), self.model.nx, False)
        return contract_centred(lin, zl, zh, tl, th, self._fb_rows)

    def _back(
        self,
        st: NonlinearIntervalState,
        vl: list[float],
        vh: list[float],
        u: list[float],
        ylo: list[float],
        yhi: list[float],
        prev: tuple[list[float], list[float]] | None = None,
    ) -> tuple[bool, tuple[list[float], list[float]] | None]:
        """Step 2 of the module docstring on ``vl = xl + wl``, ``vh`` (in place), from the box
        of ``(x[k-1], w[k-1])`` (``prev``: as an earlier sweep of this step left it); False
        when the measurement is found inconsistent, and the box of ``(x[k-1], w[k-1])``."""
        sys, nx, nw = self.model, self.model.nx, self.model.nw
        # the box of (x[k-1], w[k-1], w[k])
        pl, ph = (st.prev_lo.tolist(), st.prev_hi.tolist()) if prev is None else prev
        bl = pl + vl[nx:]
        bh = ph + vh[nx:]
        pu = st.prev_u.tolist()
        assert self._hf is not None
        for (fn, sites), a, b in zip(self._hf, ylo, yhi):
            if a == a and not sys._call(fn, sites, bl, bh, pu + u, a, b):
                return False, None
        m = nx + nw
        zl, zh = bl[:m], bh[:m]
        if not self._centred_back(zl, zh, pu, vl[:nx], vh[:nx]):  # f(ζ_{k-1}) ∈ [x]_k
            return False, None
        bl[:m], bh[:m] = zl, zh
        f = sys._f
        fl, fh = sys._call(f.tight, f.sites, bl[:nx], bh[:nx], pu, bl[nx:m], bh[nx:m])
        if not _meet(vl, vh, fl, fh):  # [x]_k ∩ F([x]_{k-1}, u_{k-1}, [w]_{k-1})
            return False, None
        vl[nx:], vh[nx:] = bl[m:], bh[m:]
        return bool(sys.contract_lists(vl, vh, u, ylo, yhi)), (bl[:m], bh[:m])


def _auto_window(sys: NonlinearSystem, x0: Box | None) -> int:
    """:data:`WINDOW` where boxes wrap under the model, else 0: where the Jacobian ``J`` of
    ``f`` in ``x`` at the centre of the prior box and of the unknowns' box has
    ``ρ(|J|) > (1 + WRAP_MARGIN) ρ(J)`` (a rotation, or a coupling of mixed signs: the box of
    ``J [x]`` is wider than the map makes the set). 0 where that Jacobian does not exist (a
    validated flow of a non-smooth ``f``) or is not finite."""
    radii = _radii(_jacobian_at_prior(sys, x0))
    if radii is None:
        return 0
    rho, rho_abs = radii
    return WINDOW if rho_abs > (1.0 + WRAP_MARGIN) * rho else 0


def _jacobian_at_prior(sys: NonlinearSystem, x0: Box | None) -> np.ndarray | None:
    """``d f / d x`` at the centre of the prior box and of the unknowns' box (inputs 0), or
    None where it cannot be evaluated."""
    if x0 is None:
        return None
    wc = 0.5 * sys.w_box.lo + 0.5 * sys.w_box.hi
    return _jacobian(sys, 0.5 * x0.lo + 0.5 * x0.hi, np.zeros(sys.nu), wc)


def _jacobian(sys: NonlinearSystem, c: Any, u: Any, wc: Any) -> np.ndarray | None:
    """``d f / d x`` at the point ``(c, u, wc)`` (the midpoint of the model's enclosure), or
    None where it cannot be evaluated."""
    try:
        jl, jh = sys.f_jac_box(c, c, u, wc, wc)[:2]
    except IvobsError:
        return None
    out: np.ndarray = 0.5 * np.asarray(jl) + 0.5 * np.asarray(jh)
    return out


def _radii(J: np.ndarray | None) -> tuple[float, float] | None:
    """The spectral radii ``ρ(J)`` and ``ρ(|J|)`` (None for no or a non-finite ``J``)."""
    if J is None or not np.isfinite(J).all():
        return None
    rho = float(np.max(np.abs(np.linalg.eigvals(J))))
    return rho, float(np.max(np.abs(np.linalg.eigvals(np.abs(J)))))


class _Form(NamedTuple):
    """What the window-centred form of a step passes to its end: the kept steps (boxes
    narrowed), ``h`` linearised over the step's box and the filter gain's parts (None: no
    measurement used), the prior covariance and whether the box narrowed."""

    rows: wf.Rows
    lh: Linearisation | None
    g: wf.Gains | None
    P: np.ndarray
    meas: wf.Measured | None
    narrowed: bool


@dataclass
class _Link:
    """One kept step of the window during a step: the box of ``(x[j], w[j])`` (lists,
    narrowed in place), ``u[j]``, ``y[j]`` and its measurement interval."""

    lo: list[float]
    hi: list[float]
    u: list[float]
    y: np.ndarray
    ylo: list[float]
    yhi: list[float]


def _meet(lo: list[float], hi: list[float], fl: list[float], fh: list[float]) -> bool:
    """``[lo, hi] ∩ [fl, fh]`` in place on the first ``len(fl)`` entries; False if empty."""
    for i, (a, b) in enumerate(zip(fl, fh)):
        lo[i], hi[i] = max(lo[i], a), min(hi[i], b)
        if lo[i] > hi[i]:
            return False
    return True


def _gained(before: list[float], lo: list[float], hi: list[float]) -> bool:
    """Whether some state's width narrowed from ``before`` by at least :data:`FIXPOINT_GAIN`
    of itself (an unbounded one: became bounded)."""
    return any(hi[i] - lo[i] < (1.0 - FIXPOINT_GAIN) * w for i, w in enumerate(before))
