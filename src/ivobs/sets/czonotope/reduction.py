"""Generator reduction of constrained zonotopes ([Scott2016, Section 4.3]), on raw arrays.

The lifted zonotope ``<[c; -b], [G; A]>`` is reduced, so the ``x`` part and the constraints shrink
together and the constrained zonotope it represents contains the original. Removed generators are
absorbed by a parallelotope ([Chisci1998]); what the basis misses, and the rounding of every
step, go to a box ([Higham2002, Lemma 3.1] bounds).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...linalg import gamma

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
    small = np.all(np.abs(G) <= tol_x, axis=0)
    if A.shape[0]:
        small &= np.all(np.abs(A) <= tol_c, axis=0)
    k = int(small.sum())
    if k <= 1:
        return c, G, A, b
    up = 1.0 + gamma(k + 1)
    gx = np.abs(G[:, small]).sum(axis=1) * up
    ga = np.abs(A[:, small]).sum(axis=1) * up
    ix, ia = np.flatnonzero(gx > 0), np.flatnonzero(ga > 0)
    if ix.size + ia.size >= k:
        return c, G, A, b
    nc = A.shape[0]
    Gb = np.zeros((n, ix.size + ia.size))
    Ab = np.zeros((nc, ix.size + ia.size))
    Gb[ix, np.arange(ix.size)] = gx[ix]
    Ab[ia, ix.size + np.arange(ia.size)] = ga[ia]
    return c, np.hstack([G[:, ~small], Gb]), np.hstack([A[:, ~small], Ab]), b


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

    The lifted zonotope is reduced with a parallelotope enclosure ([Chisci1998]): a
    basis ``P`` of ``r = rank [G; A]`` large, independent
    generators is chosen (QR with column pivoting); each generator ``l`` to remove has
    coordinates ``α = P⁺ l`` and ``<0, [P, l]> ⊆ <0, P diag(1 + |α|)>``, so the removed
    generators are absorbed by rescaling the basis, ``P diag(1 + Σ|α|)``. Those with the
    smallest ``‖α‖₁`` are removed. No generator is added, the directions of the kept ones are
    unchanged (coordinates are invariant to the scaling of the constraint rows). What the
    basis misses of the removed generators, ``Σ |l - P α|`` (the part outside the basis' span
    when the lifted generators do not span the lifted space, and the error of the computed
    ``α``), is enclosed in a box, enlarged by the bound ``γ_{r+2} (|l| + |P| |α|)`` of its
    rounding; the scale factors are rounded up. The result contains the original in exact
    arithmetic, whatever the rounding.

    At least the ``r <= n + nc`` basis generators are kept, whatever ``max_generators``.

    With ``residual=True`` the box is not added: ``(c, G, A, b, box)`` is returned, ``box``
    ``(n + nc,)`` the radii of the box the caller must add (Minkowski) to the result."""
    n, m = G.shape
    if m <= max_generators:
        return (c, G, A, b, np.zeros(n + A.shape[0])) if residual else (c, G, A, b)
    from scipy.linalg import qr  # imported here: SciPy is slow to import

    L = np.vstack([G, A])
    R, piv = qr(L, mode="r", pivoting=True)
    diag = np.abs(np.diag(R))
    rank = int(np.sum(diag > 1e-10 * diag[0])) if diag.size and diag[0] > 0 else 0
    max_generators = max(max_generators, rank)  # the basis is always kept
    basis, others = piv[:rank], piv[rank:]
    # L[:, piv] = Q R: the others have coordinates α = R11⁻¹ R12 in the basis L[:, basis]
    alpha = np.linalg.solve(R[:rank, :rank], R[:rank, rank:])  # (scipy trsm is slow here)
    order = np.argsort(np.abs(alpha).sum(axis=0), kind="stable")
    n_rm = m - max_generators
    rm, kept = order[:n_rm], others[order[n_rm:]]
    # rounding: the computed α are not the exact coordinates, so what the basis misses of each
    # removed generator l is the residual l - P α, evaluated directly (in exact arithmetic the
    # Q2 R22 part) plus the bound γ_{r+2} (|l| + |P| |α|) of its rounding; the scale factors
    # are rounded up (γ_{k+3}) so that the scaled basis is never smaller than the exact one
    Lb, a_rm = L[:, basis], alpha[:, rm]
    L_rm = L[:, others[rm]]
    resid = np.abs(L_rm - Lb @ a_rm).sum(axis=1) + gamma(rank + 2) * (
        np.abs(L_rm).sum(axis=1) + np.abs(Lb) @ np.abs(a_rm).sum(axis=1)
    )
    scale = 1.0 + np.abs(a_rm).sum(axis=1)
    if residual:
        L2 = np.hstack([Lb * (scale * (1.0 + gamma(n_rm + 3))), L[:, kept]])
        return c, L2[:n], L2[n:], b, resid
    tau = _box_in_basis(Lb, resid) if rank == L.shape[0] else None
    if tau is not None:  # the basis spans the space: absorb the box too
        scale, resid = scale + tau, np.zeros_like(resid)
    P = Lb * (scale * (1.0 + gamma(n_rm + 3)))
    big = resid > 0
    box = np.zeros((L.shape[0], int(big.sum())))
    box[np.flatnonzero(big), np.arange(box.shape[1])] = resid[big]
    L2 = np.hstack([P, L[:, kept], box])
    return c, L2[:n], L2[n:], b


def _box_in_basis(P: np.ndarray, rho: np.ndarray) -> np.ndarray | None:
    """``τ >= 0`` with ``box(ρ) ⊆ <0, P diag(τ)>`` for a square invertible ``P``, verified in
    floating point, or ``None`` (``P`` too ill-conditioned to verify).

    ``v ∈ box(ρ)`` has coordinates ``P⁻¹ v``. With ``X ≈ P⁻¹`` and ``θ >= ‖I - X P‖∞`` (the
    computed residual plus the bound ``γ_{n+1} (I + |X| |P|)`` of its rounding), ``θ < 1``
    gives ``P⁻¹ v = X v + (I - X P) P⁻¹ v``, so
    ``|P⁻¹ v| <= |X| ρ + θ / (1 - θ) ‖|X| ρ‖∞`` (a Neumann-series bound, as in verified
    linear algebra)."""
    if not np.any(rho):
        return np.zeros_like(rho)
    n = P.shape[0]
    try:
        X = np.linalg.inv(P)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(X)):
        return None
    aX = np.abs(X)
    Rm = np.eye(n) - X @ P
    row_sums = (np.abs(Rm) + gamma(n + 1) * (np.eye(n) + aX @ np.abs(P))).sum(axis=1)
    theta = float(row_sums.max()) * (1.0 + gamma(n + 2))
    if not theta < 0.5:
        return None
    v = (aX @ rho) * (1.0 + gamma(n + 1))
    tau: np.ndarray = (v + theta / (1.0 - theta) * float(v.max())) * (1.0 + gamma(4))
    return tau
