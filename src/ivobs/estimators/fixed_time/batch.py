"""Every window of a record (or of a batch of records) of the fixed-time estimator [Wang2020]
at once: :meth:`FixedTimeEstimator._run <.estimator.FixedTimeEstimator._run>`.

The windows do not depend on each other (there is no recursion): the box of ``x_k`` is a
window gain applied to the samples ``k, k-1, …``. So, for a time-invariant system,

1. the complete windows of the whole record are one product per lag over the record itself,
   ``[x̂_k; ρ_k] = Σ_i z_{k-i} G_iᵀ`` (``G_i`` the columns of lag ``i`` of the gain; the record
   is never copied into windows), with ``‖w_k‖_∞`` a running maximum over the lags;
2. the windows with missing samples are gathered and multiplied pattern by pattern, with the
   gain of the same shortest usable window as the step (:meth:`.estimator.FixedTimeEstimator.
   _window`);
3. only the windows that use the previous box (missing samples, inconsistent data, too few
   data) are then settled in time order: at each pass, all those whose previous box is known.

Rounding. Each entry of ``Σ_i z_{k-i} G_iᵀ`` is a sum of the same ``(s+1) n_z`` products as
``G w_k``, in another order; the bound of :func:`.gains.finish` holds for every order of
summation ([Higham2002, eq. (3.5)]), so it turns these sums into proven bounds as it does for
one window. Steps 2 and 3 are :func:`.gains.evaluate` and the functions of :mod:`.window`, as
in the step. The boxes are those of the loop over the step up to the order of the sums (tested:
containment, and widths equal within rounding).
"""

from __future__ import annotations

import numpy as np

from ...sets import Box
from ...sets.rounding import enclose, upper
from .gains import WindowGain, WindowGains, evaluate, finish
from .window import centre_radius, combine, no_box_error, predict

__all__ = ["RecordWindows"]

Result = tuple[np.ndarray, np.ndarray, np.ndarray]

_CHUNK = 1 << 14
"""Windows per product of step 1 (bounded temporaries, cache-sized)."""


class RecordWindows:
    """:meth:`run`: every window of a record or batch, for the window gains ``gains`` of a
    time-invariant system (``complete``: the gain of the complete window), the prior ``x0``
    (used, as in the step, only to predict before the first box) and windows of at most
    ``memory`` samples."""

    def __init__(self, gains: WindowGains, complete: WindowGain, x0: Box | None, memory: int):
        des = gains.designer
        self.gains, self.complete, self.x0, self.memory = gains, complete, x0, memory
        self.sys, self.s, self.nc = gains.sys, gains.s, des.nc
        self.const = (des.centre, des.radius) if des.const_bounds else None
        A, B, _, _, E, _ = self.sys.matrices_at(0)
        self.M = np.hstack((A, B, E))  # [A B E] of the prediction

    def run(self, u: np.ndarray, y: np.ndarray) -> Result | None:
        """``(lo, hi, inconsistent)`` of every step of a record ``(T, ·)`` or batch
        ``(B, T, ·)``; None (the loop) for bounds that depend on ``y`` and records no longer
        than the window."""
        sys, s = self.sys, self.s
        lead, T = y.shape[:-2], y.shape[-2]
        if sys.bounds_depend_on_y or T <= s:
            return None
        nx, nu, ny, nd, nc = sys.nx, sys.nu, sys.ny, sys.nd, self.nc
        Y = y.reshape(-1, T, ny)
        U = np.broadcast_to(u, (*lead, T, nu)).reshape(Y.shape[0], T, nu)
        B = Y.shape[0]
        miss = np.isnan(Y)
        if self.const is not None:
            c, r = (np.broadcast_to(a, (T, nd)) for a in self.const)
        else:
            c, r = centre_radius(*sys.d_over(T))  # d_k ∈ c_k ± r_k
        Z = np.concatenate((U, np.where(miss, 0.0, Y), np.broadcast_to(c[:, :nc], (B, T, nc))), -1)
        lo, hi = np.empty((B, T, nx)), np.empty((B, T, nx))
        bad = np.zeros((B, T), dtype=bool)
        lo[:, :s] = hi[:, :s] = np.nan  # (no window yet)
        rk = None if self.const is not None else r
        step = max(64, _CHUNK // B)
        for k0 in range(s, T, step):  # 1. every window, with the complete window's gain
            k1 = min(T, k0 + step)
            dest = (lo[:, k0:k1], hi[:, k0:k1], bad[:, k0:k1])
            _complete(self.complete, Z[:, k0 - s : k1], rk, k0, s, dest)
        pending = bad
        if miss.any():  # 2. windows with missing samples: their own gains
            incomplete = np.zeros((B, T), dtype=bool)
            for i, j in np.ndindex(s + 1, ny):
                incomplete[:, s:] |= miss[:, s - i : T - i, j]
            lo[incomplete] = hi[incomplete] = np.nan
            bad[incomplete] = False
            self._patterns(Z, miss, None if self.const is not None else r, incomplete, lo, hi, bad)
            pending = incomplete | bad
        if pending.any():  # 3. windows that use the previous box, in time order
            dlo, dhi = enclose(c, r)
            self._start(U, dlo, dhi, lo, hi)
            self._settle(pending, miss, U, dlo, dhi, lo, hi, bad)
        return lo.reshape(*lead, T, nx), hi.reshape(*lead, T, nx), bad.reshape(*lead, T)

    def _patterns(
        self,
        Z: np.ndarray,
        miss: np.ndarray,
        r: np.ndarray | None,
        incomplete: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        bad: np.ndarray,
    ) -> None:
        """Step 2: the box of every window with missing samples, from the shortest window
        whose available samples determine the state (``s + 1`` samples, then more; the rule of
        :meth:`.estimator.FixedTimeEstimator._window`), grouped by missing pattern (the
        windows without any keep NaN: step 3 predicts them). ``r``: radii of time-varying
        bounds (None: constant)."""
        s, ny, nz = self.s, self.sys.ny, Z.shape[-1]
        b, k = np.nonzero(incomplete)
        left = np.ones(b.size, dtype=bool)
        for lags in range(s + 1, self.memory + 1):
            idx = np.nonzero(left & (k >= lags - 1))[0]
            if not idx.size:
                break
            ks = k[idx, None] - np.arange(lags)  # the samples of each window, most recent first
            bs = b[idx, None]
            pats, inv = np.unique(miss[bs, ks].reshape(idx.size, -1), axis=0, return_inverse=True)
            inv = inv.ravel()
            for j, pat in enumerate(pats):
                gain = self.gains.get(0, pat.reshape(lags, ny))
                if not gain.ok:
                    continue
                m = inv == j
                W = Z[bs[m], ks[m]].reshape(-1, lags * nz)
                R = None if r is None else r[ks[m]].reshape(m.sum(), -1)
                kk, bb = ks[m, 0], bs[m, 0]
                lo[bb, kk], hi[bb, kk], bad[bb, kk] = evaluate(gain, W, R)
                left[idx[m]] = False

    def _start(
        self, U: np.ndarray, dlo: np.ndarray, dhi: np.ndarray, lo: np.ndarray, hi: np.ndarray
    ) -> None:
        """The boxes before the first window (``k < s``), from ``x0`` if given (as the step)."""
        if self.x0 is None or self.s == 0:
            return
        lo[:, 0], hi[:, 0] = self.x0.lo, self.x0.hi
        for j in range(1, self.s):
            prev = lo[:, j - 1], hi[:, j - 1], U[:, j - 1], dlo[j - 1], dhi[j - 1]
            lo[:, j], hi[:, j] = predict(self.M, *prev)

    def _settle(
        self,
        pending: np.ndarray,
        miss: np.ndarray,
        U: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        bad: np.ndarray,
    ) -> None:
        """Step 3: each ``pending`` window (missing samples, or inconsistent) combined with the
        prediction from the box before it (:func:`.window.combine`), in time order; all
        windows whose previous box is settled at once."""
        s, nx = self.s, self.sys.nx
        pending = pending.copy()
        while pending.any():
            ready = pending.copy()
            ready[:, 1:] &= ~pending[:, :-1]
            b, k = np.nonzero(ready)
            plo = np.full((b.size, nx), np.nan)
            phi = np.full((b.size, nx), np.nan)
            first = k == 0
            if self.x0 is not None:
                plo[first], phi[first] = self.x0.lo, self.x0.hi
            p = np.nonzero(~first & ~np.isnan(lo[b, k - 1]).any(axis=-1))[0]
            bp, kp = b[p], k[p] - 1
            plo[p], phi[p] = predict(self.M, lo[bp, kp], hi[bp, kp], U[bp, kp], dlo[kp], dhi[kp])
            lo[b, k], hi[b, k], bad[b, k] = combine(lo[b, k], hi[b, k], bad[b, k], plo, phi)
            none = np.isnan(lo[b, k]).any(axis=-1)
            if none.any():
                j = int(np.argmax(none))
                rank = self.gains.get(0, miss[b[j], k[j] - np.arange(s + 1)]).rank
                raise no_box_error(nx, s, int(k[j]), rank)
            pending &= ~ready


def _complete(
    gain: WindowGain,
    Zc: np.ndarray,
    r: np.ndarray | None,
    k0: int,
    s: int,
    dest: tuple[np.ndarray, np.ndarray, np.ndarray],
) -> None:
    """Step 1 for the windows ending at ``k0 … k0 + n - 1``, ``Zc`` the samples from
    ``k0 - s`` on: ``Σ_i z_{k-i} G_iᵀ``, ``‖w_k‖_∞`` and, for bounds that vary with time,
    ``Σ_i r_{k-i} HP_iᵀ`` (one product per lag), then :func:`.gains.finish` into ``dest``."""
    assert gain.GQ is not None and gain.HP is not None
    n = Zc.shape[1] - s
    G = gain.GQ.reshape(gain.GQ.shape[0], s + 1, -1)
    out = Zc[:, s:] @ G[:, 0].T
    zmax = np.abs(Zc[..., 0])
    for j in range(1, Zc.shape[-1]):  # (column by column: a reduction over n_z is slow)
        np.maximum(zmax, np.abs(Zc[..., j]), out=zmax)
    wmax = zmax[:, s:].copy()
    for i in range(1, s + 1):
        out += Zc[:, s - i : s - i + n] @ G[:, i].T
        np.maximum(wmax, zmax[:, s - i : s - i + n], out=wmax)
    if r is None:
        rhp = gain.radius(None)
    else:
        H = gain.HP.reshape(gain.HP.shape[0], s + 1, -1)
        rc = r[k0 - s : k0 + n]
        rhp = rc[s:] @ H[:, 0].T
        for i in range(1, s + 1):
            rhp += rc[s - i : s - i + n] @ H[:, i].T
        rhp = upper(rhp + gain.eta, gain.HP.shape[1] + 3)  # (as WindowGain.radius)
    finish(gain, out, wmax[..., None], rhp, dest)
