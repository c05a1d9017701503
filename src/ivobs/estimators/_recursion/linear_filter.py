"""The linear filter ``x[k+1] = M x[k] + Σ W v[k] + g`` over whole records and batches (the
package docstring: block evaluation for small states, a loop of one (sparse) product per step for
large ones)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ...model._matrix import is_scipy_sparse
from .kernels import _matrix, matrix_product, scratch

__all__ = ["BLOCK_MAX_STATES", "LinearFilter"]

BLOCK_MAX_STATES = 24
"""Largest state dimension for which the block (Toeplitz) evaluation is used."""

_SCAN_LOOP = 256
"""Block-start recursions up to this length (or with many streams) run as a Python loop."""


class LinearFilter:
    """``x[k+1] = M x[k] + Σ_s W_s v_s[k] + g``.

    Parameters
    ----------
    M : (n, n) state matrix (dense; ``scipy.sparse`` for large systems)
    W : the input matrices ``W_s`` (n, m_s), one per signal
    g : (n,) constant input of the state, or None

    :meth:`run` evaluates the states over a record ``(T, m_s)`` or a batch ``(B, T, m_s)``.
    """

    def __init__(self, M: Any, W: Sequence[np.ndarray], g: np.ndarray | None = None):
        self.sparse = is_scipy_sparse(M)
        self.M = M.tocsr() if self.sparse else np.asarray(M, dtype=float)
        n: int = self.M.shape[0]
        self.n = n
        self.W = [_matrix(w, n, None) for w in W]
        self.m: list[int] = [w.shape[1] for w in self.W]
        self.g = None if g is None or not np.any(g) else np.asarray(g, dtype=float).reshape(n)
        self.const = self.g is not None
        self.blocks = not self.sparse and n <= BLOCK_MAX_STATES
        self._ops: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._inner: dict[int, LinearFilter] = {}

    # -- block operators ------------------------------------------------------------------
    def _operators(self, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(Op, End, M^K)`` for blocks of ``K`` steps (cached). Rows of ``Op`` and ``End``
        follow the columns of the block input ``[v_0 (K m_0), v_1, ..., 1, s_q (n)]``
        (time-major inside each signal); columns of ``Op`` are ``K n`` (time-major)."""
        hit = self._ops.get(K)
        if hit is not None:
            return hit
        out = _block_operators(self, K)
        self._ops[K] = out
        return out

    def _block_size(self, b: int, T: int) -> int:
        """Steps per block: small for batches (the block-start loop is cheap there), larger for
        one long record (fewer block starts); a divisor of ``T`` when one is close."""
        width = max(sum(self.m), self.n, 1)
        K = 8 if b >= 32 else 32
        K = max(2, min(K, 256 // width, T))
        for k in range(K, max(1, K // 2) - 1, -1):
            if T % k == 0:
                return k
        return K

    # -- evaluation -----------------------------------------------------------------------
    def run(
        self,
        v: Sequence[np.ndarray],
        T: int | None = None,
        x0: np.ndarray | None = None,
        final: bool = False,
    ) -> list[np.ndarray]:
        """``[x]``: the states ``x[0 .. T-1]`` ``(..., T, n)`` for signals ``v_s`` ``(..., T,
        m_s)`` (all with the same leading shape; a batch is one leading axis) from ``x[0] = x0``
        (``(n,)`` or ``(..., n)``; default 0). With ``final=True`` the state ``x[T]`` is
        appended to the returned list."""
        if len(v) != len(self.W):
            raise ValueError(f"expected {len(self.W)} signals, got {len(v)}")
        lead = v[0].shape[:-2] if v else ()
        if T is None:
            if not v:
                raise ValueError("T is needed when there is no signal")
            T = v[0].shape[-2]
        b = int(np.prod(lead)) if lead else 1
        vs = [np.reshape(a, (b, T, a.shape[-1])) for a in v]
        x0b = np.zeros((b, self.n)) if x0 is None else np.broadcast_to(x0, (*lead, self.n))
        x0b = np.reshape(x0b, (b, self.n))
        X = np.empty((b, T, self.n))
        if T == 0:
            xT = x0b.copy()
        elif self.blocks:
            xT = self._run_blocks(vs, T, b, x0b, X)
        else:
            xT = self._run_loop(vs, T, x0b, X)
        res = [X.reshape(*lead, T, self.n)]
        if final:
            res.append(xT.reshape(*lead, self.n))
        return res

    def _fill(self, aug: np.ndarray, vs: list[np.ndarray], K: int) -> int:
        """Copy the first ``nb K`` steps of the signals into the block input ``aug``
        ``(b, nb, cols)`` (the last, shorter block: ``nb = 1`` on the signals from its first
        step); returns the column of the block start."""
        b, nb = aug.shape[:2]
        off = 0
        for a, m in zip(vs, self.m):
            if m:
                aug[:, :, off : off + K * m] = a[:, : nb * K].reshape(b, nb, K * m)
            off += K * m
        if self.const:
            aug[:, :, off] = 1.0
            off += 1
        return off

    def _run_blocks(
        self, vs: list[np.ndarray], T: int, b: int, x0: np.ndarray, X: np.ndarray
    ) -> np.ndarray:
        """Blocks of ``K`` steps (module docstring), in the stream-major layout of the data:
        the states are one product per stream (one product for contiguous batches)."""
        n = self.n
        K = self._block_size(b, T)
        Op, End, MK = self._operators(K)
        nb, tail = divmod(T, K)
        s_end = x0
        if nb:
            aug = scratch(self, "aug", (b, nb, End.shape[0] + n))
            c = self._fill(aug, vs, K)
            E = scratch(self, "ends", (b, nb, n))
            np.matmul(aug[:, :, :c], End, out=E)
            s_end = self._scan(MK, E, x0, aug[:, :, c:], K)
            main = X[:, : nb * K].reshape(b, nb, K * n)  # a view: X is row-contiguous
            if main.flags.c_contiguous:
                np.matmul(aug.reshape(b * nb, -1), Op, out=main.reshape(b * nb, K * n))
            else:
                np.matmul(aug, Op, out=main)
        if tail:
            self._tail(vs, T, b, K, tail, s_end, X, Op)
            if self.n:
                # the state after the tail, for callers that continue the recursion
                ext = self._operators(tail)
                row = np.empty((b, 1, ext[1].shape[0]))
                self._fill(row, [a[:, T - tail :] for a in vs], tail)
                s_end = row[:, 0] @ ext[1] + s_end @ ext[2].T
        return s_end

    def _tail(
        self,
        vs: list[np.ndarray],
        T: int,
        b: int,
        K: int,
        L: int,
        s: np.ndarray,
        X: np.ndarray,
        Op: np.ndarray,
    ) -> None:
        """The last ``L < K`` steps: the leading rows/columns of the ``K``-block operators."""
        n = self.n
        rows: list[int] = []
        off = 0
        for m in self.m:
            rows.extend(range(off, off + L * m))
            off += K * m
        if self.const:
            rows.append(off)
            off += 1
        rows.extend(range(off, off + n))
        row = np.empty((b, 1, len(rows)))
        c = self._fill(row, [a[:, T - L :] for a in vs], L)
        row[:, 0, c:] = s
        X[:, T - L :] = (row[:, 0] @ Op[np.asarray(rows), : L * n]).reshape(b, L, n)

    def _scan(
        self, MK: np.ndarray, E: np.ndarray, x0: np.ndarray, S: np.ndarray, K: int
    ) -> np.ndarray:
        """Block starts ``S[:, q] = s_q`` (``(b, nb, n)``) with ``s_0 = x0``,
        ``s_(q+1) = M^K s_q + E[:, q]``; returns ``s_nb``. Many streams: a loop over blocks on
        time-major copies (contiguous ``(b, n)`` slabs); few streams and many blocks: the same
        block method on the block starts."""
        b, nb, n = E.shape
        S[:, 0] = x0
        if not MK.any():  # nilpotent within a block (e.g. a window of past samples)
            S[:, 1:] = E[:, :-1]
            return E[:, -1].copy()
        MKt = MK.T
        if b >= 32:
            Et = scratch(self, "ends_t", (nb, b, n))
            Et[...] = E.transpose(1, 0, 2)
            St = scratch(self, "starts_t", (nb + 1, b, n))
            St[0] = x0
            for q in range(nb):
                np.matmul(St[q], MKt, out=St[q + 1])
                St[q + 1] += Et[q]
            S[:, 1:] = St[1:nb].transpose(1, 0, 2)
            return St[nb].copy()
        if nb <= _SCAN_LOOP:
            for q in range(nb - 1):
                S[:, q + 1] = S[:, q] @ MKt
                S[:, q + 1] += E[:, q]
            last: np.ndarray = S[:, nb - 1] @ MKt + E[:, nb - 1]
            return last
        inner = self._inner.get(K)
        if inner is None:
            inner = LinearFilter(MK, [np.eye(n)])
            self._inner[K] = inner
        states, last = inner.run([E], x0=x0, final=True)
        S[...] = states
        return last

    def _run_loop(self, vs: list[np.ndarray], T: int, x0: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Large or sparse state: the states ``X`` and ``x[T]``, one (sparse) product per step;
        the input terms are precomputed in the state buffer (``X[:, k+1] = Σ W v[k] + g``
        first, then ``X[:, k+1] += M X[:, k]``)."""
        n = self.n
        X[:, 0] = x0
        if T > 1:
            Xn = X[:, 1:]
            Xn[...] = 0.0 if self.g is None else self.g
            for a, W in zip(vs, self.W):
                rows = np.flatnonzero(np.any(W != 0.0, axis=1))
                if not rows.size:
                    continue
                if 2 * rows.size > n:
                    Xn += matrix_product(a[:, : T - 1], W.T)
                else:  # e.g. a gain that feeds a few sensors back into their own nodes
                    Xn[..., rows] += matrix_product(a[:, : T - 1], W[rows].T)
        M = self.M
        if self.sparse:
            for k in range(1, T):
                X[:, k] += (M @ X[:, k - 1].T).T
        else:
            Mt = M.T
            for k in range(1, T):
                X[:, k] += X[:, k - 1] @ Mt
        last = X[:, T - 1]
        xT: np.ndarray = (M @ last.T).T if self.sparse else last @ M.T
        for a, W in zip(vs, self.W):
            xT = xT + a[:, T - 1] @ W.T
        if self.g is not None:
            xT = xT + self.g
        return xT


def _block_operators(f: LinearFilter, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`LinearFilter._operators` (uncached): the block-Toeplitz operators of ``f``."""
    n, M = f.n, f.M
    P = [np.eye(n)]
    for _ in range(K):
        P.append(M @ P[-1])
    cols_in = K * sum(f.m) + int(f.const)
    Op = np.zeros((cols_in + n, K * n))
    End = np.zeros((cols_in, n))
    off = 0
    for W, m in zip(f.W, f.m):
        PW = [Pt @ W for Pt in P[:K]]
        for jj in range(K):
            for i in range(jj):
                Op[off + i * m : off + (i + 1) * m, jj * n : (jj + 1) * n] = PW[jj - 1 - i].T
            End[off + jj * m : off + (jj + 1) * m] = PW[K - 1 - jj].T
        off += K * m
    if f.g is not None:
        acc = np.zeros(n)
        for jj in range(K):
            Op[off, jj * n : (jj + 1) * n] = acc
            acc = acc + P[jj] @ f.g
        End[off] = sum(Pt @ f.g for Pt in P[:K])
        off += 1
    for jj in range(K):
        Op[off : off + n, jj * n : (jj + 1) * n] = P[jj].T
    return Op, End, P[K]
