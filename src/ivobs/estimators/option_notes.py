"""What each option of the built-in methods does and when to change it: the one text that
``ivobs methods --options``, :func:`ivobs.config.describe` and docs/options.md print.

The options themselves and their defaults are the classes' ``__init__`` signatures
(:meth:`Estimator.option_defaults <ivobs.estimators.Estimator.option_defaults>`); this module
holds only the prose. :data:`COMMON` documents the options of every method (declared by
:class:`~ivobs.estimators.Estimator` itself), :data:`NOTES` those of each method; a method that
redeclares a common option has its own note. tests/test_config.py checks that every option of
every built-in method has a note here and that no note names an option that is gone.
"""

from __future__ import annotations

from typing import NamedTuple

__all__ = ["COMMON", "NOTES", "Note", "note"]


class Note(NamedTuple):
    """One option: ``what`` it does (the meaning of its default included) and ``when`` to
    change it."""

    what: str
    when: str


_GAIN_L = Note(
    "The observer gain L (nx × ny), with A − LC Schur. None: designed as `gain` says.",
    'To reproduce a paper\'s comparison "with the same gain" or reuse a gain designed '
    "elsewhere; otherwise rarely (the designed gain is the narrowest ivobs knows).",
)

_GAIN_LUENBERGER = "The design when `L` is not given: 'radius' (the gain minimising the " + (
    "steady-state box), 'hinf' (the H∞ gain of [Tang2019, Theorem 1] by Riccati equations) or "
    "'hinf-lmi' (the same problem by the paper's LMI); docs/gains.md."
)

_FINITE_MEMORY = Note(
    "Intersect each box with the bound that the last N complete steps give alone (N: the "
    "observability index of (A, C)); dense time-invariant systems with exact matrices and "
    "constant bounds, up to 50 states.",
    "False for the observer's own boxes (the papers' numbers, or a comparison with other "
    "recursions), or to save its cost per step() (about 40 % of a step on the servo) where it "
    "is never the tighter bound.",
)

COMMON: dict[str, Note] = {
    "on_inconsistent": Note(
        "What a measurement that contradicts the model and its bounds does: 'warn' (a warning "
        "naming the steps), 'raise' (InconsistentDataError at the first) or 'ignore'; the step "
        "is predicted without it in every case and flagged in `Estimate.inconsistent`.",
        "'raise' where an inconsistency must stop the run (a test, a model being validated); "
        "'ignore' when you read `Estimate.inconsistent` or `est.last_inconsistent` yourself.",
    ),
    "strips": Note(
        "Meet each box of x[k] with the measurement strips of y[k] (C_i x ∈ y_i − D_i u − F_i "
        "[d], outward rounded; linear models, exactly known output rows). None: on for the "
        "filter-form methods, off for the prediction-form observers (`reachability`, "
        "`zonotope`, the `interval` family), which then give the papers' boxes.",
        "True for a prediction-form observer whose boxes should never be wider than a sensor's "
        "band (`compare`, campaigns and the monitor pass it); False to see a filter method's "
        "own recursion.",
    ),
}
"""The options declared by :class:`~ivobs.estimators.Estimator`: every method has them."""

NOTES: dict[str, dict[str, Note]] = {
    "fixed-time": {
        "s": Note(
            "The window length minus one: the box of x[k] uses the last s + 1 samples and is "
            "valid from k = s. None: nx − 1 up to 10 states, the observability index + 1 "
            "above.",
            "To reproduce a paper's window, or to start earlier or later; a longer window "
            "does not narrow Theorem 1's boxes (they can widen, docs/fixed_time.md), "
            "with criterion='width' it never widens them.",
        ),
        "T": Note(
            "An explicit gain (nx × (s+1)·ny) with T Mx = I (eq. 8). None: the optimal T of "
            "`criterion`.",
            "Rarely: to reproduce a published design (time-invariant systems).",
        ),
        "S": Note(
            "The free matrix of the general solution T = Mx† + S Mx⊥ (Lemma 2), instead of T.",
            "Rarely: to explore the gains of Lemma 2, e.g. on a time-varying system.",
        ),
        "L": Note(
            "The output-injection gain of Remark 1 (L y becomes a known input). None: none "
            "when A is invertible and the design with A is accurate, else a small, "
            "well-conditioned gain chosen and certified by ivobs.",
            "Rarely: to impose a specific injection (a paper's) on a singular or "
            "ill-conditioned A.",
        ),
        "criterion": Note(
            "'frobenius': Theorem 1's T, minimising ‖T Md‖_F; 'width' (not in the paper): each "
            "box width of eq. (11) minimised by one linear program per state at design time.",
            "'width' for narrower boxes that never widen with s (time-invariant systems with "
            "constant bounds); keep 'frobenius' for the paper's numbers.",
        ),
        "weighted": Note(
            "With criterion='frobenius', minimise ‖T Md Wd‖_F (the disturbance weighted by its "
            "bounds) instead of the paper's ‖T Md‖_F.",
            "When the disturbance components have very different bounds and you keep the "
            "Frobenius criterion (constant bounds only); criterion='width' usually does "
            "better.",
        ),
        "check_consistency": Note(
            "Test the parity residual against its proven bound at each step; a violation "
            "proves that the data contradict the model (reported, the box then predicted).",
            "Rarely: False skips the test (a little faster) when inconsistencies need not be "
            "detected.",
        ),
    },
    "reachability": {
        "L": _GAIN_L,
        "memory": Note(
            "The window K of the finite-memory form that bounds the error after the first "
            "missing or inconsistent sample, with time-varying or measurement-dependent bounds "
            "and with interval matrices. None: the smallest K with ‖|M^K|‖∞ ≤ 1e-3, at most "
            "500.",
            "Larger for tighter boxes after missing samples when the gain converges slowly, at "
            "O(K nx² (nx + nd)) work per step; smaller for speed. No effect on complete data "
            "with constant bounds.",
        ),
        "gain": Note(
            f"{_GAIN_LUENBERGER} None: 'radius', falling back to the others in that order if "
            "its design fails (a DesignWarning says so).",
            "'hinf' or 'hinf-lmi' to reproduce [Tang2019]'s H∞ design ('hinf-lmi' up to 200 "
            "states); an explicit choice that fails raises instead of falling back.",
        ),
    },
    "zonotope": {
        "L": _GAIN_L,
        "order": Note(
            "q ≥ nx, the generators kept by the reduction. None: 10 nx. With constant bounds "
            "an order whose widths do not settle is refused (DesignError) with the next order "
            "that does.",
            "Raise it when a DesignWarning says the order boxes generators that still matter "
            "(A − LC contracts slowly) or to approach Algorithm 1; lower it for speed, the "
            "cost per step grows with q.",
        ),
        "weight": Note(
            "The positive definite W (nx × nx) that ranks the generators in the reduction (by "
            "hᵀ W h). None: the identity.",
            "Rarely: when the states have very different scales, to keep the generators of "
            "the states you care about.",
        ),
        "gain": Note(
            f"{_GAIN_LUENBERGER} None: 'radius', or 'hinf' when |A − LC| is not Schur and the "
            "H∞ gain's reduced zonotope is the narrower one over 60 or more steps.",
            "'hinf' or 'hinf-lmi' to reproduce [Tang2019]'s H∞ design; 'radius' to always take "
            "the radius gain.",
        ),
    },
    "interval": {
        "L": Note(
            "The gain L (nx × ny); A − LC must be nonnegative and Schur. None: designed as "
            "`gain` says.",
            "To reproduce a paper's gain (the papers' figures do); otherwise rarely.",
        ),
        "gain": Note(
            "'width': the global minimum of the steady-state width over every gain with "
            "A − LC nonnegative and Schur (one sparse linear program); 'lmi': [Tang2019]'s LMI "
            "(41); 'lmi+width': that gain refined by local linear programs.",
            "'lmi' to reproduce the paper's design; otherwise keep 'width', the narrowest.",
        ),
        "finite_memory": _FINITE_MEMORY,
    },
    "interval-transformed": {
        "L": Note(
            "The gain L (nx × ny), A − LC Schur, instead of ivobs' search (distinct real poles, "
            "the modal steady-state width lowered, then (L, e1) searched jointly).",
            "To reproduce a paper's design; otherwise rarely.",
        ),
        "poles": Note(
            "Distinct real poles in (−1, 1) for A − LC, placed by SciPy's place_poles, instead "
            "of L.",
            "To reproduce a design given by its poles; otherwise rarely (the search places "
            "them itself).",
        ),
        "R": Note(
            "A nonnegative matrix with the spectrum of A − LC, the target of S. None: a "
            "nonnegative realisation of that spectrum (diagonal, companion or circulant "
            "blocks).",
            "Rarely: to reproduce [Tang2019, eq. (48)] with a paper's R.",
        ),
        "S": Note(
            "The transformation z = S x itself (S (A − LC) S⁻¹ must be nonnegative), instead "
            "of eq. (48).",
            "Rarely: to reuse a known transformation.",
        ),
        "e1": Note(
            "The row e1 of [Tang2019, eq. (48)] (observability matrix of (A − LC, e1)). None: "
            "the observable choice with the smallest steady-state width.",
            "Rarely: to reproduce the paper's S.",
        ),
        "e2": Note(
            "The row e2 of [Tang2019, eq. (48)] (observability matrix of (R, e2)). None: the "
            "observable choice with the smallest steady-state width.",
            "Rarely: to reproduce the paper's S.",
        ),
        "transform": Note(
            "'auto': ivobs' search up to 8 states, else (or where the search fails) S = I with "
            "the width-optimal gain when one makes A − LC nonnegative, else real Schur or "
            "modal coordinates (sound but looser); 'search': the search only; 'schur': the "
            "last route directly.",
            "'search' to get a DesignError instead of the looser fallback; 'schur' to skip the "
            "search's design time on a larger plant.",
        ),
        "finite_memory": _FINITE_MEMORY,
    },
    "interval-split": {
        "L": Note(
            "The gain L (nx × ny); |A − LC| must be Schur. None: designed as `gain` says.",
            "To reproduce a paper's gain; otherwise rarely.",
        ),
        "gain": Note(
            "'width': the global minimum of the steady-state width over every gain with "
            "|A − LC| Schur (one sparse linear program, which also proves when none exists); "
            "'lmi': [Efimov2013]'s LMIs (7)–(8) (A − LC nonnegative); 'margin': a local "
            "minimum of ρ(|A − LC|); 'margin+width': that gain refined by local linear "
            "programs.",
            "'lmi' to reproduce [Efimov2013]'s design, 'margin' for the fastest decay of the "
            "error rather than the narrowest steady state; otherwise keep 'width'.",
        ),
        "finite_memory": _FINITE_MEMORY,
    },
    "kkl": {
        "A_z": Note(
            "The target matrix A_z (nonnegative and Schur in discrete time, Metzler and "
            "Hurwitz in continuous time). None: a diagonal target tuned for width "
            "(time-invariant), blocks from the observability indices (time-varying).",
            "To reproduce [Dinh2024]'s examples or impose the observer's speed; the tuned "
            "default is usually narrower.",
        ),
        "B_z": Note(
            "The target input matrix B_z, with A_z: (A_z, B_z) controllable. None: chosen "
            "with the default A_z.",
            "With A_z, to reproduce [Dinh2024]'s examples.",
        ),
        "T": Note(
            "Time-invariant systems: an explicit solution of T A = A_z T + B_z C (eq. 4) for "
            "the given A_z, B_z. None: solved by ivobs.",
            "Rarely: to reuse a T computed elsewhere.",
        ),
        "T0": Note(
            "Time-varying systems: the transformation at the first step: 'zero' (z[0] = 0, no "
            "prior needed), 'sylvester' (eq. (4) frozen at the first step, used with x0) or a "
            "matrix. None: 'zero' in discrete time, 'sylvester' in continuous time.",
            "'sylvester' (with a prior box x0) in discrete time to start from the prior "
            "instead of z[0] = 0; otherwise rarely.",
        ),
        "gamma": Note(
            "Discrete-time, time-varying: the factor of the target, A_z = gamma Ã (16.a). None: 1.",
            "Smaller for a faster observer ([Dinh2024, Proposition 4]), e.g. when the design "
            "says no transformation becomes left-invertible in the horizon.",
        ),
        "ell": Note(
            "Continuous-time, time-varying: the factor of the target, A_z = ell Ã (11.a). "
            "None: 2, or the smallest value the flow rule needs.",
            "Larger for a faster observer ([Dinh2024, Proposition 3]); a DesignError names it "
            "when the flow rule fails.",
        ),
        "max_cond": Note(
            "The largest cond(T) accepted: time-invariant, above it a DesignError; "
            "time-varying, the threshold of left-invertibility that decides valid_from.",
            "Rarely: raise it to accept a poorly conditioned T (wider boxes) or lower it for "
            "a later but better-conditioned start of a time-varying observer.",
        ),
        "tune": Note(
            "Refine the default time-invariant target by gradient descent on the predicted "
            "width (after a search over candidate spreads).",
            "False for a faster design (the candidates only) or to compare with the untuned "
            "target; no effect with your own A_z, B_z.",
        ),
        "input_hold": Note(
            "Continuous time: the known input between samples: 'zero' (zero-order hold), "
            "'linear', or a callable t -> u(t) written with ivobs.nlmath.",
            "When the plant's input is not held between samples (a ramp, a known signal): the "
            "boxes are guaranteed only for the input the option describes.",
        ),
    },
    "strip": {
        "order": Note(
            "The generators kept between steps (at least nx). None: 10 nx. The cost per step "
            "grows with it (O(ny nx order)).",
            "To trade width for time: order = nx is the cheapest, 40 nx rarely tighter than 10 nx.",
        ),
        "reduction": Note(
            "'parallelotope': Chisci's absorption into a conditioned basis (Girard's box where "
            "it is ill-conditioned); 'girard': [Girard2005]'s box (CORA's default); 'box': "
            "[Combastel2015]'s box. The two boxes need order ≥ 2 nx.",
            "Only to reproduce another tool's results; the default is the one that stayed "
            "bounded on every system tried.",
        ),
        "weight": Note(
            "The positive definite W (nx × nx) that ranks the generators in the box reduction "
            "(by hᵀ W h). None: the identity.",
            "Rarely: with reduction='box', when the states have very different scales.",
        ),
    },
    "constrained-zonotope": {
        "max_constraints": Note(
            "The constraints kept between steps (at least 1). None: 2 nx.",
            "Raise it when the boxes are far from the `exact` hull on your system; each "
            "constraint costs a factor in every linear program.",
        ),
        "max_generators": Note(
            "The generators kept between steps (never fewer than the rank of the lifted "
            "generators). None: 16 nx.",
            "Raise it for tighter boxes (towards the exact hull), lower it for cheaper steps.",
        ),
        "reduce": Note(
            "Reduce the set to `max_constraints` and `max_generators` after each step. False: "
            "the exact filter, whose cost grows with the horizon.",
            "False only for short records or as a reference.",
        ),
        "elimination": Note(
            "How the constraint to eliminate is chosen: 'certificates' (the least loss of the "
            "LP-certified box bounds) or 'hausdorff' ([Scott2016]'s smallest Hausdorff-error "
            "estimate).",
            "'hausdorff' only to reproduce the paper's filter as published (looser).",
        ),
    },
    "exact": {
        "window": Note(
            "None: the whole horizon (the reference; the cost per step grows with k). N ≥ 1: a "
            "moving window of N past steps whose first state is bounded by this estimator's "
            "own box.",
            "A window for long records or online use (bounded cost per step, still "
            "guaranteed, never tighter); for a time-invariant system `dual-window` does the "
            "same faster.",
        ),
        "progress": Note(
            "A progress bar in run(): None when stderr is a terminal, True or False.",
            "False in scripts and logs that should stay quiet, True to see progress where "
            "stderr is not a terminal.",
        ),
        "on_inconsistent": Note(
            "What measurements that make the linear program infeasible do: 'warn', 'raise' "
            "(InconsistentDataError) or 'ignore'; the step is predicted without them.",
            "'raise' where an inconsistency must stop the run; 'ignore' when you read "
            "`Estimate.inconsistent` yourself.",
        ),
    },
    "dual-window": {
        "window": Note(
            "The past steps N whose data the bounds use (besides the box proven for x[k−N]). "
            "'auto': the shortest N whose first state's relative influence on the window's "
            "optimal bounds is at most 1 %, between 20 and 200 (`est.design.window`).",
            "Rarely: a fixed N to compare with `exact` with window=N, or a shorter window "
            "when the automatic one is too slow per step.",
        ),
        "cache": Note(
            "The LP multipliers kept per bound; every step evaluates all of them.",
            "Rarely: larger keeps more past optima (bounds closer to the hull between "
            "solves), each one more product per step; smaller for cheaper steps.",
        ),
        "refresh": Note(
            "The longest interval in steps between two solves of the window program.",
            "Rarely (the interval adapts below it, `refresh_tol`): lower it to solve at least "
            "that often, raise it for fewer solves on data whose optimum rarely moves.",
        ),
        "refresh_tol": Note(
            "The interval between solves adapts: halved when the cache's bounds were more "
            "than refresh_tol wider (relative) than the solve's, doubled when within a "
            "quarter of it, between a floor and `refresh`. None: every `refresh` steps.",
            "Smaller (0.02) for bounds closer to the exact hull at more solves; None for a "
            "cost fixed in advance.",
        ),
    },
    "intersect": {
        "methods": Note(
            "The members: method names, (name, options) pairs or built estimators. None: "
            "reachability, zonotope, strip, fixed-time, interval-split and kkl, each where "
            "it can be designed (the others in `design.skipped`).",
            "To choose the members (e.g. add `constrained-zonotope` for tightness, or keep "
            "the fastest ones).",
        ),
        "on_inconsistent": Note(
            "What an empty intersection, or a member's report of an inconsistent measurement, "
            "does: 'warn', 'raise' (InconsistentDataError) or 'ignore'.",
            "'raise' where an inconsistency must stop the run; 'ignore' when you read "
            "`Estimate.inconsistent` yourself.",
        ),
        "strips": Note(
            "Also meet the intersection with the measurement strips of y[k] (every exactly "
            "known output row). None: on.",
            "Rarely: False to see the members' intersection alone.",
        ),
    },
    "nl-interval": {
        "lag": Note(
            "How far back the measurement contracts the box: 1, one step back through h∘f; "
            "0, not at all; L from 2 to 10, the last L steps as one contractor network.",
            "0 when every state is seen by the outputs of its own step or h∘f is costly (a "
            "validated flow); 2–3 when the outputs see a state only through several steps "
            "(tighter, about L times a step back's cost; not for sampled continuous-time "
            "plants).",
        ),
        "window": Note(
            "Steps M of the window-centred form (affine enclosures of the last M transitions "
            "composed with an output correction, met with the box); None: 20 where the model's "
            "boxes would wrap (judged from the Jacobian at the prior's centre), else 0.",
            "0 for the box form alone (several times faster per step) where the boxes stay "
            "narrow; a number to force the form on a model that rotates or couples its states "
            "away from the prior's centre.",
        ),
    },
    "nl-zonotope": {
        "order": Note(
            "The generators kept by the reduction (at least nx); the set is reduced when it "
            "holds more than 1.5 order. None: 10 nx.",
            "Raise it when the widths are far above `nl-constrained-zonotope`'s on a model "
            "with many states (each generator costs time at every step); lower it for speed.",
        ),
        "box_strips": Note(
            "Also cut the zonotope with the natural-inclusion box where that box is tighter.",
            "True on strongly curved maps whose natural inclusion is sharp (the Hénon map); "
            "elsewhere the extra generators can cost more than the cut gains.",
        ),
    },
    "nl-constrained-zonotope": {
        "max_constraints": Note(
            "The constraints kept between steps. None: 2 nx.",
            "Raise it for tighter boxes at the cost of larger linear programs at every step.",
        ),
        "max_generators": Note(
            "The generators kept between steps. None: 16 nx.",
            "Raise it for tighter boxes, lower it for cheaper steps.",
        ),
    },
    "nl-horizon": {
        "window": Note(
            "The past steps N kept in the program, each linearised over the box proven for its "
            "state. None: 20.",
            "Raise it on plants whose slow states are seen only over many samples (each step "
            "costs linear programs over N + 1 blocks); lower it for cheaper steps.",
        ),
        "passes": Note(
            "Re-linearisations of the newest measurement over the box just proven, per step "
            "(the next stops when no bound moved by 1 % of its width). None: 1.",
            "0 for a cheaper step where the predictions are already tight (the late widths of "
            "the scenarios change by at most 0.3 %); more where they are wide against the "
            "curvature of h.",
        ),
    },
}
"""Method name -> option -> :class:`Note`, for the options each method declares itself."""


def note(method: str, option: str) -> Note | None:
    """The note of ``option`` of the built-in ``method`` (its own, else the common one);
    ``None`` for an option no note covers (a method defined outside ivobs)."""
    return NOTES.get(method, {}).get(option) or COMMON.get(option)
