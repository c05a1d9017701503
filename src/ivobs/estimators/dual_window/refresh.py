"""The window program solved by HiGHS, for the multipliers the cache keeps.

The program over the blocks ``(x_p, d_p)`` of the window (positions ``p = 0..N``, the newest
last): the measurement rows ``C x_p + F d_p = y_p − D u_p`` (first, so that their duals are the
first ``ny (N+1)`` entries), then the dynamics rows ``x_{p+1} − A x_p − E d_p = B u_p``. The
matrix is constant (a time-invariant system); only the right-hand sides and the bound of the
first state change: ``x_s`` in the box proven at the window's start ``s``, the other ``x_p``
free, ``d_p`` in the model's box; the rows before ``s`` are free. HiGHS sees the program shifted
to the centres of the boxes (``z = m + z'``), so that its tolerances act at the scale of the
widths, as in :mod:`ivobs.estimators.exact.highs`.

The solver's answer is never used as a bound: its measurement duals ``μ`` go into the cache,
and every bound is the certified evaluation of :mod:`.certificate`, valid for any ``μ``
[Neumaier2004]. The ``2 nx`` programs of one refresh are solved one after the other, each
warm-started from the previous optimum; the first starts from the basis saved in the state (so
that a restored state continues with the same solves), by the dual simplex with Devex pricing
(:meth:`ivobs.sets.lp.LinearProgram.solve`: steepest-edge weights would cost a solve per row to
set up there, and a solve per iteration to keep up through the primal chain that follows).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import scipy.sparse as sp

from ...sets.lp import LinearProgram, basis_of
from ..exact.highs import ITERATION_LIMIT
from .certificate import Layout

__all__ = ["WindowLP"]


class WindowLP:
    """The HiGHS model of the window program of a time-invariant system (module docstring)."""

    def __init__(self, mats: tuple[np.ndarray, ...], d_lo: np.ndarray, d_hi: np.ndarray,
                 lay: Layout):  # fmt: skip
        self.mats, self.lay = mats, lay
        self.d_lo, self.d_hi = d_lo, d_hi
        A, _B, C, _D, E, F = mats
        N, nx, nd, ny = lay.N, lay.nx, lay.nd, lay.ny
        nb = nx + nd
        blocks = N + 1
        meas = sp.kron(sp.eye(blocks), sp.csr_matrix(np.hstack([C, F])))
        prev = sp.csr_matrix(np.hstack([-A, -E]))
        nxt = sp.csr_matrix(np.hstack([np.eye(nx), np.zeros((nx, nd))]))
        dyn = sp.kron(sp.eye(N, blocks), prev) + sp.kron(sp.eye(N, blocks, k=1), nxt)
        self.M = sp.vstack([meas, dyn]).tocsr()
        self.M.eliminate_zeros()
        self.n_col, self.n_row, self.n_meas = blocks * nb, self.M.shape[0], blocks * ny
        # as the exact method's models: no scaling, bounded iterations (the duals only go to
        # the cache; any of them certifies)
        self.prog = LinearProgram(iteration_limit=ITERATION_LIMIT, scale=False)
        inf, rinf = np.full(self.n_col, np.inf), np.full(self.n_row, np.inf)
        self.prog.add_cols(-inf, inf)
        self.prog.add_rows((self.M.indptr, self.M.indices, self.M.data), -rinf, rinf)

    def _bounds(
        self, y: np.ndarray, u: np.ndarray, replaced: np.ndarray, s: int,
        prior: tuple[np.ndarray, np.ndarray], centres: np.ndarray,
    ) -> tuple[np.ndarray, ...]:  # fmt: skip
        """Column and row bounds of the shifted program."""
        _A, B, _C, D, _E, _F = self.mats
        lay = self.lay
        N, nx, nd = lay.N, lay.nx, lay.nd
        d_c = 0.5 * (self.d_lo + self.d_hi)
        shift = np.hstack([centres, np.broadcast_to(d_c, (N + 1, nd))]).ravel()
        lo = np.full((N + 1, nx + nd), -np.inf)
        hi = np.full((N + 1, nx + nd), np.inf)
        lo[:, nx:], hi[:, nx:] = self.d_lo, self.d_hi
        lo[s, :nx], hi[s, :nx] = prior
        lo, hi = lo.ravel() - shift, hi.ravel() - shift
        rhs = np.concatenate([(y - u @ D.T).ravel(), (u[:-1] @ B.T).ravel()]) - self.M @ shift
        free = np.zeros(self.n_row, dtype=bool)
        free[: s * lay.ny] = True  # measurement rows before the start
        free[: self.n_meas] |= replaced.ravel()  # and those of missing or dropped samples
        free[self.n_meas : self.n_meas + s * nx] = True  # dynamics rows into the start
        rlo = np.where(free, -np.inf, rhs)
        rhi = np.where(free, np.inf, rhs)
        return lo, hi, rlo, rhi

    def solve(
        self,
        y: np.ndarray,
        u: np.ndarray,
        replaced: np.ndarray,
        s: int,
        prior: tuple[np.ndarray, np.ndarray],
        centres: np.ndarray,
        start: Any,
        count: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray, Any]:
        """Measurement multipliers for the ``2 nx`` objectives ``+x_N[i]`` then ``−x_N[i]``
        (rows of ``(2 nx, N+1, ny)``; only the first ``count`` solved, if given), whether each
        program was solved to optimality, and the basis to start the next refresh from
        (``start``: this one's; None: a cold start).
        ``y`` (N+1, ny) and ``u`` (N+1, nu): the window's data from position ``s`` on
        (``replaced``: the measurement components that are missing or dropped, free rows);
        ``prior``: the box of ``x_s``."""
        lay, prog = self.lay, self.prog
        lo, hi, rlo, rhi = self._bounds(y, u, replaced, s, prior, centres)
        prog.set_bounds(lo, hi)
        prog.set_row_bounds(rlo, rhi)
        prog.cold()
        prog.set_basis(start)
        first = lay.N * (lay.nx + lay.nd)
        mu = np.zeros((2 * lay.nx, lay.N + 1, lay.ny))
        ok = np.zeros(2 * lay.nx, dtype=bool)
        last = None
        for r in range(2 * lay.nx if count is None else count):
            i, sense = r % lay.nx, (-1.0 if r < lay.nx else 1.0)  # min −x_i: upper bound of x_i
            col = first + i
            if last is not None:
                prog.set_cost(np.array([last]), np.zeros(1))
            prog.set_cost(np.array([col]), np.array([sense]))
            last = col
            # the first program from the last refresh's basis: by Devex (LinearProgram.solve),
            # and, should that fail, again from scratch
            status = prog.solve(primal=r > 0, devex=r == 0 and start is not None)
            if r == 0 and start is not None and status != "optimal":
                prog.cold()
                status = prog.solve()
            lam = prog.row_duals() if status == "optimal" else None
            if lam is None:
                continue
            # HiGHS: sense e_i − M^T λ = reduced costs; c = −sense e_i gives μ = −λ
            mu[r] = (-lam[: self.n_meas]).reshape(lay.N + 1, lay.ny)
            mu[r, :s] = 0.0
            ok[r] = True
        if last is not None:
            prog.set_cost(np.array([last]), np.zeros(1))
        return mu, ok, prog.basis()

    def basis_of(self, codes: np.ndarray) -> Any:
        """The basis saved as status codes (:func:`ivobs.sets.lp.basis_codes`); None if they
        do not fit this program."""
        if codes.size != self.n_col + self.n_row:
            return None
        return basis_of(codes, self.n_col)
