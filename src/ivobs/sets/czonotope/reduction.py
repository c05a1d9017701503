"""Generator reduction of constrained zonotopes ([Scott2016, Section 4.3]), on raw arrays.

The lifted zonotope ``<[c; -b], [G; A]>`` is reduced, so the ``x`` part and the constraints shrink
together and the constrained zonotope it represents contains the original. Removed generators are
absorbed by a parallelotope ([Chisci1998]); what the basis misses, and the rounding of every
step, go to a box ([Higham2002, Lemma 3.1] bounds).
"""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np

try:  # the gufunc behind np.linalg.inv (private to NumPy: present in 1.26 and 2.x)
    from numpy.linalg import _umath_linalg as _gufuncs
except ImportError:  # pragma: no cover - a NumPy without it: the public call
    _gufuncs = None  # type: ignore[assignment]

from ...linalg import UNIT_ROUNDOFF, gamma
from ..zonotope import MAX_BASIS_CONDITION, reduce_girard

__all__ = ["consolidate_small", "reduce_generators"]


def consolidate_small(
    c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray, tol_x: float, tol_c: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Replace the generators that are small in both parts (``|G_j| <= tol_x`` and
    ``|A_j| <= tol_c``: the rounding slacks and boxes of earlier steps, factors pinned down by
    rescaling) by two boxes: ``diag(Σ_j |G_j|)`` in ``x`` and ``diag(Σ_j |A_j|)`` in the
    constraints (a slack per row). The segment ``{(G_j; A_j) t}`` lies in the sum of the two,
    so the result contains the original (only correlations between rows of the replaced
    factors are lost); at most ``n + nc`` columns are left of them (the sums rounded up by
    ``γ_{k+1}``). Dropping them instead would give a subset."""
    n, m = G.shape
    if m == 0:
        return c, G, A, b
    small = (np.abs(G) <= tol_x).all(axis=0)
    if A.shape[0]:
        small &= (np.abs(A) <= tol_c).all(axis=0)
    k = int(small.sum())
    if k <= 1:
        return c, G, A, b
    up = 1.0 + gamma(k + 1)
    gx = np.abs(G[:, small]).sum(axis=1) * up
    ga = np.abs(A[:, small]).sum(axis=1) * up
    ix, ia = (gx > 0).nonzero()[0], (ga > 0).nonzero()[0]
    if ix.size + ia.size >= k:
        return c, G, A, b
    nc = A.shape[0]
    Gb = np.zeros((n, ix.size + ia.size))
    Ab = np.zeros((nc, ix.size + ia.size))
    Gb[ix, np.arange(ix.size)] = gx[ix]
    Ab[ia, ix.size + np.arange(ia.size)] = ga[ia]
    # np.concatenate: np.hstack's call on 2-D arrays, without its wrapper
    return c, np.concatenate([G[:, ~small], Gb], 1), np.concatenate([A[:, ~small], Ab], 1), b


def reduce_generators(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    max_generators: int,
    residual: bool = False,
) -> Any:
    """At most ``max_generators`` generators, by reducing the lifted zonotope
    ``<[c; -b], [G; A]>`` ([Scott2016, Section 4.3]; its ``x`` part and constraint part
    shrink together, so the constrained zonotope it represents contains the original).

    The lifted generators ``L = [G; A]`` (``N = n + nc`` rows) are first equilibrated by
    powers of two, ``D L`` (exact: only exponents change), so that the choice and the
    conditioning of the basis do not depend on the units of the states or the scaling of the
    constraint rows; the result is scaled back by ``D⁻¹``, exactly again. Then a parallelotope
    enclosure ([Chisci1998]; :func:`_absorb_in_basis`), or, when the ``N`` pivots of the QR
    with column pivoting are ill-conditioned (estimate above
    :data:`~ivobs.sets.zonotope.MAX_BASIS_CONDITION`) or do not span the lifted space,
    [Girard2005]'s box (:func:`~ivobs.sets.zonotope.reduce_girard`, as the strip method).
    An ill-conditioned basis is what lets the scale factors grow step after step without
    bound. Either way the result contains the original in exact arithmetic, whatever the
    rounding, and no box is left aside.

    At least ``N`` generators are kept, whatever ``max_generators``.

    With ``residual=True`` ``(c, G, A, b, box)`` is returned, ``box`` the zero radii of the
    box aside (kept for callers of the earlier form)."""
    n, m = G.shape
    N = n + A.shape[0]
    order = max(int(max_generators), N)
    if m <= order:
        return (c, G, A, b, np.zeros(N)) if residual else (c, G, A, b)
    # the same array as the vstack when there are no constraints (the nonlinear zonotope)
    L = G if not A.shape[0] and G.flags.c_contiguous else np.vstack([G, A])
    d = _pow2_scaling(L)
    Ls = L * d[:, None] if d is not None else L
    L2 = _absorb_in_basis(Ls, order)
    if L2 is None:
        L2 = reduce_girard(Ls, order)
    if d is not None:
        back = L2 / d[:, None]
        if _exactly_scaled(back, L2):
            L2 = back
        else:  # an entry would leave the normal range: reduce the unscaled matrix instead
            L2 = _absorb_in_basis(L, order)
            L2 = reduce_girard(L, order) if L2 is None else L2
    return (c, L2[:n], L2[n:], b, np.zeros(N)) if residual else (c, L2[:n], L2[n:], b)


_TINY = float(np.finfo(float).tiny)
_add = np.add.reduce  # ndarray.sum without its Python-level wrapper (the same reduction)


def _pow2_scaling(L: np.ndarray) -> np.ndarray | None:
    """Powers of two ``d`` with ``max_j |d_i L_ij|`` in ``[1, 2)`` (zero rows: 1), or ``None``
    when scaling an entry would leave the normal range (then it would not be exact)."""
    aL = np.abs(L)
    d = []
    for v in aL.max(axis=1).tolist():
        if not v < math.inf:  # an inf or a NaN
            return None
        e = 1 - math.frexp(v)[1] if v > 0 else 0
        if e > 1023:  # a subnormal row: its scale overflows
            return None
        d.append(math.ldexp(1.0, e))
    scale = np.array(d)
    # no entry can overflow (the largest lands in [1, 2)); the smallest nonzero one of each
    # row must stay normal (rounding is monotone: the smallest scaled entry is the scaled
    # smallest one) — the same test as _exactly_scaled(L * d, L), without forming L * d
    return scale if bool((_min_nonzero(aL) * scale >= _TINY).all()) else None


def _min_nonzero(aM: np.ndarray) -> np.ndarray:
    """The smallest nonzero entry of each row of ``aM >= 0`` (``inf`` for a zero row)."""
    out: np.ndarray = np.where(aM > 0, aM, np.inf).min(axis=1)
    return out


def _exactly_scaled(S: np.ndarray, M: np.ndarray) -> bool:
    """Whether ``S`` (``M`` scaled by powers of two) was computed exactly: every entry finite
    and normal or zero where ``M`` is zero."""
    aS = np.abs(S)
    if not np.isfinite(aS.max(initial=0.0)):  # an inf or a NaN
        return False
    return bool(np.where(M != 0, aS, np.inf).min(initial=np.inf) >= _TINY)


def _absorb_in_basis(
    L: np.ndarray, order: int, max_condition: float = MAX_BASIS_CONDITION
) -> np.ndarray | None:
    """``order >= N`` generators ``L'`` with ``<0, L> ⊆ <0, L'>`` in exact arithmetic, by a
    parallelotope enclosure ([Chisci1998]), or ``None`` when the basis is ill-conditioned.

    The basis ``P`` (``N`` generators) is chosen by QR with column pivoting; its condition
    estimate ``|R_11| / |R_NN|`` must be at most ``max_condition``. Each generator ``l`` to
    remove has coordinates ``α = P⁻¹ l`` and ``<0, [P, l]> ⊆ <0, P diag(1 + |α|)>``; those
    with the smallest ``‖α‖₁`` are removed: ``<0, L> ⊆ <0, [P diag(s₀), L_kept]> ⊕ box(ρ)``
    with ``s₀ >= 1 + Σ|α|`` (rounded up) and ``ρ >= Σ |l - P α|`` (evaluated, plus the bound
    ``γ_{N+2} (|l| + |P| |α|)`` of its rounding, [Higham2002, Lemma 3.1]). The box and the
    rounding of the product ``P diag(t)`` itself are then absorbed by the basis:
    with ``X ≈ P⁻¹``, ``θ >= ‖I - X P‖∞ < 1/2``, ``|P⁻¹ v| <= τ`` on ``box(ρ)``
    (:func:`_box_in_basis`) and ``μ >= u ‖|P⁻¹| |P|‖∞``, the computed
    ``P' = fl(P diag(t))`` is ``P (diag(t) + F)`` with ``|F diag(t)⁻¹| <= u |P⁻¹| |P|``,
    so ``t = z + μ / (1 - μ) ‖z‖∞``, ``z = s₀ + τ``, gives ``<0, P diag(s₀)> ⊕ box(ρ) ⊆
    <0, P'>`` (a Neumann-series bound on ``(I + F diag(t)⁻¹)⁻¹``)."""
    N, m = L.shape
    if m <= order:
        return L
    dgeqp3, dtrtrs = _lapack()
    R, jpvt, _, _, info = dgeqp3(L)
    if info != 0 or m < N:
        return None
    r_first, r_last = abs(float(R[0, 0])), abs(float(R[N - 1, N - 1]))
    if not r_last * max_condition >= r_first > 0.0:
        return None
    piv = jpvt - 1
    basis, others = piv[:N], piv[N:]
    alpha, info = dtrtrs(R[:N, :N], R[:N, N:])
    if info != 0 or not np.isfinite(alpha).all():
        return None
    srt = _add(np.abs(alpha), axis=0).argsort(kind="stable")
    n_rm = m - order
    rm, kept = srt[:n_rm], others[srt[n_rm:]]
    P, a_rm, L_rm = L[:, basis], alpha[:, rm], L[:, others[rm]]
    a1 = _add(np.abs(a_rm), axis=1)
    up = 1.0 + gamma(n_rm + 3)
    rho = (
        _add(np.abs(L_rm - P @ a_rm), axis=1)
        + gamma(N + 2) * (_add(np.abs(L_rm), axis=1) + np.abs(P) @ a1)
    ) * up
    absorbed = _box_in_basis(P, rho)
    if absorbed is None:
        return None
    tau, mu = absorbed
    up2, up6 = 1.0 + gamma(2), 1.0 + gamma(6)
    t: Any
    if N <= _FEW:  # the same operations on floats
        zl = [((1.0 + a) * up + b) * up2 for a, b in zip(a1.tolist(), tau.tolist())]
        c = mu / (1.0 - mu) * max(zl)
        t = [(x + c) * up6 for x in zl]
    else:
        z = ((1.0 + a1) * up + tau) * up2
        t = (z + mu / (1.0 - mu) * float(z.max())) * up6
    # [P diag(t), L_kept], column-major as the hstack of the column selections it replaces
    # (the layout decides the summation order of later reductions: same layout, same bits)
    out = np.empty((N, order), order="F")
    np.multiply(P, t, out=out[:, :N])
    out[:, N:] = L[:, kept]
    return out


@cache
def _lapack() -> tuple[Any, Any]:
    """SciPy's ``dgeqp3`` and ``dtrtrs``, imported on first use (SciPy is slow to import) and
    kept (an import statement in the loop costs as much as a small QR)."""
    from scipy.linalg.lapack import dgeqp3, dtrtrs

    return dgeqp3, dtrtrs


@cache
def _eye(n: int) -> np.ndarray:
    """``np.eye(n)``, kept (read-only)."""
    out = np.eye(n)
    out.flags.writeable = False
    return out


def _inv(P: np.ndarray) -> np.ndarray:
    """``np.linalg.inv`` without its checks and wrappers (the same LAPACK call, the same
    numbers): a singular ``P`` gives NaNs instead of an exception."""
    if _gufuncs is None:  # pragma: no cover
        try:
            return np.linalg.inv(P)
        except np.linalg.LinAlgError:
            return np.full_like(P, np.nan)
    with np.errstate(all="ignore"):
        out: np.ndarray = _gufuncs.inv(P, signature="d->d")
    return out


def _box_in_basis(P: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, float] | None:
    """``(τ, μ)`` with ``τ >= 0``, ``box(ρ) ⊆ <0, P diag(τ)>`` and ``μ >= u ‖|P⁻¹| |P|‖∞``
    (plus the bound of an underflow in ``P diag(t)``, ``t >= 1``) for a square invertible
    ``P``, verified in floating point, or ``None`` (``P`` too ill-conditioned to verify).

    ``v ∈ box(ρ)`` has coordinates ``P⁻¹ v``. With ``X ≈ P⁻¹`` and ``θ >= ‖I - X P‖∞`` (the
    computed residual plus the bound ``γ_{n+1} (I + |X| |P|)`` of its rounding), ``θ < 1/2``
    gives ``P⁻¹ v = X v + (I - X P) P⁻¹ v``, so
    ``|P⁻¹ v| <= |X| ρ + θ / (1 - θ) ‖|X| ρ‖∞``, and ``P⁻¹ = X + (I - X P) P⁻¹`` gives
    ``‖|P⁻¹| |P|‖∞ <= ‖|X| |P|‖∞ / (1 - θ)`` (Skeel's condition number, invariant to the scaling
    of the columns; Neumann-series bounds, as in verified linear algebra)."""
    n = P.shape[0]
    X = _inv(P)
    if not np.isfinite(X).all():  # singular (NaN) or overflowing
        return None
    aX = np.abs(X)
    if n <= _FEW:
        return _box_in_basis_few(aX, X @ P, aX @ np.abs(P), rho)
    eye = _eye(n)
    Rm = eye - X @ P
    aXaP = aX @ np.abs(P)
    row_sums = (np.abs(Rm) + gamma(n + 1) * (eye + aXaP)).sum(axis=1)
    theta = float(row_sums.max()) * (1.0 + gamma(n + 2))
    if not theta < 0.5:
        return None
    up = 1.0 + gamma(2 * n + 4)
    skeel = float(aXaP.sum(axis=1).max()) * up  # >= ‖|X| |P|‖∞ in exact arithmetic
    nX = float(aX.sum(axis=1).max()) * up
    mu = (UNIT_ROUNDOFF * skeel + nX * n * 2.0**-1074) / (1.0 - theta) * up
    if not mu < 0.5:
        return None
    v = (aX @ rho) * (1.0 + gamma(n + 1))
    tau: np.ndarray = (v + theta / (1.0 - theta) * float(v.max())) * (1.0 + gamma(4))
    return tau, mu


_FEW = 4
"""Up to this size the ``n``-vectors of :func:`_box_in_basis` are worked on floats (the same
operations: row sums of fewer than 8 terms are summed in order by NumPy too)."""


def _in_order(terms: list[float]) -> float:
    """The sum from the first term to the last (as NumPy sums fewer than 8 terms; ``sum``
    may compensate)."""
    t = 0.0
    for x in terms:
        t += x
    return t


def _box_in_basis_few(
    aX: np.ndarray, XP: np.ndarray, aXaP: np.ndarray, rho: np.ndarray
) -> tuple[np.ndarray, float] | None:
    """:func:`_box_in_basis` after its products (``|X|``, ``X P``, ``|X| |P|``), on floats."""
    n = aX.shape[0]
    g1 = gamma(n + 1)
    rows = []
    for i, (r, a) in enumerate(zip(XP.tolist(), aXaP.tolist())):
        t = 0.0
        for j, (rij, aij) in enumerate(zip(r, a)):
            e = 1.0 if i == j else 0.0
            t += abs(e - rij) + g1 * (e + aij)
        rows.append(t)
    theta = max(rows) * (1.0 + gamma(n + 2))
    if not theta < 0.5:
        return None
    up = 1.0 + gamma(2 * n + 4)
    skeel = max(_in_order(r) for r in aXaP.tolist()) * up  # >= ‖|X| |P|‖∞ (exact arithmetic)
    nX = max(_in_order(r) for r in aX.tolist()) * up
    mu = (UNIT_ROUNDOFF * skeel + nX * n * 2.0**-1074) / (1.0 - theta) * up
    if not mu < 0.5:
        return None
    v = [x * (1.0 + g1) for x in (aX @ rho).tolist()]
    c = theta / (1.0 - theta) * max(v)
    up4 = 1.0 + gamma(4)
    return np.array([(x + c) * up4 for x in v]), mu


def reduce_consolidated(
    c: np.ndarray,
    G: np.ndarray,
    A: np.ndarray,
    b: np.ndarray,
    max_generators: int,
    tols: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """:func:`consolidate_small` with tolerances relative to the set (``tols = (tx, tc)``:
    ``tx (1 + max |c|)`` for generators, ``tc max |A|`` for constraint entries), then
    :func:`reduce_generators` to at most ``max_generators``: the last stage of every prediction
    of the constrained-zonotope filters (linear and nonlinear)."""
    tol_x = tols[0] * (1.0 + float(np.abs(c).max(initial=0.0)))
    tol_c = tols[1] * float(np.abs(A).max(initial=0.0))
    c, G, A, b = consolidate_small(c, G, A, b, tol_x, tol_c)
    out: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] = reduce_generators(
        c, G, A, b, max_generators
    )
    return out
