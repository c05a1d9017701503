"""The floating-point error of the interval recursion, bounded: the one proof of the family.

**What is computed.** One step of :mod:`.recursion` evaluates, for the bounds ``[z̲, z̄]`` of
``z[k] = S x[k]`` (``S = I`` except for ``interval-transformed``), one product

    W v,    v = [z̄; z̲; u; y; d̄; d̲]

whose rows are the upper bounds ``[z̄+; x̄; p̄]`` and the lower bounds ``[z̲+; x̲; p̲]`` of
``z[k+1]``, of ``x[k]`` (``S ≠ I`` only) and of ``C x[k] + D_u u[k] + F d[k]`` (the
consistency test of ``y[k]``): Lemma 1 of [Efimov2013] with the float matrices of the step,

    z̄+ = Q⁺ z̄ − Q⁻ z̲ + B_z u + L_z y + G⁺ d̄ − G⁻ d̲,    x̄ = Si⁺ z̄ − Si⁻ z̲,
    p̄  = C_z⁺ z̄ − C_z⁻ z̲ + D_u u + F⁺ d̄ − F⁻ d̲        (lower rows: the mirror images)

with ``M̂ = fl(A − fl(L_k C))``, ``Q = fl(fl(S M̂) Si)``, ``B_z = fl(S fl(B − fl(L_k D_u)))``,
``L_z = fl(S L_k)``, ``G = fl(S fl(E − fl(L_k F)))``, ``Si = fl(S⁻¹)``, ``C_z = fl(C Si)``
(``S = I``: the products by ``S`` and ``Si`` are absent, ``Q = M̂``, ``C_z = C``).

**What is true.** For any gain ``L_k`` the plant obeys exactly

    S x+ = S (A − L_k C) x + S (B − L_k D_u) u + S L_k y + S (E − L_k F) d,

so with the float matrices, ``z+ = Q z + B_z u + L_z y + G d + δ`` where

    δ = (S (A − L_k C) − Q S) x + (S (B − L_k D_u) − B_z) u + (S L_k − L_z) y
        + (S (E − L_k F) − G) d,

and ``x = Si z + (I − Si S) x``, ``C x = C_z z + (C Si − C_z) z + C (I − Si S) x``. Each matrix
difference is bounded entrywise at design time ([Higham2002, §2.2, §3.1]; ``u = 2⁻⁵³``, products
of inner dimension ``n`` off by at most :func:`~ivobs.sets.rounding.product_error`, a difference
of floats by ``u`` times its rounded value, doubled): ``|A − L_k C − M̂| <=
pe(|L_k| |C|) + 2u |M̂|`` and alike; ``|S M̂ − Q S| <= (1 + 2u) |fl(fl(S M̂) − fl(Q S))| +
pe(|S| |M̂|) + pe(|Q| |S|)``; ``|I − Si S| <= R_S`` (evaluated the same way).

**The scaled norms.** The states may differ in magnitude by many orders (``x`` of ``1e6``,
``1`` and ``1e-3``): a bound on ``‖x‖∞`` would charge every row with the rounding of the
largest state. So each bound ``|M| |x|`` is taken as ``(|M| d_x) ‖D_x⁻¹ x‖∞``, ``D_x =
diag(d_x)``, and alike in ``z`` with ``d_z`` (``S = I``: ``d_x = d_z = d``), with ``d`` powers of
two (:func:`~.operators.state_scale`: the magnitude of the prior box plus one step's
disturbance radius; any positive ``d`` is sound), so that ``D⁻¹ v`` is exact but for underflow
(less than ``η`` per entry, added). Only the weighted row sums of the bounds are kept
(:class:`RowErrors`): each acts on ``‖D_x⁻¹ x‖∞``, ``‖D_z⁻¹ z‖∞`` or the ∞-norm of ``u``,
``y`` or ``d``, and ``‖D_x⁻¹ x‖∞ <= k_x ‖D_z⁻¹ z‖∞`` with ``k_x = ‖D_x⁻¹ |Si| D_z‖∞ / (1 −
‖D_x⁻¹ R_S D_x‖∞)`` (from ``x = Si z + (I − Si S) x``; ``k_x = 1`` when ``S = I``; unscaled
when ``‖D_x⁻¹ R_S D_x‖∞ >= 1/2``; sparse systems unscaled).

**The data.** A measurement is taken as recorded: the float nearest to an admissible ``y`` (a
logger rounds once), so ``|y_true − y| <= 2u |y|``. It enters the state rows through ``L_z``
(``2u |L_z| 1 ‖y‖∞``) and the test of ``y`` (its slack grows by ``2u ‖y‖∞``): a sample within
rounding of its bound is never flagged, and using it keeps the bounds sound.

**The evaluation.** Row ``i`` of ``fl(W v)`` is a sum of ``m`` products (``m``: the row length,
or the largest number of stored entries of a row of a sparse ``W``), in any order, with FMA or
not: off by at most ``2γ_{m+2} Σ_j |W_ij| |v_j| + (m + 2) η`` (:func:`product_error`), and
``Σ_j |W_ij| |v_j| <= Σ_b (Σ_{j in b} |W_ij| w_j) ‖D_b⁻¹ v_b‖∞`` over the blocks ``b`` of ``v``
(``D_b = D_z`` and ``w = d_z`` on the blocks ``z̄``, ``z̲``; ``I`` and 1 elsewhere).

**One step's bound.** So every row ``i`` satisfies

    exact bound_i <= fl(W v)_i + Σ_b R_ib ‖D_b⁻¹ v_b‖∞ + e0_i

with ``R`` the sum of the evaluation and the matrix-error coefficients of each block
(``‖D_z⁻¹ z‖∞ <= ‖D_z⁻¹ z̄‖∞ + ‖D_z⁻¹ z̲‖∞``, so the terms on ``z`` and ``x`` go on both of
those blocks; :func:`row_bounds`). ``R`` and ``e0`` are enlarged by
:func:`~ivobs.sets.rounding.upper` so that their own evaluation ``e = fl(R b + e0)`` (``b``:
the block maxima of ``|v| / w``) is at least the exact sum, and by
``4u Σ_b (Σ_{j in b} |W_ij| w_j) b_b >= 2u |fl(W v)_i|`` and a factor ``1 + 4u``, which pays
for the last addition: ``fl(o + e) >= o + e − u |o + e|`` and ``|o + e| <= |o| + e``, so with
``e' >= (1 + 2u) e + 2u |o|`` the rounded ``fl(o + e')`` is at least ``o + e`` (underflow: a
sum that rounds to a subnormal is exact). The step adds ``e`` to the upper rows and subtracts
it from the lower rows (``R``, ``e0`` negated there): every computed bound is on the safe side
of the exact Lemma-1 bound from the computed box, which contains the true state by induction
from ``z̲_0 <= S x_0 <= z̄_0``, with no directed rounding. Nothing assumes a magnitude: the
bound scales with the state, the input, the measurement and the gain, at every step and for
every missing-output pattern (no margin, no data scale: ``proven_rounding``).

The vectorised path (:mod:`.vectorised`) is another algorithm with its own proof, built on the
same :class:`RowErrors`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...errors import DesignError
from ...linalg import UNIT_ROUNDOFF
from ...sets.rounding import ETA, gamma, product_error, up, upper

__all__ = ["RowErrors", "Transform", "pattern_errors", "row_bounds", "transform"]

_U2 = 2.0 * UNIT_ROUNDOFF


def _rows(M: Any, w: np.ndarray | None = None) -> np.ndarray:
    """Row sums of ``|M|`` (dense or sparse), as an upper bound (their own rounding covered);
    with ``w``: of ``|M| diag(w)`` (``|M| w``)."""
    s = np.asarray(abs(M).sum(axis=1) if w is None else abs(M) @ w).ravel()
    return np.asarray(upper(s, max(M.shape[-1], 1)))


def _diff(M: Any, n: int, w: np.ndarray | None = None) -> np.ndarray:
    """Row sums of the bound ``2u |M|`` of a difference rounded to ``M`` (weighted by ``w``),
    with the underflow of the ``n``-term products before it."""
    tot = M.shape[-1] if w is None else float(upper(np.sum(w), len(w)))
    return np.asarray(upper(_U2 * _rows(M, w) + (n + 2) * tot * ETA, 2))


@dataclass(frozen=True)
class Transform:
    """The float ``S``, ``Si = fl(S⁻¹)``, the scalings ``dx`` of ``x`` and ``dz`` of ``z``
    (powers of two), the weighted row sums ``rs = R_S dx`` of the bound ``R_S`` of ``|I − Si
    S|`` and ``kx = max_i (|Si| dz)_i / dx_i / (1 − max_i rs_i / dx_i)``, so that ``‖Dx⁻¹ x‖∞
    <= kx ‖Dz⁻¹ z‖∞`` (module docstring)."""

    S: np.ndarray
    Si: np.ndarray
    rs: np.ndarray
    kx: float
    dx: np.ndarray
    dz: np.ndarray


def transform(
    S: np.ndarray, who: str, dx: np.ndarray | None = None, dz: np.ndarray | None = None
) -> Transform:
    """:class:`Transform` of ``S`` with the scalings ``dx``, ``dz`` (ones when not given, or
    when they leave ``max_i rs_i / dx_i >= 1/2``); :class:`~ivobs.DesignError` when ``‖R_S‖∞
    >= 1/2`` (``S`` numerically singular: no bound of ``x`` from ``z``)."""
    n = S.shape[0]
    Si = np.linalg.inv(S)
    SiS = Si @ S
    res = np.abs(SiS - np.eye(n))
    aS, aSi = np.abs(S), np.abs(Si)
    RS = upper((1.0 + _U2) * res + product_error(aSi @ aS, n), 2)  # >= |I − Si S|
    rs = _rows(RS)
    g = float(np.max(rs, initial=0.0))
    if not g < 0.5:
        raise DesignError(
            f"{who}: the transformation S is numerically singular (‖S⁻¹S − I‖ <= {g:.3g} in "
            f"floating point, cond(S) = {np.linalg.cond(S):.3g}): no guaranteed bounds through "
            "x = S⁻¹ z; give another L, R, e1, e2 or S"
        )
    one = np.ones(n)
    if dx is not None and dz is not None:
        rsd = _rows(RS, dx)
        gd = float(up(np.max(rsd / dx, initial=0.0) + ETA))  # (/ dx: exact but for underflow)
        if gd < 0.5:
            kx = float(np.max(_rows(Si, dz) / dx, initial=0.0)) + ETA
            return Transform(S, Si, rsd, float(upper(kx / (1.0 - gd), 2)), dx, dz)
    kx = float(upper(float(np.max(_rows(Si))) / (1.0 - g), 2))
    return Transform(S, Si, rs, kx, one, one)


@dataclass(frozen=True)
class RowErrors:
    """Row sums of the bounds of the matrix errors of one step (module docstring), per row of
    ``z+`` (``ex`` on ``‖D_x⁻¹ x‖∞``, ``eu``, ``ey`` (with the data's rounding), ``ed``), of
    ``x`` (``xx`` on ``‖D_x⁻¹ x‖∞``; ``S ≠ I``) and of the test rows ``C x`` (``px`` on
    ``‖D_x⁻¹ x‖∞``, ``pz`` on ``‖D_z⁻¹ z‖∞``)."""

    ex: np.ndarray
    eu: np.ndarray
    ey: np.ndarray
    ed: np.ndarray
    xx: np.ndarray
    px: np.ndarray
    pz: np.ndarray


def pattern_errors(
    mats: dict[str, Any],
    Lk: np.ndarray,
    tr: Transform | None,
    sys_mats: tuple[Any, ...],
    d: np.ndarray | None = None,
) -> RowErrors:
    """:class:`RowErrors` of the float matrices ``mats`` (``Mh``, ``Bh``, ``Gh`` in ``x``; with
    ``tr``: ``SM``, ``Q``, ``Bz``, ``Lz``, ``G``, ``Cz``) of the gain ``L_k``; ``d`` (``S = I``
    only): the scaling of the states, ``ex`` then on ``‖D⁻¹ x‖∞`` (module docstring)."""
    C, Du, F = sys_mats[2], sys_mats[3], sys_mats[5]
    ny, n = C.shape
    aL = np.abs(Lk)
    Dr, Fr = _rows(Du), _rows(F)
    # x coordinates: |A − L_k C − M̂| 1, |B − L_k D_u − B̂| 1, |E − L_k F − Ĝ| 1
    g_ny = 2.0 * gamma(ny + 2)
    dx = d if tr is None else tr.dx  # |A − L_k C − M̂| dx, on ‖Dx⁻¹ x‖∞
    em = upper(g_ny * (aL @ _rows(C, dx)) + _diff(mats["Mh"], ny, dx), 3)
    eb = upper(g_ny * (aL @ Dr) + _diff(mats["Bh"], ny), 3)
    eg = upper(g_ny * (aL @ Fr) + _diff(mats["Gh"], ny), 3)
    data = _U2 * _rows(Lk)  # the measurement's own rounding through L_k
    zero_n, zero_y = np.zeros(n), np.zeros(ny)
    if tr is None:
        return RowErrors(em, eb, upper(data, 1), eg, zero_n, zero_y, zero_y)
    S, Si = tr.S, tr.Si
    aS = np.abs(S)
    g_n = 2.0 * gamma(n + 2)
    Q, SM = mats["Q"], mats["SM"]
    QS = Q @ S
    tx, tz = float(upper(np.sum(tr.dx), n)), float(upper(np.sum(tr.dz), n))
    resid = (1.0 + _U2) * (np.abs(SM - QS) @ tr.dx)
    ex = upper(
        aS @ em
        + resid
        + g_n * (aS @ _rows(mats["Mh"], tr.dx) + np.abs(Q) @ _rows(S, tr.dx))
        + 4 * n * tx * ETA,
        n + 5,
    )
    eu = upper(aS @ eb + g_n * (aS @ _rows(mats["Bh"])) + n * n * ETA, n + 3)
    ey = upper(g_n * (aS @ _rows(Lk)) + aS @ data + n * n * ETA, n + 3)
    ed = upper(aS @ eg + g_n * (aS @ _rows(mats["Gh"])) + n * n * ETA, n + 3)
    pz = upper(g_n * (np.abs(C) @ _rows(Si, tr.dz)) + n * tz * ETA, n + 2)
    px = upper(np.abs(C) @ tr.rs, n + 1)
    return RowErrors(ex, eu, ey, ed, tr.rs, px, pz)


def row_bounds(
    blocks: list[Any],
    err: RowErrors,
    kx: float,
    sizes: tuple[int, ...],
    has_x: bool,
    m: int,
    obs: np.ndarray,
    d: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``(R, e0)`` of the module docstring for a step matrix whose row groups are
    ``[z+; x (has_x); p − y; y − p]`` (the upper rows; ``p``: the observed outputs ``obs``) and
    whose column blocks ``[z̄, z̲, u, y, d̄, d̲]`` have the ``sizes``; ``blocks[g][b]``: the part
    of ``W`` of row group ``g`` and column block ``b`` (None: zero; its row sums of absolute
    values are taken); ``m``: the longest row; ``d``: the scaling of the ``z`` blocks (their
    row sums weighted by it: ``R`` then acts on ``‖D⁻¹ z̄‖∞``, ``‖D⁻¹ z̲‖∞``). ``R`` has one
    column per nonempty block."""
    ge = 2.0 * gamma(m + 2)
    Vec = np.ndarray | None
    groups: list[tuple[str, np.ndarray, Vec, Vec, Vec]] = [("z", err.ex, err.eu, err.ey, err.ed)]
    if has_x:
        groups.append(("x", err.xx, None, None, None))
    groups += [("p", err.px[obs], None, None, None)] * 2
    R_rows, e0_rows = [], []
    for (name, on_x, on_u, on_y, on_d), sums in zip(groups, blocks, strict=True):
        rows = len(on_x)
        cols = []
        for b, s in enumerate(sums):
            w = d if b in (0, 1) else None  # the z blocks: on ‖D⁻¹ z‖∞
            a = np.zeros(rows) if s is None else _rows(s, w)
            c = (ge + 4.0 * UNIT_ROUNDOFF) * a  # (+ the last addition: 2u |fl(W v)|, doubled)
            if b in (0, 1):  # ‖Dx⁻¹ x‖ <= kx ‖Dz⁻¹ z‖ <= kx (‖Dz⁻¹ z̄‖ + ‖Dz⁻¹ z̲‖)
                c = c + kx * on_x
                if name == "p":
                    c = c + err.pz[obs]
            elif b == 2 and on_u is not None:
                c = c + on_u
            elif b == 3:
                c = c + (on_y if on_y is not None else (_U2 if name == "p" else 0.0))
            elif b in (4, 5) and on_d is not None:
                c = c + on_d
            cols.append(c)
        R_rows.append(np.column_stack(cols))
        e0_rows.append(np.full(rows, (m + 4) * ETA))
    R = np.vstack(R_rows) * (1.0 + 4.0 * UNIT_ROUNDOFF)
    keep = [b for b, size in enumerate(sizes) if size]
    nb = len(keep)
    e0 = upper(np.concatenate(e0_rows) * (1.0 + 4.0 * UNIT_ROUNDOFF), nb + 2) + (nb + 4) * ETA
    return np.ascontiguousarray(upper(R[:, keep], nb + 2)), e0
