"""Questions to a constrained zonotope ``<c, G, A, b>`` answered by linear programs in its
factors ``ξ``: interval hull, emptiness and membership ([Scott2016]).

The LPs are solved with HiGHS (the hull's through ``highspy`` directly, :mod:`._highs`; the
rare fallbacks and the other questions through ``scipy.optimize.linprog``), and every bound is
certified by LP duality, so it is a valid bound whatever the solver's tolerances: for any
multiplier ``μ``,
``min {gᵀξ : Aξ = b, |ξ| <= 1} >= μᵀb - ‖g - Aᵀμ‖₁``, evaluated with the ``γ_n`` bounds of its
rounding ([Higham2002, Lemma 3.1]) — safe bounds from an approximate dual, as in
[Neumaier2004]. Emptiness is claimed only with a dual certificate checked the same way.
:class:`Certificates` keeps the multipliers of the hull's ``2 n`` bounds, so that a reduction
can tell what it loosens. SciPy is imported where an LP is solved (it is slow to import).
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np

from ...linalg import gamma
from ._elim_kernels import load_compiled
from ._tolerances import EMPTY_TOL, ZERO_TOL

# ndarray.sum / all without their Python wrappers (the same reductions): called several times
# per elimination, on small arrays where the wrapper costs as much as the sum
_add, _all = np.add.reduce, np.logical_and.reduce

__all__ = [
    "Certificates",
    "certified_empty",
    "hull_bounds",
    "hull_certificates",
    "radius_certificate",
]


def _certified_min(
    g: np.ndarray, A: np.ndarray, b: np.ndarray, radius: float = 1.0
) -> tuple[float, np.ndarray, bool]:
    """A lower bound of ``min {gᵀξ : A ξ = b, ‖ξ‖∞ <= radius}``, its multipliers ``μ`` and
    whether the set is nonempty.

    The bound is the Lagrangian dual ``μᵀb - radius ‖g - Aᵀμ‖₁`` at HiGHS' equality multipliers
    ``μ`` (any ``μ`` gives a valid bound; the optimal one gives the optimum). When HiGHS reports
    infeasibility, ``(nan, 0, False)``; on any other solver failure ``μ = 0`` (the bound of the
    zonotope without constraints), never an unsound number.
    """
    nc = A.shape[0]
    mu = np.zeros(nc)
    if nc == 0:
        return -radius * float(np.abs(g).sum()), mu, True
    from scipy.optimize import linprog  # imported here: SciPy's optimize is slow to import

    infeasible = 0
    for method, options in _LP_ATTEMPTS:
        res = linprog(g, A_eq=A, b_eq=b, bounds=(-radius, radius), method=method, options=options)
        if res.status == 0 and getattr(res, "eqlin", None) is not None:
            marg = np.asarray(res.eqlin.marginals, dtype=float)
            if marg.shape == mu.shape and np.all(np.isfinite(marg)):
                mu = marg
                break
        infeasible += res.status == 2
    else:
        if infeasible == len(_LP_ATTEMPTS):
            return float("nan"), mu, False
    return float(_dual_bounds(g[None, :], A, b, mu[None, :], radius)[0]), mu, True


_LP_ATTEMPTS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("highs", {}),
    ("highs", {"presolve": False}),
    ("highs-ipm", {}),
)
"""HiGHS configurations tried in turn for one bound: on the ill-conditioned programs of a set
pinned down by its constraints, HiGHS' presolve sometimes fails (status 4) or calls a feasible
program infeasible; without presolve, or with the interior point method, it usually succeeds.
Any multiplier gives a valid bound, so a failure only loosens that bound."""


def _dual_bounds(
    Gs: np.ndarray, A: np.ndarray, b: np.ndarray, mu: np.ndarray, radius: float
) -> np.ndarray:
    """``μ_iᵀb - radius ‖g_i - Aᵀμ_i‖₁`` for every row, lowered by the bound
    ``γ_{nc+m+3} (|μ_i|ᵀ|b| + radius (‖g_i‖₁ + |μ_i|ᵀ|A| 1))`` of its rounding: a lower bound of
    ``min {g_iᵀξ : A ξ = b, ‖ξ‖∞ <= radius}`` in exact arithmetic, whatever ``μ``."""
    nc, m = A.shape
    am = np.abs(mu)
    err = gamma(nc + m + 3) * (
        am @ np.abs(b) + radius * (_add(np.abs(Gs), axis=1) + am @ _add(np.abs(A), axis=1))
    )
    l1 = _add(np.abs(Gs - mu @ A), axis=1)
    bounds: np.ndarray = mu @ b - radius * l1 - err * (1.0 + gamma(4))
    return bounds


def radius_certificate(A: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """``(r, r_low)``: HiGHS' value of ``r* = min {‖ξ‖∞ : A ξ = b}`` (``inf`` when it finds no
    solution, ``0`` on solver trouble) and a lower bound of ``r*`` certified in floating point.

    The set ``<c, G, A, b>`` is empty exactly when ``r* > 1``. By duality, every ``μ`` gives
    ``r* >= μᵀb / ‖Aᵀμ‖₁`` (``μᵀb = μᵀA ξ <= ‖Aᵀμ‖₁ ‖ξ‖∞``); ``r_low`` is this ratio at the
    LP's equality multipliers (or, when ``A ξ = b`` has no solution at all, at the
    least-squares residual ``μ = b - A ξ_ls``, for which ``Aᵀμ ≈ 0``), with the numerator
    lowered and the denominator raised by the ``γ_n`` bounds of their rounding. ``0`` when no
    certificate is found: emptiness is then never claimed.
    """
    nc, m = A.shape
    if nc == 0:
        return 0.0, 0.0
    if m == 0:
        ok = bool(np.all(b == 0))
        return (0.0, 0.0) if ok else (float("inf"), float("inf"))
    from scipy.optimize import linprog

    # variables (ξ, s): min s  s.t.  A ξ = b,  ξ - s <= 0,  -ξ - s <= 0
    eye = np.eye(m)
    ones = np.ones((m, 1))
    A_ub = np.vstack([np.hstack([eye, -ones]), np.hstack([-eye, -ones])])
    cost = np.zeros(m + 1)
    cost[-1] = 1.0
    res = linprog(
        cost,
        A_ub=A_ub,
        b_ub=np.zeros(2 * m),
        A_eq=np.hstack([A, np.zeros((nc, 1))]),
        b_eq=b,
        bounds=[(None, None)] * m + [(0, None)],
        method="highs",
    )
    if res.status == 2:
        r = float("inf")
        mu = b - A @ np.linalg.lstsq(A, b, rcond=None)[0]
    elif res.status == 0:
        r = float(res.x[-1])
        mu = np.asarray(getattr(res.eqlin, "marginals", np.zeros(nc)), dtype=float)
        if mu.shape != (nc,) or not np.all(np.isfinite(mu)):
            return r, 0.0
    else:  # numerical trouble: do not claim emptiness
        return 0.0, 0.0
    am = np.abs(mu)
    num = float(mu @ b) - gamma(nc + 1) * float(am @ np.abs(b))
    den = float(np.abs(A.T @ mu).sum()) + gamma(nc + m + 1) * float(am @ np.abs(A).sum(axis=1))
    den *= 1.0 + gamma(2)
    if not num > 0.0:
        return r, 0.0
    if den == 0.0:
        return r, float("inf")
    return r, num / den * (1.0 - gamma(2))


def certified_empty(A: np.ndarray, b: np.ndarray) -> bool:
    """Whether ``<c, G, A, b>`` is certainly empty, with a margin: even the set with the larger
    box ``‖ξ‖∞ <= 1 + EMPTY_TOL`` is empty (:func:`radius_certificate`)."""
    return radius_certificate(A, b)[1] > 1.0 + EMPTY_TOL


def _feasibility_radius(A: np.ndarray, b: np.ndarray) -> float:
    """``min {‖ξ‖∞ : A ξ = b}`` (``inf`` when ``A ξ = b`` has no solution): one LP.

    The set ``<c, G, A, b>`` is empty exactly when this exceeds 1.
    """
    nc, m = A.shape
    if m == 0 and nc:
        return 0.0 if np.all(np.abs(b) <= ZERO_TOL * (1.0 + np.abs(b))) else float("inf")
    return radius_certificate(A, b)[0]


def _certified_mins(
    Gs: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    radius: float = 1.0,
    chains: list[list[int]] | None = None,
    block_max: int | None = None,
) -> tuple[np.ndarray, np.ndarray, bool]:
    """:func:`_certified_min` for every row ``g_i`` of ``Gs``: ``(bounds, μ (K, nc), feasible)``.

    The programs share their constraints and are solved by HiGHS as one chain of objectives,
    each warm-started from the previous optimum (:func:`._highs.chain_duals`), or, when
    ``K m <= block_max`` (default :data:`._highs.BLOCK_MAX`), as one block program
    (:func:`._highs.block_duals`: other optimal multipliers on degenerate programs); should HiGHS
    fail on one (or call the set infeasible), they are solved one by one with the fallbacks of
    :data:`_LP_ATTEMPTS` (degenerate, over-determined or ill-conditioned constraints can fool
    it). All of them, not only the failed one: on tank30 (where one program in ~120 fails)
    the multipliers of the chain alone, as optimal but different on these degenerate programs,
    steer the elimination to boxes 1.4 % wider over the record (median; up to 3.8 %).
    """
    K, nc = Gs.shape[0], A.shape[0]
    if nc == 0 or K == 0:
        return -radius * np.abs(Gs).sum(axis=1), np.zeros((K, nc)), True
    # the module, not the package (which imports this one): no import cycle
    from ._highs import BLOCK_MAX, block_duals, chain_duals, linprog_duals

    limit = BLOCK_MAX if block_max is None else block_max
    if K * A.shape[1] <= limit:  # small: one solve of the K programs side by side
        out = block_duals(Gs, A, b, radius)
    else:
        out = chain_duals(Gs, A, b, radius, [list(range(K))] if chains is None else chains)
    if isinstance(out, np.ndarray):
        return _dual_bounds(Gs, A, b, out, radius), out, True
    # linprog's first attempt, its HiGHS called directly (the same multipliers, less work)
    first = linprog_duals(Gs, A, b, radius)
    mu = np.zeros((K, nc))
    vals = np.empty(K)
    for i in range(K):
        if first is not None and np.all(np.isfinite(first[i])):
            mu[i] = first[i]
            vals[i] = _dual_bounds(Gs[i][None, :], A, b, mu[i][None, :], radius)[0]
            continue
        vals[i], mu[i], ok = _certified_min(Gs[i], A, b, radius)
        if not ok:
            return np.full(K, np.nan), np.zeros((K, nc)), False
    return vals, mu, True


def hull_bounds(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Certified interval hull of ``<c, G, A, b>`` (two LPs per coordinate, one HiGHS call), or
    ``None`` when the set is empty. See :func:`hull_certificates`."""
    out = hull_certificates(c, G, A, b)
    return None if out is None else (out[0], out[1])


LOSS_CANDIDATES = 24
"""Candidates whose exact elimination loss :meth:`Certificates.elimination_loss` evaluates
(those with the smallest upper bound of it)."""


class Certificates:
    """Dual certificates of some linear bounds of ``<c, G, A, b>``, kept valid through reduction.

    Row ``i`` certifies ``min_ξ D_iᵀξ >= μ_iᵀb - ‖D_i - Aᵀμ_i‖₁`` (``D`` (K, m): objectives in
    the factors ``ξ``, ``μ`` (K, nc): multipliers, e.g. those of :func:`hull_certificates`).
    Each reparametrisation of the set (row scaling, rescaling, elimination of a factor) maps the
    objectives and multipliers so that the certificates keep meaning the same linear functions
    of ``x``. What a reduction step does to the certified bounds is then known before it is
    taken: :meth:`elimination_loss` is the loosening, weighted by ``weight`` (K,), of every
    bound if factor ``j`` were eliminated. This is how the estimator chooses what to eliminate
    (the bounds of the box it reports stay as tight as possible), instead of the shape-only
    Hausdorff heuristic of [Scott2016, Section 4.2], which only breaks ties here.
    """

    __slots__ = ("D", "mu", "radius", "weight")

    def __init__(self, D: np.ndarray, mu: np.ndarray, weight: np.ndarray):
        self.D, self.mu, self.weight = D, mu, weight
        self.radius = 1.0  # see hull_certificates: the factors' box the certificates assume

    def keep(self, rows: np.ndarray, cols: np.ndarray) -> None:
        """Constraints ``rows`` and factors ``cols`` are kept (the others were zero)."""
        if not _all(rows):
            self.mu = self.mu[:, rows]
        if not _all(cols):
            self.D = self.D[:, cols]

    def scale_rows(self, s: np.ndarray) -> None:
        """Constraint ``r`` was divided by ``s_r``."""
        self.mu = self.mu * s

    def scale_factors(self, rad: np.ndarray) -> None:
        """Factor ``j`` was rescaled, ``ξ_j = m_j + rad_j ξ'_j`` (offsets go to constants)."""
        self.D = self.D * rad

    def elimination_loss(
        self, A: np.ndarray, b: np.ndarray, piv: np.ndarray, cand: np.ndarray | None = None
    ) -> np.ndarray:
        """Weighted loosening of the certified bounds if factor ``j`` is eliminated with row
        ``piv[j]`` (for every ``j``; ``inf`` outside the candidates ``cand``). The multipliers
        move to ``μ + (r_j / a_pj) e_p`` so that the reduced cost ``r = D - Aᵀμ`` of ``ξ_j``,
        whose box is dropped, becomes zero.

        The exact loss costs ``O(K m)`` per candidate; it is evaluated for the
        :data:`LOSS_CANDIDATES` candidates with the smallest upper bound
        ``Σ_k w_k |t_kj| (‖A_p‖₁ + |b_p|)`` (``|r - t a| - |r| <= |t| |a|``), so that a step
        costs ``O(K m)`` rather than ``O(K m²)``; a factor whose bound is zero loses nothing."""
        m = A.shape[1]
        cand = np.ones(m, dtype=bool) if cand is None else cand
        Rc = self.D - self.mu @ A  # (K, m)
        apj = A[piv, np.arange(m)]
        t = Rc / np.where(apj != 0, apj, 1.0)  # (K, m): multiplier change per candidate
        # ‖A_p‖₁ per constraint, then per candidate: the same sums as ``|A[piv]|`` row by row
        # (each a contiguous row, summed alike) without copying a row per factor (m x m)
        row_l1 = _add(np.abs(A, order="C"), axis=1)
        upper = self.weight @ np.abs(t) * (row_l1[piv] + np.abs(b[piv]))
        idx = cand.nonzero()[0]
        if idx.size > LOSS_CANDIDATES:
            idx = idx[np.argsort(upper[idx], kind="stable")[:LOSS_CANDIDATES]]
        out = np.full(m, np.inf)
        tj = t[:, idx]  # (K, c)
        new = _shifted_l1(Rc, tj, A[piv[idx]])
        loss = new - tj * b[piv[idx]][None, :] - _add(np.abs(Rc), axis=1, keepdims=True)
        out[idx] = self.weight @ loss
        return out

    def eliminate(self, A: np.ndarray, j: int, p: int) -> None:
        """Factor ``j`` eliminated with row ``p`` (before the row and column are removed)."""
        Rc = self.D[:, j] - self.mu @ A[:, j]
        self.mu = self.mu.copy()
        self.mu[:, p] += Rc / A[p, j]
        self.D = self.D - (self.D[:, j] / A[p, j])[:, None] * A[p][None, :]  # np.outer's product


_CHUNK = 1 << 16
"""Elements of the ``(K, c, m)`` temporaries of :func:`_shifted_l1` per chunk (cache-sized:
one ``(K, m)`` block at a time is 3x faster than the whole array on tank30)."""


def _kernel() -> Any:
    """The compiled :func:`._loss_nb.shifted_l1`, or None (numba missing, or ``IVOBS_NUMBA=0``:
    :func:`._elim_kernels.load_compiled`) when first asked."""
    global _KERNEL
    if _KERNEL is False:
        found = load_compiled("_loss_nb", "shifted_l1")
        _KERNEL = None if found is None else found[0]
    return _KERNEL


_KERNEL: Any = False  # not looked up yet
_KERNEL_MIN = 1 << 16
"""``K c m`` from which :func:`_shifted_l1` uses the compiled kernel: below it (the servo's 12 x
24 x 50) NumPy takes tens of µs and importing numba and loading the kernel (~0.5 s of CPU
once per process) would not pay."""


def _shifted_l1(R: np.ndarray, T: np.ndarray, P: np.ndarray) -> np.ndarray:
    """``N[k, c] = ‖R_k - T_kc P_c‖₁`` (``R`` (K, m), ``T`` (K, c), ``P`` (c, m)), in chunks of
    candidates whose temporaries fit in cache (the same sums, term for term); with numba,
    the same numbers in one compiled pass (:mod:`._loss_nb`; 7x faster on tank30)."""
    K, m = R.shape
    # (NumPy may sum rows longer than 8192 in chunks: another order)
    if K * T.shape[1] * m >= _KERNEL_MIN and m <= 8192:
        kernel = _kernel()
        if kernel is not None:
            f = np.float64
            out: np.ndarray = kernel(
                np.ascontiguousarray(R, dtype=f),
                np.ascontiguousarray(T, dtype=f),
                np.ascontiguousarray(P, dtype=f),
            )
            return out
    c = T.shape[1]
    step = max(1, _CHUNK // max(1, K * m))
    out = np.empty((K, c))
    for s in range(0, c, step):
        e = min(c, s + step)
        buf = T[:, s:e, None] * P[None, s:e, :]
        np.subtract(R[:, None, :], buf, out=buf)
        np.abs(buf, out=buf)
        out[:, s:e] = _add(buf, axis=2)
    return out


@cache
def _hull_chains(n: int, k: int) -> list[list[int]]:
    """Two warm-start chains over the rows ``[G; -G; P; -P]`` (``G`` n rows, ``P`` k rows):
    the minima in order, the maxima in reverse order (kept: the same few sizes every step;
    read only)."""
    lo = list(range(n)) + list(range(2 * n, 2 * n + k))
    hi = list(range(2 * n - 1, n - 1, -1)) + list(range(2 * n + 2 * k - 1, 2 * n + k - 1, -1))
    return [lo, hi]


def hull_certificates(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    extra: np.ndarray | None = None,
    block_max: int | None = None,
) -> tuple[np.ndarray, np.ndarray, Certificates] | None:
    """Certified interval hull of ``<c, G, A, b>`` and the certificates of its ``2 n`` bounds
    (weighted by the inverse width of each coordinate, so that losses are relative), or
    ``None`` when the set is certainly empty (:func:`certified_empty`: a dual certificate,
    checked in floating point, that even the box ``‖ξ‖∞ <= 1 + EMPTY_TOL`` misses the
    constraints).

    ``extra`` (n', m): more objectives in the factors whose bounds the certificates should
    also keep (the rows ``P`` and ``-P`` are appended, weighted by the inverse widths of
    ``P ξ``); the filter passes the hull of its prediction, ``[A G, E R]``.

    When HiGHS calls the set infeasible without such a certificate (a set that is thin, or
    empty only by rounding), the bounds are those of the *softened* set with the box
    ``‖ξ‖∞ <= ρ``, ``ρ = max(1, r*) (1 + EMPTY_TOL)`` (``r*`` the smallest feasible radius
    found): a superset, so still sound. ``cert.radius`` is then ``ρ``: the certificates are
    those of ``<c, ρ G, ρ A, b>`` (the same set, with the factors rescaled to the unit box),
    which the caller should keep instead of the original.

    ``block_max``: the programs are solved as one block program when ``K m`` (objectives times
    factors) is at most this (:func:`._highs.block_duals`), else as warm-started chains;
    default :data:`._highs.BLOCK_MAX` (0: always chains). Either way every bound is certified
    by its multipliers; only which optimal multipliers a degenerate program gets differs.
    """
    n = G.shape[0]
    P = np.zeros((0, G.shape[1])) if extra is None else extra
    k = P.shape[0]
    Gs = np.concatenate([G, -G, P, -P] if k else [G, -G])  # np.vstack's call
    chains = _hull_chains(n, k)
    vals, mu, ok = _certified_mins(Gs, A, b, 1.0, chains, block_max)
    radius = 1.0
    if not ok:
        r, r_low = radius_certificate(A, b)
        if r_low > 1.0 + EMPTY_TOL:
            return None
        radius = (max(1.0, r) if np.isfinite(r) else 1.0) * (1.0 + EMPTY_TOL)
        vals, mu, ok = _certified_mins(Gs, A, b, radius, chains, block_max)
        if not ok:  # HiGHS contradicting itself: the bound of the zonotope (any μ is valid)
            mu = np.zeros_like(mu)
            vals = _dual_bounds(Gs, A, b, mu, radius)
    lo = c + vals[:n]
    hi = c - vals[n : 2 * n]
    width = np.maximum(hi - lo, 1e-12 * (1.0 + np.abs(c)))
    if k:
        p_width = -(vals[2 * n : 2 * n + k] + vals[2 * n + k :])
        p_width = np.maximum(p_width, 1e-12 * (1.0 + np.abs(P).sum(axis=1)))
        weight = np.concatenate([1.0 / width, 1.0 / width, 1.0 / p_width, 1.0 / p_width])
    else:  # the hull alone (the nonlinear filter): no rows of P
        weight = np.concatenate([1.0 / width, 1.0 / width])
    cert = Certificates(Gs * radius if radius != 1.0 else Gs, mu, weight)  # (x * 1.0 is x)
    cert.radius = radius
    return lo, hi, cert
