"""Gains for cooperative interval observers: ``A − LC`` nonnegative, or ``|A − LC|`` Schur.

Papers: [Tang2019, Section V.A, Theorem 4, LMI (41)]; [Efimov2013, Theorem 1 (Assumption 2),
Theorem 3 and Corollary 1, LMIs (7)–(8)].

Notation: ``D = A − LC`` ([Efimov2013]'s ``D``), ``G = E − LF`` (how ``d`` enters the estimation
error), ``Δ = d_hi − d_lo`` (widths of the disturbance box).

* :func:`nonnegative_gain` — LMI (41) of [Tang2019] (= LMIs (7)–(8) of [Efimov2013]): diagonal
  ``P ≻ 0``, ``[[P, PA − YC], [(PA − YC)ᵀ, P]] ≻ 0``, ``PA − YC ≥ 0``, ``L = P⁻¹Y``. Since ``P`` is
  diagonal and positive, ``PA − YC = PD ≥ 0`` iff ``D ≥ 0``, and the Schur complement is
  ``P − DᵀPD ≻ 0``. For a nonnegative ``D`` a diagonal Lyapunov matrix exists iff ``D`` is Schur
  (a classical fact on positive systems), so the LMI is feasible iff *some* ``L`` makes ``D``
  nonnegative and Schur: an infeasible LMI means no such gain exists ([Tang2019, Example 2],
  [Efimov2013, §IV.A]). ivobs maximises the margin ``μ`` in ``[[P, PD], [·, P]] ⪰ μ I`` with
  ``P ⪯ I`` (the paper states a feasibility problem; the margin makes the answer well defined).
* :func:`abs_schur_gain` — a gain with ``ρ(|A − LC|) < 1`` (the stability condition of
  [Efimov2013]'s observer (5): the bounds' radius obeys ``r+ = |D| r + …``). ``ρ(|D|) <= s``
  whenever ``|D| v <= s v`` for some ``v > 0``; for a fixed ``v`` this is a linear program in
  ``(L, s)`` (auxiliary ``T >= ±D``). The LP alternates with ``v ←`` Perron vector of ``|D|``;
  ``s`` never increases.
* :func:`refine_width` — the tightness objective ivobs adds (documented, not in the papers): for
  constant bounds the bounds' width obeys ``w+ = |D| w + |G| Δ``, whose fixed point
  ``w∞ = (I − |D|)⁻¹ |G| Δ`` is the steady-state width. Given the current ``w∞ = w_j``, any
  gain with ``|D'| w_j + |G'| Δ <= w_j`` (linear in ``L`` through ``T_D >= ±D'``,
  ``T_G >= ±G'``) has ``w∞' <= w_j`` componentwise (the iteration from ``w_j`` decreases
  monotonically). Each LP picks such a gain minimising the one-step image, then ``w_{j+1} = w∞'``.
  For ``interval`` the constraint ``D' >= 0`` is kept (then ``|D'| = D'``).

**Smallest gain among the optimal ones**. The LP objectives above do not always fix
``L``: with redundant noise-free outputs (``ny > nx``, ``F = 0`` or zero-width bounds) the part of
``L`` in the left null space of ``C`` changes neither ``A − LC`` nor ``E − LF``, and HiGHS returns
any vertex, e.g. ``L = (−999999.1, 10⁶)`` at the ``|L_ij| <= 10⁶`` box. Such a gain is harmless
with every output present, but the estimators use ``L_k = L diag(observed)`` when an output is
missing: ``|A − L_k C| ≈ 10⁶`` and the bounds explode (0.2 → 2·10¹⁷ in three steps). Each LP is
therefore solved in two stages: after the optimum ``q_iᵀx*`` of each objective part ``q_i``, a
second LP keeps ``q_iᵀx <= q_iᵀx* + τ·max(1, |q_iᵀx*|)`` (``τ = 1e-12``, or ``1e-9`` should HiGHS
find that infeasible: :data:`.cooperative_lp.OPT_TOL`; the tie-break of the margin LP is its own
part) and minimises ``max_j Σ_i w_j |L_ij| + REG_L1 Σ_ij w_j |L_ij|`` with ``w_j = ‖C_j‖₁``: since
``|A − L_(j) C| <= |A − LC| + |L_:j| |C_j|`` (``L_(j)``: column ``j`` zeroed), the largest
weighted column norm bounds how much any single missing output can degrade the error
dynamics; the weighted ℓ₁ term decides the remaining ties. On the redundant example the gain
becomes ``(0.45, 0.45)``. Optimal values move by at most ``τ`` (relative), which changed the
paper examples' gains by ``<= 1e-11`` and their widths by ``<= 1.3e-11`` (relative).
:func:`missing_radius` reports ``ρ(|A − L_(j) C|)`` per output; :func:`refine_width` never trades a
single-output gap that its start gain rides out (radius ``< 1``) for a diverging one.

Nothing here loops over time; LPs go to HiGHS (``scipy.optimize.linprog``), LMIs to CVXPY
(:func:`ivobs.design._lmi.solve`). Every result is checked on the numbers it returns.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

from ..errors import DesignError
from ..linalg import spectral_radius
from ._lmi import check_size, solve, sym
from .balance import state_scaling
from .cooperative_lp import (
    COPOSITIVE_TOL,
    L_BOUND,
    LP,
    abs_bound_rows,
    copositive_lp,
    output_weights,
    solve_lp,
)

__all__ = [
    "NONNEG_TOL",
    "abs_schur_gain",
    "check_abs_schur",
    "check_nonnegative_schur",
    "fixed_radius",
    "missing_radius",
    "nonnegative_gain",
    "refine_width",
    "steady_width",
]

NONNEG_TOL = 1e-9
"""Entries of ``A − LC`` above ``−NONNEG_TOL·max(1, max|A|)`` count as nonnegative (solver
round-off). The estimators propagate with the ``D⁺/D⁻`` split, so such entries stay sound."""

_MU_MIN = 1e-7  # LMI (41) margin below which the LMI is considered infeasible


def steady_width(D: np.ndarray, G: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``w∞ = (I − |D|)⁻¹ |G| Δ``: steady-state width of the bounds of observers (3)/(5) of
    [Efimov2013]
    for constant bounds (``inf`` where ``|D|`` is not Schur)."""
    Dabs = np.abs(D)
    n = D.shape[0]
    if spectral_radius(Dabs) >= 1.0:
        return np.full(n, np.inf)
    return np.linalg.solve(np.eye(n) - Dabs, np.abs(G) @ delta)


def missing_radius(A: np.ndarray, C: np.ndarray, L: np.ndarray) -> np.ndarray:
    """``ρ(|A − L_(j) C|)`` for each output ``j`` missing alone (``L_(j)``: ``L`` with column
    ``j`` set to zero, the gain the estimators use then): the growth rate of the bounds' width
    while output ``j`` is missing (``>= 1``: they grow until it returns)."""
    out = np.empty(C.shape[0])
    for j in range(C.shape[0]):
        Lj = np.array(L, dtype=float)
        Lj[:, j] = 0.0
        out[j] = spectral_radius(np.abs(A - Lj @ C))
    return out


def _structural_obstruction(A: np.ndarray, C: np.ndarray) -> str:
    """An entry of ``A − LC`` that is negative for every ``L`` (its column of ``C`` is zero)."""
    found = np.argwhere(((A < 0) & ~np.any(C != 0.0, axis=0)[None, :]).T)  # column by column
    if not found.size:
        return ""
    j, i = found[0]
    return (
        f"; entry ({i + 1}, {j + 1}) of A − LC equals A[{i + 1}, {j + 1}] = "
        f"{A[i, j]:g} < 0 for every L (column {j + 1} of C is zero)"
    )


def fixed_radius(A: np.ndarray, C: np.ndarray) -> float:
    """A lower bound of ``ρ(|A − LC|)`` over all ``L``: the columns ``Z`` where ``C`` is zero are
    not touched by ``L``, so ``|A − LC|`` contains the principal block ``|A[Z, Z]|`` and (Perron–
    Frobenius monotonicity) ``ρ(|A − LC|) >= ρ(|A[Z, Z]|)``."""
    Z = np.flatnonzero(~np.any(C != 0.0, axis=0))
    return spectral_radius(np.abs(A[np.ix_(Z, Z)])) if Z.size else 0.0


def check_nonnegative_schur(A: np.ndarray, C: np.ndarray, L: np.ndarray, who: str) -> np.ndarray:
    """Return ``D = A − LC`` or raise :class:`DesignError` naming the negative entry or the
    spectral radius ([Tang2019, Theorem 4] / [Efimov2013, Assumption 2])."""
    D: np.ndarray = A - L @ C
    tol = NONNEG_TOL * max(1.0, float(np.max(np.abs(A), initial=0.0)))
    if np.any(D < -tol):
        i, j = np.unravel_index(int(np.argmin(D)), D.shape)
        raise DesignError(
            f"{who}: A − LC is not nonnegative: entry ({i + 1}, {j + 1}) = {D[i, j]:.6g} < 0 "
            "([Tang2019, Theorem 4] / [Efimov2013, Assumption 2.B] need A − LC >= 0); use "
            "'interval-split' or 'interval-transformed' with this gain"
        )
    rho = spectral_radius(D)
    if rho >= 1.0:
        raise DesignError(
            f"{who}: A − LC is not Schur: spectral radius {rho:.6g} >= 1 "
            "([Efimov2013, Assumption 2.A])"
        )
    return D


def check_abs_schur(A: np.ndarray, C: np.ndarray, L: np.ndarray, who: str) -> np.ndarray:
    """Return ``D = A − LC`` or raise :class:`DesignError` when ``|D| = D⁺ + D⁻`` is not Schur
    (the stability condition of [Efimov2013, Theorem 3])."""
    D: np.ndarray = A - L @ C
    rho = spectral_radius(np.abs(D))
    if rho >= 1.0:
        raise DesignError(
            f"{who}: |A − LC| = D⁺ + D⁻ is not Schur: spectral radius {rho:.6g} >= 1 "
            f"([Efimov2013, Theorem 3]; ρ(A − LC) = {spectral_radius(D):.4g}); the bounds would "
            "diverge"
        )
    return D


# -- LMI (41) ---------------------------------------------------------------------------------
def nonnegative_gain(A: np.ndarray, C: np.ndarray, who: str = "interval") -> np.ndarray:
    """Gain ``L`` with ``A − LC`` nonnegative and Schur from LMI (41) of [Tang2019] (LMIs (7)–(8)
    of [Efimov2013]), maximising the margin ``μ`` (see the module docstring), solved in balanced
    coordinates (:func:`ivobs.design.balance.state_scaling`). Where the LMI route refuses (solver
    trouble, a margin below its threshold, or a gain that fails the check), the linear program
    :func:`~ivobs.design.cooperative_lp.copositive_lp` decides: its gain (checked) is returned,
    or :class:`DesignError` says what it proved (no gain exists, certified by its optimum) or
    that HiGHS failed."""
    check_size(A.shape[0], f"{who}: LMI (41)")
    reason = _structural_obstruction(A, C)
    if reason:
        raise DesignError(
            f"{who}: no gain L makes A − LC nonnegative and Schur{reason} ([Tang2019, LMI (41)] "
            "is infeasible); use 'interval-split' or 'interval-transformed'"
        )
    try:
        return _lmi41_gain(A, C, who)
    except DesignError as exc:
        lmi_error = str(exc)
    return _lp_gain(A, C, who, lmi_error)


def _lmi41_gain(A: np.ndarray, C: np.ndarray, who: str) -> np.ndarray:
    """LMI (41) in the balanced coordinates ``x = diag(dv) x̃`` (``Ã = D⁻¹AD``, ``C̃ = CD``,
    ``L = D L̃``: ``A − LC = D (Ã − L̃C̃) D⁻¹``, same signs and spectrum), checked."""
    import cvxpy as cp

    dv = state_scaling(A, C)
    At, Ct = A * dv[None, :] / dv[:, None], C * dv[None, :]
    n, p = A.shape[0], C.shape[0]
    pvec = cp.Variable(n)
    Y = cp.Variable((n, p))
    mu = cp.Variable()
    P = cp.diag(pvec)  # type: ignore[attr-defined]  # cvxpy exports its atoms by a star import
    X = P @ At - Y @ Ct
    big = cp.bmat([[P, X], [X.T, P]])  # type: ignore[attr-defined]  # (the same)
    cons = [sym(big) >> mu * np.eye(2 * n), X >= 0, pvec <= 1.0, mu <= 1.0]
    prob = cp.Problem(cp.Maximize(mu), cons)
    solve(prob, f"{who}: LMI (41) (A − LC nonnegative and Schur)")
    assert mu.value is not None and pvec.value is not None and Y.value is not None  # solved
    mu_val = float(mu.value)
    if mu_val <= _MU_MIN:
        raise DesignError(f"{who}: LMI (41) margin μ = {mu_val:.3g} <= {_MU_MIN:g}")
    L = dv[:, None] * np.linalg.solve(np.diag(pvec.value), Y.value)
    return _finish(A, C, L, who)


def _finish(A: np.ndarray, C: np.ndarray, L: np.ndarray, who: str) -> np.ndarray:
    """``L`` moved to the nearest gain with ``A − LC >= 0`` if round-off left it slightly
    negative, then checked (:func:`check_nonnegative_schur`)."""
    tol = NONNEG_TOL * max(1.0, float(np.max(np.abs(A), initial=0.0)))
    if np.any(A - L @ C < -tol):
        L = _nearest_nonnegative_gain(A, C, L)
    check_nonnegative_schur(A, C, L, who)
    return L


def _lp_gain(A: np.ndarray, C: np.ndarray, who: str, lmi_error: str) -> np.ndarray:
    """The gain of :func:`copositive_lp` (checked), or the :class:`DesignError` it justifies."""
    L, s, status = copositive_lp(A, C)
    if L is not None:
        try:
            return _finish(A, C, L, who)
        except DesignError as exc:
            raise DesignError(
                f"{who}: the linear program (copositive Lyapunov function, module "
                f"ivobs.design.cooperative_lp) proves that a gain making A − LC nonnegative and "
                f"Schur exists (margin {s:.3g} > 0), but the gain extracted from it fails its "
                f"check ({exc}); LMI (41) failed as well ({lmi_error}). Rescale the states "
                "(e.g. to comparable magnitudes) or pass a gain L=..."
            ) from None
    if np.isnan(s):
        raise DesignError(
            f"{who}: neither LMI (41) ({lmi_error}) nor the linear program deciding whether a "
            f"gain making A − LC nonnegative and Schur exists could be solved (HiGHS: {status}); "
            "rescale the states or pass a gain L=..., or use 'interval-split'"
        )
    if s == -np.inf:
        raise DesignError(
            f"{who}: no gain L makes A − LC nonnegative (let alone Schur): the linear program "
            "L_i C <= A_i (row i of L and of A) is infeasible, proved by HiGHS ([Tang2019, LMI "
            "(41)] is infeasible); use 'interval-split' or 'interval-transformed'"
        )
    if s < -COPOSITIVE_TOL:
        raise DesignError(
            f"{who}: no gain L makes A − LC nonnegative and Schur: the linear program (q >= 1, "
            "Y = diag(q) L, diag(q) A − YC >= 0, qᵀA − 1ᵀYC <= qᵀ − s·1ᵀ) has the optimal "
            f"margin s = {s:.3g} < 0, which proves it ([Tang2019, LMI (41)] is infeasible); use "
            "'interval-split' or 'interval-transformed'"
        )
    raise DesignError(
        f"{who}: whether a gain makes A − LC nonnegative and Schur is undecided: the linear "
        f"program's optimal margin s = {s:.3g} is within HiGHS's tolerance of 0 (any such gain "
        "leaves A − LC with a spectral radius within about that of 1), and LMI (41) refused "
        f"({lmi_error}); use 'interval-split' or 'interval-transformed', or pass a gain L=..."
    )


def _nearest_nonnegative_gain(A: np.ndarray, C: np.ndarray, L: np.ndarray) -> np.ndarray:
    """The gain closest to ``L`` (``Σ |L'_ij − L_ij|``) with ``A − L'C >= 0``, by LP (HiGHS).

    The SDP solver meets ``P A − Y C >= 0`` only to its tolerance, so ``L = P⁻¹ Y`` may leave
    entries of ``A − LC`` slightly negative (e.g. ``−4e-9`` on ``kkl-random8``); the LP moves
    ``L`` by about as much, which keeps the spectral radius (checked by the caller). The entries
    that ``L`` can move are kept ``1e-6 max(1, max|A|)`` above zero if possible (HiGHS meets its
    constraints only to its own tolerance). Returns ``L`` unchanged if the LP fails."""
    n, p = L.shape
    m = A.shape[1]
    # variables: L' (row-major, n p), t (n p) with |L' − L| <= t; rows (L' C)_ij <= A_ij
    rows = np.hstack([np.kron(np.eye(n), C.T), np.zeros((n * m, n * p))])
    eye = np.eye(n * p)
    A_ub = np.vstack([rows, np.hstack([eye, -eye]), np.hstack([-eye, -eye])])
    c = np.concatenate([np.zeros(n * p), np.ones(n * p)])
    bounds = [(None, None)] * (n * p) + [(0, None)] * (n * p)
    # entries that L can move get a margin above HiGHS's feasibility tolerance (else none)
    movable = (np.abs(C).sum(axis=0) > 0)[None, :].repeat(n, axis=0).ravel()
    scale = max(1.0, float(np.max(np.abs(A), initial=0.0)))
    for margin in (1e-6 * scale, 0.0):
        b_ub = np.concatenate([A.ravel() - margin * movable, L.ravel(), -L.ravel()])
        res = linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs",
                      options={"primal_feasibility_tolerance": 1e-10})  # fmt: skip
        if res.status == 0:
            gain: np.ndarray = res.x[: n * p].reshape(n, p)
            return gain
    return L


def _margin_lp(A: np.ndarray, C: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, float] | None:
    """min s s.t. T v <= s v, T >= ±(A − LC): ``ρ(|A − LC|) <= s``."""
    n, p = A.shape[0], C.shape[0]
    lp = LP(n, p, {"T": n * n, "s": 1})
    A1, b1 = abs_bound_rows(lp.lin(A, C), lp.aux("T", n * n))
    # (T v)_i − s v_i <= 0
    A2 = np.zeros((n, lp.size))
    A2[:, lp.offset["T"] : lp.offset["T"] + n * n] = np.kron(np.eye(n), v)
    A2[:, lp.offset["s"]] = -v
    c_s = np.zeros(lp.size)
    c_s[lp.offset["s"]] = 1.0
    # tie-break among optimal gains: the smallest |A − LC| v (degenerate optima otherwise stall
    # the alternation, e.g. [Efimov2013]'s planar example at ρ = 0.7 instead of 0.5)
    c_t = np.zeros(lp.size)
    c_t[lp.offset["T"] : lp.offset["T"] + n * n] = np.tile(v, n) / v.sum()
    c = c_s + 1e-6 * c_t
    bounds = [(-L_BOUND, L_BOUND)] * (n * p) + [(0, None)] * (n * n) + [(0, None)]
    x = solve_lp(
        c,
        np.vstack([A1, A2]),
        np.concatenate([b1, np.zeros(n)]),
        bounds,
        (n, output_weights(C)),
        [c_s, c_t],
    )
    if x is None:
        return None
    return lp.gain(x), float(x[lp.offset["s"]])


def _perron_vector(M: np.ndarray) -> np.ndarray:
    """Positive right Perron vector of a nonnegative matrix (regularised for reducible ones)."""
    n = M.shape[0]
    Mr = M + 1e-9 * max(1.0, float(M.max(initial=0.0))) * np.ones((n, n))
    w, V = np.linalg.eig(Mr)
    v = np.abs(np.real(V[:, int(np.argmax(np.real(w)))]))
    v = v / v.max()
    out: np.ndarray = np.maximum(v, 1e-8)
    return out


def abs_schur_gain(A: np.ndarray, C: np.ndarray, iters: int = 30) -> tuple[np.ndarray, float]:
    """Gain minimising (locally) ``ρ(|A − LC|)`` by the alternating LP of the module docstring.

    Starts from ``L = 0`` and ``v = 1``. Returns ``(L, ρ(|A − LC|))``; the caller decides
    whether ``ρ < 1`` is good enough.
    """
    n, p = A.shape[0], C.shape[0]
    v = np.ones(n)
    best_L = np.zeros((n, p))
    best_rho, prev = spectral_radius(np.abs(A)), np.inf
    for _ in range(iters):
        out = _margin_lp(A, C, v)
        if out is None:
            break
        L, _s = out
        Dabs = np.abs(A - L @ C)
        rho = spectral_radius(Dabs)
        if rho < best_rho:
            best_L, best_rho = L, rho
        if rho > prev - 1e-9:
            break
        prev = rho
        v = _perron_vector(Dabs)
    return best_L, best_rho


def refine_width(
    A: np.ndarray,
    C: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    delta: np.ndarray,
    L0: np.ndarray,
    *,
    nonnegative: bool,
    iters: int = 30,
) -> np.ndarray:
    """Decrease the steady-state width ``(I − |D|)⁻¹ |G| Δ`` from a stable start ``L0``
    (module docstring). ``nonnegative=True`` keeps ``A − LC >= 0`` (observer (3)/(36));
    otherwise only ``|A − LC|`` Schur is kept (observer (5)). Never returns a gain whose
    steady-state width is larger (componentwise) than ``L0``'s, nor one that makes the bounds
    diverge during a gap of one output that ``L0`` rides out: every output ``j`` with
    ``ρ(|A − L0_(j) C|) < 1`` (:func:`missing_radius`) keeps ``ρ(|A − L_(j) C|) < 1`` (the
    refinement stops at the last gain that does)."""
    n, p = A.shape[0], C.shape[0]
    m = E.shape[1]
    L = L0
    gaps = missing_radius(A, C, L) < 1.0  # single-output gaps L0 rides out
    w = steady_width(A - L @ C, E - L @ F, delta)
    if m == 0 or not np.all(np.isfinite(w)) or not np.any(delta > 0):
        return L
    lp = LP(n, p, {"T": n * n, "TG": n * m})
    D_lin = lp.lin(A, C)
    G_rows, G_b = abs_bound_rows(lp.lin(E, F), lp.aux("TG", n * m))
    if nonnegative:  # D >= 0 and T = D: T − D = 0 expressed as two inequalities
        coef, const = D_lin
        aux = lp.aux("T", n * n)
        D_rows = np.vstack([coef - aux, aux - coef, -coef])
        D_b = np.concatenate([-const, const, const])
    else:
        D_rows, D_b = abs_bound_rows(D_lin, lp.aux("T", n * n))
    bounds = [(-L_BOUND, L_BOUND)] * (n * p) + [(0, None)] * (n * n + n * m)
    weights = (n, output_weights(C))
    for _ in range(iters):
        # one-step image  T w + TG Δ  (row i), constrained <= w, objective Σ_i image_i / w_i
        img = np.zeros((n, lp.size))
        img[:, lp.offset["T"] : lp.offset["T"] + n * n] = np.kron(np.eye(n), w)
        img[:, lp.offset["TG"] : lp.offset["TG"] + n * m] = np.kron(np.eye(n), delta)
        scale = 1.0 / np.maximum(w, 1e-12 * max(1.0, float(w.max())))
        c = scale @ img
        x = solve_lp(
            c, np.vstack([D_rows, G_rows, img]), np.concatenate([D_b, G_b, w]), bounds, weights
        )
        if x is None:
            break
        L_new = lp.gain(x)
        D_new = A - L_new @ C
        if nonnegative and np.any(D_new < -NONNEG_TOL * max(1.0, float(np.abs(A).max()))):
            break
        w_new = steady_width(D_new, E - L_new @ F, delta)
        if not np.all(np.isfinite(w_new)) or spectral_radius(np.abs(D_new)) >= 1.0 - 1e-9:
            break
        if np.any(w_new > w * (1 + 1e-9) + 1e-15):
            break
        if gaps.any() and np.any(missing_radius(A, C, L_new)[gaps] >= 1.0):
            break
        gain = float(np.sum((w - w_new) * scale))
        L, w = L_new, w_new
        if gain < 1e-6:
            break
    return L
