"""The linear filter ``x[k+1] = M x[k] + Σ W v[k] + g``, ``o = H x + J v + h`` over whole records
and batches (the package docstring: block evaluation for small states, a loop of one (sparse)
product per step for large ones)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .kernels import _issparse, _matrix, matrix_product, scratch

__all__ = ["BLOCK_MAX_STATES", "LinearFilter", "affine_recursion"]

BLOCK_MAX_STATES = 24
"""Largest state dimension for which the block (Toeplitz) evaluation is used."""

_SCAN_LOOP = 256
"""Block-start recursions up to this length (or with many streams) run as a Python loop."""


class LinearFilter:
    """``x[k+1] = M x[k] + Σ_s W_s v_s[k] + g``, ``o_j[k] = H_j x[k] + Σ_s J_js v_s[k] + h_j``.

    Parameters
    ----------
    M : (n, n) state matrix (dense; ``scipy.sparse`` for large systems)
    W : the input matrices ``W_s`` (n, m_s), one per signal
    H : the output matrices ``H_j`` (p_j, n)
    J : ``J[j][s]`` (p_j, m_s) feedthrough or None (zero); default all zero
    g : (n,) constant input of the state, or None
    h : ``h[j]`` (p_j,) constant of output ``j`` (or None)
    block : force the block evaluation with blocks of this many steps (e.g. a moving window
        written as a shift register, whose state is larger than :data:`BLOCK_MAX_STATES`)

    :meth:`run` evaluates the outputs over a record ``(T, m_s)`` or a batch ``(B, T, m_s)``.
    """

    def __init__(
        self,
        M: Any,
        W: Sequence[np.ndarray],
        H: Sequence[np.ndarray],
        J: Sequence[Sequence[np.ndarray | None]] | None = None,
        g: np.ndarray | None = None,
        h: Sequence[np.ndarray | None] | None = None,
        block: int | None = None,
    ):
        self.sparse = _issparse(M)
        self.M = M.tocsr() if self.sparse else np.asarray(M, dtype=float)
        n: int = self.M.shape[0]
        self.n = n
        self.W = [_matrix(w, n, None) for w in W]
        self.m: list[int] = [w.shape[1] for w in self.W]
        self.H = [h_ if _issparse(h_) else _matrix(h_, None, n) for h_ in H]
        self.p = [h_.shape[0] for h_ in self.H]
        nj, ns = len(self.H), len(self.W)
        J = J if J is not None else [[None] * ns for _ in range(nj)]
        self.J = [
            [None if J[j][s] is None else _matrix(J[j][s], self.p[j], self.m[s]) for s in range(ns)]
            for j in range(nj)
        ]
        self.g = None if g is None or not np.any(g) else np.asarray(g, dtype=float).reshape(n)
        hh = h if h is not None else [None] * nj
        self.h = [None if v is None or not np.any(v) else np.asarray(v, float) for v in hh]
        self.const = self.g is not None or any(v is not None for v in self.h)
        self.blocks = not self.sparse and (n <= BLOCK_MAX_STATES or block is not None)
        self.block = block
        self._ops: dict[int, tuple[list[np.ndarray], np.ndarray, np.ndarray]] = {}
        self._inner: dict[int, LinearFilter] = {}

    # -- block operators ------------------------------------------------------------------
    def _operators(self, K: int) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
        """``(Op_j, End, M^K)`` for blocks of ``K`` steps (cached). Rows of ``Op_j`` and ``End``
        follow the columns of the block input ``[v_0 (K m_0), v_1, ..., 1, s_q (n)]``
        (time-major inside each signal); columns of ``Op_j`` are ``K p_j`` (time-major)."""
        hit = self._ops.get(K)
        if hit is not None:
            return hit
        out = _block_operators(self, K)
        self._ops[K] = out
        return out

    def _block_size(self, b: int, T: int) -> int:
        """Steps per block: small for batches (the block-start loop is cheap there), larger for
        one long record (fewer block starts); a divisor of ``T`` when one is close."""
        if self.block is not None:
            return max(1, min(self.block, T))
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
        out: Sequence[np.ndarray | None] | None = None,
        final: bool = False,
        temp: Sequence[int] = (),
    ) -> list[np.ndarray]:
        """The outputs ``o_j`` ``(..., T, p_j)`` for signals ``v_s`` ``(..., T, m_s)`` (all with
        the same leading shape; a batch is one leading axis) from ``x[0] = x0`` (``(n,)`` or
        ``(..., n)``; default 0). ``out``: arrays to write into (or None). Outputs listed in
        ``temp`` go to reusable buffers (:func:`scratch`: valid until the next call). With
        ``final=True`` the state ``x[T]`` is appended to the returned list."""
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
        outs = []
        for j, p in enumerate(self.p):
            o = None if out is None else out[j]
            if o is None:
                o = scratch(self, f"out{j}", (b, T, p)) if j in temp else np.empty((b, T, p))
            outs.append(o.reshape(b, T, p))
        if T == 0:
            xT = x0b.copy()
        elif self.blocks:
            xT = self._run_blocks(vs, T, b, x0b, outs)
        else:
            xT = self._run_loop(vs, T, b, x0b, outs)
        res = [o.reshape(*lead, T, p) for o, p in zip(outs, self.p)]
        if out is not None:
            for j, o in enumerate(out):
                if o is not None and not np.shares_memory(o, res[j]):
                    o[...] = res[j].reshape(o.shape)
                    res[j] = o
        if final:
            res.append(xT.reshape(*lead, self.n))
        return res

    def _fill(self, aug: np.ndarray, vs: list[np.ndarray], K: int) -> int:
        """Copy the first ``nb K`` steps of the signals into the block input ``aug``
        ``(b, nb, cols)``; returns the column of the block start."""
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
        self, vs: list[np.ndarray], T: int, b: int, x0: np.ndarray, outs: list[np.ndarray]
    ) -> np.ndarray:
        """Blocks of ``K`` steps (module docstring), in the stream-major layout of the data:
        every output is one product per stream (one product for contiguous batches)."""
        n = self.n
        K = self._block_size(b, T)
        ops, End, MK = self._operators(K)
        nb, tail = divmod(T, K)
        s_end = x0
        if nb:
            aug = scratch(self, "aug", (b, nb, End.shape[0] + n))
            c = self._fill(aug, vs, K)
            E = scratch(self, "ends", (b, nb, n))
            np.matmul(aug[:, :, :c], End, out=E)
            s_end = self._scan(MK, E, x0, aug[:, :, c:], K)
            for Op, o, p in zip(ops, outs, self.p):
                main = o[:, : nb * K].reshape(b, nb, K * p)  # a view: o is row-contiguous
                if main.flags.c_contiguous:
                    np.matmul(aug.reshape(b * nb, -1), Op, out=main.reshape(b * nb, K * p))
                else:
                    np.matmul(aug, Op, out=main)
        if tail:
            self._tail(vs, T, b, K, tail, s_end, outs, ops)
            if self.n:
                # the state after the tail, for callers that continue the recursion
                ext = self._operators(tail)
                row = np.empty((b, ext[1].shape[0]))
                self._fill_tail(row, vs, T - tail, tail)
                s_end = row @ ext[1] + s_end @ ext[2].T
        return s_end

    def _fill_tail(self, row: np.ndarray, vs: list[np.ndarray], k0: int, L: int) -> int:
        b = row.shape[0]
        off = 0
        for a, m in zip(vs, self.m):
            if m:
                row[:, off : off + L * m] = a[:, k0 : k0 + L].reshape(b, L * m)
            off += L * m
        if self.const:
            row[:, off] = 1.0
            off += 1
        return off

    def _tail(
        self,
        vs: list[np.ndarray],
        T: int,
        b: int,
        K: int,
        L: int,
        s: np.ndarray,
        outs: list[np.ndarray],
        ops: list[np.ndarray],
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
        row = np.empty((b, len(rows)))
        c = self._fill_tail(row, vs, T - L, L)
        row[:, c:] = s
        idx = np.asarray(rows)
        for Op, o, p in zip(ops, outs, self.p):
            o[:, T - L :] = (row @ Op[idx, : L * p]).reshape(b, L, p)

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
            inner = LinearFilter(MK, [np.eye(n)], [np.eye(n)])
            self._inner[K] = inner
        states, last = inner.run([E], x0=x0, final=True)
        S[...] = states
        return last

    def states(
        self, v: Sequence[np.ndarray], T: int | None = None, x0: np.ndarray | None = None
    ) -> np.ndarray:
        """The state trajectory ``x[0 .. T-1]`` ``(..., T, n)`` (signals as in :meth:`run`)."""
        lead = v[0].shape[:-2] if v else ()
        T = v[0].shape[-2] if T is None else T
        b = int(np.prod(lead)) if lead else 1
        vs = [np.reshape(a, (b, T, a.shape[-1])) for a in v]
        x0b = np.zeros((b, self.n)) if x0 is None else np.broadcast_to(x0, (*lead, self.n))
        X, _ = self._loop_states(vs, T, b, np.reshape(x0b, (b, self.n)))
        return X.reshape(*lead, T, self.n)

    def _loop_states(
        self, vs: list[np.ndarray], T: int, b: int, x0: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(X, x[T])``: one (sparse) product per step; the input terms are precomputed in the
        state buffer (``X[:, k+1] = Σ W v[k] + g`` first, then ``X[:, k+1] += M X[:, k]``)."""
        n = self.n
        X = np.empty((b, T, n))
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
        xT = (M @ last.T).T if self.sparse else last @ M.T
        for a, W in zip(vs, self.W):
            xT = xT + a[:, T - 1] @ W.T
        if self.g is not None:
            xT = xT + self.g
        return X, xT

    def _run_loop(
        self, vs: list[np.ndarray], T: int, b: int, x0: np.ndarray, outs: list[np.ndarray]
    ) -> np.ndarray:
        """Large or sparse state: the trajectory by :meth:`_loop_states`, then the outputs."""
        X, xT = self._loop_states(vs, T, b, x0)
        for j, (H, o) in enumerate(zip(self.H, outs)):
            matrix_product(X, H.T, out=o)
            for a, Js in zip(vs, self.J[j]):
                if Js is not None and np.any(Js):
                    o += matrix_product(a, Js.T)
            if self.h[j] is not None:
                o += self.h[j]
        return xT


def _block_operators(f: LinearFilter, K: int) -> tuple[list[np.ndarray], np.ndarray, np.ndarray]:
    """:meth:`LinearFilter._operators` (uncached): the block-Toeplitz operators of ``f``."""
    n, M = f.n, f.M
    P = [np.eye(n)]
    for _ in range(K):
        P.append(M @ P[-1])
    cols_in = K * sum(f.m) + int(f.const)
    ops = []
    for j, H in enumerate(f.H):
        p = f.p[j]
        HP = [H @ Pt for Pt in P[:K]]
        Op = np.zeros((cols_in + n, K * p))
        off = 0
        for s, W in enumerate(f.W):
            m = f.m[s]
            HPW = [Hp @ W for Hp in HP[: K - 1]]
            Js = f.J[j][s]
            for jj in range(K):
                oc = slice(jj * p, (jj + 1) * p)
                for i in range(jj):
                    Op[off + i * m : off + (i + 1) * m, oc] = HPW[jj - 1 - i].T
                if Js is not None:
                    Op[off + jj * m : off + (jj + 1) * m, oc] = Js.T
            off += K * m
        if f.const:
            hj = f.h[j]
            acc = np.zeros(p) if hj is None else hj.copy()
            for jj in range(K):
                Op[off, jj * p : (jj + 1) * p] = acc
                if f.g is not None:
                    acc = acc + HP[jj] @ f.g
            off += 1
        for jj in range(K):
            Op[off : off + n, jj * p : (jj + 1) * p] = HP[jj].T
        ops.append(Op)
    End = np.zeros((cols_in, n))
    off = 0
    for s, W in enumerate(f.W):
        m = f.m[s]
        for i in range(K):
            End[off + i * m : off + (i + 1) * m] = (P[K - 1 - i] @ W).T
        off += K * m
    if f.const and f.g is not None:
        End[off] = sum(Pt @ f.g for Pt in P[:K])
    return ops, End, P[K]


def affine_recursion(M: np.ndarray, v: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """Return ``x`` of shape ``(..., T+1, n)`` with ``x[0] = x0``, ``x[k+1] = M x[k] + v[k]``.

    ``v`` has shape ``(..., T, n)`` (leading batch axes allowed); ``x0`` shape ``(..., n)`` or
    ``(n,)``.
    """
    M = np.asarray(M, dtype=float)
    v = np.asarray(v, dtype=float)
    T, n = v.shape[-2], v.shape[-1]
    lead = v.shape[:-2]
    X = np.empty((*lead, T + 1, n))
    f = LinearFilter(M, [np.eye(n)], [np.eye(n)])
    _, xT = f.run([v], T=T, x0=np.asarray(x0, dtype=float), out=[X[..., :T, :]], final=True)
    X[..., T, :] = xT
    return X
