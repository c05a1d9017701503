"""The matrices of the split-form recursion in ``z = S x`` and what is derived from them.

Everything here is computed once when the estimator is designed (:class:`SplitOperators`), except
the step matrices of a missing-sample pattern, computed the first time that pattern occurs
(there are ``2^ny`` of them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...design.finite_memory import WindowBound, window_bound
from ...linalg import gamma
from ...model import LinearSystem
from ...sets import Box, image_bounds, neg, pos
from .rounding import CONSISTENCY_TOL, Margins, largest, transform_conversion, transform_step_error

__all__ = ["FusedStep", "FusedTransformed", "SparseStep", "SplitOperators", "StepMatrices", "hull"]


def hull(
    Mp: np.ndarray, Mn: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Lemma 1 of [Tang2019] with precomputed ``M⁺``, ``M⁻`` (finite bounds)."""
    return Mp @ lo - Mn @ hi, Mp @ hi - Mn @ lo


@dataclass(frozen=True)
class StepMatrices:
    """What one step needs for a given set of observed components."""

    Qp: np.ndarray  # Q⁺
    Qn: np.ndarray  # Q⁻
    Bz: np.ndarray  # S (B − L_k D_u)
    Lz: np.ndarray  # S L_k
    Gz: np.ndarray  # S (E − L_k F)
    Gp: np.ndarray  # (S (E − L_k F))⁺
    Gn: np.ndarray  # (S (E − L_k F))⁻
    # S ≠ I: coefficients of one step's error on (‖x‖∞, ‖z‖∞, ‖y‖∞, ‖u‖∞, ‖d‖∞)
    err: np.ndarray | None = None


@dataclass(frozen=True)
class SparseStep:
    """One step of a sparse system (``S = I``): the stacked matrix acting on ``[z̄; z̲]``."""

    S2: Any  # CSR [[Q⁺, −Q⁻], [−Q⁻, Q⁺]], Q = A − L_k C: one sparse product per step
    K: Any  # CSC [[L_k, B_z], [L_k, B_z]]: the known inputs [y; u] of both bounds
    Bz: np.ndarray
    Lz: np.ndarray
    Gz: np.ndarray
    Gp: np.ndarray
    Gn: np.ndarray


@dataclass(frozen=True)
class FusedStep:
    """The step with every output observed (``S = I``, dense, constant bounds) as one product:
    ``W [z̄; z̲; u; y] + w = [z̄+; z̲+; p̄; p̲]`` (before the rounding bound), with
    ``W = [[Q⁺, −Q⁻, B_z, L], [−Q⁻, Q⁺, B_z, L], [C⁺, −C⁻, D_u, 0], [−C⁻, C⁺, D_u, 0]]``,
    ``w = [ḡ; g̲; f̄; f̲]``: the next bounds and those of ``C x + D_u u + F d`` (consistency).
    ``starts``, ``coef``, ``e_d``: the rounding bound :meth:`Margins.local_error` on the
    blocks ``[z̄; z̲]``, ``u``, ``y`` of the same vector (``γ`` folded in); ``bounds``,
    ``coef_list``: the same blocks as ``(start, end)`` and ``coef`` as Python floats (the
    fast step's float loop)."""

    W: np.ndarray
    w: np.ndarray
    starts: np.ndarray
    coef: np.ndarray
    e_d: float
    bounds: list[tuple[int, int]]
    coef_list: list[float]


@dataclass(frozen=True)
class FusedTransformed:
    """:class:`FusedStep` for ``S ≠ I``: ``W [z̄; z̲; u; y] + w = [z̄+; z̲+; x̄; x̲; p̄; p̲]``
    (before the rounding terms): the next bounds, the hull of ``S⁻¹ [z̲, z̄]`` ([Tang2019,
    eqs. (42e-f)]) and that of ``C`` on it plus ``D_u u + F d`` (consistency; the widening of
    the ``x`` box for the computed inverse enters it as ``|C| 1`` times that widening).
    ``starts``: the blocks ``[z̄; z̲]``, ``u``, ``y`` of the vector; ``err``: the coefficients of
    :attr:`StepMatrices.err`; ``dmax``: the largest bound of ``d``; ``cabs``: ``|C| 1``."""

    W: np.ndarray
    w: np.ndarray
    starts: np.ndarray
    err: list[float]
    dmax: float
    cabs: np.ndarray


class SplitOperators:
    """The recursion's matrices for a gain ``L`` and a transformation ``S`` (None: ``S = I``),
    the consistency test of ``y[k]``, the map back to ``x`` and the rounding terms of one step.

    ``sparse``: ``A`` is ``scipy.sparse`` and ``S = I`` (one sparse product of the stacked
    system per step). ``margins``: the rounding factors of ``S = I`` (None for ``S ≠ I``, whose
    step errors are :attr:`StepMatrices.err`)."""

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box,
        L: np.ndarray,
        S: np.ndarray | None,
        margins: Margins | None,
        who: str,
    ):
        self.sys = sys
        self.x0 = x0
        self.nx, self.ny, self.nd = sys.nx, sys.ny, sys.nd
        self.sparse: bool = sys.is_sparse and S is None
        self.A: np.ndarray | None = None if self.sparse else sys.A_at(0)
        self.B, self.C, self.Du = sys.B_at(0), sys.C_at(0), sys.D_at(0)
        self.E, self.F = sys.E_at(0), sys.F_at(0)
        self.L = L
        self.S = S
        self.Si: np.ndarray | None = None if S is None else np.linalg.inv(S)
        self.Si_pm: tuple[np.ndarray, np.ndarray] | None = None
        self.tconv: tuple[float, float] | None = None  # transform_conversion (S ≠ I)
        if S is not None:
            assert self.Si is not None
            self.Si_pm = (pos(self.Si), neg(self.Si))
            self.tconv = transform_conversion(S, self.Si, who)
        self.margins = margins
        self.unc = sys.uncertainty
        """The radii of the interval matrices (None: exact matrices), ivobs.model.uncertain."""
        self.mu = 1.0 if margins is None else margins.mu
        self.nu = 1.0 if margins is None else margins.nu
        self.ctol = CONSISTENCY_TOL if margins is None else margins.ctol
        self.C_pm = (pos(self.C), neg(self.C))
        self.F_pm = (pos(self.F), neg(self.F))
        self._patterns: dict[bytes, Any] = {}
        self._inputs: dict[bytes, np.ndarray] = {}
        # constant bounds: the disturbance terms, once
        self.const: bool = sys.has_constant_bounds
        self.d_const: Box | None = sys.d_at(0) if self.const else None
        self.dmax: float | None = None
        self.f_hull: tuple[np.ndarray, np.ndarray] | None = None
        self.f_mid_const: tuple[np.ndarray, np.ndarray] | None = None
        if self.d_const is not None:
            d = self.d_const
            if self.nd:
                self.dmax = float(max(np.abs(d.lo).max(), np.abs(d.hi).max()))
            self.f_hull = hull(*self.F_pm, d.lo, d.hi)
            self.f_mid_const = self._f_mid(d)
        # sparse systems: Lemma 1 for C on the few states it reads (point sensors)
        self.C_gather: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.C_stacked: np.ndarray | None = None
        if self.sparse:
            self._point_sensors()
        observed = np.ones(self.ny, dtype=bool)
        self.full = self.matrices(observed)
        """The step matrices with every output observed."""
        self.full_inputs: np.ndarray | None = None
        if self.sparse and self.d_const is not None:
            self.full_inputs = self.input_bounds(self.full, observed, self.d_const)
        self.kappa_z = np.inf if S is None else self._transform_kappa()
        self.fused = self._fused()
        """:class:`FusedStep` of a complete ``y`` (dense, ``S = I``, exact matrices, constant
        bounds), else None."""
        self.fused_z = self._fused_transformed()
        """:class:`FusedTransformed`: the same for ``S ≠ I``, else None."""
        self.window: WindowBound | None = None
        """The finite-memory bound used after missing samples (:mod:`.window`): dense,
        time-invariant systems with constant bounds, ``S = I``."""
        exact = self.unc is None  # the bound of a window uses the exact A
        if S is None and self.A is not None and self.const and not sys.is_time_varying and exact:
            db = self.d_const
            dlo, dhi = (np.zeros(0), np.zeros(0)) if db is None else (db.lo, db.hi)
            self.window = window_bound(self.A, self.B, self.C, self.Du, self.E, self.F, dlo, dhi)

    # -- design-time helpers -----------------------------------------------------------------
    def _fused(self) -> FusedStep | None:
        """The step of a complete ``y`` as one product (:class:`FusedStep`)."""
        if self.sparse or self.S is not None or self.unc is not None or self.margins is None:
            return None
        if self.d_const is None or self.f_hull is None:
            return None
        m, n, ny, nu = self.full, self.nx, self.ny, self.sys.nu
        Cp, Cn = self.C_pm
        Zy = np.zeros((ny, ny))
        W = np.block(
            [
                [m.Qp, -m.Qn, m.Bz, m.Lz],
                [-m.Qn, m.Qp, m.Bz, m.Lz],
                [Cp, -Cn, self.Du, Zy],
                [-Cn, Cp, self.Du, Zy],
            ]
        )
        glo, ghi = hull(m.Gp, m.Gn, self.d_const.lo, self.d_const.hi)
        flo, fhi = self.f_hull
        w = np.concatenate([ghi, glo, fhi, flo])
        rb = self.margins.bound
        sizes = np.array([2 * n, nu, ny])
        keep = sizes > 0
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])[keep]
        coef = np.array([rb.a_z, rb.a_u, rb.a_y])[keep] * rb.gamma
        e_d = rb.gamma * rb.a_d * (self.dmax or 0.0) if rb.a_d else 0.0
        ends = [*starts.tolist()[1:], W.shape[1]]
        bounds = list(zip(starts.tolist(), ends, strict=True))
        return FusedStep(W, w, starts, coef, e_d, bounds, coef.tolist())

    def _fused_transformed(self) -> FusedTransformed | None:
        """A complete ``y``'s step in ``z = S x`` as one product (:class:`FusedTransformed`)."""
        if self.S is None or self.Si_pm is None or self.tconv is None or self.unc is not None:
            return None
        if self.A is None or self.d_const is None or self.f_hull is None:
            return None
        m, n, ny, nu = self.full, self.nx, self.ny, self.sys.nu
        Sp, Sn = self.Si_pm
        Cp, Cn = self.C_pm
        P, N = Cp @ Sp + Cn @ Sn, Cp @ Sn + Cn @ Sp  # C⁺, C⁻ after the hull of S⁻¹
        Zu, Zy = np.zeros((n, nu)), np.zeros((n, ny))
        W = np.block(
            [
                [m.Qp, -m.Qn, m.Bz, m.Lz],
                [-m.Qn, m.Qp, m.Bz, m.Lz],
                [Sp, -Sn, Zu, Zy],
                [-Sn, Sp, Zu, Zy],
                [P, -N, self.Du, np.zeros((ny, ny))],
                [-N, P, self.Du, np.zeros((ny, ny))],
            ]
        )
        glo, ghi = hull(m.Gp, m.Gn, self.d_const.lo, self.d_const.hi)
        flo, fhi = self.f_hull
        w = np.concatenate([ghi, glo, np.zeros(2 * n), fhi, flo])
        sizes = np.array([2 * n, nu, ny])
        starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])[sizes > 0]
        assert m.err is not None
        dmax = largest(self.d_const.lo, self.d_const.hi)
        return FusedTransformed(W, w, starts, m.err.tolist(), dmax, np.abs(self.C).sum(axis=1))

    def _point_sensors(self) -> None:
        """Lemma 1 for ``C`` on the few states it reads (point sensors of sparse systems)."""
        Cc = self.sys.sparse("C").tocoo()
        Rp = np.zeros((Cc.nnz, self.ny))
        Rn = np.zeros((Cc.nnz, self.ny))
        Rp[np.arange(Cc.nnz), Cc.row] = np.maximum(Cc.data, 0.0)
        Rn[np.arange(Cc.nnz), Cc.row] = np.maximum(-Cc.data, 0.0)
        # centre/radius form: C c = ½ (x̲ + x̄)[cols] (Rp − Rn), |C| r = ½ (x̄ − x̲)[cols] |R|
        self.C_gather = (Cc.col.astype(np.intp), 0.5 * (Rp - Rn), 0.5 * (Rp + Rn))
        # the same on the stacked state [z̄; z̲]: [C c, |C| r] = [z̄[cols], z̲[cols]] @ R2
        Rs, Ra = self.C_gather[1:]
        self.C_stacked = np.block([[Rs, Ra], [Rs, -Ra]])

    def _transform_kappa(self) -> float:
        """``κ_z = ‖(I − |Q|)⁻¹‖_∞`` of the step with every output observed (``S ≠ I``):
        how the steps' errors add up in ``z`` (``inf`` if ``|Q|`` is not Schur)."""
        m = self.full
        n = self.nx
        with np.errstate(all="ignore"):
            try:
                v = np.linalg.solve(np.eye(n) - (m.Qp + m.Qn), np.ones(n))
            except np.linalg.LinAlgError:
                v = np.full(n, np.inf)
        ok = np.all(np.isfinite(v)) and v.min() >= 1.0 - 1e-9
        return float(v.max()) if ok else np.inf

    def initial_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``z_0 = S x_0``: the prior box (``S = I``), or [Tang2019, eqs. (42a-b)]
        widened by the rounding of the products (``γ_{n+1} |S| |x0|``)."""
        lo, hi = self.x0.lo.copy(), self.x0.hi.copy()
        if self.S is not None:
            mag = np.abs(self.S) @ np.maximum(np.abs(lo), np.abs(hi))
            lo, hi = image_bounds(self.S, lo, hi)
            mag *= gamma(self.nx + 1)
            lo, hi = lo - mag, hi + mag
        return lo, hi

    # -- the step matrices of a missing-sample pattern -------------------------------------
    def matrices(self, observed: np.ndarray) -> Any:
        """:class:`StepMatrices` (:class:`SparseStep` for sparse systems) with the gain
        ``L_k = L diag(observed)``."""
        key = observed.tobytes()
        hit = self._patterns.get(key)
        if hit is not None:
            return hit
        Lk = self.L * observed[None, :]
        Bz = self.B - Lk @ self.Du
        Gz = self.E - Lk @ self.F
        if self.sparse:
            self._patterns[key] = self._sparse_step(Lk, Bz, Gz)
            return self._patterns[key]
        assert self.A is not None
        Q = self.A - Lk @ self.C
        err = None
        if self.S is not None:
            S, Si = self.S, self.Si
            assert Si is not None
            Q = S @ Q @ Si
            Bz, Lz, Gz = S @ Bz, S @ Lk, S @ Gz
            err = transform_step_error(S, Si, self.A, Lk, self.C, self.B, self.Du,
                                       self.E, self.F, Q, (Bz, Lz, Gz))  # fmt: skip
            Lk = Lz
        self._patterns[key] = StepMatrices(pos(Q), neg(Q), Bz, Lk, Gz, pos(Gz), neg(Gz), err)
        return self._patterns[key]

    def _sparse_step(self, Lk: np.ndarray, Bz: np.ndarray, Gz: np.ndarray) -> SparseStep:
        from scipy.sparse import bmat, csc_matrix, csr_matrix

        Q = (self.sys.sparse("A") - csr_matrix(Lk) @ self.sys.sparse("C")).tocsr()
        Qp, Qn = Q.maximum(0).tocsr(), (-Q).maximum(0).tocsr()
        S2 = bmat([[Qp, -Qn], [-Qn, Qp]], format="csr")
        S2.eliminate_zeros()
        K = csc_matrix(np.vstack([np.hstack([Lk, Bz])] * 2))  # few columns: CSC
        return SparseStep(S2, K, Bz, Lk, Gz, pos(Gz), neg(Gz))

    def input_bounds(self, m: Any, obs: np.ndarray, dbox: Box) -> np.ndarray:
        """``[ḡ; g̲]`` (Lemma 1 of ``G_k = E − L_k F`` on the bounds of ``d``), kept per
        missing pattern when the bounds are constant."""
        key = obs.tobytes()
        hit = self._inputs.get(key) if self.const else None
        if hit is None:
            glo, ghi = hull(m.Gp, m.Gn, dbox.lo, dbox.hi)
            hit = np.concatenate([ghi, glo])
            if self.const:
                self._inputs[key] = hit
        return hit

    # -- one step -----------------------------------------------------------------------------
    def disturbance(self, k: int, y_k: np.ndarray) -> Box:
        """The bounds of ``d[k]`` (a callable's receive ``y[k]``)."""
        return self.d_const if self.d_const is not None else self.sys.d_at(k, y_k)

    def local_error(self, v: np.ndarray, dbox: Box | None) -> float:
        """:meth:`Margins.local_error` of one step (``S = I``) for ``v = [z̲; z̄; y_obs; u]``
        (any order of the blocks' entries; overwritten)."""
        assert self.margins is not None
        dm = 0.0
        if self.margins.bound.a_d and dbox is not None:
            dm = self.dmax if self.dmax is not None else largest(dbox.lo, dbox.hi)
        return self.margins.local_error(v, dm)

    def to_x(self, k: int, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The box of ``x`` from the bounds of ``z = S x`` ([Tang2019, eqs. (42e-f)]) widened
        for the computed inverse (:func:`transform_conversion`); the prior box at ``k = 0``."""
        if self.Si_pm is None or self.tconv is None:
            return lo, hi
        if k == 0:  # [Tang2019, eq. (42)]: the prior box itself at k = 0
            return self.x0.lo.copy(), self.x0.hi.copy()
        xlo, xhi = hull(*self.Si_pm, lo, hi)
        g, c = self.tconv
        cz = c * largest(lo, hi)
        xi = largest(xlo, xhi)
        e = cz + g * (xi + cz) / (1.0 - g)
        return xlo - e, xhi + e

    def consistent(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        u: np.ndarray,
        y: np.ndarray,
        obs: np.ndarray,
        dbox: Box,
        v: np.ndarray | None = None,
    ) -> bool:
        """``y`` (observed components) ∈ ``C[lo, hi] + D_u u + F[d]`` (``+ [−v, v]``: the
        interval matrices' term, ivobs.estimators._uncertain) up to round-off."""
        if self.sparse:
            if obs.all():
                return self._consistent_stacked(lo, hi, u, y, dbox)
            return self._consistent_sparse(lo, hi, u, y, obs, dbox)
        plo, phi = hull(*self.C_pm, lo, hi)
        if self.f_hull is not None:
            flo, fhi = self.f_hull
        else:
            flo, fhi = hull(*self.F_pm, dbox.lo, dbox.hi)
        du = self.Du @ u
        plo, phi = plo + du + flo, phi + du + fhi
        if v is not None:
            plo, phi = plo - v, phi + v
        tol = self.ctol * (1.0 + np.abs(y) + (phi - plo))  # NaN (missing) compares False
        bad = ((y < plo - tol) | (y > phi + tol)) & obs
        return not bool(np.any(bad))

    def _consistent_sparse(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        u: np.ndarray,
        y: np.ndarray,
        obs: np.ndarray,
        dbox: Box,
    ) -> bool:
        """:meth:`consistent` in centre/radius form on the few states ``C`` reads (sparse
        systems): ``|y − C c − D_u u − F c_d| <= |C| r + |F| r_d`` up to round-off."""
        assert self.C_gather is not None
        cols, Rs, Ra = self.C_gather
        clo, chi = lo[cols], hi[cols]
        yc = (clo + chi) @ Rs
        yr = (chi - clo) @ Ra
        if u.shape[0]:
            yc += self.Du @ u
        fd = self.f_mid(dbox)
        yc += fd[0]
        yr += fd[1]
        return self._within(y, yc, yr, obs)

    def _consistent_stacked(
        self, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, y: np.ndarray, dbox: Box
    ) -> bool:
        """:meth:`_consistent_sparse` for a complete ``y``, on the stacked state ``[z̄; z̲]``."""
        assert self.C_gather is not None and self.C_stacked is not None
        cols, R2 = self.C_gather[0], self.C_stacked
        p = np.concatenate([hi[cols], lo[cols]]) @ R2  # [C c, |C| r]
        fd = self.f_mid(dbox)
        yc = p[: self.ny] + fd[0]
        if u.shape[0]:
            yc += self.Du @ u
        yr = p[self.ny :] + fd[1]
        return self._within(y, yc, yr, None)

    def _within(
        self, y: np.ndarray, yc: np.ndarray, yr: np.ndarray, obs: np.ndarray | None
    ) -> bool:
        """``|y − yc| <= yr`` up to round-off on the observed components (``obs``; None: all)."""
        dev = np.abs(y - yc)
        dev -= yr
        if not (dev > 0.0).any():  # NaN (missing) compares False
            return True
        tol = self.ctol * (1.0 + np.abs(y) + 2.0 * yr)
        bad = dev > tol
        return not bool(np.any(bad if obs is None else bad & obs))

    def f_mid(self, dbox: Box) -> tuple[np.ndarray, np.ndarray]:
        """Centre and radius of ``F d`` over the bounds."""
        if self.f_mid_const is not None:
            return self.f_mid_const
        return self._f_mid(dbox)

    def _f_mid(self, dbox: Box) -> tuple[np.ndarray, np.ndarray]:
        flo, fhi = hull(*self.F_pm, dbox.lo, dbox.hi)
        return 0.5 * (flo + fhi), 0.5 * (fhi - flo)
