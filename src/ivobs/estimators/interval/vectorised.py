"""The whole record at once (complete measurements, constant or tabulated bounds): the interval
recursion as linear filters of the shared kernels (:mod:`ivobs._recursion`).

The midpoint ``c+ = Q c + S L y + S(B − L D_u) u + gc`` and the innovation
``y − C S⁻¹ c − D_u u − fc`` are outputs of one :class:`~ivobs._recursion.SplitFilter` pass; the
radius ``r+ = |Q| r + gr`` does not depend on the data (computed once per record length, shared
by the streams of a batch). Sparse systems run the bounds themselves through one
:class:`~ivobs._recursion.LinearFilter` (loop form). The margins of the rounding are in
:mod:`.rounding`; tests check these paths equal to the loop over the step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...sets import Box, image_bounds
from .._recursion import (
    LinearFilter,
    SplitFilter,
    centre_band,
    matrix_product,
    redo_streams,
    within_band,
)
from ..rounding import ROUNDING
from .operators import SplitOperators
from .rounding import largest, norm_inf

__all__ = ["VectorPath"]

Bounds = tuple[np.ndarray, ...]


def bad_streams(res: np.ndarray, rad: np.ndarray, y: np.ndarray, ctol: float) -> Any:
    """The loop's test ``|res| <= rad + tol`` (:meth:`SplitOperators.consistent`) over a record
    or a batch: None when it passes; for a batch the ``(B,)`` mask of streams that fail; True
    when the single record fails (the caller falls back to its loop)."""
    fail = np.abs(res) > rad + ctol * (1.0 + np.abs(y) + 2.0 * rad)
    if not fail.any():
        return None
    return fail.reshape(fail.shape[0], -1).any(axis=1) if y.ndim == 3 else True


@dataclass(frozen=True)
class _Terms:
    """What the vectorised path needs for a record of ``T`` steps: the filter, the radius
    ``(T, nx)`` in ``x`` coordinates, the output band radius ``|C| r + fr``, for time-varying
    bounds the known-input signals ``(gc, fc)`` (else None), and ``fc`` at step 0."""

    T: int
    filt: SplitFilter
    rad: np.ndarray
    yrad: np.ndarray
    known: tuple[np.ndarray, np.ndarray] | None
    fc0: np.ndarray


class VectorPath:
    """``_run`` of the interval observers (module docstring)."""

    def __init__(self, ops: SplitOperators):
        self.ops = ops
        self._terms: _Terms | None = None  # the last record length's (batches share it)

    def run(self, est: Any, u: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> Bounds | None:
        """The bounds of the record or batch; ``None`` (the loop) for callable bounds, missing
        samples, time-varying bounds shorter than the record, or an inconsistent measurement
        of a single record (the loop reports it and predicts without it); streams of a batch
        with one go through ``est``'s loop."""
        ops = self.ops
        box = ops.sys.d
        T = y.shape[-2]
        if not T or (box is not None and not isinstance(box, Box)):
            return None  # (an empty record: the loop)
        if box is not None and box.is_time_varying and box.lo.shape[0] < T:
            return None
        if np.isnan(y).any() or ops.unc is not None:  # interval matrices: terms from the box
            return None
        if ops.sparse:
            return self._run_sparse(est, u, y, T)
        if ops.S is not None and not np.isfinite(ops.kappa_z):
            return None  # |Q| not Schur in floating point: the loop bounds each step's error
        return self._run_dense(est, u, y, t)

    def _run_dense(
        self, est: Any, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> Bounds | None:
        ops = self.ops
        vec = self._vector_terms(y.shape[-2])
        hi = np.empty((*y.shape[:-1], ops.nx))
        sig = [y, u] if vec.known is None else [y, u, *vec.known]
        lo0, hi0 = ops.initial_bounds()
        (xc, innov), shared = vec.filt.run(sig, x0=0.5 * (lo0 + hi0), out=[hi, None], temp=[1])
        s_x, s_i = (None, None) if shared is None else shared
        if ops.Si is not None:  # [Tang2019, eq. (42)]: the prior box itself at k = 0
            row0 = ops.x0.center - (0.0 if s_x is None else s_x[0])
            xc[..., 0, :] = row0
            inn0 = y[..., 0, :] - ops.x0.center @ ops.C.T - u[..., 0, :] @ ops.Du.T
            inn0 -= vec.fc0 + (0.0 if s_i is None else s_i[0])
            innov[..., 0, :] = inn0
        # the loop's test is |res| <= pr + tol(|y|, pr); without |y| the band is narrower, so
        # passing it decides without touching y again
        bad = None
        if not within_band(innov, s_i, vec.yrad + ops.ctol * (1.0 + 2.0 * vec.yrad)):
            bad = bad_streams(innov if s_i is None else innov + s_i, vec.yrad, y, ops.ctol)
            if bad is True:
                return None
        del innov
        lo, xc = centre_band(xc, vec.rad, s_x)
        self._widen(lo, xc)
        if ops.S is not None:
            extra = self._transform_margin(lo, xc, u, y)
            lo -= extra
            xc += extra
        if bad is not None:  # only the streams with an inconsistent measurement by the loop
            return redo_streams(est, u, y, t, lo, xc, bad)
        return lo, xc

    def _widen(self, lo: np.ndarray, hi: np.ndarray) -> None:
        """In place: ``(mu − 1) ROUNDING |bound|`` on top of the base margin (when ``mu > 1``;
        :mod:`.rounding`)."""
        mu = self.ops.mu
        if mu > 1.0:
            m = np.maximum(np.abs(lo), np.abs(hi))
            m *= (mu - 1.0) * ROUNDING
            lo -= m
            hi += m

    def _transform_margin(
        self, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, y: np.ndarray
    ) -> np.ndarray:
        """The rounding of the vectorised path in ``z = S x`` (``S ≠ I``; :mod:`.rounding`): per
        step, ``‖Si‖ κ_z max_{j<=k} δ_j`` plus the conversion to ``x``
        (:func:`~.rounding.transform_conversion`), with ``δ_j`` from
        :func:`~.rounding.transform_step_error` on the running maxima of ``‖x‖`` (the bounds),
        ``‖z‖ <= 2 ‖S‖ ‖x‖``, ``‖y‖``, ``‖u‖`` and ``‖d‖``. When the margin from each stream's
        whole-record maxima is below ``1e-3 ROUNDING`` that one is used (whole-array
        reductions): shape ``(..., 1, 1)``; else the running maxima are taken per block of
        ``T / 64`` steps (the maximum up to the end of a step's block): shape ``(..., T, 1)``."""
        ops = self.ops
        assert ops.S is not None and ops.Si is not None and ops.tconv is not None
        err = ops.full.err
        assert err is not None
        c_x, c_z, c_y, c_u, c_d = err
        nS, nSi, kap = norm_inf(ops.S), norm_inf(ops.Si), ops.kappa_z
        g, c = ops.tconv
        box = ops.sys.d
        Dm = 0.0
        if isinstance(box, Box):
            Dm = largest(box.lo, box.hi)

        def margin(X: Any, Y: Any, U: Any) -> Any:
            delta = (c_x + 2.0 * nS * c_z) * X + c_y * Y + c_u * U + c_d * Dm
            zeta = 2.0 * nS * X
            return nSi * kap * delta + c * zeta + g * (X + c * zeta) / (1.0 - g)

        lead = y.shape[:-2]
        B = int(np.prod(lead))

        def stream_max(a: np.ndarray) -> np.ndarray:  # max |a| per stream (u may be shared)
            flat = a.reshape(B, -1) if a.ndim == y.ndim else a.reshape(1, -1)
            if not flat.shape[1]:
                return np.zeros(flat.shape[0])
            big: np.ndarray = np.maximum(flat.max(axis=1), -flat.min(axis=1))
            return big

        extra = margin(np.maximum(stream_max(hi), stream_max(lo)), stream_max(y), stream_max(u))
        if float(np.max(extra)) <= 1e-3 * ROUNDING:
            return np.asarray(extra).reshape(*lead, 1, 1)

        # per block of K steps (64 blocks: contiguous reductions), then the running maximum
        # over blocks: at step k, the maximum up to the end of k's block (>= the one up to k)
        T = y.shape[-2]
        K = max(1, -(-T // 64))
        starts = np.arange(0, T, K)

        def running(a: np.ndarray) -> np.ndarray:
            if not a.shape[-1]:
                return np.zeros((*a.shape[:-2], starts.size))
            r = np.maximum(
                np.maximum.reduceat(a, starts, axis=-2).max(axis=-1),
                -np.minimum.reduceat(a, starts, axis=-2).min(axis=-1),
            )
            out: np.ndarray = np.maximum.accumulate(r, axis=-1, out=r)
            return out

        X = np.maximum(running(hi), running(lo))
        extra = margin(X, running(y), running(u))
        return np.repeat(extra, K, axis=-1)[..., :T, None]

    def _disturbance_images(self, T: int) -> tuple[np.ndarray, ...]:
        """Lemma 1's bounds of the disturbance terms over ``T`` steps with every output observed:
        ``(glo, ghi, flo, fhi)``, ``[glo, ghi] ∋ (S(E − LF)) d`` and ``[flo, fhi] ∋ F d``
        (``(T, ·)`` for time-varying bounds; zeros without ``d``)."""
        ops = self.ops
        box = ops.sys.d
        n, ny = ops.nx, ops.ny
        if box is None:
            return np.zeros(n), np.zeros(n), np.zeros(ny), np.zeros(ny)
        assert isinstance(box, Box)
        dlo, dhi = (box.lo[:T], box.hi[:T]) if box.is_time_varying else (box.lo, box.hi)
        glo, ghi = image_bounds(ops.full.Gz, dlo, dhi)
        flo, fhi = image_bounds(ops.F, dlo, dhi)
        return glo, ghi, flo, fhi

    def _run_sparse(self, est: Any, u: np.ndarray, y: np.ndarray, T: int) -> Bounds | None:
        """Sparse ``A``: the bounds themselves, ``[z̄; z̲]+ = S2 [z̄; z̲] + v[k]``, one sparse
        product per step with every input term ``v`` precomputed by one matrix product
        (:class:`~ivobs._recursion.LinearFilter`, loop form); then the consistency of ``y``."""
        ops = self.ops
        n, m = ops.nx, ops.full
        glo, ghi, flo, fhi = self._disturbance_images(T)
        two = np.vstack
        W = [two([m.Lz, m.Lz]), two([m.Bz, m.Bz])]
        sig = [y, u]
        g = None
        if glo.ndim == 2:  # time-varying bounds: one more (shared) input
            W.append(np.eye(2 * n))
            sig.append(np.broadcast_to(np.hstack([ghi, glo]), (*y.shape[:-2], T, 2 * n)))
        else:
            g = np.concatenate([ghi, glo])
        filt = LinearFilter(m.S2, W, [], g=g)
        lead = y.shape[:-2]
        sig = [np.broadcast_to(a, (*lead, *a.shape[-2:])) for a in sig]
        lo0, hi0 = ops.initial_bounds()
        X = filt.states(sig, x0=np.concatenate([hi0, lo0]))
        hi, lo = X[..., :n], X[..., n:]
        # consistency of y[k] with C[x̲_k, x̄_k] + D_u u + F[d] (the loop's test), on the few
        # states C reads
        assert ops.C_gather is not None
        cols, Rs, Ra = ops.C_gather
        clo, chi = lo[..., cols], hi[..., cols]
        yc = (clo + chi) @ Rs
        yc += matrix_product(u, ops.Du.T) + 0.5 * (flo + fhi)
        yr = (chi - clo) @ Ra + 0.5 * (fhi - flo)
        bad = bad_streams(y - yc, yr, y, ops.ctol)
        if bad is True:
            return None
        self._widen(lo, hi)
        if bad is not None and bad.any():
            return redo_streams(est, u, y, None, lo, hi, bad)
        return lo, hi

    def _vector_terms(self, T: int) -> _Terms:
        """The :class:`_Terms` of a record of ``T`` steps (kept for the next call)."""
        if self._terms is not None and self._terms.T == T:
            return self._terms
        ops = self.ops
        n, ny = ops.nx, ops.ny
        m = ops.full
        glo, ghi, flo, fhi = self._disturbance_images(T)
        gc, gr = 0.5 * (glo + ghi), 0.5 * (ghi - glo)
        fc, fr = 0.5 * (flo + fhi), 0.5 * (fhi - flo)
        Q = m.Qp - m.Qn
        H = np.eye(n) if ops.Si is None else ops.Si
        tv = gc.ndim == 2
        W = [m.Lz, m.Bz] + ([np.eye(n), np.zeros((n, ny))] if tv else [])
        J_inn: list[np.ndarray | None] = [np.eye(ny), -ops.Du]
        if tv:
            J_inn += [None, -np.eye(ny)]
        J: list[list[np.ndarray | None]] = [[None] * len(W), J_inn]
        filt = SplitFilter(
            Q, W, [H, -ops.C @ H], J, g=None if tv else gc, h=[None, None if tv else -fc]
        )
        z0lo, z0hi = ops.initial_bounds()
        r0 = 0.5 * (z0hi - z0lo)
        if tv:
            rad = LinearFilter(m.Qp + m.Qn, [np.eye(n)], [np.abs(H)]).run([gr], x0=r0)[0]
        else:
            rad = LinearFilter(m.Qp + m.Qn, [], [np.abs(H)], g=gr).run([], T=T, x0=r0)[0]
        if ops.Si is not None:
            rad[0] = ops.x0.radius
        yrad = rad @ np.abs(ops.C).T + fr
        terms = _Terms(T, filt, rad, yrad, (gc, fc) if tv else None, fc[0] if tv else fc)
        self._terms = terms
        return terms
