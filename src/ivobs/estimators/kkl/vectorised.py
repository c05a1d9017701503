"""Observers (3) and (6) of [Dinh2024] over whole records and batches at once (discrete-time,
time-invariant, complete measurements, bounds of ``d`` known in advance), from the shared kernels
of :mod:`ivobs._recursion`; equal to the step-by-step recursion of :mod:`.discrete` up to
rounding (sums in another order), which the outward margin covers.

(3.a) is two linear recursions with matrix ``A_z``, in centre/radius form: ``c = (z̄ + z̲)/2``
follows ``c+ = A_z c + B_z y + (TB - B_zD) u + (ḡ + g̲)/2`` and the radius ``r+ = A_z r +
(ḡ - g̲)/2`` does not depend on the data (one recursion for a whole batch). Observer (6)
(``coordinates="x"``) runs the same in ``x̂`` with ``A - LC``. The centre ``x = T⁺ c``, ``c``
itself (for the recovery margin) and the innovation ``y - C T⁺ c - D u - F d_c`` are outputs of
one :class:`~ivobs._recursion.SplitFilter` pass.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ...model import LinearSystem
from ...sets import Box, image_bounds
from .._recursion import (
    LinearFilter,
    SplitFilter,
    centre_band,
    matrix_product,
    redo_streams,
    scratch,
    within_band,
)
from .design import KKLDesign, ObserverMatrices
from .observer import prior_box

__all__ = ["VectorisedLTI"]


class _Terms(NamedTuple):
    """The filter and the data-free terms of a record of ``T`` steps."""

    filt: SplitFilter
    xr0: np.ndarray  # data-free part of the radius of x: |T⁺| r + margin part
    yr0: np.ndarray  # |C| xr0 + |F| d_r: the half-width of the output band
    gsig: np.ndarray | None  # time-varying bounds: the centre g_c of G d (a known input)
    fsig: np.ndarray | None  # and F d_c
    c0: np.ndarray  # the initial state of the filter
    dlo0: np.ndarray  # bounds of d[0]
    dhi0: np.ndarray


class VectorisedLTI:
    """The vectorised run of a discrete-time time-invariant KKL design."""

    def __init__(self, sys: LinearSystem, x0: Box, design: KKLDesign, m: ObserverMatrices):
        self.sys, self.x0, self.design, self.m = sys, x0, design, m
        self._terms: tuple[int, _Terms] | None = None

    def run(
        self, est: Any, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        """The bounds of the record (or batch), or None for the loop of ``est`` (missing
        samples, bounds computed from ``y``, an empty record). Streams with an inconsistent
        measurement are redone by ``est``'s loop, which reports and skips it."""
        if not y.shape[-2] or np.isnan(y).any():
            return None  # (an empty record: the loop)
        if self.sys.d is not None and not isinstance(self.sys.d, Box):
            return None  # bounds computed from y (callable): the loop evaluates them per step
        Tn = y.shape[-2]
        d = self.sys.d
        if isinstance(d, Box) and d.is_time_varying and d.lo.shape[0] < Tn:
            return None  # the loop raises the informative error
        tm = self.terms(Tn)
        hi = np.empty((*y.shape[:-1], self.sys.nx))
        sig = [y, u] if tm.gsig is None or tm.fsig is None else [y, u, tm.gsig, tm.fsig]
        (xc, zc, innov), shared = tm.filt.run(sig, x0=tm.c0, out=[hi, None, None], temp=[1, 2])
        s_x, s_z, s_i = (None, None, None) if shared is None else shared
        # consistency of y[k], k >= 1, with the band of the box at k (row 0: below, from the box
        # intersected with the prior, as in the loop); the data-free band is the narrower one
        yr0 = tm.yr0
        band = yr0[1:] + 1e-9 * (1.0 + yr0[1:])  # the test below without |yc| (narrower)
        fail = None
        if not within_band(innov[..., 1:, :], None if s_i is None else s_i[1:], band):
            full = (innov if s_i is None else innov + s_i)[..., 1:, :]
            yc = y[..., 1:, :] - full
            fail = np.abs(full) > yr0[1:] + 1e-9 * (1.0 + np.abs(yc) + yr0[1:])
        del innov
        # radius: data-free part + recovery margin |c| ρ' |T⁺| (design.fused_margin)
        if s_z is not None:
            zc += s_z
        np.abs(zc, out=zc)
        xr = matrix_product(zc, self.m.margin.T, out=scratch(self, "xr", hi.shape))
        del zc
        lo, xc = centre_band(xc, tm.xr0, s_x)
        lo -= xr
        xc += xr
        lo[..., 0, :], xc[..., 0, :] = prior_box(self.x0, lo[..., 0, :], xc[..., 0, :])
        fail0 = self._first_inconsistent(tm, u, y, lo, xc)
        if not fail0.any() and (fail is None or not fail.any()):
            return lo, xc
        if y.ndim != 3:
            return None  # the loop reports the step and predicts without it
        bad = np.asarray(fail0.any(axis=-1))
        if fail is not None:
            bad |= fail.any(axis=(-2, -1))
        return redo_streams(est, u, y, t, lo, xc, bad)

    def _first_inconsistent(
        self, tm: _Terms, u: np.ndarray, y: np.ndarray, lo: np.ndarray, hi: np.ndarray
    ) -> np.ndarray:
        """Components of ``y[0]`` outside the band of the first box (intersected with the
        prior), as the loop tests them."""
        _, _, C, D, _, F = self.m.mats
        dc0, dr0 = (0.5 * (tm.dlo0 + tm.dhi0), 0.5 * (tm.dhi0 - tm.dlo0))
        c0b, r0b = 0.5 * (lo[..., 0, :] + hi[..., 0, :]), 0.5 * (hi[..., 0, :] - lo[..., 0, :])
        yc0 = c0b @ C.T + u[..., 0, :] @ D.T + F @ dc0
        yr0b = r0b @ np.abs(C).T + np.abs(F) @ dr0
        fail0: np.ndarray = np.abs(y[..., 0, :] - yc0) > yr0b + 1e-9 * (1.0 + np.abs(yc0) + yr0b)
        return fail0

    def terms(self, Tn: int) -> _Terms:
        """The filter and the data-free terms for ``Tn`` steps (kept for the next record of
        the same length)."""
        if self._terms is not None and self._terms[0] == Tn:
            return self._terms[1]
        d = self.sys.d
        if isinstance(d, Box) and d.is_time_varying:
            dlo, dhi = d.lo[:Tn], d.hi[:Tn]
        else:
            dd = self.sys.d_at(0)
            dlo, dhi = dd.lo, dd.hi
        tv = dlo.ndim == 2
        glo, ghi = image_bounds(self.m.G, dlo, dhi)
        gc, gr = 0.5 * (glo + ghi), 0.5 * (ghi - glo)
        z0lo, z0hi = image_bounds(self.design.T, self.x0.lo, self.x0.hi)
        c0, r0 = 0.5 * (z0lo + z0hi), 0.5 * (z0hi - z0lo)
        P, Tm = self.m.tr.P, self.design.T
        _, _, C, D, _, F = self.m.mats
        ny, nz = self.sys.ny, self.design.n_z
        fc, fr = 0.5 * (dlo + dhi) @ F.T, 0.5 * (dhi - dlo) @ np.abs(F).T
        if self.m.Mx is not None:  # observer (6) in x̂, z = T x̂
            M, Win, Hz, x0 = self.m.Mx, P, Tm, P @ c0
        else:
            M, Win, Hz, x0 = self.design.A_z, np.eye(nz), np.eye(nz), c0
        Hx = P @ Hz
        W = [Win @ self.design.B_z, Win @ self.m.Lu]
        if tv:
            W += [Win, np.zeros((Win.shape[0], ny))]
        nsig = len(W)
        J: list[list[np.ndarray | None]] = [[None] * nsig, [None] * nsig, [np.eye(ny), -D]]
        if tv:
            J[2] += [None, -np.eye(ny)]
        g = None if tv else Win @ gc
        filt = SplitFilter(M, W, [Hx, Hz, -C @ Hx], J, g=g, h=[None, None, None if tv else -fc])
        if tv:
            zr = LinearFilter(M, [Win], [Hz]).run([gr], x0=Win @ r0)[0]
        else:
            zr = LinearFilter(M, [], [Hz], g=Win @ gr).run([], T=Tn, x0=Win @ r0)[0]
        xr0 = zr @ (np.abs(P) + self.m.margin).T  # data-free part of the x radius
        yr0 = xr0 @ np.abs(C).T + fr  # data-free half-width of the output band
        dlo0, dhi0 = (dlo[0], dhi[0]) if tv else (dlo, dhi)
        terms = _Terms(filt, xr0, yr0, gc if tv else None, fc if tv else None, x0, dlo0, dhi0)
        self._terms = (Tn, terms)
        return terms
