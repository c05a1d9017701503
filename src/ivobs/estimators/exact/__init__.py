"""The exact reference: the tightest box any guaranteed method can give from the same data.

The set-membership problem [Tang2019, Section I] asks for "all the admissible state values that are
consistent with the measurements and the bounded uncertainties". For the model

::

    x[j+1] = A_j x[j] + B_j u[j] + E_j d[j],    y[j] = C_j x[j] + D_j u[j] + F_j d[j],
    x[0] ∈ x0,   d[j] ∈ d_j = sys.d_at(j, y[j])        (one d[j] in both equations)

that set at step ``k`` is the projection on ``x[k]`` of the polytope of trajectories
``z = (x[0], d[0], ..., x[k], d[k])`` satisfying the equations for ``j <= k``. Its interval hull,
component by component, is given by two linear programs per state::

    lower_k[i] = min x[k][i],   upper_k[i] = max x[k][i]   over that polytope.          (LP)

No guaranteed method that uses ``x0``, ``d``, ``u[0..k]``, ``y[0..k]`` can return a smaller box
(a tighter one would exclude a state the data cannot rule out), so this is the reference the
other methods are measured against (``Estimate.tightness_ratio``).

Formulation. The LP is kept sparse: the variables are the blocks ``(x[j], d[j])``, the constraints
the dynamics rows ``x[j+1] - A_j x[j] - E_j d[j] = B_j u[j]`` and the measurement rows
``C_j x[j] + F_j d[j] = y[j] - D_j u[j]``. It is built incrementally (a block per step; the oldest
block dropped in a moving window) and handed to two HiGHS models (``highspy``), one for the ``nx``
minimisations and one for the ``nx`` maximisations, solved in two threads. Each model keeps its
basis from program to program and from step to step (only the cost, the bounds or appended rows
change), so every solve is warm-started: a chain of neighbouring objectives
``min x[k][0], ..., min x[k][n-1]`` (and the maxima in reverse order). Each step starts from the
bases alone (no factorisation or pricing weights kept from the previous step), and HiGHS's own
scaling is off (it was computed once and extended row by row, so a program rebuilt in one go
was scaled differently): a state saved with its bases (``state()``) therefore continues, once
restored, with exactly the solves of the run that saved it. Each solve is capped
at 20,000 simplex iterations (a stalled or very long solve); a capped program still gives the
safe bound (S) of its last multipliers, and the step warns (``RuntimeWarning``).
HiGHS sees the program shifted to the centres of the variable bounds (``z = m + z'``; ``m``:
the centre of the interval prediction of ``x[j]`` and of the box of ``d[j]``), so that its
absolute tolerances act at the scale of the widths, not of ``|x|`` (a state near ``1e9`` with a
width of 10 is an ordinary LP).

Soundness under floating point. The data are floating-point numbers, so each equation is kept up
to the rounding of one floating-point evaluation of it: row ``i`` is the range
``|a_i^T z - b_i| <= tau_i``, with (``γ_n = n ε / (1 - n ε)``, ``ε = 2^-52``, [Higham2002, §3.1])

::

    dynamics:     tau = γ_{nx+nu+nd} (|A| x̄ + |B| |u| + |E| d̄) + γ_{nu} |B| |u|
    measurement:  tau = γ_{nx+nu+nd} (|C| x̄ + |D| |u| + |F| d̄) + γ_{nu+1} (|y| + |D| |u|)

(``x̄``, ``d̄``: bounds on ``|x[j]|``, ``|d[j]|``). The second term covers the computation of the
right-hand side ``B u`` or ``y - D u``; the first lets the data be a floating-point simulation of
the model (a trajectory from :func:`ivobs.simulate`, a logger's rounding of ``y``). The program
is therefore a relaxation of (LP) by rounding-level amounts: its hull contains the exact one and
exceeds it by about ``ε`` times the magnitudes involved.

The returned bounds are not the solver's objective values (which hold up to its tolerances) but
*safe dual bounds* [Neumaier2004]: for any multipliers ``λ``
and any box ``l <= z <= u`` containing the feasible set, with ``r = c - M^T λ``,

::

    min c^T z  >=  Σ_i min(λ_i b_i^lo, λ_i b_i^hi) + Σ_j min(r_j l_j, r_j u_j).       (S)

HiGHS's row duals give a ``λ`` for which (S) is tight; whatever the solver returns, (S) is valid.
(S) is evaluated in floating point and the rounding of that evaluation is subtracted, a bound
[Higham2002, §3.1] on dot products: with ``N`` the length of the longest sum,

::

    safe = fl(S) - γ_N ( Σ_i |λ_i| max|b_i| + Σ_j |r̂_j| w_j + Σ_i |λ_i| (|M| w)_i + |c|^T w )

(``w_j = max(|l_j|, |u_j|)``; the third term is the error of the reduced costs ``r̂`` computed
from ``λ``), rounded once more downwards. So the bound holds in exact arithmetic whatever ``λ``
is, and a bound too tight by rounding can never become, as a variable bound of later programs, a
constraint that cuts the true trajectory. Every variable bound is itself proven: ``x[0] ∈ x0``,
``d[j] ∈ d_j`` (the model), ``x[k]`` within the interval prediction from ``x[k-1]``
([Efimov2013, Lemma 1], widened by the same kind of error term and the dynamics range), and each
past ``x[j]`` within the box proven at step ``j`` (widened by :data:`~.rows.VAR_MARGIN`
relative, which keeps the optimum off those implied bounds); none of them changes the optimum.

Moving window (``window=N``): only the blocks ``j = k-N .. k`` are kept, ``x[k-N]`` constrained
to the box this estimator returned at step ``k-N`` (and every ``x[j]`` in the window to its own
box). Each step then costs a bounded amount; the box is still guaranteed and never tighter than
the full-horizon one (its constraints are implied by the full problem).

Faults and missing data. A measurement is reported inconsistent (``on_inconsistent``) only with a
*certificate*: HiGHS declares the program infeasible and its dual ray ``λ`` satisfies (S) with
``c = 0`` and a safe value ``> 0`` (Farkas: ``0 >= safe > 0`` for any feasible ``z``), evaluated
as above, so the report is never false under the model's assumptions (the Monitor raises alarms
from it). The sample is then dropped and the step predicted without it. A sample that lies outside
what the interval prediction of ``x[k]`` can explain ([Efimov2013, Lemma 1], rounding
subtracted) is certified inconsistent before any LP (gross faults, and right-hand sides beyond
HiGHS's infinite bound ``1e20``, which HiGHS would take as free rows). When HiGHS says
infeasible but no certificate holds (a warm start may stall at a tiny infeasibility: the verdict
is retaken from a cold start with the dual, then the primal simplex), the sample is dropped
*silently*: the box is still guaranteed (the program without ``y[k]``, or the interval
prediction), only less tight. NaN components of ``y[k]`` are missing: their rows are free rows
(no constraint).

Data used: ``x0``, the bounds ``d`` and ``u[0..k]``, ``y[0..k]`` for the box of ``x[k]`` (the
filtered hull; ``d[k]`` enters through ``y[k]``).

Every bound the estimator returns is therefore proven in floating point (``proven_rounding``:
the base class adds no margin).

Layout: :mod:`.safe` (the safe bounds (S) and the Farkas certificate), :mod:`.rows` (the rows
and their rounding ranges, the interval prediction, the gross-fault test), :mod:`.program` (the
sparse trajectory program), :mod:`.highs` (the warm-started models,
:class:`ivobs.sets.lp.LinearProgram`, and their cache outside the online state),
:mod:`.estimator` (the estimator, its design and its state).
"""

from __future__ import annotations

from .estimator import Exact, ExactDesign, ExactState

__all__ = ["Exact", "ExactDesign", "ExactState"]
