"""The window gains of the fixed-time estimator [Wang2020] and their certified radii.

A window gain maps the window vector ``w = [z_k; …; z_{k-s}]``, ``z = [u; y; c]`` (``y`` zero
where missing, ``c`` the centre of ``d``), to the estimate ``x̂_k = T(𝐲_k - Mu 𝐮_k)``
[Wang2020, eq. (7)] and to the parity residual ``ρ = N(𝐲 - Mv 𝐯)``, ``N Mx = 0``. It is computed
once per missing-data pattern (and per step for a time-varying system, [Wang2020, Remark 4]),
certified on the forward form of the window (:func:`ivobs.design.certify.window_bound`), and
cached by :class:`WindowGains`. :func:`evaluate_window` gives the bounds of eq. (11) of one
window; :func:`choose_injection` picks the output injection of [Wang2020, Remark 1] by the
certified accuracy of the complete window's gain.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...design.certify import forward_window, gamma, window_bound
from ...design.injection import injection_candidates
from ...design.parity import optimal_T, pinv_perp
from ...errors import DesignError
from ...sets import Box
from .design import CACHE_SIZE, WindowDesigner

__all__ = ["ACCURACY", "WindowGain", "WindowGains", "choose_injection", "evaluate_window"]

_EPS = np.finfo(float).eps
ACCURACY = 1e-9
"""A design whose certified error exceeds ``ACCURACY ‖G_i‖₁ ‖w‖_∞`` (:meth:`WindowGains.
_certify`) is replaced by an output injection ([Wang2020, Remark 1]), when one does better."""


@dataclass(frozen=True)
class WindowGain:
    """Gains of one window (one missing-data pattern, one step for time-varying systems).

    On the window vector ``w`` and the stacked radii ``𝐫``: ``GQ w = [x̂; ρ]`` (estimate,
    eq. 7, and parity residual); ``HP 𝐫 = [|T Md| 𝐫; |N Md| 𝐫]`` (radius, eq. 11, and the bound
    of ``ρ``). ``rad_coef``, ``tol_coef``: rounding margins per unit of ``‖w‖_∞`` (see
    :func:`evaluate_window`). ``ok`` is False when the window does not determine the state
    (``rank`` of the available rows of ``Mx`` below ``nx``, or no certificate).
    """

    ok: bool
    rank: int
    nx: int = 0
    GQ: np.ndarray | None = None
    HP: np.ndarray | None = None
    rad_coef: np.ndarray | None = None
    tol_coef: np.ndarray | None = None
    accuracy: float = np.inf


def evaluate_window(
    gain: WindowGain, w: np.ndarray, r: np.ndarray
) -> tuple[np.ndarray, np.ndarray, bool]:
    """Eq. (11) for one window ``w`` with radii ``r``: ``(lo, hi)`` and whether the parity
    residual exceeds its bound, ``|ρ| > |N Md| 𝐫`` (tolerance ``1e-9`` relative).

    The radius is ``HP 𝐫 + rad_coef ‖w‖_∞``: the certified disturbance gain and remainder of
    :meth:`WindowGains._certify`, plus the evaluation rounding ``64 (s+1) n_z ε ‖G_i‖₁``."""
    assert gain.GQ is not None and gain.HP is not None and gain.rad_coef is not None
    assert gain.tol_coef is not None
    nx = gain.nx
    out = gain.GQ @ w
    rhp = gain.HP @ r
    wmax = float(np.abs(w).max()) if w.size else 0.0
    rad = wmax * gain.rad_coef + rhp[:nx]
    bad = False
    if out.shape[0] > nx:
        bound = wmax * gain.tol_coef + (rhp[nx:] * (1.0 + 1e-9) + 1e-9)
        bad = bool((np.abs(out[nx:]) > bound).any())
    return out[:nx] - rad, out[:nx] + rad, bad


class WindowGains:
    """The certified gain of every window, by step (time-varying systems) and missing
    pattern, cached. ``check``: include the parity rows (consistency test)."""

    def __init__(self, designer: WindowDesigner, check: bool):
        self.designer = designer
        self.sys = designer.sys
        self.s = designer.s
        self.check = check
        self._gains: OrderedDict[Any, WindowGain] = OrderedDict()
        self._models: OrderedDict[int, tuple[np.ndarray, ...]] = OrderedDict()

    def clear(self) -> None:
        """Forget the gains (the design changed)."""
        self._gains.clear()

    def get(self, k: int, missing: np.ndarray) -> WindowGain:
        """The window gain for step ``k`` and missing pattern ``missing`` ((s+1, ny) bool)."""
        key = (k if self.designer.tv else 0, missing.tobytes())
        hit = self._gains.get(key)
        if hit is not None:
            return hit
        gain = self._make(k, missing)
        self._gains[key] = gain
        if len(self._gains) > CACHE_SIZE:
            self._gains.popitem(last=False)
        return gain

    def complete(self, k: int) -> WindowGain:
        """The gain of the complete window ending at ``k``."""
        return self.get(k, np.zeros((self.s + 1, self.sys.ny), dtype=bool))

    def _make(self, k: int, missing: np.ndarray) -> WindowGain:
        des = self.designer
        nx, ny, nu, nz, s = self.sys.nx, self.sys.ny, self.sys.nu, des.nz, self.s
        Mx, Mv, Md = des.stack(k)
        rows = ~missing.ravel()
        if not rows.all():
            # a missing y_{k-j} is also an unknown input through L y (Remark 1): drop the rows
            # that depend on it
            ycols = (np.arange(s + 1)[:, None] * nz + nu + np.arange(ny)[None, :]).ravel()
            miss_cols = ycols[missing.ravel()]
            rows &= np.all(Mv[:, miss_cols] == 0, axis=1)
        MxR = Mx[rows]
        if MxR.shape[0] < nx:
            return WindowGain(ok=False, rank=int(np.linalg.matrix_rank(MxR)) if MxR.size else 0)
        _, _, N, rank = pinv_perp(MxR)
        if rank < nx:
            return WindowGain(ok=False, rank=rank)
        if rows.all():  # the design's T (time-invariant: computed once, e.g. the width LP)
            if des.tv:
                T_R = des.T_full(Mx, Md)[0]
            else:
                assert des.design is not None
                T_R = des.design.T
        else:
            try:
                T_R = optimal_T(MxR, Md[rows], des.weights()).T
            except DesignError:
                return WindowGain(ok=False, rank=rank)
        K = des.selection - Mv
        T_pad = np.zeros((nx, Mx.shape[0]))
        T_pad[:, rows] = T_R
        G = T_pad @ K
        N_pad = np.zeros((N.shape[0] if self.check else 0, Mx.shape[0]))
        if self.check:
            N_pad[:, rows] = N
        GQ = np.vstack([G, N_pad @ K])
        cert = self._certify(k, missing, GQ)
        if cert is None:  # the window does not determine its oldest state: use the prediction
            return WindowGain(ok=False, rank=rank)
        GQ, HP, extra = cert
        # rounding of the evaluation x̂ = G w (and of the recorded data), |G_i| |w| <= l1_i ‖w‖_∞
        l1 = np.abs(GQ).sum(axis=1) * (64.0 * (s + 1) * nz * _EPS)
        return WindowGain(
            ok=True,
            rank=rank,
            nx=nx,
            GQ=GQ,
            HP=HP,
            rad_coef=l1[:nx] + extra[:nx],
            tol_coef=l1[nx:] * (1e-9 / (64.0 * (s + 1) * nz * _EPS)) + extra[nx:],
            accuracy=float(np.max(extra[:nx] / np.maximum(np.abs(GQ[:nx]).sum(axis=1), 1e-300))),
        )

    def _certify(
        self, k: int, missing: np.ndarray, GQ: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """The window gain ``GQ`` (rows ``x̂``, then ``ρ``), refined, and its certified radius.

        ``GQ`` was computed from the stacked matrices of eq. (6), i.e. from the inverses of
        eq. (4) (of ``A - LC`` with an output injection) and an SVD: rounding, amplified by the
        conditioning of ``A``, makes ``T Mx = I``, the cancellation of the known inputs and
        ``|T Md|`` inexact (with ``rcond(A) ~ 1e-7`` the computed ``T`` missed ``T Mx = I`` by
        ``1e-2``). :func:`ivobs.design.certify.window_bound` evaluates what ``GQ`` actually
        does on the forward form of the window (products of the original model matrices only,
        with a ``γ_n`` rounding bound, [Higham2002, Lemma 3.1]): for the true trajectory
        ``x_k - G w = R_x x_{k-a} + R_v 𝐯 + R_δ 𝛅`` exactly, ``a`` the oldest lag that ``GQ``
        uses, else an older one (see the loop below), ``𝐯`` the known inputs and centres
        (entries of ``w``), ``|δ| <= 𝐫``.
        With ``‖x_{k-a}‖_∞ <= κ ‖w‖_∞ + ν 𝐫`` (the same window) and ``a_i = Σ_j |R_x|_ij``:

        ``|x_k - x̂_k|_i <= (|R_δ| + a ν)_i 𝐫 + (Σ_j |R_v|_ij + a_i κ) ‖w‖_∞``

        returned as ``(GQ, HP, extra)``: ``GQ`` after one step of iterative refinement (it
        moves by the size of its error only), ``HP`` (times ``1 + γ`` for the evaluation of
        ``HP 𝐫``) replaces ``|T Md|``; ``extra`` is added to the per-``‖w‖_∞`` radius. With
        re-centred bounds, ``c = (lo + hi)/2`` and ``r = (hi - lo)/2`` are rounded:
        ``|d - c| <= (1 + ε) r + ε |c|``, ``|c| <= ‖w‖_∞``. None when the window does not
        determine ``x_{k-a}`` (the prediction is used instead).
        """
        s, nz = self.s, self.designer.nz
        used = np.any(GQ.reshape(GQ.shape[0], s + 1, nz) != 0.0, axis=(0, 2))
        lag = int(np.nonzero(used)[0].max()) if used.any() else 0
        mats = [self._model(k - i) for i in range(s + 1)]
        # the anchor: the oldest lag the gain uses; with a singular A (Remark 1) a gain may use
        # only recent samples yet rely on x_k lying in the range of A (the parity relations of
        # the injected system), which only an older anchor shows: then the whole window, then
        # the lags in between while none determines its anchor state
        best: tuple[float, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        order = [lag] + ([s] if s > lag else []) + list(range(lag + 1, s))
        for i, a in enumerate(order):
            if i >= 2 and best is not None:
                break
            cert = self._certify_at(GQ, mats, a, missing)
            if cert is None:
                continue
            nrm = np.maximum(np.abs(cert[0][: self.sys.nx]).sum(axis=1), 1e-300)
            acc = float(np.max(cert[2][: self.sys.nx] / nrm, initial=0.0))
            if best is None or acc < best[0]:
                best = (acc, cert)
            if acc <= ACCURACY:
                break
        return None if best is None else best[1]

    def _certify_at(
        self, GQ: np.ndarray, mats: list[tuple[np.ndarray, ...]], a: int, missing: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """:meth:`_certify` with the anchor ``x_{k-a}`` (None when the window does not
        determine it)."""
        s, nx, nd, nc = self.s, self.sys.nx, self.sys.nd, self.designer.nc
        fw = forward_window(mats, centre=bool(nc), lag=a, missing=missing)
        wb = window_bound(GQ, nx, fw)
        if not np.isfinite(wb.kappa):
            return None
        ax = wb.Rx.sum(axis=1)
        HP = wb.Rd + ax[:, None] * wb.nu[None, :]
        extra = wb.Rv.sum(axis=1) + ax * wb.kappa
        if nc:
            extra += _EPS * (1.0 + _EPS) * HP.sum(axis=1)
            HP *= 1.0 + _EPS
        HP *= 1.0 + gamma((s + 1) * nd + 2)
        return wb.G, HP, extra

    def _model(self, j: int) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, E, F)`` of the original system at step ``j`` (no injection)."""
        key = j if self.designer.tv else 0
        hit = self._models.get(key)
        if hit is None:
            hit = self._models[key] = self.sys.matrices_at(key)
            if len(self._models) > CACHE_SIZE:
                self._models.popitem(last=False)
        return hit

    def quality(self) -> tuple[float, float]:
        """``(accuracy, width)`` of the complete window: the certified error per unit of
        ``‖G_i‖₁ ‖w‖_∞`` (:meth:`_certify`, worst state) and ``Σ_i (|T Md| 𝐫)_i`` (unit radii
        for bounds that vary with time)."""
        gain = self.complete(self.s)
        if not gain.ok:
            return np.inf, np.inf
        assert gain.HP is not None
        nx, nd = self.sys.nx, self.sys.nd
        r = np.ones(nd)
        if self.designer.const_bounds and nd:
            box = self.sys.d
            assert isinstance(box, Box)
            r = box.radius
        return gain.accuracy, float(np.sum(gain.HP[:nx] @ np.tile(r, self.s + 1)))


def choose_injection(gains: WindowGains, error: DesignError | None) -> None:
    """[Wang2020, Remark 1] when ``A`` is invertible but ill-conditioned, or when the
    injection placed first is not accurate: if the certified error of the complete window
    (:meth:`WindowGains.quality`) exceeds :data:`ACCURACY` of the data scale, every gain of
    :func:`ivobs.design.injection.injection_candidates` is tried, and the one with the
    narrowest box among the accurate ones is kept (the most accurate one if none is).
    Nothing changes for a well-conditioned design (the paper's examples). ``error``: the
    design with ``A`` itself failed (re-raised if no injection works either)."""
    des = gains.designer

    def use(L: np.ndarray | None) -> None:
        gains.clear()
        des.redesign(L)

    options: list[tuple[float, float, np.ndarray | None]] = []
    if error is None:
        acc, width = gains.quality()
        if acc <= ACCURACY:
            return
        options.append((acc, width, des.L))
    A, _, C, _, _, _ = gains.sys.matrices_at(0)
    for L in injection_candidates(A, C):
        try:
            use(L)
            options.append((*gains.quality(), L))
        except DesignError:
            continue
    if not options:
        assert error is not None
        raise error
    good = [o for o in options if o[0] <= ACCURACY]
    best = min(good, key=lambda o: o[1]) if good else min(options, key=lambda o: o[0])
    use(best[2])
