"""The ``dual-window`` estimator: its design, its online state (the window's data, the proven
boxes and the cached multipliers) and its step (refresh the cache now and then, evaluate it
every step). The formulation is in the package docstring (:mod:`ivobs.estimators.dual_window`).
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass, field, replace
from typing import Any, ClassVar

import numpy as np

from ..._validate import as_int
from ...errors import IvobsError
from ...model import LinearSystem
from ...sets import Box
from ...sets.lp import basis_codes
from .. import register
from .._balanced import balanced, unbalanced
from .._uncertain import magnitude as mag
from ..base import Design, Estimator, check_size
from ..state import OnlineState, Step
from .auto import choose_window
from .certificate import Coefficients, Layout, Predictor, coefficients, data_vector, upper_bounds
from .refresh import WindowLP

__all__ = ["DualWindow", "DualWindowDesign", "DualWindowState"]


@dataclass(frozen=True)
class DualWindowDesign(Design):
    """``window``: ``N``, the past steps of the moving window; ``cache``: multipliers kept per
    bound (``2 nx`` bounds); ``refresh``: steps between two solves of the window program once
    the window is full (more often while it fills), the longest interval when it adapts;
    ``window_rule``: ``"auto"`` (chosen from the model, :mod:`.auto`) or ``"given"``;
    ``influence``: for a chosen window, the relative influence ``η(N)`` of its first state on
    the bounds (:mod:`.auto`; None when given); ``refresh_tol``: the adaptive interval's
    tolerance (None: every ``refresh`` steps; see :class:`DualWindow`)."""

    window: int = 20
    cache: int = 16
    refresh: int = 60
    window_rule: str = "given"
    influence: float | None = None
    refresh_tol: float | None = None
    x_scale: np.ndarray | None = None
    """The balanced coordinates ``x = diag(x_scale) x̃`` the method works in (powers of two;
    None: ``x`` itself), :class:`DualWindow`'s "Scaling"."""


@dataclass(frozen=True)
class DualWindowState(OnlineState):
    """The window of the last ``N + 1`` steps (oldest first; the blocks before step 0 are
    empty: the window then starts at step 0).

    ``data`` (N+1, ny+nu+4): each block's ``y``, ``u`` and the four magnitudes of its rounding
    terms (:mod:`.certificate`: ``κ‖y‖ + 2 max τ'``, ``‖u‖``, ``2 max τ``, ``2 ‖x‖``, with
    ``‖x‖`` that of the block's interval prediction); ``y_rad`` (N+1, ny): the radius of the
    box that replaced a missing or dropped measurement component (its centre is in ``data``;
    0: measured); ``x_lo``, ``x_hi`` (N+1, nx): the box proven for each block's state (the
    window's first state is bounded by it). ``mu`` (2 nx, cache, N+1, ny): the cached
    multipliers of each bound (``+x_i`` then ``−x_i``; zeros: the open-loop bound, valid too);
    ``used`` (2 nx, cache): the step at which each gave the best bound (the least recently
    useful one is replaced); ``since``: steps since the last solve; ``basis``: the HiGHS basis
    the next solve starts from (status codes), written when the state is saved (while running
    the estimator holds it; empty and unknown: a cold start); ``period``: the steps between
    solves now (adapted; 0: ``refresh``)."""

    data: np.ndarray
    x_lo: np.ndarray
    x_hi: np.ndarray
    y_rad: np.ndarray
    mu: np.ndarray
    used: np.ndarray
    since: int = 0
    basis: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int8))
    period: int = 0

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("x_lo", "x_hi"),)


REFRESH_TOL = 0.05
"""Default ``refresh_tol``: the cache may lag the window's exact hull by 5 % before the
interval between solves shrinks."""

SOLVE_BUDGET = 20_000
"""Work allowed per step for the adaptive solves, in program columns times programs (a solve is
``2 nx`` programs of ``(N + 1)(nx + nd)`` columns): the interval never drops below the solve's
work over this, so a large system is not solved at every step (CORA's 30-tank system: 60
programs of 5,751 columns, every 18 steps at least; systems up to about 8 states with windows of
tens of steps: every step)."""

MAX_CACHE_VALUES = 2**26
"""Most numbers the multiplier cache ``mu`` (2 nx, cache, window + 1, ny) may hold (512 MiB)."""


@register
class DualWindow(Estimator):
    """The moving-window exact hull, certified each step from a cache of LP multipliers.

    Parameters
    ----------
    sys : LinearSystem (discrete time, time-invariant, constant disturbance bounds)
    x0 : Box, the prior box on ``x[0]`` (required)
    window : ``"auto"`` (default) or an int ``N >= 1``: the past steps whose data the bounds
        use (besides the box proven for ``x[k-N]``). ``"auto"`` chooses the shortest ``N``
        whose first state's relative influence on the window program's optimal bounds is at
        most 1 % (:mod:`ivobs.estimators.dual_window.auto`), between 20 and 200 steps and at
        most what a program of 5,800 columns allows; the choice is ``self.window`` and
        ``self.design.window``
    cache : int >= 1 (default 16): multipliers kept per bound
    refresh : int >= 1 (default 60): the longest interval between two solves of the window
        program (more often while the window fills: every ``k/2`` steps)
    refresh_tol : float > 0 or None (default 0.05): the interval adapts to the data. At each
        solve the cache's bounds from before it are compared with the solve's (the window's
        exact hull): when the cache was more than ``refresh_tol`` wider (relative, on the
        widest state) the interval is halved, down to a floor that bounds the solves' work per
        step (:data:`SOLVE_BUDGET`; every step on small systems); when it was within a quarter
        of it the interval doubles, up to ``refresh``. Disturbances that sit on the vertices of
        their box change the optimal multipliers at nearly every step, and a fixed interval
        then leaves the bounds at those of stale multipliers (1.2-9x the hull on random
        systems); the adaptive interval pays the solves they need. None: every ``refresh``
        steps (the cost fixed in advance)

    Notes
    -----
    Data used for the box of ``x[k]``: ``u``, ``y`` of steps ``k-N..k`` and the box this
    estimator proved for ``x[k-N]`` (``x0`` at the start). Every bound is the certified value
    of a cached multiplier (weak duality, evaluated with its rounding; see the package
    docstring), so it holds whatever the cache holds; it equals the window's exact hull when
    the optimal multiplier is cached. A missing or inconsistent measurement component is
    replaced by the box of what the interval prediction can produce (every cached multiplier
    stays valid; the window's program then has that row free).

    **Scaling.** The certificate bounds its rounding through norms of the data and of the
    states (:mod:`ivobs.estimators.dual_window.certificate`), which would put the rounding of a
    state of magnitude ``1e6`` on a state of magnitude ``1e-3``: the method works in the
    model's balanced coordinates (:mod:`ivobs.estimators._balanced`).
    """

    name = "dual-window"
    order = 105
    summary = "moving-window exact hull from cached, certified LP multipliers (time-invariant)"
    reference = "weak duality of the window program [Neumaier2004]; [Higham2002, §3.1]"
    needs_x0 = True
    proven_rounding = True  # every bound is a certified evaluation: certificate.py

    design: DualWindowDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        window: int | str = "auto",
        cache: int = 16,
        refresh: int = 60,
        refresh_tol: float | None = REFRESH_TOL,
        **options: Any,
    ):
        super().__init__(sys, x0, **options)
        check_size(self.name, sys.nx, "evaluates a cache of 2 nx LP multipliers")
        if not sys.has_constant_bounds:
            raise IvobsError(
                "sys: the dual-window method needs constant disturbance bounds d (an ivobs.Box); "
                "this system's bounds vary with k or y. Use 'exact'"
            )
        cache, refresh = as_int("cache", cache, 1), as_int("refresh", refresh, 1)
        if refresh_tol is not None and (
            isinstance(refresh_tol, bool)
            or not isinstance(refresh_tol, (int, float))
            or not 0.0 < refresh_tol < np.inf
        ):
            raise IvobsError(f"refresh_tol: expected a number > 0 or None, got {refresh_tol!r}")
        mats = tuple(np.asarray(m, dtype=float) for m in sys.matrices_at(0))
        d = sys.d_at(0)
        self.d_lo, self.d_hi = np.asarray(d.lo, dtype=float), np.asarray(d.hi, dtype=float)
        assert self.x0 is not None
        self.mats, self._x0s, scale = balanced(mats, self.x0)
        if isinstance(window, str) and window == "auto":
            N, eta = choose_window(self.mats, self.d_lo, self.d_hi, self._x0s.hi - self._x0s.lo)
            rule, influence = "auto", (eta if np.isfinite(eta) else None)
        else:  # (as_int refuses any other string)
            N, rule, influence = as_int("window", window, 1), "given", None
        tol = None if refresh_tol is None else float(refresh_tol)
        self.design = DualWindowDesign(window=N, cache=cache, refresh=refresh, window_rule=rule,
                                       influence=influence, refresh_tol=tol,
                                       x_scale=scale)  # fmt: skip
        self.window = N
        """The window ``N`` in use (chosen from the model or given)."""
        size = 2 * sys.nx * cache * (N + 1) * sys.ny  # refused before it is allocated
        if size > MAX_CACHE_VALUES:
            raise IvobsError(
                f"cache, window: the multiplier cache holds 2 nx * cache * (window + 1) * ny = "
                f"{size} numbers (cache = {cache}, window = {N}), more than the limit of "
                f"{MAX_CACHE_VALUES}; give a smaller cache or window"
            )
        self.lay = Layout(sys.nx, sys.nu, sys.ny, sys.nd, self.design.window)
        work = 2 * sys.nx * (self.design.window + 1) * (sys.nx + sys.nd)
        self._min_period = min(refresh, max(1, -(-work // SOLVE_BUDGET)))
        """The shortest adaptive interval between solves (:data:`SOLVE_BUDGET`)."""
        nx, K = sys.nx, self.design.cache
        self.c = np.repeat(np.vstack([np.eye(nx), -np.eye(nx)]), K, axis=0)
        self._rows = np.arange(2 * nx)
        self.pred = Predictor(self.mats, self.d_lo, self.d_hi)
        self._lp: WindowLP | None = None
        # the HiGHS basis each state's next solve starts from, by its ``mu`` array (a solve
        # makes a new one): a cache outside the states, written out when a state is saved
        self._bases: dict[int, tuple[weakref.ref[np.ndarray], Any]] = {}
        self._coef: tuple[np.ndarray, Coefficients] | None = None

    def __repr__(self) -> str:
        return (
            f"<{type(self).__name__} {self.name!r} nx={self.sys.nx} window={self.window} "
            f"({self.design.window_rule}) valid_from={self.valid_from}>"
        )

    # -- state ----------------------------------------------------------------------------
    def _initial_state(self) -> DualWindowState:
        lay, K = self.lay, self.design.cache
        n = lay.N + 1
        return DualWindowState(
            data=np.zeros((n, lay.width + 4)),
            y_rad=np.zeros((n, lay.ny)),
            x_lo=np.zeros((n, lay.nx)),
            x_hi=np.zeros((n, lay.nx)),
            mu=np.zeros((2 * lay.nx, K, n, lay.ny)),
            used=np.full((2 * lay.nx, K), -1, dtype=np.int64),
            # an adaptive interval starts at its shortest and grows while the cache keeps up
            period=self._min_period if self.design.refresh_tol is not None else 0,
        )

    def _coefficients(self, mu: np.ndarray) -> Coefficients:
        """The coefficients of the cached multipliers (kept for the last ``mu`` array)."""
        if self._coef is None or self._coef[0] is not mu:
            flat = mu.reshape(-1, self.lay.N + 1, self.lay.ny)
            # a row repeated in the cache is computed once: the initial cache holds ``cache``
            # copies of each bound's zero multiplier
            key = np.concatenate([self.c, flat.reshape(flat.shape[0], -1)], axis=1)
            _, first, copy = np.unique(key, axis=0, return_index=True, return_inverse=True)
            part = coefficients(self.mats, self.d_lo, self.d_hi, self.c[first], flat[first],
                                self.lay)  # fmt: skip
            self._coef = (mu, Coefficients(*(a[copy.ravel()] for a in part)))
        return self._coef[1]

    def save_state(self, st: Any) -> dict[str, Any]:
        """The state with the HiGHS basis its next solve starts from (status codes), so that a
        restored state continues with the same solves."""
        if isinstance(st, DualWindowState) and not st.basis.size:
            basis = self._basis_of(st.mu)
            if basis is not None and basis.valid:
                st = replace(st, basis=basis_codes(basis))
        return super().save_state(st)

    def _basis_of(self, mu: np.ndarray) -> Any:
        """The basis kept for the states holding ``mu`` (None if there is none)."""
        entry = self._bases.get(id(mu))
        return entry[1] if entry is not None and entry[0]() is mu else None

    def _keep_basis(self, mu: np.ndarray, basis: Any) -> None:
        """Keep ``basis`` for the states holding ``mu``, as long as ``mu`` lives."""
        key, bases = id(mu), self._bases

        def forget(ref: weakref.ref[np.ndarray]) -> None:
            if key in bases and bases[key][0] is ref:
                del bases[key]

        bases[key] = (weakref.ref(mu, forget), basis)

    # -- one step -------------------------------------------------------------------------
    def _step(
        self, state: DualWindowState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[DualWindowState]:
        k, lay = state.k, self.lay
        # each ring moved one row up (new arrays; the last row is the old first one)
        data, x_lo, x_hi, y_rad = (
            np.roll(a, -1, axis=0) for a in (state.data, state.x_lo, state.x_hi, state.y_rad)
        )
        W = lay.width
        if k == 0:
            p_lo, p_hi = self._x0s.lo.copy(), self._x0s.hi.copy()
        else:
            # the previous block: its dynamics row's range τ (its box is within its prediction)
            p_lo, p_hi, data[-2, W + 2] = self.pred.predict(
                state.x_lo[-1], state.x_hi[-1], state.data[-1, lay.ny : W],
                0.5 * data[-2, W + 3], state.data[-1, W + 1],
            )  # fmt: skip
        u_mag, p_mag = float(np.abs(u_k).max(initial=0.0)), float(mag(p_lo, p_hi).max(initial=0.0))
        y_rad[-1] = 0.0
        missing = inconsistent = False
        if not np.isfinite(y_k.sum()):  # missing (NaN) or absurd (inf) components: replaced
            missing, inconsistent = bool(np.isnan(y_k).any()), bool(np.isinf(y_k).any())
            y_k = self._replace(y_k, ~np.isfinite(y_k), y_rad, p_lo, p_hi, u_k, p_mag, u_mag)
        self._set_row(data, y_k, u_k, u_mag, p_mag)
        s = max(lay.N - k, 0)
        prior = (x_lo[s], x_hi[s]) if s < lay.N else (p_lo, p_hi)
        mu, used, since, basis = state.mu, state.used, state.since + 1, state.basis
        period = state.period or self.design.refresh
        due = since >= (period if s == 0 else min(period, (k + 1) // 2))
        adapt = due and self.design.refresh_tol is not None and not self._branching
        if adapt:  # what the cache gave without this solve (``refresh_tol`` in the class docstring)
            before = self._evaluate(mu, used, data, y_rad, s, prior, k, p_lo, p_hi)[:2]
        if due and not self._branching:  # a look-ahead (predict) uses the cache as it is
            mu, used, basis = self._refresh(state, data, y_rad, s, prior, (p_lo, p_hi), x_lo, x_hi)
            since = 0
        lo, hi, used = self._evaluate(mu, used, data, y_rad, s, prior, k, p_lo, p_hi)
        if adapt:
            period = self._adapt(period, before[1] - before[0], hi - lo)
        if (hi - lo).min() < 0.0:  # both bounds proven: no state is consistent with y_k
            inconsistent = True
            y_k = self._replace(y_k, np.ones(lay.ny, bool), y_rad, p_lo, p_hi, u_k, p_mag, u_mag)
            self._set_row(data, y_k, u_k, u_mag, p_mag)
            lo, hi, used = self._evaluate(mu, used, data, y_rad, s, prior, k, p_lo, p_hi)
        x_lo[-1], x_hi[-1] = lo, hi
        new = DualWindowState(data=data, y_rad=y_rad, x_lo=x_lo, x_hi=x_hi, mu=mu, used=used,
                              since=since, basis=basis, period=period)  # fmt: skip
        lo, hi = unbalanced(lo, hi, self.design.x_scale)  # x = S x̃ (class docstring, "Scaling")
        return Step(new, lo, hi, inconsistent and not missing)

    def _adapt(self, period: int, stale: np.ndarray, fresh: np.ndarray) -> int:
        """The next interval between solves from how much wider the cache's box was than the
        solve's (``stale``, ``fresh``: their widths): halved above ``refresh_tol``, doubled
        below a quarter of it (between the floor of :data:`SOLVE_BUDGET` and ``refresh``)."""
        tol = self.design.refresh_tol
        assert tol is not None
        with np.errstate(divide="ignore", invalid="ignore"):
            gap = np.where(fresh > 0.0, stale / fresh - 1.0, 0.0)
        worst = float(np.nan_to_num(gap, nan=np.inf).max(initial=0.0))
        if worst > tol:
            return max(self._min_period, period // 2)
        if worst < 0.25 * tol:
            return min(self.design.refresh, 2 * period)
        return period

    def _replace(
        self,
        y_k: np.ndarray,
        which: np.ndarray,
        y_rad: np.ndarray,
        p_lo: np.ndarray,
        p_hi: np.ndarray,
        u_k: np.ndarray,
        p_mag: float,
        u_mag: float,
    ) -> np.ndarray:
        """``y_k`` with the components ``which`` replaced by the centre of what the predicted
        box can produce, their radius in the last row of ``y_rad``."""
        mid, rad = self.pred.y_range(p_lo, p_hi, u_k, p_mag, u_mag)
        y_rad[-1] = np.where(which, rad, 0.0)
        return np.where(which, mid, y_k)

    def _set_row(
        self, data: np.ndarray, y_k: np.ndarray, u_k: np.ndarray, u_mag: float, p_mag: float
    ) -> None:
        """The newest row of ``data``: ``y``, ``u`` and the magnitudes of its rounding terms."""
        lay, W = self.lay, self.lay.width
        y_mag = float(np.abs(y_k).max(initial=0.0))
        data[-1, : lay.ny] = y_k
        data[-1, lay.ny : W] = u_k
        data[-1, W:] = (lay.kappa * y_mag + self.pred.tau_y(p_mag, u_mag, y_mag), u_mag, 0.0,
                        2.0 * p_mag)  # fmt: skip

    def _evaluate(
        self,
        mu: np.ndarray,
        used: np.ndarray,
        data: np.ndarray,
        y_rad: np.ndarray,
        s: int,
        prior: tuple[np.ndarray, np.ndarray],
        k: int,
        p_lo: np.ndarray,
        p_hi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The box of ``x[k]``: the best certified bound of the cache, met with the interval
        prediction; and the cache's use record updated."""
        lay, rows = self.lay, self._rows
        coef = self._coefficients(mu)
        ub = upper_bounds(coef, data_vector(data, s, *prior, lay.width), s, lay)
        if y_rad.any():  # replaced measurements: + |μ|^T rad, rounded up
            my = np.abs(coef.main.reshape(-1, lay.N + 1, lay.width)[:, :, : lay.ny])
            extra = my.reshape(my.shape[0], -1) @ y_rad.ravel()
            ub = np.nextafter(ub + extra * (1.0 + 2.0 * lay.kappa), np.inf)
        ub = ub.reshape(2 * lay.nx, -1)
        best = ub.argmin(axis=1)
        val = ub[rows, best]
        used = used.copy()
        used[rows, best] = k
        return np.maximum(p_lo, -val[lay.nx :]), np.minimum(p_hi, val[: lay.nx]), used

    def _refresh(
        self,
        state: DualWindowState,
        data: np.ndarray,
        y_rad: np.ndarray,
        s: int,
        prior: tuple[np.ndarray, np.ndarray],
        pred: tuple[np.ndarray, np.ndarray],
        x_lo: np.ndarray,
        x_hi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Solve the window program and put its multipliers in the cache (each replacing the
        least recently useful one, unless already there)."""
        lay = self.lay
        if self._lp is None:
            self._lp = WindowLP(self.mats, self.d_lo, self.d_hi, lay)
        centres = 0.5 * (x_lo + x_hi)
        centres[-1] = 0.5 * (pred[0] + pred[1])
        y, u = data[:, : lay.ny], data[:, lay.ny : lay.width]
        start = self._basis_of(state.mu)  # the basis this state's last solve ended on
        if start is None and state.basis.size:
            start = self._lp.basis_of(state.basis)  # saved with a restored state
        new, ok, basis = self._lp.solve(y, u, y_rad > 0.0, s, prior, centres, start)
        mu, used = state.mu.copy(), state.used.copy()
        self._keep_basis(mu, basis)
        changed = []
        for r in np.flatnonzero(ok):
            scale = max(1.0, float(np.abs(new[r]).max()))
            same = np.abs(mu[r] - new[r]).reshape(mu.shape[1], -1).max(axis=1) <= 1e-9 * scale
            slot = int(np.argmax(same)) if same.any() else int(np.argmin(used[r]))
            used[r, slot] = state.k
            if not same.any():
                mu[r, slot] = new[r]
                changed.append(r * mu.shape[1] + slot)
        self._update_coefficients(state.mu, mu, changed)
        return mu, used, _NO_BASIS

    def _update_coefficients(self, old: np.ndarray, mu: np.ndarray, rows: list[int]) -> None:
        """The coefficients of ``mu`` from those of ``old`` (if kept) with ``rows`` redone, in
        place: only the newest ``mu``'s are kept, so those of ``old`` are not looked up again
        (a state that still holds ``old`` has them recomputed)."""
        if self._coef is None or self._coef[0] is not old:
            self._coef = None
            return
        lay, coef = self.lay, self._coef[1]
        if rows:
            flat = mu.reshape(-1, lay.N + 1, lay.ny)[rows]
            part = coefficients(self.mats, self.d_lo, self.d_hi, self.c[rows], flat, lay)
            for whole, new in zip(coef, part, strict=True):
                whole[rows] = new
        self._coef = (mu, coef)


_NO_BASIS = np.zeros(0, dtype=np.int8)
