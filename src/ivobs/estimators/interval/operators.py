"""The matrices of the interval recursion, built once per missing-output pattern.

:class:`Operators` holds what the three observers share after their design (the gain ``L``,
the transformation ``S`` or none), and builds on first use, for each pattern of observed
outputs, the :class:`StepOperator` of one step (:mod:`.rounding` for the rows and the error
bound): one matrix ``W`` (dense, or ``scipy.sparse`` when ``A`` is) and the coefficients of its
rounding bound. There are at most ``2^ny`` patterns; a system with ``ny`` outputs missing at
random uses few of them.

**The gain of a pattern.** While outputs are missing the observer uses a gain whose columns of
the missing outputs are zero (the identity behind the step holds for any gain). ``L diag(obs)``
keeps the design's gain on the outputs present; its error dynamics ``|Q|`` (the matrix that
propagates the width, ``Q = S (A − L_k C) S⁻¹``) may fail to be Schur although the plant is
stable (with ``S ≠ I`` often: ``|S A S⁻¹|`` can be far from ``|A|``). So when ``ρ(|Q|) >= 1``
the pattern takes the gain among ``L diag(obs)``, zero (the open-loop prediction) and the
width-optimal gain of the observed outputs in ``z`` coordinates
(:func:`~ivobs.design.width_lp.width_gain` on ``(S A S⁻¹, C_obs S⁻¹)``, which exists whenever
some gain makes ``|Q|`` Schur) with the smallest ``ρ(|Q|)``: designed once, cached with the
pattern. Dense systems only (a sparse system keeps ``L diag(obs)``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...design.finite_memory import WindowBound, window_bound
from ...errors import DesignError
from ...linalg import spectral_radius
from ...model import LinearSystem
from ...sets import Box, image_bounds, neg, pos
from ...sets.rounding import ETA, upper
from .rounding import RowErrors, Transform, pattern_errors, row_bounds, transform

__all__ = ["Operators", "StepOperator"]

_GROUPED = 64
"""Above this many upper rows a step's rounding bound takes one coefficient per group of rows
(their largest): for a large sparse system a dense ``R b`` would cost as much as the step."""


@dataclass(frozen=True)
class StepOperator:
    """One step for a pattern of observed outputs (:mod:`.rounding`): ``W`` maps
    ``v = [z̄; z̲; u; y; d̄; d̲]`` to the upper rows ``[z̄+; x̄; p̄ − y; y − p̲]`` (the first
    ``h``; ``p`` the bounds of ``C x + D_u u + F d`` on the observed outputs: the consistency
    test of ``y[k]``) and the lower rows ``[z̲+; x̲]``; ``R``, ``e0``: the rounding bound
    ``R b + e0`` with ``b`` the largest ``|v_i|`` of each nonempty block (``starts``), negated
    on the lower rows. ``L``: the gain of the pattern (in ``x``); ``Lmag >= |S L|``; ``Q``,
    ``Bz``, ``Lz``, ``G``, ``Cz``: the float matrices (:mod:`.rounding`); ``err``: their error
    bounds; ``rho``: ``ρ(|Q|)`` (NaN: not computed)."""

    W: Any
    R: np.ndarray
    e0: np.ndarray
    starts: np.ndarray
    h: int
    rows: np.ndarray | None
    L: np.ndarray
    Lmag: np.ndarray
    Q: Any
    Bz: np.ndarray
    Lz: np.ndarray
    G: np.ndarray
    Cz: np.ndarray
    err: RowErrors
    rho: float
    weights: np.ndarray | None = None

    def bounds(self, v: np.ndarray) -> np.ndarray:
        """The upper rows (the first :attr:`h`) and the lower rows of one step, each rounded to
        the safe side of the exact Lemma-1 bound (:mod:`.rounding`): ``fl(W v) ± (R b + e0)``,
        with the rounding of that last addition covered. ``weights``: ``1 / d`` on the ``z``
        blocks, 1 elsewhere (powers of two: ``|v| w`` is exact but for underflow, less than
        ``η`` per entry, added)."""
        out: np.ndarray = self.W @ v
        a = np.abs(v)
        if self.weights is not None:
            a *= self.weights
            a += ETA
        e = self.R @ np.maximum.reduceat(a, self.starts)  # (R, e0: signed per side)
        e += self.e0
        out += e if self.rows is None else np.repeat(e, self.rows)
        return out


def state_scale(x0: Box, E: np.ndarray, dw: np.ndarray) -> np.ndarray:
    """The scaling ``d`` of the states (powers of two within ``2^±400``): the magnitude of the
    prior box plus one step's disturbance radius ``|E| Δ / 2``, each at least ``2⁻³⁰`` times
    the largest; ones when they are all within a factor ``2¹⁰`` (:mod:`.rounding`: any
    positive ``d`` is sound; this one weighs each state's rounding by its own magnitude, not
    the largest state's, where they differ by orders of magnitude)."""
    n = len(x0.lo)
    with np.errstate(all="ignore"):
        m = np.maximum(np.abs(x0.lo), np.abs(x0.hi)) + np.abs(E) @ (0.5 * dw)
    m = np.where(np.isfinite(m) & (m > 0.0), m, 0.0)
    top = float(np.max(m, initial=0.0))
    if not top > 0.0:
        return np.ones(n)
    m = np.maximum(m, top * 2.0**-30)
    if top <= 1024.0 * float(np.min(m)):  # magnitudes within 2^10: the plain ∞-norm
        return np.ones(n)
    d: np.ndarray = np.ldexp(1.0, np.clip(np.frexp(m)[1], -400, 400))
    return d


class Operators:
    """The step operators of a gain ``L`` and a transformation ``S`` (None: ``S = I``), the
    prior bounds of ``z[0]``, the bounds of ``d[k]`` and the finite-memory bound
    (:mod:`.window`)."""

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box,
        L: np.ndarray,
        S: np.ndarray | None,
        who: str,
        memory: bool = True,
    ):
        self.sys, self.x0, self.L, self.who = sys, x0, L, who
        self.memory = memory
        """Whether every box is met with the finite-memory bound (:mod:`.window`; the option
        ``finite_memory``)."""
        self.nx, self.ny, self.nu, self.nd = sys.nx, sys.ny, sys.nu, sys.nd
        self.sparse: bool = sys.is_sparse and S is None
        A = sys.sparse("A") if self.sparse else sys.A_at(0)
        self.mats = (A, sys.B_at(0), sys.C_at(0), sys.D_at(0), sys.E_at(0), sys.F_at(0))
        self.tr: Transform | None = None
        if S is not None:
            dw = sys.d_widths()
            dx = state_scale(x0, self.mats[4], dw)
            zlo, zhi = image_bounds(S, x0.lo, x0.hi)
            dz = state_scale(Box(zlo, zhi), np.abs(S) @ np.abs(self.mats[4]), dw)
            self.tr = transform(S, who, dx, dz)
        self.xrows = 0 if S is None else sys.nx
        """Rows of the box of ``x`` in a step's bounds (``S ≠ I``)."""
        self.unc = sys.uncertainty
        """The radii of the interval matrices (None: exact matrices), ivobs.model.uncertain."""
        n, nu, ny, nd = self.nx, self.nu, self.ny, self.nd
        self.sizes = (n, n, nu, ny, nd, nd)
        ends = np.cumsum(self.sizes)
        self.starts = np.array([e - s for e, s in zip(ends, self.sizes, strict=True) if s])
        self._patterns: dict[bytes, StepOperator] = {}
        self.scale: np.ndarray | None = None
        """The scaling ``d`` of ``z`` (powers of two) in which the step's rounding is measured
        (:mod:`.rounding`; ``S ≠ I``: ``tr.dz``); None: unscaled (sparse systems, or states of
        magnitudes within ``2¹⁰``)."""
        self.weights: np.ndarray | None = None
        if self.tr is not None or not self.sparse:
            self.scale = (
                state_scale(x0, self.mats[4], sys.d_widths()) if self.tr is None else self.tr.dz
            )
            if np.all(self.scale == 1.0):  # the plain ∞-norm: no weights in the step
                self.scale = None
            else:
                one = np.ones(nu + ny + 2 * nd)
                self.weights = np.concatenate((1.0 / self.scale, 1.0 / self.scale, one))
        self.d_const: tuple[np.ndarray, np.ndarray] | None = None
        if sys.has_constant_bounds:
            box = sys.d_at(0)
            self.d_const = (box.hi, box.lo)
        self.full = self.pattern(np.ones(ny, dtype=bool))
        """The step with every output observed."""
        self.window: WindowBound | None = None
        """The finite-memory bound (:mod:`.window`): dense, time-invariant systems with exact
        matrices and constant bounds, ``(A, C)`` observable."""
        if not self.sparse and self.d_const is not None and not sys.is_time_varying:
            if self.unc is None:
                dhi, dlo = self.d_const
                self.window = window_bound(*self.mats, dlo, dhi)

    @property
    def S(self) -> np.ndarray | None:
        return None if self.tr is None else self.tr.S

    # -- one pattern ---------------------------------------------------------------------------
    def pattern(self, obs: np.ndarray) -> StepOperator:
        """The :class:`StepOperator` of the outputs ``obs`` (module docstring: its gain)."""
        key = obs.tobytes()
        hit = self._patterns.get(key)
        if hit is not None:
            return hit
        op = self._build(self.L * obs[None, :], obs)
        if not obs.all() and not self.sparse and not op.rho < 1.0:
            for Lk in self._other_gains(obs):
                cand = self._build(Lk, obs)
                if cand.rho < op.rho:
                    op = cand
        self._patterns[key] = op
        return op

    def _other_gains(self, obs: np.ndarray) -> list[np.ndarray]:
        """Zero, and the width-optimal gain of the observed outputs in ``z`` coordinates."""
        from ...design.width_lp import MAX_LP_STATES, width_gain

        zero = np.zeros_like(self.L)
        if not obs.any() or self.nx > MAX_LP_STATES:
            return [zero]
        A, _, C, _, E, F = self.mats
        S, Si = (np.eye(self.nx), np.eye(self.nx)) if self.tr is None else (self.tr.S, self.tr.Si)
        try:
            Lz = width_gain(S @ A @ Si, C[obs] @ Si, S @ E, F[obs], self.sys.d_widths(),
                            nonnegative=False, who=self.who)  # fmt: skip
        except DesignError:
            return [zero]
        Lk = np.zeros_like(self.L)
        Lk[:, obs] = Si @ Lz
        return [zero, Lk]

    def _build(self, Lk: np.ndarray, obs: np.ndarray) -> StepOperator:
        """The :class:`StepOperator` of the gain ``L_k`` and the observed outputs ``obs``
        (:mod:`.rounding`)."""
        A, B, C, Du, E, F = self.mats
        if self.sparse:
            from scipy.sparse import csr_matrix

            Mh: Any = (A - csr_matrix(Lk) @ csr_matrix(C)).tocsr()
        else:
            Mh = A - Lk @ C
        Bh, Gh = B - Lk @ Du, E - Lk @ F
        mats: dict[str, Any] = {"Mh": Mh, "Bh": Bh, "Gh": Gh}
        tr = self.tr
        if tr is None:
            Q, Bz, Lz, G, Cz = Mh, Bh, Lk, Gh, C
            Lmag = np.abs(Lk)
        else:
            SM = tr.S @ Mh
            Q, Bz, Lz, G, Cz = SM @ tr.Si, tr.S @ Bh, tr.S @ Lk, tr.S @ Gh, C @ tr.Si
            mats.update(SM=SM, Q=Q)
            Lmag = upper(np.abs(tr.S) @ np.abs(Lk), self.nx)
        err = pattern_errors(mats, Lk, tr, self.mats, self.scale)
        W, sums = self._rows(Q, Bz, Lz, G, Cz, obs)
        m = self.nx * 2 + self.nu + self.ny + 2 * self.nd
        if self.sparse:
            m = int(np.max(np.diff(W.indptr), initial=1))
        kx = 1.0 if tr is None else tr.kx
        R1, e01 = row_bounds(sums, err, kx, self.sizes, tr is not None, m, obs, self.scale)
        rho = np.nan if self.sparse else spectral_radius(np.abs(Q))
        h = R1.shape[0]
        lows = h - 2 * int(obs.sum())  # the lower rows: [z̲+; x̲]
        R, e0, rows = np.vstack([R1, -R1[:lows]]), np.concatenate([e01, -e01[:lows]]), None
        if h > _GROUPED:  # one bound per group of rows (the largest): a few operations a step
            no = int(obs.sum())
            sizes = np.array([self.nx, self.xrows, no, no])
            ends = np.cumsum(sizes)
            nb = R1.shape[1]
            Rg = np.array(
                [R1[a - k : a].max(axis=0) if k else np.zeros(nb) for a, k in zip(ends, sizes)]
            )
            e0g = np.array([e01[a - k : a].max() if k else 0.0 for a, k in zip(ends, sizes)])
            R, e0 = np.vstack([Rg, -Rg[:2]]), np.concatenate([e0g, -e0g[:2]])
            rows = np.concatenate([sizes, sizes[:2]])
        return StepOperator(
            W=W,
            R=np.ascontiguousarray(R),
            e0=e0,
            rows=rows,
            starts=self.starts,
            h=h,
            L=Lk,
            Lmag=Lmag,
            Q=Q,
            Bz=Bz,
            Lz=Lz,
            G=G,
            Cz=Cz,
            err=err,
            rho=float(rho),
            weights=self.weights,
        )

    def _rows(
        self, Q: Any, Bz: np.ndarray, Lz: np.ndarray, G: np.ndarray, Cz: np.ndarray, obs: np.ndarray
    ) -> tuple[Any, list[list[Any]]]:
        """``W`` (:mod:`.rounding`: the upper rows ``[z̄+; x̄; p̄ − y; y − p̲]``, then the lower
        rows ``[z̲+; x̲]``; test rows for the observed outputs only) and the row sums of ``|W|``
        per row group and column block (both sides alike: ``|Q| = Q⁺ + Q⁻``)."""
        _, _, _, Du, _, F = self.mats
        n, nu, nd = self.nx, self.nu, self.nd
        Gp, Gn = pos(G), neg(G)
        Cp, Cn, Dy, Fp, Fn = pos(Cz[obs]), neg(Cz[obs]), Du[obs], pos(F[obs]), neg(F[obs])
        Iy = np.eye(self.ny)[obs]
        if self.sparse:
            from scipy.sparse import bmat, csr_matrix

            Qp, Qn = Q.maximum(0).tocsr(), (-Q).maximum(0).tocsr()
            c = csr_matrix
            rows = [
                [Qp, -Qn, c(Bz), c(Lz), c(Gp), c(-Gn)],
                [c(Cp), c(-Cn), c(Dy), c(-Iy), c(Fp), c(-Fn)],
                [c(Cn), c(-Cp), c(-Dy), c(Iy), c(Fn), c(-Fp)],
                [-Qn, Qp, c(Bz), c(Lz), c(-Gn), c(Gp)],
            ]
            W: Any = bmat(rows, format="csr", dtype=float)
            W.eliminate_zeros()
            aQ = abs(Q)
        else:
            Qp, Qn = pos(Q), neg(Q)
            rows = [[Qp, -Qn, Bz, Lz, Gp, -Gn]]
            low = [[-Qn, Qp, Bz, Lz, -Gn, Gp]]
            if self.tr is not None:
                Sp, Sn = pos(self.tr.Si), neg(self.tr.Si)
                Zu, Zx, Zd = np.zeros((n, nu)), np.zeros((n, self.ny)), np.zeros((n, nd))
                rows.append([Sp, -Sn, Zu, Zx, Zd, Zd])
                low.append([-Sn, Sp, Zu, Zx, Zd, Zd])
            rows += [[Cp, -Cn, Dy, -Iy, Fp, -Fn], [Cn, -Cp, -Dy, Iy, Fn, -Fp]]
            W = np.block(rows + low)
            aQ = np.abs(Q)
        sums: list[list[Any]] = [[aQ, aQ, Bz, Lz, G, G]]
        if self.tr is not None:
            sums.append([self.tr.Si, self.tr.Si, None, None, None, None])
        test = [Cz[obs], Cz[obs], Dy, Iy, F[obs], F[obs]]
        sums += [test, test]
        return W, sums

    # -- data ----------------------------------------------------------------------------------
    def disturbance(self, k: int, y_k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(d̄, d̲)``: the bounds of ``d[k]`` (a callable's receive ``y[k]``)."""
        if self.d_const is not None:
            return self.d_const
        box = self.sys.d_at(k, y_k)
        return box.hi, box.lo

    def initial_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``z_0 = S x_0``: the prior box (``S = I``), or [Tang2019, eqs. (42a-b)]
        (Lemma 1 of ``S``, evaluated with its rounding bound)."""
        lo, hi = self.x0.lo.copy(), self.x0.hi.copy()
        if self.tr is not None:
            lo, hi = image_bounds(self.tr.S, lo, hi)
        return lo, hi
