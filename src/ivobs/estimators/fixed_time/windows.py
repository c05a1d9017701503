"""Many windows of the fixed-time estimator [Wang2020] at once: every window of a record (or
batch of records) is one row of a matrix product with its window gain (eqs. (7), (11)).

The same arithmetic as the online step (:func:`.gains.evaluate_window`) on rows of windows:
:func:`finish` turns ``[x̂; ρ]`` and the certified radii into bounds and parity flags. The
window functions fill views of the result arrays for one chunk of the record: complete windows
of a time-invariant system (:func:`windows_full`), windows with missing samples grouped by
pattern (:func:`windows_patterns`), and the per-step gains of a time-varying system
(:func:`windows_tv`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...model import LinearSystem
from ...sets import Box
from .gains import WindowGain, WindowGains

__all__ = [
    "bounds_rows",
    "chunks",
    "evaluate",
    "finish",
    "windows_full",
    "windows_patterns",
    "windows_tv",
]

_CHUNK = 1 << 16
"""Windows per chunk of the record (bounded memory for large batches, cache-friendly)."""
_BLOCK = 1024
"""Rows per product of :func:`rows_matmul`."""

Out = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""Views ``(lo, hi, need, incons)`` of one chunk of the results; rows ``s:`` are filled."""


def rows_matmul(X: np.ndarray, Mt: np.ndarray) -> np.ndarray:
    """``X @ Mt`` for a tall, thin ``X`` ``(..., n, w)``, as a stack of ``_BLOCK``-row products.

    One tall product with a handful of columns makes OpenBLAS start its threads for almost no
    work per thread, which is slow (and very slow on a busy machine); a stack of small
    products runs each one on one thread, at memory speed.
    """
    n = X.shape[-2]
    nb = n // _BLOCK
    if X.ndim != 2 or nb < 2:
        out: np.ndarray = X @ Mt
        return out
    out = np.empty((n, Mt.shape[1]))
    kb = nb * _BLOCK
    out[:kb].reshape(nb, _BLOCK, -1)[...] = X[:kb].reshape(nb, _BLOCK, -1) @ Mt
    out[kb:] = X[kb:] @ Mt
    return out


def finish(
    gain: WindowGain,
    out: np.ndarray,
    rhp: np.ndarray,
    wmax: np.ndarray,
    dest: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From ``[x̂; ρ]`` (``out``), ``[|T Md| 𝐫; |N Md| 𝐫]`` (``rhp``, the certified
    disturbance gains ``HP 𝐫``) and ``‖w‖_∞``: the bounds ``x̂ ∓ rad`` of eq. (11) and the
    inconsistency flags ``|ρ| > |N Md| 𝐫`` (tolerance ``1e-9`` relative).
    ``rad = rhp + rad_coef ‖w‖_∞``, ``rad_coef`` the evaluation rounding
    ``64 (s+1) n_z ε ‖G_i‖₁`` plus the certified remainder (:class:`.gains.WindowGains`).
    Written into ``dest = (lo, hi, bad)`` when given (``out`` is then overwritten).
    """
    assert gain.rad_coef is not None and gain.tol_coef is not None
    nx = gain.nx
    if dest is None:
        shape = out.shape[:-1]
        dest = (np.empty((*shape, nx)), np.empty((*shape, nx)), np.empty(shape, dtype=bool))
    lo, hi, bad = dest
    xhat = out[..., :nx]
    rad = wmax[..., None] * gain.rad_coef
    rad += rhp[..., :nx]
    np.subtract(xhat, rad, out=lo)
    np.add(xhat, rad, out=hi)
    bad[...] = False
    if out.shape[-1] > nx:
        res = np.abs(out[..., nx:], out=out[..., nx:])
        res -= wmax[..., None] * gain.tol_coef
        over = res > rhp[..., nx:] * (1.0 + 1e-9) + 1e-9
        for j in range(over.shape[-1]):  # an OR per column: faster than any() over a short axis
            bad |= over[..., j]
    return lo, hi, bad


def evaluate(
    gain: WindowGain, W: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Bounds (eq. 11) and the parity test for windows ``W`` ``(n, (s+1)nz)`` with radii
    ``R`` ``(n, (s+1)nd)``."""
    assert gain.GQ is not None and gain.HP is not None
    out = rows_matmul(W, gain.GQ.T)
    wmax = np.max(np.abs(W), axis=1, initial=0.0)
    return finish(gain, out, rows_matmul(R, gain.HP.T), wmax)


def chunks(s: int, Bn: int, T: int) -> list[tuple[int, int, int, int]]:
    """``(b0, b1, k0, k1)``: streams ``b0:b1``, windows ending at ``k0:k1``, about
    :data:`_CHUNK` windows each (bounded memory for large batches, cache-friendly)."""
    bstep = max(1, _CHUNK // T)
    tstep = T if bstep > 1 else _CHUNK
    return [
        (b0, min(Bn, b0 + bstep), k0, min(T, k0 + tstep))
        for b0 in range(0, Bn, bstep)
        for k0 in range(s, T, tstep)
    ]


def bounds_rows(sys: LinearSystem, T: int) -> tuple[np.ndarray, np.ndarray]:
    """The bounds of ``d`` at steps ``0 .. T-1`` (a Box of the system)."""
    nd = sys.nd
    if nd == 0:
        return np.zeros((T, 0)), np.zeros((T, 0))
    box = sys.d
    assert isinstance(box, Box)
    if not box.is_time_varying:
        return np.broadcast_to(box.lo, (T, nd)), np.broadcast_to(box.hi, (T, nd))
    sys.d_at(T - 1)  # raises a clear error when the bounds do not cover the record
    return box.lo[:T], box.hi[:T]


def lag_product(s: int, Z: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``Σ_i Z[:, k-i] M_iᵀ`` for every window end ``k >= s`` of ``Z`` ``(B, T, n)``, with
    ``M`` ``(r, (s+1) n)`` lag-major: shape ``(B, T - s, r)``."""
    T = Z.shape[-2]
    M3 = M.reshape(M.shape[0], s + 1, -1)
    if Z.shape[0] == 1:
        out = rows_matmul(Z[0, s:], M3[:, 0].T)
        for i in range(1, s + 1):
            out += rows_matmul(Z[0, s - i : T - i], M3[:, i].T)
        return out[None]
    acc: np.ndarray = Z[:, s:] @ M3[:, 0].T
    for i in range(1, s + 1):
        acc += Z[:, s - i : T - i] @ M3[:, i].T
    return acc


def window_max(s: int, Z: np.ndarray) -> np.ndarray:
    """``‖w_k‖_∞`` of every window of the chunk, shape ``(B, T - s)``."""
    T = Z.shape[-2]
    zmax = np.zeros(Z.shape[:-1])
    for j in range(Z.shape[-1]):  # column by column: much faster than a reduce over n_z
        np.maximum(zmax, np.abs(Z[..., j]), out=zmax)
    wmax = zmax[:, s:].copy()
    for i in range(1, s + 1):
        np.maximum(wmax, zmax[:, s - i : T - i], out=wmax)
    return wmax


def _gather(s: int, X: np.ndarray, b: np.ndarray, k: np.ndarray) -> np.ndarray:
    """Lag-major window vectors ``[X[b, k]; X[b, k-1]; …; X[b, k-s]]`` (rows)."""
    lags = k[:, None] - np.arange(s + 1)[None, :]
    out: np.ndarray = X[b[:, None], lags].reshape(len(k), -1)
    return out


def windows_full(gains: WindowGains, Z: np.ndarray, R: np.ndarray, out: Out) -> None:
    """No missing sample, time-invariant: every window of the chunk at once (rows ``s:``).

    ``Σ_i z_{k-i} G_iᵀ`` over the lags, each term one product over the whole chunk (a
    sliding window of the record, without copying it).
    """
    s = gains.s
    lo, hi, need, incons = out
    gain = gains.complete(s)
    if not gain.ok:  # cannot happen for a complete window (checked at design)
        need[:, s:] = True
        return
    assert gain.GQ is not None and gain.HP is not None
    xq = lag_product(s, Z, gain.GQ)
    if gains.designer.const_bounds:
        rhp = gain.HP @ np.tile(R[0], s + 1)
    else:
        rhp = lag_product(s, R[None], gain.HP)[0]
    wmax = window_max(s, Z)
    finish(gain, xq, rhp, wmax, (lo[:, s:], hi[:, s:], incons[:, s:]))


def windows_patterns(
    gains: WindowGains, Z: np.ndarray, R: np.ndarray, miss: np.ndarray, out: Out
) -> None:
    """Missing samples, time-invariant: one window gain per missing pattern (cached)."""
    s, ny, T = gains.s, gains.sys.ny, Z.shape[-2]
    lo, hi, need, incons = out
    # pattern of the window ending at k: miss[k - i] for lags i = 0..s
    pats = np.stack([miss[:, s - i : T - i] for i in range(s + 1)], axis=-2)
    flat = pats.reshape(-1, (s + 1) * ny)
    if flat.shape[1] <= 62:
        code = flat.astype(np.int64) @ (np.int64(1) << np.arange(flat.shape[1], dtype=np.int64))
        ucode, inv = np.unique(code, return_inverse=True)
        patterns = [(int(c) >> np.arange(flat.shape[1])) & 1 for c in ucode]
    else:
        uniq, inv = np.unique(flat, axis=0, return_inverse=True)
        patterns = list(uniq)
    codes = inv.reshape(Z.shape[0], T - s)
    Rb = np.broadcast_to(R, (Z.shape[0], *R.shape))
    for j, pattern in enumerate(patterns):
        b, kk = np.nonzero(codes == j)
        kk = kk + s
        gain = gains.get(s, np.asarray(pattern, dtype=bool).reshape(s + 1, ny))
        if not gain.ok:
            need[b, kk] = True
            continue
        W, Rw = _gather(s, Z, b, kk), _gather(s, Rb, b, kk)
        lo[b, kk], hi[b, kk], incons[b, kk] = evaluate(gain, W, Rw)


def windows_tv(gains: WindowGains, Z: np.ndarray, R: np.ndarray, t0: int, out: Out) -> None:
    """Time-varying, no missing sample: the per-step gains ``T_k`` (closed form, cached)
    stacked over the chunk and applied to all its windows and streams in one product.
    ``t0`` is the step of the chunk's first row."""
    from numpy.lib.stride_tricks import sliding_window_view

    s, nx, T = gains.s, gains.sys.nx, Z.shape[-2]
    lo, hi, need, incons = out
    gs = [gains.complete(t0 + k) for k in range(s, T)]
    ok = np.array([g.ok for g in gs])
    need[:, s:] = ~ok
    if not ok.any():
        return
    good = [g for g in gs if g.ok]
    assert all(g.GQ is not None and g.HP is not None for g in good)

    def stacked(name: str, fill: Any) -> np.ndarray:
        arrs = [getattr(g, name) if g.ok else None for g in gs]
        like = getattr(good[0], name)
        return np.stack([a if a is not None else np.full_like(like, fill) for a in arrs])

    def lag_major(V: np.ndarray) -> np.ndarray:
        # sliding view (..., K, n, s+1), time ascending -> lag-major rows (..., K, (s+1) n)
        return np.flip(V, axis=-1).swapaxes(-1, -2).reshape(*V.shape[:-2], -1)

    W = lag_major(sliding_window_view(Z, s + 1, axis=-2))
    Rw = lag_major(sliding_window_view(R, s + 1, axis=0))
    gain = WindowGain(
        ok=True,
        rank=nx,
        nx=nx,
        GQ=None,
        HP=None,
        rad_coef=stacked("rad_coef", 0.0),
        tol_coef=stacked("tol_coef", 0.0),
    )
    xq = np.einsum("bkw,krw->bkr", W, stacked("GQ", 0.0))
    rhp = np.einsum("kw,krw->kr", Rw, stacked("HP", 0.0))
    wmax = np.max(np.abs(W), axis=-1, initial=0.0)
    lo[:, s:], hi[:, s:], incons[:, s:] = finish(gain, xq, rhp, wmax)
    incons[:, s:] &= ok
