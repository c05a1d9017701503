"""Moving-horizon set-membership estimation for nonlinear systems: the window's model
linearised over proven boxes, the hull of ``x[k]`` certified by weak duality.

For ``x[j+1] = f(x[j], u[j], w[j])``, ``y[j] = h(x[j], u[j], w[j])`` (a
:class:`~ivobs.NonlinearSystem`; ``w[j] ∈ W = sys.w_box``, the unknown parameters and bounded
signals, any value in their bounds at every step, one ``w[j]`` in both maps), a recursive filter
keeps one set of ``x[k]`` and loses what a single step's data cannot pin down: on a weakly
observable plant (a position seen only through a range) its box drifts. This estimator keeps
the last ``N`` steps as a program over the blocks ``(x[j], w[j])``, each step's maps linearised
over a *proven* box of its state, so that every constraint is linear with an interval remainder
and the window's data act together, as in the linear ``exact`` reference.

**The rows.** Over a box ``B = X × W`` that holds ``ζ = (x[j], w[j])``, the mean-value form
[Moore2009, Ch. 6], [Jaulin2001, Ch. 2] ((MV) of
:func:`~ivobs.estimators.nonlinear.meanvalue.linearise`, [Rego2020]) gives double ``g0``, ``J``
and ``ρ`` with ``|g(ζ) - g0 - J (ζ - c)| <= ρ`` for *every* ``ζ ∈ B`` (exact arithmetic), ``c``
the centre. With ``J = [Jx Jw]``:

::

    dynamics, j -> j+1:  x[j+1] - Jx x[j] - Jw w[j]  ∈  (g0 - J c) ± tau         (D)
    measurement at j:    Hx x[j] + Hw w[j]           ∈  (y[j] - g0 + H c) ± tau_h  (M)

``tau = ρ`` plus the rounding of the right-hand side, ``γ_{n+2} (|g0| + |J| |c|)`` (and
``|y|`` in (M), [Higham2002, Section 3.1]), the one ulp of the sample ``y`` (the real it stands
for, :func:`~ivobs.estimators.nonlinear.meanvalue.measurement`), the data margin of a float64
record of the model (``RECORD_MARGIN``, as ``nl-constrained-zonotope``), the sum enlarged by
``(1 + γ_{n+6})`` for its own rounding and rounded up, then ``2 ε (|rhs| + tau)`` more so that
the floating-point row bounds ``fl(rhs ∓ tau)`` still contain the exact range. These are the
rows ``Dynamics(A=Jx, E=Jw, bu, tau)`` and ``Measurement(C=Hx, F=Hw, rhs, tau_h)`` of the
``exact`` program (:class:`~ivobs.estimators.exact.program.TrajectoryLP`), with ``d[j] = w[j]``.

**The step.** With ``X_{k-1}`` this estimator's box of ``x[k-1]``:

1. an inner ``nl-constrained-zonotope`` filter (run by composition, its state nested in this
   one) gives a box ``B_k`` of ``x[k]``; the prediction ``P_k = f(X_{k-1}, u, W) ∩ B_k`` (the
   model's tight inclusion, widened by ``RECORD_MARGIN``; ``P_0 = x0 ∩ B_0``);
2. (D) of step ``k-1`` over ``X_{k-1} × W``; (M) of step ``k`` over ``P_k × W`` (NaN
   components of ``y``: free rows);
3. the block ``(x[k], w[k])`` with bounds ``P_k × W`` is pushed, the oldest beyond the window
   popped (its successor keeps its own proven box as bounds); the bounds of ``x[k]`` are the
   safe dual bounds (S) of the ``2 nx`` programs ``min/max x[k]_i`` [Neumaier2004]
   (:meth:`~ivobs.estimators.exact.highs.WarmStartedLP.last_x_box`, warm-started from the
   previous bases); an infeasible verdict with a Farkas certificate drops ``y[k]`` (its rows
   freed) and is reported;
4. (M) of step ``k`` is rebuilt over the box just proven, ``X_k × W``, and the programs solved
   again (``passes`` times, or until no bound moves by 1 % of the width): the remainder shrinks
   with the square of the box, so the tighter box gives a tighter row, and a tighter box.

**Soundness (proof).** By induction on ``k``: ``X_{k-1}`` holds the true ``x[k-1]`` and every
kept box holds its true state. Then ``P_k`` holds ``x[k]`` (an inclusion of ``f`` over boxes
that hold its arguments, met with the inner filter's proven box). Each row was built over a box
that holds the true ``(x[j], w[j])`` at the time it was built (every later box of ``x[j]`` is a
subset of it), so the true trajectory of the window satisfies every row in exact arithmetic,
and lies within every variable bound: the program is feasible, and the safe bound (S) of *any*
multipliers bounds ``x[k]`` over it, whatever HiGHS returns. A rebuilt (M) is built over
``X_k``, proven by the previous solve, so it too holds at the true state. Hence ``x[k] ∈ X_k``.
When ``y[k]`` is certified inconsistent, its rows are free and the box is that of the rest.
Every bound is proven in floating point (``proven_rounding``; the base adds no margin).

**The window.** Each step solves ``2 nx`` programs of ``N + 1`` blocks (and again per pass);
the width falls with ``N`` and levels off once the window spans what the data can pin. On
``range-only`` (uniform signals, mean widths over steps 300-599) the speed's width at ``N = 5``
is 1.24 times that at ``N = 20``, at ``N = 10`` 1.09 times, and ``N = 40`` gains 0.4 % over
``N = 20``: the default is 20.

**The passes.** Step 4 matters where the prediction ``P_k`` is wide against the curvature of
``h``. On the scenarios' late steps it changes the widths by at most 0.3 % (``unicycle-range``;
nothing to four digits on ``range-only``, ``henon-nl``, ``pendulum-nl``, ``cstr``): the default
is one pass, a second one rarely runs (the 1 % rule), and ``passes=0`` is the cheaper step.

Data used: ``x0``, ``W``, ``u[0..k]``, ``y[0..k]`` (filtered).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..._validate import as_int
from ...errors import IvobsError
from ...linalg import gamma
from ...sets import Box
from ...sets.rounding import ETA, UNIT_ROUNDOFF, down, up
from .. import register
from .._balanced import balancing
from ..base import Design, Estimator, check_size
from ..exact.estimator import appended
from ..exact.highs import (
    INFEASIBLE,
    OK,
    WarmStartedLP,
    WarmStarts,
    check_basis_codes,
    with_saved_bases,
)
from ..exact.program import TrajectoryLP
from ..exact.rows import Dynamics, Measurement, widen
from ..state import OnlineState, Step, dump_state, load_state
from .czonotope import (
    RECORD_MARGIN,
    NonlinearConstrainedZonotopeEstimator,
    NonlinearConstrainedZonotopeState,
)
from .meanvalue import linearise

__all__ = ["NonlinearHorizonDesign", "NonlinearHorizonEstimator", "NonlinearHorizonState"]

DEFAULT_WINDOW = 20
"""The window ``N`` when none is given (module docstring, "The window")."""

DEFAULT_PASSES = 1
"""Re-linearisations of the newest measurement over the box just proven, per step (module
docstring, "The passes")."""

GAIN = 0.01
"""A pass that moves no bound by more than this fraction of the width ends the step."""

EPS = 2.0 * UNIT_ROUNDOFF


@dataclass(frozen=True)
class NonlinearHorizonDesign(Design):
    """``window``: steps ``N`` kept in the program; ``passes``: re-linearisations of the
    newest measurement per step."""

    window: int
    passes: int


@dataclass(frozen=True)
class NonlinearHorizonState(OnlineState):
    """The kept window (the last ``N`` steps), from which the program is rebuilt; one row per
    kept step ``j``:

    ``x_lo``, ``x_hi`` (·, nx): the bounds of ``x[j]`` in the program (the box proven for it,
    widened, met with ``P_j``), over which (D) of step ``j`` is built; ``m_lo``, ``m_hi``
    (·, nx): the box over which (M) of step ``j`` was built; ``p_lo``, ``p_hi`` (·, nx): the
    prediction ``P_j`` (its centre shifts the program HiGHS sees); ``u``, ``y``: the data;
    ``used``: whether ``y[j]`` entered the program. ``basis_min``, ``basis_max``: the simplex
    bases the next step starts from, written when the state is saved (as in ``exact``: a
    restored state continues with the same solves). ``inner``: the state of the inner
    ``nl-constrained-zonotope`` filter."""

    x_lo: np.ndarray
    x_hi: np.ndarray
    m_lo: np.ndarray
    m_hi: np.ndarray
    p_lo: np.ndarray
    p_hi: np.ndarray
    u: np.ndarray
    y: np.ndarray
    used: np.ndarray
    inner: Any = None
    basis_min: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    basis_max: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (
        ("x_lo", "x_hi"),
        ("m_lo", "m_hi"),
        ("p_lo", "p_hi"),
    )
    optional: ClassVar[tuple[str, ...]] = ("inner",)  # saved in its own envelope (_dump)

    @property
    def history(self) -> tuple[np.ndarray, ...]:
        """The arrays of the kept window (what identifies its warm-started program)."""
        return (self.x_lo, self.x_hi, self.m_lo, self.m_hi, self.p_lo, self.p_hi, self.u,
                self.y, self.used)  # fmt: skip


def _tau(core: np.ndarray, rhs: np.ndarray, n: int) -> np.ndarray:
    """The half-width of a row (module docstring): ``core`` (nonnegative terms) enlarged by
    ``(1 + γ_{n+6})`` and rounded up, then ``2 ε (|rhs| + tau)`` more (the rounding of the
    row bounds ``fl(rhs ∓ tau)``) and the underflows."""
    tau = up(core * (1.0 + gamma(n + 6)) + (n + 6) * ETA)
    with np.errstate(invalid="ignore"):  # NaN rhs (a free row) stays NaN
        out: np.ndarray = up(tau + 2.0 * EPS * (np.abs(rhs) + tau) + ETA)
    return out


def dynamics_row(
    sys: Any, x_lo: np.ndarray, x_hi: np.ndarray, u: np.ndarray, w_lo: np.ndarray,
    w_hi: np.ndarray,
) -> Dynamics:  # fmt: skip
    """(D): ``x[j+1] - Jx x[j] - Jw w[j] ∈ bu ± tau`` for every ``x[j] ∈ [x_lo, x_hi]``,
    ``w[j] ∈ [w_lo, w_hi]`` (module docstring)."""
    nx = sys.nx
    lo, hi = np.concatenate([x_lo, w_lo]), np.concatenate([x_hi, w_hi])
    c = 0.5 * lo + 0.5 * hi
    lin = linearise(sys.evaluators("f"), lo, hi, c, u, nx, False)
    J, aJ, n = lin.J, np.abs(lin.J), lo.size
    bu = lin.g0 - J @ lin.c
    delta = up(np.maximum(hi - lin.c, lin.c - lo))
    core = (
        lin.rho
        + 2.0 * gamma(n + 2) * (np.abs(lin.g0) + aJ @ np.abs(lin.c))
        + RECORD_MARGIN * (1.0 + np.abs(lin.g0) + aJ @ (np.abs(lin.c) + delta))
    )
    return Dynamics(J[:, :nx], J[:, nx:], bu, _tau(core, bu, n))


def measurement_row(
    sys: Any, x_lo: np.ndarray, x_hi: np.ndarray, u: np.ndarray, y: np.ndarray,
    w_lo: np.ndarray, w_hi: np.ndarray,
) -> Measurement:  # fmt: skip
    """(M): ``Hx x[j] + Hw w[j] ∈ rhs ± tau`` for every ``x[j] ∈ [x_lo, x_hi]``,
    ``w[j] ∈ [w_lo, w_hi]`` with ``y = h(x[j], u, w[j])`` (module docstring); NaN in ``y``:
    NaN ``rhs`` (a free row)."""
    nx = sys.nx
    lo, hi = np.concatenate([x_lo, w_lo]), np.concatenate([x_hi, w_hi])
    c = 0.5 * lo + 0.5 * hi
    lin = linearise(sys.evaluators("h"), lo, hi, c, u, nx, False)
    J, aJ, n = lin.J, np.abs(lin.J), lo.size
    rhs = y - lin.g0 + J @ lin.c
    ay = np.abs(y)
    core = (
        lin.rho
        + 2.0 * gamma(n + 3) * (ay + np.abs(lin.g0) + aJ @ np.abs(lin.c))
        + 2.0 * EPS * ay  # the real the double y stands for (one ulp)
        + RECORD_MARGIN * (1.0 + ay)
    )
    return Measurement(J[:, :nx], J[:, nx:], rhs, np.where(np.isnan(rhs), 0.0, _tau(core, rhs, n)))


def _free(meas: Measurement) -> Measurement:
    return Measurement(meas.C, meas.F, np.full_like(meas.rhs, np.nan), np.zeros_like(meas.tau))


@register
class NonlinearHorizonEstimator(Estimator):
    """Moving-horizon set-membership estimator for nonlinear systems: the last ``N`` steps
    linearised over proven boxes (mean-value form), the hull of ``x[k]`` by linear programming
    with safe dual bounds [Neumaier2004], met with an inner ``nl-constrained-zonotope`` box.

    Uses ``u[0..k]`` and ``y[0..k]`` (filtered). Needs the prior box ``x0``. Per step: the
    inner filter's step, three interval Jacobians and up to ``2 nx (1 + passes)`` linear
    programs over ``N + 1`` blocks, warm-started.

    Parameters
    ----------
    sys : NonlinearSystem (discrete time), or a time-invariant LinearSystem (converted)
    x0 : Box, the prior box on ``x[0]``
    window : int >= 1, the steps ``N`` kept (default 20: module docstring)
    passes : int >= 0, re-linearisations of the newest measurement over the box just proven
        (default 1; more stop early when no bound moves by 1 % of its width)
    on_inconsistent : 'warn', 'raise' or 'ignore'
    """

    name = "nl-horizon"
    order = 930
    summary = "nonlinear moving-horizon estimator: window linearised over proven boxes, LP hull"
    reference = "mean-value form [Moore2009, Ch. 6] over a window; [Neumaier2004]; [Rego2020]"
    data_used = "filter"
    supports_nonlinear = True
    needs_x0 = True
    proven_rounding = True  # see "Soundness (proof)" in the module docstring
    design: NonlinearHorizonDesign

    def __init__(
        self,
        sys: Any,
        x0: Box | None = None,
        *,
        window: int | None = None,
        passes: int | None = None,
        **options: Any,
    ) -> None:
        super().__init__(sys, x0, **options)
        model = self.model
        check_size(self.name, model.nx, "solves 2 nx linear programs over the window per pass")
        N = DEFAULT_WINDOW if window is None else as_int("window", window, 1)
        p = DEFAULT_PASSES if passes is None else as_int("passes", passes, 0)
        self.design = NonlinearHorizonDesign(window=N, passes=p)
        self.inner = NonlinearConstrainedZonotopeEstimator(model, self.x0, on_inconsistent="ignore")
        self._wlo, self._whi = model.w_box.lo.copy(), model.w_box.hi.copy()
        self._warm = WarmStarts()
        self._x_scale = _scale_at_prior(model, self.x0)

    # -- state ----------------------------------------------------------------------------
    def _initial_state(self) -> NonlinearHorizonState:
        s = self.model
        nx = s.nx
        return NonlinearHorizonState(
            x_lo=np.zeros((0, nx)), x_hi=np.zeros((0, nx)),
            m_lo=np.zeros((0, nx)), m_hi=np.zeros((0, nx)),
            p_lo=np.zeros((0, nx)), p_hi=np.zeros((0, nx)),
            u=np.zeros((0, s.nu)), y=np.zeros((0, s.ny)), used=np.zeros(0, dtype=bool),
            inner=self.inner.initial_state(),
        )  # fmt: skip

    # -- one step -------------------------------------------------------------------------
    def _step(
        self, state: NonlinearHorizonState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[NonlinearHorizonState]:
        k, sys = state.k, self.model
        inner, box = self.inner.advance(state.inner, u_k, y_k, t_k, finite=False,
                                        keep=not self._branching)  # fmt: skip
        b_lo, b_hi = np.nan_to_num(box.lo, nan=-np.inf), np.nan_to_num(box.hi, nan=np.inf)
        tag = (k, state.inner.k)
        warm = None if self._branching else self._warm.take(state.history, tag)
        if warm is None:
            bases = self._bases(state)
            warm = self._rebuild(state)
            if bases is not None:
                warm.start(bases)
        lp = warm.lp
        wlo, whi = self._wlo, self._whi
        dyn = None
        if k > 0:
            x_prev = (state.x_lo[-1], state.x_hi[-1])
            dyn = dynamics_row(sys, *x_prev, state.u[-1], wlo, whi)
            f_lo, f_hi = sys.f_tight_box(*x_prev, state.u[-1], wlo, whi)
            m = RECORD_MARGIN * (1.0 + np.maximum(np.abs(f_lo), np.abs(f_hi)))
            p_lo, p_hi = down(f_lo - m), up(f_hi + m)
        else:
            assert self.x0 is not None
            p_lo, p_hi = self.x0.lo.copy(), self.x0.hi.copy()
        inconsistent = bool(inner.inconsistent)
        q_lo, q_hi = np.maximum(p_lo, b_lo), np.minimum(p_hi, b_hi)
        if np.any(q_lo > q_hi):  # two proven boxes apart: the data contradict the model
            inconsistent = True
            q_lo, q_hi = np.minimum(p_lo, b_lo), np.maximum(p_hi, b_hi)
        p_lo, p_hi = q_lo, q_hi
        used = not inconsistent
        meas = measurement_row(sys, p_lo, p_hi, u_k, y_k, wlo, whi)
        lp.push(dyn, meas if used else _free(meas), (p_lo, p_hi), (wlo, whi), 0.5 * (p_lo + p_hi))
        if len(lp.n_dyn) > self.design.window + 1:
            lp.pop_front()
        lo, hi, verdict = warm.last_x_box()
        if used and verdict != OK:
            used, inconsistent = False, verdict == INFEASIBLE
            lp.free_last_measurement()
            lo, hi, _ = warm.last_x_box()
        lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
        m_lo, m_hi = p_lo, p_hi
        for _ in range(self.design.passes if used else 0):
            # (M) again over the box just proven (it holds x[k]); its bounds as variable bounds
            m_lo, m_hi = lp.tighten_last_x(*widen(lo, hi))
            lp.replace_last_measurement(measurement_row(sys, m_lo, m_hi, u_k, y_k, wlo, whi))
            lo2, hi2, verdict = warm.last_x_box()
            if verdict != OK:  # (a solver failure: the rows hold at the true state)
                break
            gain = np.max(np.maximum(lo2 - lo, hi - hi2) / np.maximum(hi - lo, ETA))
            lo, hi = np.maximum(lo, lo2), np.minimum(hi, hi2)
            lo, hi = np.minimum(lo, hi), np.maximum(lo, hi)
            if gain < GAIN:
                break
        x_lo, x_hi = lp.tighten_last_x(*widen(lo, hi))
        rows = {"x_lo": x_lo, "x_hi": x_hi, "m_lo": m_lo, "m_hi": m_hi, "p_lo": p_lo,
                "p_hi": p_hi, "u": u_k, "y": y_k}  # fmt: skip
        new = self._remember(state, rows, used, inner)
        if not self._branching:
            self._warm.put(new.history, (k + 1, inner.k), warm)
        return Step(new, lo, hi, inconsistent)

    def _remember(
        self,
        state: NonlinearHorizonState,
        rows: dict[str, np.ndarray],
        used: bool,
        inner: NonlinearConstrainedZonotopeState,
    ) -> NonlinearHorizonState:
        """The state with step ``k``'s rows appended (the oldest beyond ``N`` dropped)."""
        new = appended(state, rows, used, self.design.window)
        empty = np.zeros(0, dtype=np.int8)
        return replace(state, inner=inner, basis_min=empty, basis_max=empty, **new)

    def _rebuild(self, state: NonlinearHorizonState) -> WarmStartedLP:
        """The program of the kept window (empty at step 0), with new HiGHS models."""
        sys = self.model
        lp = TrajectoryLP(sys.nx, sys.nw, sys.ny, self._x_scale)
        lp.relaxed = True  # the rows are ranges of linearisation remainders, not roundings
        warm = WarmStartedLP(lp)
        wlo, whi = self._wlo, self._whi
        for i in range(state.x_lo.shape[0]):
            dyn = None
            if i > 0:
                dyn = dynamics_row(sys, state.x_lo[i - 1], state.x_hi[i - 1], state.u[i - 1],
                                   wlo, whi)  # fmt: skip
            meas = measurement_row(sys, state.m_lo[i], state.m_hi[i], state.u[i], state.y[i],
                                   wlo, whi)  # fmt: skip
            if not state.used[i]:
                meas = _free(meas)
            p_c = 0.5 * (state.p_lo[i] + state.p_hi[i])
            lp.push(dyn, meas, (state.x_lo[i], state.x_hi[i]), (wlo, whi), p_c)
        return warm

    def _bases(self, state: NonlinearHorizonState) -> tuple[Any, Any] | None:
        """The bases the next step of ``state`` starts from: saved with it, or those of its
        warm-started program; None if neither (a cold start)."""
        n_col = min(state.k, self.design.window + 1) * (self.model.nx + self.model.nw)
        return self._warm.start_of(state, (state.k, state.inner.k), n_col)

    # -- persistence ----------------------------------------------------------------------
    def _dump(self, st: Any) -> dict[str, Any]:
        """The window with the bases of its warm-started program, and the inner filter's state
        in its own envelope."""
        out = dump_state(with_saved_bases(st, self._bases))
        out["inner"] = self.inner.save_state(st.inner)
        return out

    def _load(self, saved: Any) -> NonlinearHorizonState:
        if not isinstance(saved, dict) or "inner" not in saved:
            raise IvobsError("state: expected the dict returned by Estimator.state()")
        rest = {key: val for key, val in saved.items() if key != "inner"}
        st = load_state(rest, self.initial_state())
        assert isinstance(st, NonlinearHorizonState)
        inner = self.inner.check_state(saved["inner"])
        m = st.x_lo.shape[0]
        if m > min(st.k, self.design.window) or any(
            getattr(st, key).shape[0] != m for key in ("m_lo", "p_lo", "u", "y", "used")
        ):
            raise IvobsError(
                "state: the kept window does not match the step count and the window; the "
                "state was altered or is not from Estimator.state() of this estimator"
            )
        check_basis_codes(st)
        return replace(st, inner=inner)


def _scale_at_prior(sys: Any, x0: Box | None) -> np.ndarray | None:
    """The state scaling of the window program HiGHS sees
    (:class:`~ivobs.estimators.exact.program.TrajectoryLP`): the balancing of the model's
    Jacobians at the centre of the prior box and of the unknowns' box (None: where they are not
    finite, or cannot be evaluated)."""
    if x0 is None or not (np.isfinite(x0.lo).all() and np.isfinite(x0.hi).all()):
        return None
    c = 0.5 * x0.lo + 0.5 * x0.hi
    w = 0.5 * sys.w_box.lo + 0.5 * sys.w_box.hi
    u = np.zeros(sys.nu)
    try:
        f, h = sys.f_jac_box(c, c, u, w, w), sys.h_jac_box(c, c, u, w, w)
    except IvobsError:
        return None
    A, E, C, F = (0.5 * lo + 0.5 * hi for lo, hi in ((f[0], f[1]), (f[2], f[3]), (h[0], h[1]),
                                                      (h[2], h[3])))  # fmt: skip
    return balancing(A, C, E, F)
