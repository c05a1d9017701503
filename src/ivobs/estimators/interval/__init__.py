"""Interval observers built on cooperative (monotone) error dynamics: one family, three members.

Papers: [Tang2019, Section V, Theorems 4–5, eqs. (36)–(48)]; [Efimov2013, Theorems 1–3,
eqs. (3)–(8), Remark 1].

ivobs' model ``x+ = A x + B u + E d``, ``y = C x + D_u u + F d`` (one disturbance ``d`` in both
equations; ``D_u`` is the feedthrough) gives, for any gain ``L``,

    x+ = (A − LC) x + (B − L D_u) u + L y + (E − LF) d                          (*)

so with ``G = E − LF`` the Lemma-1 bounds ``G⁺ d_lo − G⁻ d_hi <= G d <= G⁺ d_hi − G⁻ d_lo``
play the role of [Tang2019]'s ``d̲, d̄`` (eq. (37): for ``d = [w; v]``, ``E = [E 0]``,
``F = [0 F]`` they are exactly ``E⁺w̄ − E⁻w̲ + (−LF)⁺v̄ − (−LF)⁻v̲``) and of [Efimov2013]'s
``b̲ − LV``, ``b̄ + LV``.

* ``interval`` — [Tang2019, eq. (36)] = [Efimov2013, eq. (3)]: ``A − LC`` nonnegative and Schur
  ([Tang2019, Theorem 4] / [Efimov2013, Theorem 1]);
* ``interval-transformed`` — [Tang2019, Theorem 5, eqs. (42)–(43)] = [Efimov2013, Theorem 2]:
  observer (36) for ``z = S x`` with ``R = S (A − LC) S⁻¹ >= 0``, bounds mapped back by Lemma 1
  ([Efimov2013, Theorem 2] writes ``z = S⁻¹ x``: its ``S`` is ivobs' ``S⁻¹``, docs/notation.md);
* ``interval-split`` — [Efimov2013, Theorem 3, eq. (5)]: same coordinates,
  ``D = A − LC = D⁺ − D⁻`` of any sign, stable iff ``|D| = D⁺ + D⁻`` is Schur.

All three propagate one recursion (:mod:`.recursion`), the split form of (*) in coordinates
``z = S x`` (``S = I`` except for ``interval-transformed``), with ``Q = S (A − LC) S⁻¹``::

    z̄+ = Q⁺ z̄ − Q⁻ z̲ + S(B − L D_u) u + S L y + (SG)⁺ d_hi − (SG)⁻ d_lo
    z̲+ = Q⁺ z̲ − Q⁻ z̄ + S(B − L D_u) u + S L y + (SG)⁺ d_lo − (SG)⁻ d_hi

Soundness: multiply (*) by ``S``; Lemma 1 bounds ``Q z`` over ``[z̲, z̄]`` and ``SG d`` over the
``d`` box, so ``z̲ <= z <= z̄`` carries over by induction from ``z̲_0 <= S x_0 <= z̄_0`` (Lemma 1
on ``x0``). When ``Q >= 0`` (``Q⁻ = 0``) this *is* [Tang2019]'s (36)/(42) and [Efimov2013]'s
(3)/(4); for ``interval-split`` it is [Efimov2013]'s (5). The midpoint obeys ``c+ = Q c + …`` and
the radius ``r+ = |Q| r + radius(SG d)`` (``|Q| = Q⁺ + Q⁻``): bounded iff ``|Q|`` is Schur.
(The stacked bounds follow ``[[Q⁺, −Q⁻], [−Q⁻, Q⁺]]``, not [Efimov2013]'s error matrix Σ; both
are Schur iff ``|Q|`` is.) The vectorised path (:mod:`.vectorised`) runs the centre and the
radius as two linear filters of :mod:`ivobs.estimators._recursion`.

**Missing samples** (NaN in ``y[k]``): the gain's columns of the missing components are zero
for that step; (*) holds for *any* gain, so the same Lemma-1 step with ``Q_k = S(A − L_k C)S⁻¹``
(which may have negative entries even when ``Q`` has none: the split form covers it) stays
sound; with every component missing it is the model's prediction. ``L_k = L diag(observed)``
unless that leaves ``|Q_k|`` non-Schur: then the gain of that pattern is the one with the
smallest ``ρ(|Q_k|)`` among it, zero and the width-optimal gain of the observed outputs
(designed once, cached; :mod:`.operators`). **Inconsistent data**: when ``y[k]`` lies outside
``C[x̲_k, x̄_k] + D_u u_k + F[d]`` (rounding included) no state in the box explains it (a
fault); it is reported and treated as missing.

**The finite-memory bound** (dense, time-invariant, constant bounds, exact matrices,
``(A, C)`` observable; :mod:`.window`, :mod:`ivobs.design.finite_memory`). The ``N`` complete
steps before ``k`` (``N``: the observability index) bound ``x[k]`` on their own, whatever
happened before them. With ``finite_memory=True`` (the default) every box of ``x[k]`` is
intersected with that bound: the recursion forgets its past only at the rate ``ρ(|Q|)``, 0.9995
on the servo of [Tang2019], whose summed width falls from 254 to 1.28 with complete data.
``finite_memory=False`` gives the papers' observers' boxes. **After a gap** (either setting)
the observer's own bounds are intersected once, ``N`` complete steps after it, with the bound of
those steps (its image by ``S`` for ``interval-transformed``): the width is back within that
bound ``N`` steps after a gap of any length (docs/operating.md, "After a gap"). In coordinates
``z = S x`` some patterns have no gain with ``|Q_k|`` Schur although the plant is stable
(``|S A S⁻¹|`` is not ``|A|``): widths then grow during such gaps until the window bound resets
them (docs/interval.md).

**Rounding** (``proven_rounding``): every bound the step returns or keeps is on the safe side
of the exact one, by a proven model of the floating-point error of the step (:mod:`.rounding`);
the vectorised path has its own proof (:mod:`.vectorised`); the finite-memory bound its own
(:meth:`ivobs.design.finite_memory.WindowBound.box`), the same on both paths. No margin is
added.

The package: :mod:`.design` (offline: gains, ``S``; no time loop), :mod:`.operators` (the step
matrix of each missing-output pattern, built once), :mod:`.recursion` (the typed state and the
step), :mod:`.rounding` (the proof), :mod:`.vectorised` (whole records and batches),
:mod:`.observers` (the three registered estimators), :mod:`.window` (the finite-memory bound:
every box, and recovery after gaps).
"""

from __future__ import annotations

from .design import IntervalDesign, SplitDesign
from .observers import IntervalObserver, SplitIntervalObserver, TransformedIntervalObserver
from .recursion import CooperativeState, IntervalState, SplitState, TransformedState
from .transformed import TransformedDesign

__all__ = [
    "CooperativeState",
    "IntervalDesign",
    "IntervalObserver",
    "IntervalState",
    "SplitDesign",
    "SplitIntervalObserver",
    "SplitState",
    "TransformedDesign",
    "TransformedIntervalObserver",
    "TransformedState",
]
