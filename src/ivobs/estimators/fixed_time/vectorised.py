"""The whole record (or batch of records) of the fixed-time estimator [Wang2020] at once.

Every window is one row of a matrix product (eqs. (7), (11), :mod:`.windows`); for a
time-invariant system with constant bounds and complete data, all windows are the outputs of one
linear filter of the data (a shift register holding the window), evaluated by the shared kernel
:class:`ivobs._recursion.LinearFilter`. Windows that need the model prediction from the previous
box (too few data, inconsistent, or a missing sample) are then filled in time order, as the
online step (:mod:`.recursion`) does. Tested equal to the loop over the step on random systems.
"""

from __future__ import annotations

import numpy as np

from ...sets import Box
from .._recursion import LinearFilter, is_shared, scratch, within_band
from ..rounding import outward
from .gains import WindowGain, WindowGains
from .recursion import Bounds, combine, no_box_error, predict
from .windows import bounds_rows, chunks, windows_full, windows_patterns, windows_tv

__all__ = ["WindowBatch"]

Result = tuple[np.ndarray, np.ndarray, np.ndarray]


class WindowBatch:
    """``run(u, y)``: the bounds and inconsistency flags of every step of a record or batch
    for the window gains ``gains`` and the optional prior ``x0`` (as the online step)."""

    def __init__(self, gains: WindowGains, x0: Box | None):
        self.gains = gains
        self.sys = gains.sys
        self.s = gains.s
        self.x0 = x0
        self._filter: tuple[LinearFilter, np.ndarray] | None = None
        self._band: np.ndarray | None = None

    def run(self, u: np.ndarray, y: np.ndarray) -> Result | None:
        """The whole record at once.

        Windows are grouped by missing pattern (one gain each); windows that need the model
        prediction (too few data, or inconsistent) are then filled in time order, as the loop
        does. ``None`` (use the loop) for bounds computed from the measurement and for
        time-varying systems with missing samples.
        """
        sys, s, nx = self.sys, self.s, self.sys.nx
        des = self.gains.designer
        if sys.nd and not isinstance(sys.d, Box):
            return None
        lead, T = y.shape[:-2], y.shape[-2]
        if not T:
            return None  # an empty record: the loop
        y3 = y.reshape(-1, T, sys.ny)
        u3 = u.reshape(int(np.prod(u.shape[:-2])), T, sys.nu)  # (also for nu = 0)
        miss = np.isnan(y3)
        any_miss = bool(miss.any())
        if des.tv and any_miss:
            return None
        Bn = y3.shape[0]
        if T > s and not des.tv and not any_miss and des.const_bounds:
            fast = self._windows_filter(u3, y3)
            if fast is not None:
                lo, hi, incons = fast
                if incons.any():  # predicted from the previous box, in time order (as the loop)
                    dlo, dhi = bounds_rows(sys, T)
                    none = np.zeros_like(incons)
                    self._fill_predictions(incons.copy(), none, incons, u3, miss, dlo, dhi, lo, hi)
                return lo.reshape(*lead, T, nx), hi.reshape(*lead, T, nx), incons.reshape(*lead, T)
        lo = np.full((Bn, T, nx), np.nan)
        hi = np.full_like(lo, np.nan)
        need = np.zeros((Bn, T), dtype=bool)
        incons = np.zeros((Bn, T), dtype=bool)
        if T > s:
            dlo, dhi = bounds_rows(sys, T)
            c, R = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo)
            for b0, b1, k0, k1 in chunks(s, Bn, T):
                t0 = k0 - s  # each chunk carries the s samples before its first window
                mc = miss[b0:b1, t0:k1]
                yc = y3[b0:b1, t0:k1]
                parts = [u3[b0:b1, t0:k1], np.where(mc, 0.0, yc) if any_miss else yc]
                if des.nc:
                    parts.append(np.broadcast_to(c[t0:k1], (b1 - b0, k1 - t0, des.nc)))
                Z = np.concatenate(parts, axis=-1)
                # views of the results: the window functions fill rows s: (steps k0:k1)
                v_lo, v_hi, v_need, v_inc = (a[b0:b1, t0:k1] for a in (lo, hi, need, incons))
                out = (v_lo, v_hi, v_need, v_inc)
                if des.tv:
                    windows_tv(self.gains, Z, R[t0:k1], t0, out)
                elif not any_miss or not mc.any():
                    windows_full(self.gains, Z, R[t0:k1], out)
                else:
                    windows_patterns(self.gains, Z, R[t0:k1], mc, out)
            need |= incons
            # windows with a missing sample are intersected with the prediction (as the loop)
            pats = np.zeros((Bn, T), dtype=bool)
            if any_miss:
                row_miss = miss.any(axis=-1)
                for i in range(s + 1):
                    pats[:, s:] |= row_miss[:, s - i : T - i]
            if need.any() or pats.any():
                self._fill_predictions(need, pats & ~need, incons, u3, miss, dlo, dhi, lo, hi)
        return lo.reshape(*lead, T, nx), hi.reshape(*lead, T, nx), incons.reshape(*lead, T)

    def _window_filter(self, gain: WindowGain) -> tuple[LinearFilter, np.ndarray]:
        """Eqs. (7), (11) and the parity residual for complete windows as one linear filter of
        ``(u, y, ‖w‖_∞)``: the window ``z_(k-1) .. z_(k-s)`` is the state of a shift register
        (``z = [u; y; c]``), the outputs are ``x̂ ∓ (|T Md| 𝐫 + γ_i ‖w‖_∞)`` (the bounds,
        :func:`.windows.finish`) and ``ρ`` (the residual). Cached."""
        if self._filter is not None:
            return self._filter
        assert gain.GQ is not None and gain.HP is not None and gain.rad_coef is not None
        sys, s, nz = self.sys, self.s, self.gains.designer.nz
        nu, ny, nx = sys.nu, sys.ny, sys.nx
        n = s * nz
        M = np.zeros((n, n))
        for i in range(1, s):  # block i of x[k+1] is block i-1 of x[k]
            M[i * nz : (i + 1) * nz, (i - 1) * nz : i * nz] = np.eye(nz)
        Wz = np.eye(n, nz)  # z_k enters block 0 (s = 0: no state)
        G0, Gs = gain.GQ[:, :nz], gain.GQ[:, nz:]
        cols_u, cols_y = slice(0, nu), slice(nu, nu + ny)
        g = None
        hc = np.zeros(G0.shape[0])
        box = sys.d
        assert isinstance(box, Box) or sys.nd == 0
        if self.gains.designer.nc:
            assert isinstance(box, Box)
            c = box.center
            g = Wz[:, nu + ny :] @ c
            hc = G0[:, nu + ny :] @ c
        rhp = gain.HP @ np.tile(box.radius if isinstance(box, Box) else np.zeros(0), s + 1)
        rc = gain.rad_coef[:, None]
        H = [Gs[:nx], Gs[:nx], Gs[nx:]]
        J: list[list[np.ndarray | None]] = [
            [G0[:nx, cols_u], G0[:nx, cols_y], -rc],
            [G0[:nx, cols_u], G0[:nx, cols_y], rc],
            [G0[nx:, cols_u], G0[nx:, cols_y], None],
        ]
        h = [hc[:nx] - rhp[:nx], hc[:nx] + rhp[:nx], hc[nx:]]
        W = [Wz[:, cols_u], Wz[:, cols_y], np.zeros((n, 1))]
        filt = LinearFilter(M, W, H, J, g=g, h=h, block=min(64, max(8, s + 1)))
        self._filter = (filt, rhp[nx:] * (1.0 + 1e-9) + 1e-9)
        return self._filter

    def _windows_filter(self, u3: np.ndarray, y3: np.ndarray) -> Result | None:
        """Time-invariant, constant bounds, no missing sample: every window of the record (or
        batch ``(B, T, ·)``) by :meth:`_window_filter`; rows before ``s`` are NaN. Returns
        ``(lo, hi, inconsistent)`` or None when the complete window has no gain."""
        s, T = self.s, y3.shape[1]
        gain = self.gains.complete(s)
        if not gain.ok:
            return None
        filt, thr = self._window_filter(gain)
        # ‖w_k‖_∞ over the window z_k .. z_(k-s), z = [u; y; c]: column maxima, then lags
        zmax = np.abs(y3[..., 0], out=scratch(self, "zmax", y3.shape[:2]))
        for j in range(1, y3.shape[-1]):
            np.maximum(zmax, np.abs(y3[..., j]), out=zmax)
        shared_u = is_shared(u3, 1)
        umax = np.max(np.abs(u3[0] if shared_u else u3), axis=-1, initial=0.0)
        np.maximum(zmax, umax, out=zmax)
        if self.gains.designer.nc:
            box = self.sys.d
            assert isinstance(box, Box)
            np.maximum(zmax, float(np.max(np.abs(box.center))), out=zmax)
        wmax = scratch(self, "wmax", y3.shape[:2])
        wmax[...] = zmax
        for i in range(1, s + 1):
            np.maximum(wmax[:, i:], zmax[:, : T - i], out=wmax[:, i:])
        lo, hi, rho = filt.run([u3, y3, wmax[..., None]], temp=[2])
        inc = np.zeros(y3.shape[:2], dtype=bool)
        band = self._band
        if band is None or band.shape[0] != T:  # (T, nρ): rows before s (no window) ignored
            band = np.empty((T, thr.shape[0]))
            band[:s], band[s:] = np.inf, thr
            self._band = band
        if rho.shape[-1] and not within_band(rho, None, band):
            assert gain.tol_coef is not None
            over = np.abs(rho[:, s:]) - wmax[:, s:, None] * gain.tol_coef > thr
            inc[:, s:] = over.any(axis=-1)
        lo[:, :s] = np.nan
        hi[:, :s] = np.nan
        return lo, hi, inc

    def _fill_predictions(
        self,
        need: np.ndarray,
        inter: np.ndarray,
        incons: np.ndarray,
        u3: np.ndarray,
        miss: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
    ) -> None:
        """Windows that use the previous box, in time order, as the online step does
        (:func:`.recursion.combine`): ``need`` (no usable window, or inconsistent: the
        prediction) and ``inter`` (a window with missing samples: its box intersected with the
        prediction). The first window (``k = s``) predicts from ``x0`` propagated forward, if
        given; later ones from the box at ``k - 1``, level by level: all windows whose
        predecessor is settled at once."""
        s, sys = self.s, self.sys
        for first in np.nonzero(need[:, s] | inter[:, s])[0]:
            prior = self._first_prior(int(first), u3, dlo, dhi)
            own = None if need[first, s] and not incons[first, s] else (lo[first, s], hi[first, s])
            if prior is None and own is None:
                gain = self.gains.get(s, miss[first, s - np.arange(s + 1)])
                raise no_box_error(sys.nx, s, s, gain.rank)
            if prior is not None:
                box, incons[first, s] = combine(own, bool(incons[first, s]), prior)
                lo[first, s], hi[first, s] = box
        pending = need | inter
        pending[:, : s + 1] = False
        while pending.any():
            ready = pending.copy()
            ready[:, 1:] &= ~pending[:, :-1]  # the previous box is known
            b, k = np.nonzero(ready)
            plo, phi = outward(lo[b, k - 1], hi[b, k - 1])
            if self.gains.designer.tv:
                pred = [
                    predict(sys, plo[j], phi[j], u3[bj, kj - 1], dlo[kj - 1], dhi[kj - 1], kj)
                    for j, (bj, kj) in enumerate(zip(b.tolist(), k.tolist(), strict=True))
                ]
                p_lo, p_hi = np.array([p[0] for p in pred]), np.array([p[1] for p in pred])
            else:
                p_lo, p_hi = predict(sys, plo, phi, u3[b, k - 1], dlo[k - 1], dhi[k - 1], 1)
            # need: the prediction; inter: the intersection (empty -> inconsistent, prediction)
            i_lo, i_hi = np.maximum(lo[b, k], p_lo), np.minimum(hi[b, k], p_hi)
            empty = inter[b, k] & (i_lo > i_hi).any(axis=-1)
            use_pred = need[b, k] | empty
            lo[b, k] = np.where(use_pred[:, None], p_lo, i_lo)
            hi[b, k] = np.where(use_pred[:, None], p_hi, i_hi)
            incons[b, k] |= empty
            pending &= ~ready

    def _first_prior(
        self, b: int, u3: np.ndarray, dlo: np.ndarray, dhi: np.ndarray
    ) -> Bounds | None:
        """The prediction of the box at ``k = s`` from ``x0`` (None without ``x0``)."""
        s, sys = self.s, self.sys
        if self.x0 is None:
            return None
        if s == 0:
            return self.x0.lo, self.x0.hi  # the prior box of x[0] itself
        plo, phi = outward(np.array(self.x0.lo), np.array(self.x0.hi))
        for j in range(1, s):
            plo, phi = outward(*predict(sys, plo, phi, u3[b, j - 1], dlo[j - 1], dhi[j - 1], j))
        return predict(sys, plo, phi, u3[b, s - 1], dlo[s - 1], dhi[s - 1], s)
