"""Guaranteed discretisation of a continuous-time :class:`~ivobs.NonlinearSystem`: the
validated flow over one sampling period as a discrete-time model (docs/continuous.md,
docs/nonlinear.md "Continuous-time plants").

``x' = f(x, u, p, d)`` sampled every ``Ts``; ``u`` is held constant over each period
(zero-order hold) and so are the unknown parameters ``p`` (constants). The signals ``d`` vary
in their box at every instant (``disturbances="varying"``, the default: see "Signals that
vary" below) or are held (``"held"``: any value of their box, one per period, the discrete
model's ``w[k]``). With held signals

    x[k+1] = Φ_Ts(x[k], u[k], w[k])

and :class:`FlowSystem` encloses ``Φ_Ts`` over boxes with the interval Taylor method of order
``k`` ([Lohner1987], [Nedialkov1999]), ``n`` substeps of ``h = Ts / n``:

1. **a priori enclosure** ``B`` with ``[x0] + [0, h] f(B, u, [w]) ⊆ B``: then the solution from
   every ``x0 ∈ [x0]`` exists on ``[0, h]`` and stays in ``B`` (Picard–Lindelöf; the Picard
   operator maps the continuous functions into ``B`` to themselves, Schauder's fixed point and
   uniqueness for a locally Lipschitz ``f``). Found by inflating ``[x0] + [0, h] f([x0])`` and
   retrying; when it fails the substep is halved (up to :data:`MAX_HALVINGS` times), then an
   :class:`~ivobs.IvobsError` says so (the solution may blow up within the period);
2. **the Taylor step** (:mod:`.taylor`): natural ∩ mean-value enclosure of the polynomial, plus
   the remainder ``h^k f^[k](B)``, intersected with ``B``.

Every operation is rounded outward (the generated code of :mod:`.codegen`; the a priori tests
below with ``nextafter``); ``h`` is the interval enclosing ``Ts / n``, halved exactly.

The Jacobian of ``Φ`` (for ``nl-zonotope`` and ``nl-constrained-zonotope``) comes from the
variational equation with the same method (:mod:`.taylor`), its a priori enclosure
``M_B ⊇ [I 0] + [0, h] ∂f/∂z(B, [w]) M_B`` found likewise, and the substeps chained by interval
matrix products.

**Signals that vary** (a differential inclusion ``x' ∈ f(x, u, p, [d])``, [Kapela2009]). Let
``x̃`` be the solution with the signals held at the centre ``c`` of their box, ``x`` one with
any measurable ``d(t)`` in the box, from the same ``x0``; ``y = x − x̃``. Over a substep both
stay in the a priori box ``B`` of the inclusion (step 1 with ``[d]`` for the signals, from
``[x0] ± z``: the Picard argument holds for every ``d(t)`` in the box), and

    y' = J_c y + (J(t) − J_c) y + G(t) (d − c),   J(t) ∈ [J] = ∂f/∂x(B),  |G(t) (d − c)| <= δ

(mean-value theorem on segments of ``B`` and of the box; ``J_c = mid [J]``,
``|[J] − J_c| <= R``, ``δ = |∂f/∂d|(B) r``, ``r`` the radii). Variation of constants gives,
for ``t`` in the substep, ``|y(t)| <= P z + I (R Y + δ)`` with ``z >= |y(0)|``,
``P >= |e^{J_c s}|`` over ``[0, h]``, ``I >= ∫_0^h |e^{J_c s}| ds`` (validated exponentials of
:mod:`ivobs.sets.expm`, on :data:`SPREAD_PIECES` pieces) and ``Y >= sup |y|``: any ``Y > 0``
with ``P z + I (R Y + δ) <= Y`` and ``I R Y < Y`` is such a bound (then ``ρ(I R) < 1`` and the
least solution of ``W <= a + I R W`` is below ``Y``). At the end of the substep
``|y(h)| <= |e^{J_c h}| z + I (R Y + δ)``, rounded up. ``J_c`` carries the rotation of the
dynamics, so the bound does not grow like a componentwise (Metzler) comparison system would on
an oscillator; where they do not, that system (``z' = M z + δ``, ``M`` the Metzler bound of
``[J]``) can be tighter, and the smaller of the two bounds is kept. So
``x(Ts) ∈ Φ_c(x0) ± z``: the flow's box is that of ``Φ_c`` widened by ``z``, and the mean-value
methods linearise ``Φ_c`` and add ``z`` as a spread
(:mod:`ivobs.estimators.nonlinear.meanvalue`). For a non-smooth ``f`` the bound is the a priori
box itself (first order). Only the signals that ``f`` reads vary; those in ``h`` alone
are the sensor's noise at the sampling instant.

**The mean form** (used when ``f`` is smooth and ``h`` reads none of the varying signals).
Hold the signals at their *mean over the period* ``d̄ = (1/Ts) ∫ d ∈ [d]`` instead of the centre:
``x̄`` is then the held flow with ``w``'s signal column equal to ``d̄`` — the discrete model's
``w[k]`` keeps its Jacobian, so the set methods keep the correlation a held ``d`` has — and
``y = x − x̄`` obeys ``y' = J_c y + (J − J_c) y + G_c (d − d̄) + (G − G_c)(d − d̄)`` with ``[J]``,
``[G] = ∂f/∂(x, d)`` over an a priori box ``B`` of the inclusion over the whole period
(:meth:`FlowSystem._period_apriori`), ``|G − G_c| <= R_G``, ``|d − d̄| <= 2 r``. Since
``∫_0^Ts (d − d̄) = 0``, for any matrix ``M̄``,
``∫ e^{J_c σ} G_c (d − d̄) = ∫ (e^{J_c σ} − M̄) G_c δ + (M̄ Ts − ∫ e^{J_c σ}) G_c δ̄`` with
``δ = d − c``, ``δ̄ = d̄ − c`` (``|δ|, |δ̄| <= r``): with ``M̄`` the average of the pieces'
enclosures of ``e^{J_c σ}`` both terms are second order in ``Ts``. With
``Y >= sup |y|`` found as above (``a = ∫|e^{J_c σ} G_c| 2r + I R_G 2r``),
``|y(Ts)| <= (∫|(e^{J_c σ} − M̄) G_c| + Σ |J| rad) r + I (R Y + R_G 2r)``.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Any

import numpy as np

from ...errors import DivergenceError, IvobsError
from ._runtime import DomainError
from ._runtime import dn as _dn
from ._runtime import up as _up
from .codegen import _enclose_fraction
from .flowback import FlowBackContractor
from .forms import Forms
from .system import NonlinearSystem
from .taylor import MAX_ORDER, TaylorCode

__all__ = ["MAX_HALVINGS", "FlowSystem"]

Pair = tuple[np.ndarray, np.ndarray] | None

MAX_HALVINGS = 10
"""Halvings of a substep whose a priori enclosure fails before giving up."""
TRIES = 8
"""Inflate-and-retry rounds of one a priori enclosure."""
INFLATE_REL, INFLATE_ABS = 0.1, 1e-9
SPREAD_PIECES = 8
"""Pieces of a substep over which the magnitude of ``e^{J_c s}`` is integrated (the spread)."""
MEAN_PIECES = 16
"""Pieces of the period over which ``e^{J_c s}`` is integrated (the mean form's spread)."""

Vec = list[float]


_ND, _NU = np.float64(-np.inf), np.float64(np.inf)


def _count(what: str, v: Any, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
        raise IvobsError(f"{what}: expected an integer in [{lo}, {hi}], got {v!r}")
    return int(v)


class FlowSystem(NonlinearSystem):
    """The discrete-time model ``x[k+1] = Φ_Ts(x[k], u[k], w[k])`` of a continuous-time
    :class:`~ivobs.NonlinearSystem` (module docstring); made by
    :meth:`NonlinearSystem.discretize`. ``h`` and its members are those of the continuous
    system; ``f_box``, ``f_tight_box`` and ``f_jac_box`` enclose the flow and its Jacobian;
    ``f_exprs`` stay the vector field. ``hf_contractors()`` step back through the flow
    (:mod:`.flowback`)."""

    def __init__(
        self,
        continuous: NonlinearSystem,
        Ts: Any,
        order: Any = 4,
        substeps: Any = 1,
        disturbances: Any = "varying",
    ):
        if not continuous.is_continuous:
            raise IvobsError("discretize: the system is already discrete-time")
        if isinstance(Ts, bool) or not isinstance(Ts, (int, float)) or not 0 < Ts < math.inf:
            raise IvobsError(f"Ts: expected a sampling period > 0, got {Ts!r}")
        self.__dict__.update(continuous.__dict__)
        self.continuous = continuous
        self.dt = float(Ts)
        self.order = _count("order", order, 1, MAX_ORDER)
        self.substeps = _count("substeps", substeps, 1, 1 << 16)
        if disturbances not in ("varying", "held"):
            raise IvobsError(
                f"disturbances: expected 'varying' (any signal in its box between samples) "
                f"or 'held' (constant over each period), got {disturbances!r}"
            )
        self.disturbances = disturbances
        self.smooth: bool = _check_smooth(self.f_exprs, self.order)
        self._taylor = TaylorCode(self.f_exprs, self._groups(), self._consts, self.order)
        # the signals d that f reads: only they vary between samples (module docstring)
        np_ = len(self.param_names)
        used = set().union(*(e.free_symbols for e in self.f_exprs)) if self.f_exprs else set()
        self._varying = [
            np_ + j
            for j, n in enumerate(self.signal_names)
            if disturbances == "varying" and self._sym[n] in used
        ]
        # the mean form (module docstring): d's column in w is its mean over the period, which
        # h must not read (h sees d at the sampling instant, another value)
        in_h = set().union(*(e.free_symbols for e in self.h_exprs)) if self.h_exprs else set()
        self._mean = (
            bool(self._varying)
            and self.smooth
            and not any(self._sym[self.signal_names[j - np_]] in in_h for j in self._varying)
        )
        # no symbolic h∘Φ: one step back through the flow's mean-value form, per output (it
        # needs the flow's Jacobian: a non-smooth f has none here, its contractors do nothing)
        self._hf = [
            (FlowBackContractor(self, i) if self.smooth else _no_contraction, [])
            for i in range(self.ny)
        ]
        self._spread_cache: list[tuple[tuple[float, ...], list[float]]] = []
        self._collect: list[tuple[Vec, Vec]] | None = None  # a priori boxes (period_box)
        self._h_step = _enclose_fraction(Fraction(self.dt) / self.substeps)
        self._back_cache: Any = None  # the step back's last linearisation (.flowback)
        # the Forms of f are the flow's, so the nonlinear methods call it as a discrete map (no
        # sites: domain errors become IvobsError inside)
        self._f = Forms(
            self._enclose,
            self._enclose,
            self._enclose_jacobian,
            self._enclose_natjac,
            [],
            self._taylor.source,
        )

    def f_contractor(self) -> tuple[Any, list[str]]:
        """Refused: ``f_exprs`` is the vector field, not the map of a step (the flow steps back
        one step only, through :meth:`hf_contractors`)."""
        raise IvobsError(
            "lag: a sampled continuous-time plant steps back through its flow one step only "
            "(lag 0 or 1)"
        )

    # -- the flow over a box ------------------------------------------------------------------
    def _enclose(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Vec, Vec]:
        """``(lo, hi)`` lists enclosing ``Φ_Ts(x, u, w)`` for every ``x ∈ [xl, xh]``,
        ``w ∈ [wl, wh]`` (every signal path in its box, when the signals vary)."""
        lo, hi, _, z = self._run(xl, xh, u, wl, wh, False, True)
        return _widen(lo, hi, z)

    def _enclose_jacobian(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Any, Any]:
        """``∂Φ_Ts/∂(x, w)`` enclosed over the box, flattened ``(nx, nx + nw)`` (of the flow
        with the varying signals at their centre, when they vary: module docstring)."""
        if not self.smooth:
            raise IvobsError(
                "sys: the Jacobian of a validated flow needs a smooth f (this one uses abs, min "
                "or max), so nl-zonotope and nl-constrained-zonotope cannot take it; use "
                "nl-interval"
            )
        _, _, A, _ = self._run(xl, xh, u, wl, wh, True, False)
        assert A is not None
        return A[0][: self.nx].ravel(), A[1][: self.nx].ravel()

    def _enclose_natjac(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Any, ...]:
        """The flow's box and its Jacobian over the same box in one pass (the ``natjac`` form
        of :class:`.forms.Forms` that the set methods call): ``(lo, hi, jac_lo, jac_hi)``,
        lists, the Jacobian row-major over ``(x, w)``."""
        if not self.smooth:
            self._enclose_jacobian(xl, xh, u, wl, wh)  # the refusal, with its message
        lo, hi, A, z = self._run(xl, xh, u, wl, wh, True, True)
        assert A is not None
        lo, hi = _widen(lo, hi, z)  # the box of the set-valued flow, as _enclose gives it
        return lo, hi, A[0][: self.nx].ravel().tolist(), A[1][: self.nx].ravel().tolist()

    def period_box(self, xl: Any, xh: Any, u: Any, wl: Any, wh: Any) -> tuple[Vec, Vec]:
        """``(lo, hi)`` containing ``x(t)`` for every ``t`` in the period, from every ``x(0)``
        in ``[xl, xh]`` (and every signal path, when they vary): the hull of the substeps' a
        priori enclosures (step 1 of the module docstring; halved substeps included)."""
        self._collect = []
        try:
            self._run(xl, xh, u, wl, wh, False, True)
            boxes = self._collect
        finally:
            self._collect = None
        if not boxes:  # an unbounded start: the whole space
            return [-math.inf] * self.nx, [math.inf] * self.nx
        lo = [min(b[0][i] for b in boxes) for i in range(self.nx)]
        hi = [max(b[1][i] for b in boxes) for i in range(self.nx)]
        return lo, hi

    def evaluators(self, which: str) -> tuple[Any, ...]:
        """As :meth:`NonlinearSystem.evaluators`; for ``f`` with varying signals a third
        member, the spread: ``(value, natjac, spread)`` enclose the flow ``Φ_c`` with the
        signals held at their centre and its Jacobian, and ``Φ_Ts(x, u, w) ⊆ Φ_c(x, u, w) ±
        spread(B)`` for every ``x`` of the box ``B`` (module docstring)."""
        if which != "f" or not self._varying:
            return super().evaluators(which)
        return self._held_value, self._held_natjac, self._spread_of

    def _held_value(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Vec, Vec]:
        lo, hi, _, _ = self._run(xl, xh, u, wl, wh, False, False)
        return lo, hi

    def _held_natjac(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Any, ...]:
        lo, hi, A, _ = self._run(xl, xh, u, wl, wh, True, True)
        assert A is not None
        return lo, hi, A[0][: self.nx].ravel().tolist(), A[1][: self.nx].ravel().tolist()

    def _spread_of(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> list[float]:
        """The spread over the box (the last boxes' are cached: the forward step, the
        linearisation and the step back of one estimator step ask for the same box)."""
        key = _key(xl, xh, u, wl, wh)
        for k, z in self._spread_cache:
            if k == key:
                return z
        return self._run(xl, xh, u, wl, wh, False, True)[3] or []

    def _run(
        self, xl: Any, xh: Any, u: Any, wl: Any, wh: Any, jac: bool, spread: bool = True
    ) -> tuple[Vec, Vec, Pair, Vec | None]:
        """The substeps from ``[xl, xh]``: the box at ``Ts``, (``jac``) the augmented
        Jacobian ``∂(x, w)(Ts)/∂(x0, w)`` ``(lo, hi)`` or None, and the spread of the varying
        signals (None when none vary, or when not asked for in the mean form)."""
        xl, xh = [float(v) for v in xl], [float(v) for v in xh]
        wl, wh, u = [float(v) for v in wl], [float(v) for v in wh], [float(v) for v in u]
        nz = self.nx + self.nw
        A: Pair = (np.eye(nz), np.eye(nz)) if jac else None
        if not all(map(math.isfinite, xl + xh + wl + wh)):  # the whole space (sound)
            full = np.full((nz, nz), np.inf)
            inf = [math.inf] * self.nx
            return [-math.inf] * self.nx, inf, (-full, full) if jac else None, None
        x0l, x0h, w0l, w0h = xl, xh, wl, wh
        if self._mean:  # the flow held at the period's mean of d, plus its spread
            for _ in range(self.substeps):
                xl, xh, A, _ = self._advance(xl, xh, u, wl, wh, self._h_step, A, 0)
            self._check_finite(x0l, x0h, xl, xh)
            if not spread:
                return xl, xh, A, None
            spread_ = self._mean_spread(x0l, x0h, u, w0l, w0h)
            self._spread_cache = [(_key(x0l, x0h, u, w0l, w0h), spread_), *self._spread_cache[:3]]
            return xl, xh, A, spread_
        vary = self._inclusion(wl, wh) if self._varying else None
        z: Vec | None = None
        if vary is not None:
            wl, wh, z = vary[2], vary[2], [0.0] * self.nx  # the flow held at the centre
        for _ in range(self.substeps):
            xl, xh, A, z = self._advance(xl, xh, u, wl, wh, self._h_step, A, 0, z, vary)
        self._check_finite(x0l, x0h, xl, xh)
        if A is not None and vary is not None:  # Φ_c does not read the varying signals
            cols = [self.nx + j for j in self._varying]
            A[0][:, cols], A[1][:, cols] = 0.0, 0.0
        if z is not None:
            self._spread_cache = [(_key(x0l, x0h, u, w0l, w0h), z), *self._spread_cache[:3]]
        return xl, xh, A, z

    def _check_finite(self, xl: Vec, xh: Vec, lo: Vec, hi: Vec) -> None:
        """A finite box whose flow overflowed: the solution escapes within the period, or the
        box is too wide for it (:class:`~ivobs.DivergenceError`)."""
        if not all(map(math.isfinite, lo + hi)):
            raise DivergenceError(
                f"discretize: the enclosure of the flow over Ts = {self.dt:g} ({self.substeps} "
                f"substep(s)) from x in [{xl}, {xh}] overflowed: the solution may escape within "
                "the period, or the box has grown too wide for it; more substeps, a smaller Ts, "
                "or a method that keeps the box narrower"
            )

    def _inclusion(self, wl: Vec, wh: Vec) -> tuple[Vec, Vec, Vec, Vec]:
        """``(wl, wh)`` with the varying signals over their whole box (the differential
        inclusion), ``w`` with them at their centre ``c``, and their radii ``r`` around it."""
        box = self.w_box
        fl, fh, wc, r = list(wl), list(wh), list(wl), [0.0] * len(wl)
        for j in self._varying:
            lo, hi = float(box.lo[j]), float(box.hi[j])
            c = 0.5 * lo + 0.5 * hi
            fl[j], fh[j], wc[j] = lo, hi, c
            r[j] = _up(max(hi - c, c - lo))
        return fl, fh, wc, r

    def _advance(
        self,
        xl: Vec,
        xh: Vec,
        u: Vec,
        wl: Vec,
        wh: Vec,
        h: tuple[float, float],
        A: Pair,
        depth: int,
        z: Vec | None = None,
        vary: tuple[Vec, Vec, Vec, Vec] | None = None,
    ) -> tuple[Vec, Vec, Pair, Vec | None]:
        """One substep of length in ``h = (hl, hh)``, halved while an a priori enclosure
        fails; ``A``: the augmented Jacobian so far (or None); ``z``: the spread so far of the
        varying signals ``vary`` (:meth:`_inclusion`), or None."""
        B = self._apriori(xl, xh, u, wl, wh, h[1])
        M = None if B is None or A is None else self._apriori_jac(B[0], B[1], u, wl, wh, h[1])
        Z = None
        if B is not None and (A is None or M is not None) and vary is not None:
            assert z is not None
            Z = self._spread(xl, xh, z, u, vary, h)
        if B is None or (A is not None and M is None) or (vary is not None and Z is None):
            if depth >= MAX_HALVINGS or h[0] * 0.5 == 0.0:
                what = "the flow" if B is None else "the flow's Jacobian"
                raise DivergenceError(
                    f"discretize: no a priori enclosure of {what} over {h[1]:.6g} (a substep "
                    f"Ts / substeps = {self.dt:g} / {self.substeps}, halved {depth} times) from "
                    f"x in [{xl}, {xh}]: the solution may leave every bounded set within the "
                    "period (finite escape), f is unbounded near the box, or the box has grown "
                    "too wide for the period; more substeps, a smaller Ts, or a method that "
                    "keeps the box narrower"
                )
            half = (h[0] * 0.5, h[1] * 0.5)  # exact: a power of two
            xl, xh, A, z = self._advance(xl, xh, u, wl, wh, half, A, depth + 1, z, vary)
            return self._advance(xl, xh, u, wl, wh, half, A, depth + 1, z, vary)
        assert B is not None
        if self._collect is not None and not self._varying:
            self._collect.append(B)  # x(t) over the substep (held signals)
        args = (xl, xh, u, wl, wh, B[0], B[1], h[0], h[1])
        if A is not None:
            assert M is not None
            A = _imatmul(*self._substep_jac(args, M), *A)
        lo, hi = self._generated(self._taylor.step, args)
        return lo, hi, A, Z

    def _spread(
        self, xl: Vec, xh: Vec, z: Vec, u: Vec, vary: tuple[Vec, Vec, Vec, Vec], h: Any
    ) -> Vec | None:
        """The spread after one substep (module docstring, "Signals that vary"); None when the
        a priori box of the inclusion or the bound ``Y`` is not found (the substep is
        halved)."""
        from ...sets.expm import expm, expm_integral, interval_product, scaled
        from ...sets.rounding import up, upper

        nx = self.nx
        fl, fh, _, r = vary
        B = self._apriori(*_widen(xl, xh, z), u, fl, fh, h[1])
        if B is None:
            return None
        if self._collect is not None:
            self._collect.append(B)  # x(t) over the substep, whatever d(t) does
        if not self.smooth:  # first order: x(h) ∈ B, x̃(h) ∈ [xl, xh] ⊆ B
            return [_up(b - a) for a, b in zip(B[0], B[1])]
        Jl, Jh = self._jacobian(B, u, fl, fh)
        if not (np.all(np.isfinite(Jl)) and np.all(np.isfinite(Jh))):
            return None
        Jc, R = _mid_rad(Jl[:, :nx], Jh[:, :nx])  # |[J] − J_c| <= R
        cols = [nx + j for j in self._varying]
        mag = np.maximum(np.abs(Jl[:, cols]), np.abs(Jh[:, cols]))
        delta = upper(mag @ np.array([r[j] for j in self._varying]), len(cols) + 1)
        # e^{J_c s} over the substep: at its end, its largest magnitude over [0, h], and the
        # integral of its magnitude (pieces of h / SPREAD_PIECES, exact: a power of two)
        hh = float(h[1])
        E1, RE1 = expm(*scaled(Jc, (float(h[0]), hh)))
        step = hh / SPREAD_PIECES
        Ps, RPs = expm(*scaled(Jc, step))
        Q, RQ = expm(*scaled(Jc, (0.0, step)))
        peak = np.zeros((nx, nx))
        integral = np.zeros((nx, nx))
        for _ in range(SPREAD_PIECES):
            mag_q = up(np.abs(Q) + RQ)
            peak = np.maximum(peak, mag_q)
            integral = up(integral + mag_q)
            Q, RQ = interval_product(Ps, RPs, Q, RQ)
        integral = up(upper(integral, SPREAD_PIECES) * step)
        zz = np.array(z)
        a = upper(peak @ zz + integral @ delta, 2 * nx + 2)
        Y = _sup_bound(a, upper(integral @ R, nx + 1))  # sup |y| over the substep
        if Y is None:
            return None
        out = upper(up(np.abs(E1) + RE1) @ zz + integral @ up(R @ Y + delta), 2 * nx + 3)
        # the componentwise comparison system z' = M z + δ (M: the Metzler bound of [J]) bounds
        # |y| too [Kapela2009]; it is the tighter one where the dynamics do not rotate
        M = np.maximum(np.abs(Jl[:, :nx]), np.abs(Jh[:, :nx]))
        M[np.diag_indices(nx)] = np.diag(Jh[:, :nx])
        (EM, REM), (GM, RGM) = expm_integral(M, delta[:, None], (float(h[0]), hh))
        metzler = upper(up(EM + REM) @ zz + up(GM[:, 0] + RGM[:, 0]), nx + 2)
        out = np.minimum(out, metzler)
        if not np.all(np.isfinite(out)):
            return None
        return [float(v) for v in out]

    def _jacobian(self, B: tuple[Vec, Vec], u: Vec, wl: Vec, wh: Vec) -> tuple[Any, Any]:
        """The Jacobian of the vector field over ``B × [wl, wh]``: ``(lo, hi)``, each
        ``(nx, nx + nw)``."""
        f, nx = self.continuous._f, self.nx
        jl, jh = self.continuous._call(f.jacobian, f.sites, B[0], B[1], u, wl, wh)
        return _arr(jl, nx, nx + self.nw), _arr(jh, nx, nx + self.nw)

    def _mean_spread(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> Vec:
        """The spread of the mean form over the whole period (module docstring, "The mean
        form"): ``|x(Ts) − x̄(Ts)|`` for ``x̄`` held at the mean ``d̄`` of ``d`` over the
        period."""
        from ...sets.expm import expm, interval_product, scaled
        from ...sets.rounding import up, upper

        nx = self.nx
        fl, fh, _, r = self._inclusion(wl, wh)
        B = self._period_apriori(xl, xh, u, fl, fh)
        Jl, Jh = self._jacobian(B, u, fl, fh)
        if not (np.all(np.isfinite(Jl)) and np.all(np.isfinite(Jh))):
            raise IvobsError(
                "discretize: the Jacobian of f is not bounded over the period's enclosure "
                f"[{B[0]}, {B[1]}]; use a smaller Ts"
            )
        Jc, R = _mid_rad(Jl[:, :nx], Jh[:, :nx])
        cols = [nx + j for j in self._varying]
        Gc, RG = _mid_rad(Jl[:, cols], Jh[:, cols])
        r2 = np.array([up(2.0 * r[j]) for j in self._varying])  # >= |d(s) − d̄|
        Ts = float(self._h_step[1]) * self.substeps  # >= the period (h rounded up, times n)
        Ts = float(up(Ts))
        step = Ts / MEAN_PIECES
        Ps, RPs = expm(*scaled(Jc, step))
        Q, RQ = expm(*scaled(Jc, (0.0, step)))
        Qs, RQs = [], []
        for _ in range(MEAN_PIECES):
            Qs.append(Q)
            RQs.append(RQ)
            Q, RQ = interval_product(Ps, RPs, Q, RQ)
        Qa, RQa = np.array(Qs), np.array(RQs)  # (pieces, nx, nx): e^{J_c σ} on each piece
        Mbar = Qa.mean(axis=0)  # any matrix: the estimate of the mean
        D = Qa - Mbar
        RD = up(RQa + np.abs(D) * 2.0**-52 + 5e-324)  # the enclosure and the subtraction
        # per piece, rounded up: |e| (integral), |e G_c| (moved), |(e − M̄) G_c| + |e − M̄|'s
        # enclosure error through |M̄ Ts − ∫ e| G_c (deviation): summed over the pieces
        integral = np.sum(up(np.abs(Qa) + RQa), axis=0)
        moved = np.sum(_product_bound(Qa, Gc, RQa), axis=0)
        # the mean's rounding and the period's (Ts rounded up): a few units of rounding of
        # |e| + |M̄| per piece (module docstring, "The mean form")
        slack = (MEAN_PIECES + 4) * 2.0**-52 * (np.abs(Qa) + RQa + np.abs(Mbar))
        extra = upper((RQa + slack) @ np.abs(Gc), nx + 1)
        deviation = np.sum(_product_bound(D, Gc, RD) + extra, axis=0)
        integral = up(upper(integral, MEAN_PIECES) * step)
        moved = up(upper(moved, MEAN_PIECES) * step)
        deviation = up(upper(deviation, 2 * MEAN_PIECES) * step)
        r1 = np.array([r[j] for j in self._varying])
        a = upper(moved @ r2 + integral @ upper(RG @ r2, len(cols) + 1), 2 * nx + len(cols) + 4)
        Y = _sup_bound(a, upper(integral @ R, nx + 1))  # sup |x − x̄| over the period
        if Y is None:
            raise IvobsError(
                "discretize: the effect of the varying signals over one period could not be "
                "bounded (the linearised dynamics grow too fast over the period); use a smaller "
                "Ts or disturbances='held' for held signals"
            )
        out = upper(
            deviation @ r1 + integral @ up(R @ Y + upper(RG @ r2, len(cols) + 1)),
            2 * nx + 2 * len(cols) + 4,
        )
        return [float(v) for v in out]

    def _period_apriori(self, xl: Vec, xh: Vec, u: Vec, fl: Vec, fh: Vec) -> tuple[Vec, Vec]:
        """A box containing every path of the inclusion over the whole period from
        ``[xl, xh]``: the hull of a chain of a priori boxes over ``n`` substeps (each one's box
        contains the state at its end, the next one's start), ``n`` doubled until found."""
        n = self.substeps
        for _ in range(MAX_HALVINGS + 1):
            h = float(self._h_step[1]) * self.substeps / n
            h = float(math.nextafter(h, math.inf))
            sl, sh = xl, xh
            lo, hi = list(xl), list(xh)
            for _ in range(n):
                B = self._apriori(sl, sh, u, fl, fh, h)
                if B is None:
                    break
                sl, sh = B
                lo = [min(a, b) for a, b in zip(lo, B[0])]
                hi = [max(a, b) for a, b in zip(hi, B[1])]
            else:
                if self._collect is not None:
                    self._collect.append((lo, hi))
                return lo, hi
            n *= 2
        raise DivergenceError(
            f"discretize: no a priori enclosure of the flow with varying signals over Ts = "
            f"{self.dt:g} from x in [{xl}, {xh}]: more substeps, a smaller Ts, or check the model"
        )

    def _generated(self, fn: Any, args: tuple[Any, ...]) -> Any:
        try:
            return fn(*args)
        except DomainError as exc:
            sites = self._taylor.sites
            where = sites[exc.site] if 0 <= exc.site < len(sites) else "expression"
            raise IvobsError(
                f"discretize: {where}: {exc.what} (the range [{exc.lo:.17g}, {exc.hi:.17g}] "
                "reached it); the Taylor coefficients are undefined over the box"
            ) from None

    def _picard(
        self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec, bl: Vec, bh: Vec, hh: float
    ) -> tuple[Vec, Vec]:
        """``[x0] + [0, hh] f(B)``, outward rounded."""
        f = self.continuous._f
        fl, fh = self.continuous._call(f.natural, f.sites, bl, bh, u, wl, wh)
        lo = [_dn(a + min(0.0, _dn(hh * f))) for a, f in zip(xl, fl)]
        hi = [_up(a + max(0.0, _up(hh * f))) for a, f in zip(xh, fh)]
        return lo, hi

    def _apriori(
        self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec, hh: float
    ) -> tuple[Vec, Vec] | None:
        """A box ``B`` with ``[x0] + [0, hh] f(B) ⊆ B`` (module docstring), or None."""
        bl, bh = self._picard(xl, xh, u, wl, wh, xl, xh, hh)
        for _ in range(TRIES):
            if not all(map(math.isfinite, bl + bh)):
                return None
            tl, th = _inflate(bl, bh)
            nl, nh = self._picard(xl, xh, u, wl, wh, tl, th, hh)
            if all(a >= c for a, c in zip(nl, tl)) and all(b <= d for b, d in zip(nh, th)):
                # T is verified, so x(t) ∈ x0 + [0, t] f(T) ⊆ N for t in [0, hh]: N holds it
                return nl, nh
            bl = [min(a, c) for a, c in zip(nl, tl)]
            bh = [max(b, d) for b, d in zip(nh, th)]
        return None

    # -- the Jacobian of one substep ------------------------------------------------------------
    def _substep_jac(
        self, args: tuple[Any, ...], M: tuple[np.ndarray, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Augmented ``∂(x, w)(h)/∂(x0, w)`` over the substep (module docstring of
        :mod:`.taylor`): ``P + Q M_B`` on top of ``[0 I]``."""
        nx, nz = self.nx, self.nx + self.nw
        Pl, Ph, Ql, Qh = self._generated(self._taylor.jac, args)
        Ml, Mh = M
        Rl, Rh = _imatmul(_arr(Ql, nx, nz), _arr(Qh, nx, nz), Ml, Mh)
        Jl = _aug(np.nextafter(_arr(Pl, nx, nz) + Rl, _ND), nz)
        Jh = _aug(np.nextafter(_arr(Ph, nx, nz) + Rh, _NU), nz)
        return Jl, Jh

    def _apriori_jac(
        self, bl: Vec, bh: Vec, u: Vec, wl: Vec, wh: Vec, hh: float
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """An enclosure ``M_B`` (augmented, ``(nz, nz)``) of the sensitivity over ``[0, hh]``:
        ``[I 0] + [0, hh] ∂f/∂z(B, [w]) M_B ⊆ M_B``, or None."""
        nx, nz = self.nx, self.nx + self.nw
        jl, jh = self._jacobian((bl, bh), u, wl, wh)
        with np.errstate(invalid="ignore", over="ignore"):
            El = np.minimum(0.0, np.nextafter(hh * jl, _ND))
            Eh = np.maximum(0.0, np.nextafter(hh * jh, _NU))
        I0 = np.eye(nz)[:nx]
        # candidate radius around I (not itself rigorous, the test below is): the image of
        # I ± R is within I ± |E| (I + R), strictly inside I ± R when R - |E| R = |E| + D, D > 0
        # (R = (I - |E|)^-1 (|E| + D)); the rows of the constant w stay exactly [0 I]
        mag = np.zeros((nz, nz))
        mag[:nx] = np.maximum(np.abs(El), np.abs(Eh))
        if not np.all(np.isfinite(mag)) or np.max(np.abs(np.linalg.eigvals(mag))) >= 0.5:
            return None  # ρ(|E|) too large: a shorter substep
        D = np.zeros((nz, nz))
        D[:nx] = 1e-12 + 1e-9 * mag[:nx]
        R = np.maximum(np.linalg.solve(np.eye(nz) - mag, mag + D), 0.0) * (1.0 + 1e-9)
        for _ in range(TRIES):
            Tl, Th = np.eye(nz) - R, np.eye(nz) + R
            Sl, Sh = _imatmul(El, Eh, Tl, Th)
            Nl = _aug(np.nextafter(I0 + Sl, _ND), nz)
            Nh = _aug(np.nextafter(I0 + Sh, _NU), nz)
            if np.all(Nl >= Tl) and np.all(Nh <= Th):
                return Nl, Nh  # T verified, so M(t) ∈ I0 + [0, t] [J] T ⊆ N
            R = 2.0 * R + D
        return None

    # -- identity ------------------------------------------------------------------------------
    @property
    def is_continuous(self) -> bool:
        return False

    def spec(self) -> dict[str, Any]:
        """The continuous system's keyword arguments and the discretisation."""
        out = self.continuous.spec()
        out["discretize"] = {
            "Ts": self.dt,
            "order": self.order,
            "substeps": self.substeps,
            "disturbances": self.disturbances,
        }
        return out

    def __reduce__(self) -> Any:
        return (
            FlowSystem,
            (self.continuous, self.dt, self.order, self.substeps, self.disturbances),
        )

    def _repr_html_(self) -> str:
        from ..._html import summary_html

        rows = [(f"{x}' =", str(e)) for x, e in zip(self.state_names, self.f_text)]
        rows += [(f"{n} =", str(e)) for n, e in zip(self.output_names, self.h_text)]
        rows += [
            ("sampled", f"Ts = {self.dt:g}, Taylor order {self.order}, {self.substeps} substep(s)")
        ]
        return summary_html("ivobs NonlinearSystem (validated flow)", rows)

    def __repr__(self) -> str:
        return (
            f"FlowSystem(nx={self.nx}, nu={self.nu}, ny={self.ny}, Ts={self.dt:g}, "
            f"order={self.order}, substeps={self.substeps})"
        )


def _sup_bound(a: np.ndarray, K: np.ndarray) -> np.ndarray | None:
    """A ``Y > 0`` with ``a + K Y <= Y`` and ``K Y < Y`` (``a, K >= 0``), checked with rounding
    upward, or None. Then ``ρ(K) < 1`` and every ``W >= 0`` with ``W <= a + K W`` is below
    ``Y`` (module docstring, "Signals that vary"): ``Y`` bounds the deviation over the interval."""
    from ...sets.rounding import up, upper

    n = a.shape[0]
    try:
        Y = np.linalg.solve(np.eye(n) - K, a)
    except np.linalg.LinAlgError:
        return None
    Y = np.maximum(Y, 0.0) * (1.0 + 1e-9) + 1e-300
    KY = upper(K @ Y, n + 1)
    if not (np.all(np.isfinite(Y)) and np.all(KY < Y) and np.all(up(a + KY) <= Y)):
        return None
    return Y


def _key(*vectors: Any) -> tuple[float, ...]:
    return tuple(float(v) for vec in vectors for v in vec)


def _product_bound(X: np.ndarray, G: np.ndarray, RX: np.ndarray) -> np.ndarray:
    """``>= |Y G|`` (elementwise) for every ``|Y − X| <= RX``: ``|fl(X G)|`` plus its rounding
    ([Higham2002, Lemma 3.1]) plus ``RX |G|``, rounded up."""
    from ...sets.rounding import product_error, upper

    n = X.shape[-1]
    aG = np.abs(G)
    out: np.ndarray = upper(np.abs(X @ G) + product_error(np.abs(X) @ aG, n) + RX @ aG, n + 2)
    return out


def _no_contraction(*args: Any) -> bool:
    return True


def _check_smooth(f: list[Any], order: int) -> bool:
    """Refuse ``abs``, ``min``, ``max`` in ``f`` above order 2. Up to order 2 the step holds
    with their generalised derivatives: ``x(h) - x0 - h f(x0) = ∫_0^h (f(x(s)) - f(x0)) ds``
    with ``f_i(x(s)) - f_i(x0) ∈ ∂f_i(B) s f(B)`` (Lebourg [Clarke1983, Theorem 2.3.7]), i.e.
    ``h² f^[2](B)``; beyond, Taylor's remainder needs derivatives that do not exist at the
    kinks. Returns whether ``f`` is smooth (the flow's Jacobian is only offered then)."""
    import sympy as sp

    kinks = (sp.Abs, sp.Min, sp.Max, sp.sign, sp.Heaviside)
    smooth = not any(e.has(*kinks) for e in f)
    if order > 2 and not smooth:
        raise IvobsError(
            f"order: {order} needs a smooth f (the Taylor remainder of order k uses k "
            "derivatives); f uses abs, min or max: use order=1 or 2 (and more substeps)"
        )
    return smooth


def _mid_rad(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The centre ``c`` of ``[lo, hi]`` and a radius ``>= max(hi - c, c - lo)``."""
    from ...sets.rounding import up

    c = 0.5 * lo + 0.5 * hi
    return c, up(np.maximum(hi - c, c - lo))


def _arr(v: Any, n: int, m: int) -> np.ndarray:
    return np.asarray(v, dtype=float).reshape(n, m)


def _aug(top: np.ndarray, nz: int) -> np.ndarray:
    """``[[top], [0 I]]``: the rows of the constant ``w`` below the state rows."""
    nx = top.shape[0]
    return np.vstack([top, np.eye(nz)[nx:]])


def _widen(lo: Vec, hi: Vec, z: Vec | None) -> tuple[Vec, Vec]:
    """``[lo - z, hi + z]`` rounded outward (``[lo, hi]`` for no ``z``)."""
    if z is None:
        return lo, hi
    return [_dn(a - e) for a, e in zip(lo, z)], [_up(b + e) for b, e in zip(hi, z)]


def _inflate(lo: list[float], hi: list[float]) -> tuple[list[float], list[float]]:
    e = [INFLATE_REL * (b - a) + INFLATE_ABS * (1.0 + max(abs(a), abs(b))) for a, b in zip(lo, hi)]
    return [_dn(a - d) for a, d in zip(lo, e)], [_up(b + d) for b, d in zip(hi, e)]


def _imatmul(
    Al: np.ndarray, Ah: np.ndarray, Bl: np.ndarray, Bh: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Interval matrix product, outward rounded: each product within one ulp (``nextafter``),
    a ``0 × ∞`` corner counted as 0 (IEEE 1788); the sum's error bounded by ``γ_n Σ|terms|``
    [Higham2002, Section 3.1] plus ``n`` times the smallest subnormal, then one more ulp."""
    from ...linalg import gamma

    with np.errstate(invalid="ignore", over="ignore"):
        a = (Al[:, :, None], Ah[:, :, None])
        b = (Bl[None, :, :], Bh[None, :, :])
        P = np.stack([a[i] * b[j] for i in (0, 1) for j in (0, 1)])
        P = np.where(np.isnan(P), 0.0, P)
        lo = np.nextafter(P.min(axis=0), _ND)
        hi = np.nextafter(P.max(axis=0), _NU)
        n = Al.shape[1]
        g, eta = gamma(n + 1), n * 5e-324
        sl = lo.sum(axis=1) - (g * np.abs(lo).sum(axis=1) + eta)
        sh = hi.sum(axis=1) + (g * np.abs(hi).sum(axis=1) + eta)
        sl = np.where(np.isnan(sl), -np.inf, sl)
        sh = np.where(np.isnan(sh), np.inf, sh)
    return np.nextafter(sl, _ND), np.nextafter(sh, _NU)
