"""The steady-state-width-optimal gain of ``interval`` and ``interval-split``: one sparse LP.

Papers: the observers of [Tang2019, eqs. (36)–(41)] / [Efimov2013, Theorem 1, eq. (3)]
(``D = A − LC >= 0`` and Schur) and [Efimov2013, Theorem 3, eq. (5)] (``|D|`` Schur, any
sign). The width objective is ivobs' (not in the papers); the LP is exact, not a heuristic.

For constant bounds the bounds' width obeys ``w+ = |D| w + |G| Δ`` (``G = E − LF``,
``Δ = d_hi − d_lo``), whose fixed point ``w∞ = (I − |D|)⁻¹ |G| Δ`` is the steady-state width.
For weights ``c > 0`` and any ``q >= 0`` with ``|D|ᵀ q <= q − c``,

    cᵀ w∞ <= (q − |D|ᵀq)ᵀ w∞ = qᵀ (I − |D|) w∞ = qᵀ |G| Δ,

with equality at ``q = (I − |D|ᵀ)⁻¹ c``. Hence ``min_L cᵀ w∞ = min_{L, q} qᵀ|G|Δ`` subject to
``|D|ᵀ q <= q − c`` (which also certifies ``ρ(|D|) < 1``: ``V(e) = qᵀe`` is a linear copositive
Lyapunov function, [Efimov2013]'s argument for observer (5)). With ``Y = diag(q) L`` every term
is linear in ``(q, Y)`` (``q > 0``): ``diag(q) D = diag(q) A − Y C``, ``diag(q) G = diag(q) E −
Y F``, and ``|q_i D_ij| <= T_ij``, ``|q_i G_ij| <= U_ij`` by auxiliary variables:

    minimise   Σ_ij U_ij Δ_j
    subject to ±(q_i A_ij − Y_i C_j) <= T_ij      (interval: q_i A_ij − Y_i C_j >= 0, T = D q)
               Σ_i T_ij <= q_j − c_j              (the copositive decrease)
               ±(q_i E_ij − Y_i F_j) <= U_ij

The LP is feasible iff some gain makes ``D`` nonnegative and Schur (``interval``) or ``|D|``
Schur (``interval-split``), so it also *decides* that question (no heuristic, no LMI): an
infeasible LP proves that no gain exists. Its optimum is the global minimum of ``cᵀ w∞``. The
matrix is sparse (``O(n² (p + 2) + n m (p + 2))`` nonzeros) and HiGHS solves it for hundreds of
states in seconds. It is solved in balanced coordinates (:func:`ivobs.design.balance.
state_scaling`) with ``c = 1`` there: the sum of the balanced widths. Without disturbances
(``|G| Δ = 0``) the objective is ``Σ q = 1ᵀ(I − |D|ᵀ)⁻¹ 1`` (how strongly an initial error is
amplified in ℓ₁), which favours fast, non-overshooting error decay.

**Smallest gain among the optimal ones.** The part of ``L`` acting on the left null space ``N``
of ``[C, F_Δ]`` (``F_Δ``: the columns of ``F`` with ``Δ_j > 0``) changes neither ``D`` nor
``|G|Δ``; the returned gain is ``L (I − P_N)``, its component orthogonal to ``N`` (redundant
noise-free sensors share the correction instead of one getting ``10⁶`` and the other ``−10⁶``,
which matters when one of them goes missing).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .balance import state_scaling

__all__ = ["WidthLP", "kernel_obstruction", "null_space_free", "width_gain", "width_lp"]


@dataclass(frozen=True)
class WidthLP:
    """The answer of :func:`width_lp`: ``status`` ``'optimal'`` (``L``, ``q`` and the optimal
    ``value`` set), ``'infeasible'`` (proved by HiGHS: no gain exists) or ``'failed'``
    (``message`` says what HiGHS said)."""

    status: str
    message: str
    L: np.ndarray | None = None
    q: np.ndarray | None = None
    value: float = float("nan")


def null_space_free(L: np.ndarray, C: np.ndarray, F: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """``L (I − P_N)``: the gain without its part on the left null space ``N`` of ``[C, F_Δ]``
    (same ``A − LC``, same ``|E − LF| Δ``; module docstring)."""
    Fd = F[:, np.asarray(delta) > 0] if F.size else F
    M = np.hstack([C, Fd])
    if M.shape[0] == 0:
        return L
    U, sv, _ = np.linalg.svd(M, full_matrices=True)
    tol = max(M.shape) * np.finfo(float).eps * (sv[0] if sv.size else 0.0)
    Nb = U[:, int(np.sum(sv > tol)) :]  # (no column: L itself)
    out: np.ndarray = L - (L @ Nb) @ Nb.T
    return out


def width_lp(
    A: np.ndarray,
    C: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    delta: np.ndarray,
    *,
    nonnegative: bool,
) -> WidthLP:
    """The gain minimising the (balanced) steady-state width, by the LP of the module docstring
    (``nonnegative=True``: ``interval``'s ``A − LC >= 0``; else ``interval-split``'s
    ``|A − LC|`` Schur). The caller checks the gain it returns."""
    from scipy.optimize import linprog

    dv = state_scaling(A, C, E if E.size else None, F if E.size else None)
    At = A * dv[None, :] / dv[:, None]
    Ct = C * dv[None, :]
    Et = E / dv[:, None]
    n, p = A.shape[0], C.shape[0]
    A_ub, b_ub, obj, bounds = _constraints(At, Ct, Et, F, delta, nonnegative)
    res = linprog(obj, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs", options=_OPTIONS)
    if res.status == 2:
        return WidthLP("infeasible", str(res.message))
    if res.status != 0 or res.x is None:
        return WidthLP("failed", f"status {res.status}: {res.message}")
    x = res.x
    q = x[:n]
    if np.any(q <= 0.0) or not np.all(np.isfinite(x)):
        return WidthLP("failed", "the LP returned a certificate q with a zero entry")
    Lt = x[n : n + n * p].reshape(n, p) / q[:, None]
    L = null_space_free(dv[:, None] * Lt, C, F, delta)
    return WidthLP("optimal", str(res.message), L, q, float(res.fun))


def _lin_rows(
    M: np.ndarray, K: np.ndarray, pairs: tuple[np.ndarray, np.ndarray], n: int, p: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """COO entries of ``q_i M_ij − Σ_l Y_il K_lj`` for the pairs ``(i, j)`` (one row each;
    columns: ``q`` first, then ``Y`` from column ``n``, row-major)."""
    ii, jj = pairs
    r = ii.size
    rows = np.repeat(np.arange(r), 1 + p)
    cq = np.column_stack([ii] + [n + ii * p + l for l in range(p)])
    vq = np.column_stack([M[ii, jj]] + [-K[l, jj] for l in range(p)])
    return rows, cq.ravel(), vq.ravel()


def _constraints(
    A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, delta: np.ndarray, nonneg: bool
) -> tuple[Any, np.ndarray, np.ndarray, list[tuple[float | None, float | None]]]:
    """``(A_ub, b_ub, objective, bounds)`` of the width LP (module docstring)."""
    from scipy.sparse import coo_matrix, vstack

    n, p, m = A.shape[0], C.shape[0], E.shape[1]
    # disturbance columns whose |G_ij| needs an auxiliary variable (F_j ≠ 0); the others enter
    # the objective through q_i |E_ij| Δ_j directly
    active = delta > 0 if m else np.zeros(0, bool)
    hasF = np.any(F != 0.0, axis=0) if m else np.zeros(0, bool)
    aux_j = np.flatnonzero(active & hasF)
    direct_j = np.flatnonzero(active & ~hasF)
    gi, gj = (a.ravel() for a in np.meshgrid(np.arange(n), aux_j, indexing="ij"))
    # columns: q (n), Y (n p, row-major), T (n n, split only), U (one per entry of |G| Δ)
    nT = 0 if nonneg else n * n
    col_T = n + n * p
    col_U = col_T + nT
    size = col_U + gi.size
    di, dj = (a.ravel() for a in np.meshgrid(np.arange(n), np.arange(n), indexing="ij"))
    blocks, b_parts = [], []
    r, c, v = _lin_rows(A, C, (di, dj), n, p)
    if nonneg:  # −(q_i A_ij − Y_i C_j) <= 0
        blocks.append(coo_matrix((-v, (r, c)), shape=(n * n, size)))
        b_parts.append(np.zeros(n * n))
        # Σ_i (q_i A_ij − Y_i C_j) − q_j <= −1 : the column sums of the same entries
        dec = coo_matrix((v, (dj[r], c)), shape=(n, size)).tocsr()
    else:  # ±(q_i A_ij − Y_i C_j) − T_ij <= 0
        t_col = col_T + np.arange(n * n)
        for sgn in (1.0, -1.0):
            rr = np.concatenate([r, np.arange(n * n)])
            cc = np.concatenate([c, t_col])
            vv = np.concatenate([sgn * v, -np.ones(n * n)])
            blocks.append(coo_matrix((vv, (rr, cc)), shape=(n * n, size)))
            b_parts.append(np.zeros(n * n))
        dec = coo_matrix((np.ones(n * n), (dj, t_col)), shape=(n, size)).tocsr()
    eye_q = coo_matrix((np.ones(n), (np.arange(n), np.arange(n))), shape=(n, size))
    dec = dec - eye_q.tocsr()
    blocks.append(dec)
    b_parts.append(-np.ones(n))
    if gi.size:  # ±(q_i E_ij − Y_i F_j) − U_ij <= 0
        r, c, v = _lin_rows(E, F, (gi, gj), n, p)
        u_col = col_U + np.arange(gi.size)
        for sgn in (1.0, -1.0):
            rr = np.concatenate([r, np.arange(gi.size)])
            cc = np.concatenate([c, u_col])
            vv = np.concatenate([sgn * v, -np.ones(gi.size)])
            blocks.append(coo_matrix((vv, (rr, cc)), shape=(gi.size, size)))
            b_parts.append(np.zeros(gi.size))
    obj = np.zeros(size)
    pos: tuple[float | None, float | None] = (0.0, None)
    free: tuple[float | None, float | None] = (None, None)
    bounds = [pos] * n + [free] * (n * p) + [pos] * (nT + gi.size)
    obj[col_U:] = delta[gj]
    if direct_j.size:
        obj[:n] += np.abs(E[:, direct_j]) @ delta[direct_j]
    if not np.any(obj):
        obj[:n] = 1.0  # no disturbance: Σ q (module docstring)
    return vstack(blocks).tocsr(), np.concatenate(b_parts), obj, bounds


_OPTIONS = {
    "primal_feasibility_tolerance": 1e-10,
    "dual_feasibility_tolerance": 1e-10,
    "time_limit": 300.0,  # beyond, the design is refused as undecided (solver failure)
}


# -- the design: existence decided, gain checked ---------------------------------------------
MAX_LP_STATES = 2000
"""Above this many states the designs that call :func:`width_gain` refuse the width LP (``O(n²)``
variables): pass a gain."""


def _row_obstruction(A: np.ndarray, C: np.ndarray) -> str:
    """A row ``i`` for which no ``L_i`` makes ``A_i − L_i C >= 0`` (each row is its own small LP
    in ``p`` unknowns, so the reason is specific), or ``''``."""
    from scipy.optimize import linprog

    p = C.shape[0]
    for i in range(A.shape[0]):
        res = linprog(np.zeros(p), A_ub=C.T, b_ub=A[i], bounds=[(None, None)] * p,
                      method="highs")  # fmt: skip
        if res.status == 2:
            return (
                f"; row {i + 1}: no L_{i + 1} satisfies L_{i + 1} C <= A[{i + 1}, :] (its own "
                "linear program, infeasible as proved by HiGHS)"
            )
    return ""


KERNEL_TOL = 1e-6
"""A kernel test margin below ``−KERNEL_TOL`` proves that no gain exists (HiGHS's tolerances
are 1e-7)."""


def kernel_obstruction(A: np.ndarray, C: np.ndarray) -> float:
    """A fast necessary condition for ``ρ(|A − LC|) < 1`` (some ``L``): the margin ``s*``.

    For ``x`` with ``C x = 0``, ``(A − LC) x = A x`` whatever ``L``, so ``|A x| <= |D| |x|``; a
    certificate ``qᵀ|D| < qᵀ`` (``q > 0``) then gives ``qᵀ|A x| < qᵀ|x|``. For the columns ``x``
    of ``X = [N, N Nᵀ A N]`` (``N`` an orthonormal basis of ``ker C``) the LP ``max s`` subject to
    ``qᵀ(|A x| − |x|) <= −s ‖x‖₁``, ``q >= 0``, ``Σ q = 1`` (``n`` variables) has ``s* < 0`` only
    if no ``q >= 0`` passes them all: then no gain exists (for ``interval`` too, since there
    ``|D| = D``). ``s* >= 0`` proves nothing; ``inf`` when ``C`` has no kernel or HiGHS fails.
    Settles the random dense systems of the benchmarks in a fraction of the full LP's time."""
    from scipy.linalg import null_space
    from scipy.optimize import linprog

    n = A.shape[0]
    N = null_space(C) if C.size else np.eye(n)
    if N.shape[1] == 0:
        return float("inf")
    X = np.hstack([N, N @ (N.T @ A @ N)])
    M = np.abs(A @ X) - np.abs(X)
    w = np.abs(X).sum(axis=0)
    c = np.zeros(n + 1)
    c[-1] = -1.0
    res = linprog(
        c,
        A_ub=np.hstack([M.T, w[:, None]]),
        b_ub=np.zeros(X.shape[1]),
        A_eq=np.concatenate([np.ones(n), [0.0]])[None, :],
        b_eq=[1.0],
        bounds=[(0.0, None)] * n + [(None, 1.0)],
        method="highs",
    )
    return float(res.x[-1]) if res.status == 0 and res.x is not None else float("inf")


def width_gain(
    A: np.ndarray,
    C: np.ndarray,
    E: np.ndarray,
    F: np.ndarray,
    delta: np.ndarray,
    *,
    nonnegative: bool,
    who: str,
) -> np.ndarray:
    """The width-optimal gain of :func:`width_lp`, checked on the original matrices:
    ``A − LC >= 0`` up to ``NONNEG_TOL`` (``interval``) and ``ρ(|A − LC|) < 1`` by the
    eigenvalues (:mod:`ivobs.design.cooperative`'s checks).

    :class:`~ivobs.DesignError` says which of three things happened: no gain exists (a row that
    cannot be made nonnegative, or the LP infeasible: proved by HiGHS), HiGHS failed or ran out
    of time (not a proof: what to try), or the gain failed its check (refused)."""
    from ..errors import DesignError
    from .cooperative import check_abs_schur, check_nonnegative_schur, fixed_radius

    cond = "A − LC nonnegative and Schur" if nonnegative else "|A − LC| Schur"
    ref = "[Tang2019, Theorem 4] / [Efimov2013, Theorem 1]" if nonnegative else (
        "[Efimov2013, Theorem 3]")  # fmt: skip
    other = "'interval-split' or 'interval-transformed'" if nonnegative else (
        "'interval-transformed' (needs only A − LC Schur)")  # fmt: skip
    low = fixed_radius(A, C)
    if low >= 1.0:
        other += (f"; no gain can do better than {low:.6g}: the unmeasured states (zero columns "
                  "of C) keep |A| on their block")  # fmt: skip
    if nonnegative:
        why = _row_obstruction(A, C)
        if why:
            raise DesignError(f"{who}: no gain L makes A − LC nonnegative{why}; use {other}")
    s_ker = kernel_obstruction(A, C)
    if s_ker < -KERNEL_TOL:
        raise DesignError(
            f"{who}: no gain L makes {cond} ({ref}): for x in the kernel of C, (A − LC) x = A x "
            "whatever L, and no q > 0 has qᵀ|A x| < qᵀ|x| on a basis of that kernel and its "
            f"image (margin {s_ker:.3g} < 0, proved by a linear program), which a copositive "
            f"certificate qᵀ|A − LC| < qᵀ would give; use {other}"
        )
    res = width_lp(A, C, E, F, delta, nonnegative=nonnegative)
    if res.status == "infeasible":
        raise DesignError(
            f"{who}: no gain L makes {cond} ({ref}): the linear program 'q > 0, Y = diag(q) L, "
            f"|diag(q) A − Y C|ᵀ 1 < q' (a linear copositive Lyapunov function, which exists iff "
            f"such a gain does) is infeasible, as proved by HiGHS; use {other}"
        )
    if res.status != "optimal":
        raise DesignError(
            f"{who}: HiGHS could not solve the linear program that decides whether a gain makes "
            f"{cond} ({res.message}); this is a solver failure, not a proof that no gain exists: "
            f"rescale the states, pass a gain L=..., or use {other}"
        )
    assert res.L is not None
    if nonnegative:
        check_nonnegative_schur(A, C, res.L, who)
    else:
        check_abs_schur(A, C, res.L, who)
    return res.L
