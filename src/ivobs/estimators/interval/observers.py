"""The three registered interval observers: design in ``__init__`` (:mod:`.design`), the matrices
derived from it once (:class:`~.operators.Operators`), the step of :mod:`.recursion` and the
vectorised path of :mod:`.vectorised`."""

from __future__ import annotations

from typing import Any, ClassVar, Generic, TypeVar

import numpy as np

from ..._validate import as_bool
from ...errors import DesignError
from ...model import LinearSystem
from ...sets import Box
from .. import register
from .._uncertain import growth_radius
from ..base import Estimator
from ..state import Step
from .design import IntervalDesign, SplitDesign, gain_design
from .operators import Operators
from .recursion import CooperativeState, IntervalState, SplitState, TransformedState, interval_step
from .transformed import TransformedDesign, transformed_design
from .vectorised import VectorPath
from .window import empty_window

__all__ = ["IntervalObserver", "SplitIntervalObserver", "TransformedIntervalObserver"]

S = TypeVar("S", bound=CooperativeState)


class CooperativeObserver(Estimator, Generic[S]):
    """What the three observers share (package docstring): the split-form recursion in
    ``z = S x`` with the operators of the design, its typed state and the vectorised path, each
    with its proven rounding bound (:mod:`.rounding`, :mod:`.vectorised`)."""

    needs_x0: ClassVar[bool] = True
    proven_rounding: ClassVar[bool] = True
    data_used: ClassVar[str] = "prediction"
    supports_uncertain: ClassVar[bool] = True
    """Interval matrices ([Efimov2013]'s uncertain ``A = A0 + ΔA``, docs/uncertain.md): the gain
    is designed for the nominal matrices; with ``w = ΔA x + ΔB u``, ``v = ΔC x + ΔD u`` the
    plant obeys ``x+ = (A0 − L C0) x + (B0 − L D0) u + L y + (E − LF) d + (w − L v)``, so the
    same Lemma-1 step stays sound with ``S (w − L_k v)`` as one more bounded input, bounded from
    the box of ``x[k]`` (``|w| <= R_A |x| + R_B |u|``, :mod:`ivobs.estimators._uncertain`,
    rounded upwards); the consistency test widens by ``|v|``. The loop only (the term depends
    on the box), no window after gaps (its bound assumes the exact ``A``)."""
    state_type: ClassVar[type[CooperativeState]] = CooperativeState

    def _build(
        self, L: np.ndarray, D: Any, S_: np.ndarray | None = None, finite_memory: Any = True
    ) -> None:
        """The step operators of the gain ``L`` (``D = A − LC``) and transformation ``S``;
        ``finite_memory``: the option (class docstring)."""
        assert self.x0 is not None
        if self.sys.uncertainty is not None:
            self._check_growth(L, D, S_)
        memory = as_bool("finite_memory", finite_memory)
        self.operators = Operators(self.sys, self.x0, L, S_, self.name, memory)
        self.vector = VectorPath(self.operators)
        self.valid_from = 0

    def _check_growth(self, L: np.ndarray, D: Any, S_: np.ndarray | None) -> None:
        """Refuse interval matrices too wide for the gain's stability margin: the bounds'
        radius obeys ``r+ >= G r`` (:func:`~ivobs.estimators._uncertain.growth_radius`), so
        ``ρ(G) >= 1`` means bounds that cannot converge (with ``ρ(G) > 1``, diverge)."""
        sys = self.sys
        R = D if S_ is None else S_ @ (sys.A - L @ sys.C) @ np.linalg.inv(S_)
        rho = growth_radius(sys.uncertainty, np.asarray(R, dtype=float), L, S_)
        if rho >= 1.0:
            raise DesignError(
                f"{self.name}: the interval matrices are too wide for this design: the radius of "
                f"the bounds grows as r+ >= G r with G = |S(A0 - L C0)S^-1| + (|S| R_A + "
                f"|S L| R_C)|S^-1|, whose spectral radius is {rho:.6g} >= 1, so the bounds "
                "cannot converge; use a method that keeps the correlations (zonotope, "
                "reachability, strip, constrained-zonotope) or narrower intervals"
            )

    def _initial_state(self) -> S:
        ops = self.operators
        lo, hi = ops.initial_bounds()
        window = empty_window(ops.window, ops.ny, self.sys.nu)
        return self.state_type(lo=lo, hi=hi, window=window)  # type: ignore[return-value]

    def _step(self, state: S, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> Step[S]:
        return interval_step(self.operators, state, u_k, y_k)

    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        return self.vector.run(self, u, y, t)


class _GainObserver(CooperativeObserver[S]):
    """``interval`` and ``interval-split``: ``S = I``, the design is the gain ``L`` (given, or
    designed as ``gain=`` says: :func:`.design.gain_design` of ``design_type``)."""

    design_type: ClassVar[type[IntervalDesign] | type[SplitDesign]]

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        gain: str = "width",
        finite_memory: bool = True,
        **options: Any,
    ):
        super().__init__(sys, x0, **options)
        design = gain_design(self.design_type, sys, L, gain, self.name)
        self._build(design.L, design.D, finite_memory=finite_memory)
        self.design: IntervalDesign | SplitDesign = design


@register
class IntervalObserver(_GainObserver[IntervalState]):
    """Interval observer with ``A − LC`` nonnegative and Schur ([Tang2019, eqs. (36)–(37),
    Theorem 4]; [Efimov2013, eq. (3), Theorem 1]; bounds from measurements as in
    [Efimov2013, Remark 1])::

        x̄[k+1] = A x̄ + B u + L (y − C x̄ − D_u u) + Ḡ,    Ḡ = G⁺ d_hi − G⁻ d_lo
        x̲[k+1] = A x̲ + B u + L (y − C x̲ − D_u u) + G̲,    G̲ = G⁺ d_lo − G⁻ d_hi,  G = E − LF

    Errors ``x̄ − x``, ``x − x̲`` obey ``e+ = (A − LC) e + (nonnegative input)``: a
    nonnegative ``A − LC`` keeps them nonnegative ([Tang2019, Lemma 3]), Schur keeps them
    bounded. ``d`` bounds may be callables ``(k, y_k) -> Box`` ([Efimov2013, Remark 1], the Hénon
    example).

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Gain** (``L=`` to give one; it must make ``A − LC`` nonnegative and Schur):
    ``gain="lmi"``: LMI (41) of [Tang2019] with diagonal ``P`` (a margin maximised,
    :func:`ivobs.design.cooperative.nonnegative_gain`); ``gain="lmi+width"``: that gain
    refined by local linear programs (:func:`ivobs.design.cooperative.refine_width`);
    ``gain="width"`` (default): the global minimum of the (balanced) steady-state width
    ``(I − D)⁻¹|G|Δ`` over every gain with ``D >= 0`` and Schur, by one sparse linear program in
    ``(q, Y = diag(q) L)`` whose ``q`` is a copositive Lyapunov certificate
    (:mod:`ivobs.design.width_lp`; hundreds of states in seconds; among equally good gains the
    one without a component on the left null space of ``[C, F]``, e.g. with redundant
    noise-free sensors). When no gain makes ``A − LC`` nonnegative and Schur ([Tang2019,
    Example 2], [Efimov2013, §IV.A]) a :class:`~ivobs.DesignError` says so and what proves it
    (a row that no ``L_i`` makes nonnegative, a kernel test, or the infeasible LP), distinct
    from a solver failure: use ``interval-split`` or ``interval-transformed``.

    **Finite-memory bound** (``finite_memory=True``, the default; package docstring,
    :mod:`~ivobs.estimators.interval.window`): each box of ``x[k]`` is intersected with the bound
    that the ``N`` complete steps before ``k`` give alone (``N``: the observability index of
    ``(A, C)``), on every path. It matters where the gain leaves a slow mode uncorrected (the
    servo's current: ``ρ(A − LC) = 0.9995``); it costs a product of the window per step
    (``run()`` computes every window's bound at once; BENCHMARKS.md has the figures).
    ``finite_memory=False``:
    the observer's own boxes, as in the papers ([Tang2019, eq. (36)]: to compare with them, or to
    save that product per ``step()`` where the window bound is never the tighter one). Only
    dense time-invariant systems with exact matrices and constant bounds have one
    (``est.operators.window``; None otherwise).

    Missing samples, inconsistent data and the vectorised path: see the package docstring.
    """

    name = "interval"
    order = 40
    summary = "interval observer, A − LC nonnegative and Schur ([Tang2019, eq. (36)])"
    reference = "[Tang2019, Section V.A, eqs. (36)-(41)]; [Efimov2013, Theorem 1, eq. (3)]"
    state_type = IntervalState
    design_type = IntervalDesign


@register
class SplitIntervalObserver(_GainObserver[SplitState]):
    """Interval observer in the original coordinates with ``D = A − LC = D⁺ − D⁻`` of any sign
    ([Efimov2013, Theorem 3, eq. (5)]; error system (6); Corollary 1)::

        x̄[k+1] = D⁺ x̄ − D⁻ x̲ + (B − L D_u) u + L y + Ḡ
        x̲[k+1] = D⁺ x̲ − D⁻ x̄ + (B − L D_u) u + L y + G̲        (Ḡ, G̲ as for ``interval``)

    Sound for every ``L`` (Lemma 1); bounded iff ``|D| = D⁺ + D⁻`` is Schur ([Efimov2013]'s
    copositive argument: the radius obeys ``r+ = |D| r + …``).

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Gain** (``L=`` to give one; ``|A − LC|`` must be Schur):
    ``gain="lmi"``: LMIs (7)–(8) of [Efimov2013] (Corollary 1; they force ``D >= 0``, the same
    LMI as [Tang2019]'s (41)); ``gain="margin"``: a local minimum of ``ρ(|A − LC|)`` by linear
    programs on ``|A − LC| v <= s v`` alternating with the Perron vector ``v``
    (:func:`ivobs.design.cooperative.abs_schur_gain`); ``gain="margin+width"``: that gain refined
    by local LPs (:func:`ivobs.design.cooperative.refine_width`); ``gain="width"`` (default): the
    global minimum of the steady-state width ``(I − |D|)⁻¹|G|Δ`` over every gain with ``|D|``
    Schur, by one sparse LP (:mod:`ivobs.design.width_lp`), which also decides whether such a
    gain exists: :class:`~ivobs.DesignError` with the proof when none does.

    ``finite_memory``: the finite-memory bound, as for ``interval``. Missing samples, rounding and
    the vectorised path: see the package docstring.
    """

    name = "interval-split"
    order = 60
    summary = "interval observer with D⁺/D⁻, |A − LC| Schur ([Efimov2013, Theorem 3, eq. (5)])"
    reference = "[Efimov2013, Theorem 3, eqs. (5)-(8), Corollary 1]"
    state_type = SplitState
    design_type = SplitDesign


@register
class TransformedIntervalObserver(CooperativeObserver[TransformedState]):
    """Interval observer in coordinates ``z = S x`` where ``R = S (A − LC) S⁻¹`` is nonnegative
    ([Tang2019, Theorem 5, eqs. (42)–(43), (48)]; [Efimov2013, Theorem 2, eq. (4)])::

        z̲_0, z̄_0 = Lemma 1 of S on x0                                           (42a-b)
        z̄+ = R z̄ + S(B − L D_u) u + S L y + ḡ,  z̲+ = R z̲ + … + g̲,  g = bounds of S(E − LF) d
                                                                                 (42c-d, 43)
        x̲, x̄ = Lemma 1 of S⁻¹ on [z̲, z̄]  (k >= 1; the prior box at k = 0)       (42e-f)

    ``A − LC`` only needs to be Schur. ``S = O_R⁻¹ O_{A−LC}`` ([Tang2019, eq. (48)]) with the
    observability matrices of ``(R, e2)`` and ``(A − LC, e1)``.

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Design** (each step can be given). ``L=``, or ``poles=`` (distinct real poles placed by
    SciPy's ``place_poles``). By default (:func:`ivobs.design.similarity.default_design`) ivobs
    places distinct poles in ``(0, 1)`` (then ``R = diag(λ)`` is a nonnegative realisation),
    lowers the steady-state width ``|V|(I − Λ)⁻¹|V⁻¹ G| Δ`` of the observer in modal coordinates
    by Nelder–Mead over ``L``, then searches ``(L, e1)`` jointly over every real spectrum the
    realisation below supports (a local search; ``design.gain == 'search'``). ``R=``: a
    nonnegative matrix with the spectrum of ``A − LC`` (default
    :func:`ivobs.design.similarity.nonnegative_realization`: diagonal/bidiagonal, Suleimanova
    companion blocks, 3×3 circulants for complex pairs; ``DesignError`` with the reason when the
    spectrum has no such realisation, e.g. [Efimov2013]'s planar example with
    ``L = (0.3, 0.6)``: ``{0, −0.5}``, negative trace). ``e1=``, ``e2=``: the rows of eq. (48)
    (defaults: observable choices with the smallest steady-state width). ``S=``: the
    transformation itself.

    **Beyond the search** (``transform="auto"``, the default: above 8 states, or where the
    search fails; ``transform="schur"`` to ask for it): eq. (48) goes through observability
    matrices whose condition number grows exponentially with ``nx``, so ivobs takes ``S = I``
    with the width-optimal gain of ``interval`` when some gain makes ``A − LC`` nonnegative and
    Schur (``design.gain == 'identity'``, [Tang2019, Theorem 5] with ``S = I``), else real
    Schur or modal coordinates for a decay-rate Kalman gain (``'schur'``,
    :mod:`ivobs.design.schur_transform`): ``S`` orthogonal (or ``V⁻¹``), ``R`` of any sign with
    ``ρ(|R|) < 1``, propagated in the split form ([Efimov2013, Theorem 3] in ``z``). Sound for
    any detectable plant whose ``A − LC`` spectrum fits ``|Re λ| + |Im λ| < 1``, but loose: the
    box of ``x`` is ``|S⁻¹|`` times that of ``z``.

    The observer propagates with ``S (A − LC) S⁻¹`` (``design.R``), which equals the requested
    ``R`` up to round-off; the split form makes any round-off-sized negative entry sound.
    Its rounding in ``z = S x``: :mod:`.rounding`. ``finite_memory``: the finite-memory bound of
    ``x``, as for ``interval`` (the box of ``x`` is intersected with it).
    """

    name = "interval-transformed"
    order = 50
    summary = "interval observer in z = S x with nonnegative R ([Tang2019, Theorem 5])"
    reference = "[Tang2019, Section V.B, Theorem 5, eqs. (42)-(48)]; [Efimov2013, Theorem 2]"
    state_type = TransformedState

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        poles: Any = None,
        R: Any = None,
        S: Any = None,
        e1: Any = None,
        e2: Any = None,
        transform: str = "auto",
        finite_memory: bool = True,
        **options: Any,
    ):
        super().__init__(sys, x0, **options)
        design = transformed_design(
            sys, self.name, L=L, poles=poles, R=R, S=S, e1=e1, e2=e2, transform=transform
        )
        self._build(design.L, None, design.S, finite_memory)
        self.design: TransformedDesign = design
