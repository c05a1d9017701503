"""Zonotopic set-membership filter with strip intersection [Alamo2005].

**Intersection with a strip [Alamo2005].** For a zonotope ``<p, H>`` and a strip
``S = {x : |hᵀx - t| <= σ}``, every ``λ`` gives a zonotope containing ``<p, H> ∩ S``::

    X(λ) = <p + λ (t - hᵀp), [(I - λ hᵀ) H, σ λ]>

and the one with the smallest Frobenius radius of its generator matrix has the closed form
``λ* = H Hᵀ h / (hᵀ H Hᵀ h + σ²)`` (:func:`ivobs.sets.strip.intersect_strip`).

**Correlated disturbance.** ``d`` enters both ``x+ = A x + B u + E d`` and ``y = C x + D u +
F d``, so the filter works on the pair ``ζ = (x_k, d_jc)`` (``jc``: the components of ``d``
that enter a measurement): the joint zonotope ``<(p, c_d), blkdiag(H, R)>`` (``d = c_d + R δ``),
each measured component ``i`` the strip ``|C_i x + F_i d - (y_i - D_i u)| <= σ_i`` in the
joint space, and the prediction maps the intersected joint set with ``[A E_jc]`` and adds
``E_pc d_pc`` for the other components. This is exact for the correlation, and reduces to the
classical strip ``σ_i = Σ_j |F_ij| r_j`` when the noise enters one output and not the state.
The components of ``y_k`` are intersected one after the other; a missing one (NaN) is not.

**Boxes.** The box of ``x[k]`` is the interval hull of the filtered zonotope, intersected with
two exact enclosures computed at each strip before the zonotope's update: the interval hull of
``(current zonotope) ∩ (strip)`` per coordinate (the Lagrangian dual of the LP ``max x_j``,
minimised at a weighted quantile of its breakpoints: no solver) and one pass of constraint
propagation of the strip over the box of ``(x, d)``. When every state is measured the box is
therefore the measurement box whenever the prediction is wider.

**Order reduction.** After the prediction the zonotope keeps at most ``order`` generators. The
default (``reduction="parallelotope"``) absorbs the generators to remove into a basis of ``nx``
large, independent ones ([Chisci1998]'s parallelotope rule), on the steps where that basis is
well conditioned, and otherwise encloses them in Girard's box ([Girard2005], CORA's default,
``reduction="girard"``): a basis picked among the generators can become nearly dependent, and
without the check the boxes diverged (CORA's tank30 at ``order = 2 nx``: radius 10⁷).
``reduction="box"`` is the box of [Combastel2015] ([Tang2019, Remark 2]). The parallelotope
rule leaves a box ``e`` of what the basis could not absorb: the state is ``x ∈ <p, H> ⊕
box(e)``.

**Rounding, proven.** Every bound contains the exact set at every magnitude; no margin is added
(``proven_rounding``). With ``γ_n = n u / (1 - n u)``, ``u = 2⁻⁵³`` [Higham2002, §3.1], and
``η`` the underflow of one product:

* *the strip*: ``t_i = fl(y_i - D_i u)`` is within ``γ_{nu+1} (|y_i| + |D_i||u|)`` of the exact
  value; the half-width ``σ_i`` adds that, the same bound for a float64 evaluation of the
  output equation (``γ_N (|y_i| + |D_i||u| + |h|ᵀ|ζ|)``, ``N = nx + nd + nu + 1``: a record from
  a float64 simulation) and the interval matrices' ``v̄_i``. ``σ_i > 0``, which also keeps
  ``λ*`` bounded when the set is thin along ``h``;
* *each strip's operations* (:mod:`ivobs.sets.strip`): the strip in the generators'
  coordinates is widened by the rounding of ``s = Hᵀh`` and ``e = t - hᵀz`` and by the box
  aside; the box contraction and the section hull round their sums with ``γ`` bounds and their
  ends outwards; the rounding of Alamo's update goes into a box kept aside, ``acc``;
* *the box of* ``x[k]``: ``z ± (|H| 1 + acc)`` rounded outwards, intersected with the
  contracted box;
* *the prediction*: ``p = fl(M z + E_pc c + B u)`` and ``fl(M H)``; one box of generators
  holds ``γ`` of their dot products times ``|M|(|z| + |H| 1 + acc) + |E_pc|(|c| + r) + |B||u|``
  (twice: ours and a float64 plant's), the image ``|M| acc`` of the box aside and the
  interval matrices' ``w̄``;
* *the reduction* (:mod:`ivobs.sets.reduction`): the box of Girard's rule and the basis'
  scale factors rounded up, the parallelotope's residual ``e`` bounded with ``γ``.

A measurement is reported inconsistent only when the strip certainly misses the set (``|e| >
‖s‖₁ + σ_z``, or an empty contracted box): both hold every point that explains the data, so an
admissible sample is never flagged.

**Work per step.** ``ny`` strips of ``O(nz m)`` each (``nz`` the joint dimension, ``m <=
order + ny + ...`` generators; the section hull's quantiles by selection, ``O(m)`` per
coordinate), the prediction ``O(nx nz m)`` and the reduction ``O(nx² m)``. The step is loops
over raw arrays (:mod:`.recursion`), compiled by numba when installed (``pip install
ivobs[fast]``); without numba the same source runs interpreted, about a hundred times slower.
"""

from __future__ import annotations

from .estimator import REDUCTIONS, StripDesign, StripEstimator, StripState

__all__ = ["REDUCTIONS", "StripDesign", "StripEstimator", "StripState"]
