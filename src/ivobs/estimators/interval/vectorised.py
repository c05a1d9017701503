"""The whole record at once (complete measurements, constant or tabulated bounds): the interval
recursion as a centre and a radius, each a linear filter over the record, with its own proof.

**Algorithm.** With every output observed, the bounds of ``z = S x`` are ``ĉ_k ± ρ_k``: the
centre follows ``ĉ+ = Q ĉ + L_z y + B_z u + G d_c`` (one :class:`~ivobs._recursion.SplitFilter`
pass over the record or batch, evaluated in blocks: sums in another order than the loop's) and
the radius ``r+ = |Q| r + |G| d_r`` does not depend on the data (one pass per record length,
shared by the streams of a batch). In exact arithmetic this is the loop's recursion
(:mod:`.recursion`: ``Q⁺ z̄ − Q⁻ z̲`` has centre ``Q c`` and radius ``|Q| r``).

**Proof** (the float matrices and their error bounds are those of :mod:`.rounding`). Whatever
the computed centres ``ĉ_k`` are, ``e_k = z_k − ĉ_k`` obeys

    e+ = Q e + G (d − d_c) + β,    β_k = (G d_c − fl(G d_c)) + δ_k − ρ_k,

with ``δ_k`` the matrix errors of :mod:`.rounding` (row ``i``: ``ex_i ‖D_x⁻¹ x_k‖∞ +
eu_i ‖u_k‖∞ + ey_i ‖y_k‖∞ + ed_i ‖d_k‖∞`` in its scaled norms ``D_x``, ``D_z``) and
``ρ_k = ĉ_{k+1} − (Q ĉ_k + L_z y_k + B_z u_k + fl(G d_c))`` the
*defect* of the computed sequence, evaluated afterwards by one product over the record, each
row with its rounding ([Higham2002, §3.1]: row ``i`` off by at most ``2γ (Σ_j |Q_ij| |ĉ_j| +
|ĉ_{k+1,i}| + …)``). Split ``e = a + b``: ``a+ = Q a + G (d − d_c)``, ``|a_0| <= r_0`` gives
``|a_k| <= r_k`` (the exact radius recursion), and ``b+ = Q b + β``, ``b_0 = 0``. The computed
radii ``r̂`` fall short of the exact ones by at most ``p_k``, ``p+ = |Q| p + τ`` with ``τ_k``
the (evaluated) deficit ``|Q| r̂_k + |G| d_r − r̂_{k+1}``.

**The scaled norm.** Every such bound is measured in ``‖v‖_D = ‖D⁻¹ v‖∞``, ``D = diag(d)``
with ``d`` powers of two (:func:`scalings`: the steady radius of each state, or ``d = 1``,
whichever predicts the bound closer to the loop's; the choice does not enter the proof), so
``D⁻¹|Q|D``, ``D⁻¹ v`` and ``d s`` are exact (a scaled entry outside the normal range rejects
the scaling; an underflowed ``D⁻¹ v`` is short by less than ``η``, added). Row ``i`` of ``β``
divided by ``d_i`` is at most the same expression with the coefficients ``max_i (|Q| d)_i /
d_i`` on ``‖D⁻¹ ĉ_k‖∞`` and ``max_i ex_i / d_i`` (and alike) on the norms: each state's
rounding counts relative to its own scale, not to the largest state. ``‖D⁻¹ Q^i D‖∞ <=
‖(D⁻¹|Q|D)^i‖∞ <= c λ^i`` (:class:`~ivobs.sets.rounding.DecayBound` of ``D⁻¹|Q|D``), so
``‖D⁻¹ b_k‖∞ + ‖D⁻¹ p_k‖∞ <= s_k``, ``s+ = λ s + c (‖D⁻¹ β‖∞ + ‖D⁻¹ τ‖∞)``: one more linear
filter (:meth:`~ivobs.sets.rounding.DecayBound.accumulate`; ``δ_k`` depends on
``‖D_x⁻¹ x_k‖∞ <= k_x ‖D_z⁻¹ z_k‖∞ <= k_x (‖D_z⁻¹ ĉ_k‖∞ + ‖D_z⁻¹ r̂_k‖∞ + max(d / d_z) s_k)``,
whose last term goes into ``λ``). Hence,
componentwise, ``z_k ∈ ĉ_k ± (r̂_k + d s_k)``, rounded outwards; ``s_k`` is of the order of
the scaled rounding of the data times ``c / (1 − λ)``. The box of ``x`` (``S ≠ I``: its rows
add ``s_k |Si| d``) and the consistency test of ``y[k]`` (``s_k |C_z| d``) are evaluated from
it with their rounding bounds, as in the loop; a measurement found inconsistent sends the
record (or that stream of a batch) to the loop, which reports it. Each box of ``x[k]``, ``k
>= N``, is then met with the finite-memory bound of the ``N`` steps before it, as in the loop
(:mod:`.window`: the bounds of every window of the record in one product; they do not feed back
into the recursion).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DesignError, IvobsError
from ...linalg import UNIT_ROUNDOFF
from ...sets.rounding import ETA, DecayBound, gamma, mid_rad, up, upper
from .._recursion import LinearFilter, SplitFilter, abs_max, matrix_product, norm_inf, redo_streams
from .operators import Operators
from .window import meet

__all__ = ["VectorPath"]

Bounds = tuple[np.ndarray, ...]

_U2 = 2.0 * np.finfo(float).eps / 2

_BLOCK = 1 << 15
"""Elements (steps x states) per block of the finite-memory bounds (:meth:`VectorPath._memory`)."""


def _enclose(c: np.ndarray, r: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` with ``[c − ρ, c + ρ] ⊆ [lo, hi]`` exactly for ``ρ = r + s`` (``r``
    ``(T, n)`` shared by the streams, ``s`` ``(..., T, n)`` or ``(..., T, 1)``, both upper
    bounds of their exact values), in round-to-nearest: ``ρ' = 2u (1 + 8u) |c| + (r + s)(1 +
    8u) + η`` evaluated in three rounded operations (after the factors) is at least ``(ρ + u
    |c|) / (1 − u)``, and ``fl(c + ρ') >= c + ρ' − u (|c| + ρ') >= c + ρ`` (the same below; a
    result in the subnormal range is exact)."""
    k = 1.0 + 8.0 * UNIT_ROUNDOFF
    r2 = np.abs(c)
    r2 *= 2.0 * UNIT_ROUNDOFF * k
    r2 += r * k + ETA
    r2 += s * k
    return c - r2, c + r2


def scalings(
    aQ: np.ndarray, g: np.ndarray, bounds: tuple[np.ndarray, np.ndarray], ex: np.ndarray
) -> list[tuple[np.ndarray, np.ndarray, Any]]:
    """The candidate scalings ``d`` of the states (powers of two; module docstring), each with
    ``D⁻¹|Q|D`` and a score of the gain ``c / (1 − λ)`` of its decay bound: none (``d = 1``),
    and ``w = (I − |Q|)⁻¹ (g + r_0)`` (the steady radius with the disturbance radius ``g`` and
    the prior radius ``r_0`` as a constant input, each entry at least ``2⁻³⁰`` times the
    largest, rounded to a power of two within ``2^±400``) when its entries spread over more
    than ``2¹⁰``. The score is the mean over the
    states of the predicted excess ``d_i (c / (1 − λ)) max_j a_j / d_j`` over the loop's
    ``((I − |Q|)⁻¹ a)_i`` for a rounding ``a = ex ‖w‖ + u (|Q| w + w)`` of every row (the
    step's rounding per state, :mod:`.rounding`): the scaling that costs least against the
    loop's componentwise bound. No choice enters the proof (any positive ``d`` is sound)."""
    n = aQ.shape[0]
    one = np.ones(n)
    out: list[tuple[np.ndarray, np.ndarray, Any]] = []
    lo, hi = bounds
    v = np.nan_to_num(g + 0.5 * (hi - lo), nan=1.0, posinf=1.0)
    try:
        w = np.linalg.solve(np.eye(n) - aQ, v)
    except np.linalg.LinAlgError:
        w = np.full(n, np.nan)
    w = np.where(np.isfinite(w) & (w > 0.0), w, 0.0)
    top = float(np.max(w, initial=0.0))
    if not top > 0.0:
        return [(one, aQ, lambda gain: 0.0)]
    w = np.maximum(w, top * 2.0**-30)
    a = ex * top + UNIT_ROUNDOFF * (aQ @ w + w)
    with np.errstate(all="ignore"):
        loop = np.linalg.solve(np.eye(n) - aQ, a)
    loop = np.maximum(np.nan_to_num(loop, nan=np.inf), a)

    def score(d: np.ndarray) -> Any:
        excess = d * float(np.max(a / d))
        return lambda gain: float(np.mean(excess * gain / loop))

    out.append((one, aQ, score(one)))
    d = np.ldexp(1.0, np.clip(np.frexp(w)[1], -400, 400))
    Qd = _scaled(aQ, d)
    if Qd is not None and float(np.max(d)) > 1024.0 * float(np.min(d)):
        out.append((d, Qd, score(d)))
    return out


def _scaled(aQ: np.ndarray, d: np.ndarray) -> np.ndarray | None:
    """``D⁻¹ |Q| D`` for the powers of two ``d``, exact (None when an entry would leave the
    normal range: a scaling by ``2^e`` is exact there, and the round trip tells)."""
    e = np.frexp(d)[1]
    Qd: np.ndarray = np.ldexp(aQ, e[None, :] - e[:, None])
    if not np.isfinite(Qd).all():
        return None
    if not np.array_equal(np.ldexp(Qd, e[:, None] - e[None, :]), aQ):
        return None
    return Qd


class VectorPath:
    """``_run`` of the interval observers (module docstring)."""

    def __init__(self, ops: Operators):
        self.ops = ops
        self._decay: tuple[DecayBound, np.ndarray] | bool | None = False  # False: not computed
        self._radius: tuple[int, np.ndarray, np.ndarray] | None = None
        self._filter: SplitFilter | None = None
        self._coef: tuple[Any, ...] | None = None
        self._unit = True  # d = 1 (set with the decay bound)

    def _decay_bound(self) -> tuple[DecayBound, np.ndarray] | None:
        """The scaling ``d`` (:func:`scalings`) and ``c``, ``λ`` of ``D⁻¹|Q|D`` with the matrix
        errors' feedback (module docstring); None when they cannot be certified (then the loop
        runs)."""
        if self._decay is False:
            ops, m = self.ops, self.ops.full
            aQ = np.abs(m.Q)
            kx = 1.0 if ops.tr is None else ops.tr.kx
            de = np.ones(ops.nx) if ops.scale is None else ops.scale
            w = np.abs(m.G) @ (0.5 * ops.sys.d_widths())
            best: tuple[float, DecayBound, np.ndarray] | None = None
            for d, Qd, score in scalings(aQ, w, ops.initial_bounds(), kx * m.err.ex):
                try:
                    db = DecayBound.of(Qd)
                except DesignError:
                    continue
                ex = (float(np.max(m.err.ex / d, initial=0.0)) + ETA) * float(np.max(d / de))
                lam = float(up(db.lam + db.c * float(upper(kx * ex, 4))))
                cost = score(db.c / (1.0 - lam)) if lam < 1.0 else np.inf
                if lam < 1.0 and (best is None or cost < best[0]):
                    best = (cost, DecayBound(db.c, lam), d)
            self._decay = None if best is None else best[1:]
            self._unit = best is None or bool(np.all(best[2] == 1.0))
        return self._decay if isinstance(self._decay, tuple) else None

    def run(self, est: Any, u: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> Bounds | None:
        """The bounds of the record or batch; ``None`` (the loop) for sparse systems (one
        sparse product per step: the loop is as fast), interval matrices, callable bounds,
        missing samples, time-varying bounds shorter than the record, or an inconsistent
        measurement of a single record (the loop reports it); streams of a batch with one go
        through ``est``'s loop."""
        ops = self.ops
        sys = ops.sys
        T = y.shape[-2]
        if not T or ops.sparse or ops.unc is not None or sys.bounds_depend_on_y:
            return None
        if np.isnan(y).any():
            return None
        try:
            dlo, dhi = sys.d_over(T)
        except IvobsError:
            return None
        decay = self._decay_bound()
        if decay is None:
            return None
        if sys.has_constant_bounds:
            dlo, dhi = dlo[:1], dhi[:1]
        return self._run(est, decay, u, y, t, dlo, dhi)

    def _run(
        self,
        est: Any,
        decay: tuple[DecayBound, np.ndarray],
        u: np.ndarray,
        y: np.ndarray,
        t: np.ndarray | None,
        dlo: np.ndarray,
        dhi: np.ndarray,
    ) -> Bounds | None:
        ops, m = self.ops, self.ops.full
        n, ny, nu, nd = ops.nx, ops.ny, ops.nu, ops.nd
        T = y.shape[-2]
        db, d = decay
        di = 1.0 / d  # exact (powers of two)
        dimax = float(np.max(di, initial=1.0))
        tv = dlo.shape[0] > 1  # time-varying bounds: (T, nd); constant: (1, nd)
        dc, dr = mid_rad(dlo, dhi)
        aG, aF = np.abs(m.G), np.abs(ops.mats[5])
        gc = dc @ m.G.T  # (1 or T, n)
        g_err = abs_max(upper(np.abs(dc) @ aG.T, nd) * di) * (2.0 * gamma(nd + 2))
        g_err += (nd + 2) * ETA * dimax + ETA
        gr = upper(dr @ aG.T, nd)
        fc = dc @ ops.mats[5].T
        f_err = abs_max(upper(np.abs(dc) @ aF.T, nd)) * (2.0 * gamma(nd + 2)) + (nd + 2) * ETA
        fr = upper(dr @ aF.T, nd)
        d_mag = abs_max(np.maximum(np.abs(dlo), np.abs(dhi)))  # (1 or T,)
        lo0, hi0 = ops.initial_bounds()
        c0, r0 = mid_rad(lo0, hi0)

        # -- the centre: one filter pass -------------------------------------------------------
        c = self._centre(u, y, c0, gc if tv else gc[0], tv)
        c[..., 0, :] = c0
        # -- the radius (data-free) and its deficit --------------------------------------------
        rad, tau = self._radius_of(T, r0, gr if tv else gr[0], di)
        rmax = abs_max(rad)  # (T,)
        # -- the defect of the centres: whole (contiguous) arrays, then the rows k < T − 1 -------
        cmax, ymax = abs_max(c), abs_max(y)
        unit = self._unit
        cs = cmax if unit else abs_max(c * di)  # ‖D⁻¹ ĉ_k‖∞ (exact but for underflow: + η)
        # the norms of ĉ_k, r̂_k on which the matrix errors act (:mod:`.rounding`: ‖D_e⁻¹ x‖∞)
        if ops.scale is None:
            ce, re, de_max = cmax, rmax, float(np.max(d, initial=1.0))
        else:
            dei = 1.0 / ops.scale
            de_max = float(np.max(d * dei, initial=1.0))
            ce = cs if np.array_equal(ops.scale, d) else abs_max(c * dei)
            re = abs_max(rad * dei)
        umax: Any = abs_max(u) if nu else 0.0
        pred = matrix_product(c, m.Q.T)
        pred += matrix_product(y, m.Lz.T)
        if nu and m.Bz.any():
            pred += matrix_product(u, m.Bz.T)
        pred += gc if tv else gc[0]
        defect = pred[..., :-1, :]
        defect -= c[..., 1:, :]
        if not unit:
            defect *= di
        ge = 2.0 * gamma(n + ny + nu + 4)

        def row(v: np.ndarray) -> float:  # max_i v_i / d_i, rounded up (v >= 0, upper bounds)
            return float(np.max(v * di, initial=0.0)) + ETA

        def rows(M: np.ndarray) -> np.ndarray:  # row sums of |M|, rounded up
            return np.asarray(upper(np.abs(M).sum(axis=1), max(M.shape[-1], 1)))

        if self._coef is None:  # data-free: once
            self._coef = (
                float(upper(row(upper(np.abs(m.Q) @ d, n)), 1)),  # max_i (|Q| d)_i / d_i
                row(rows(m.Lz)),
                row(rows(m.Bz)),
                (ops.tr.kx if ops.tr is not None else 1.0) * row(m.err.ex),
                row(m.err.eu),
                row(m.err.ey),
                row(m.err.ed),
                upper(np.abs(m.Cz) @ d, n),
                None if ops.tr is None else upper(np.abs(ops.tr.Si) @ d, n),
                None if ops.tr is None else rows(ops.tr.Si),
            )
        nQ, nL, nB, ex, eu, ey, ed, Cd, Sid, sr = self._coef
        nG = row(abs_max(np.abs(gc.T)))
        e = ops.tr.kx if ops.tr is not None else 1.0
        cs0, ym = cs[..., :-1], ymax[..., :-1]
        um = umax[..., :-1] if nu else 0.0
        beta = (1.0 + _U2) * abs_max(defect) + ETA
        del pred, defect
        beta += ge * nQ * cs0 + ex * (ce[..., :-1] + re[:-1] + 2.0 * ETA) + ge * cs[..., 1:]
        beta += (ge * nL + ey) * ym + (ge * nB + eu) * um
        beta += ge * nG + (n + ny + nu + 4) * ETA * dimax + 2.0 * ETA + tau
        beta += ed * (d_mag[:-1] if tv else d_mag[0]) + (g_err[:-1] if tv else g_err[0])
        s = np.zeros(cmax.shape)
        if T > 1:  # per stream (identical streams, identical bounds)
            beta = upper(beta, 14)
            for out, b in zip(s.reshape(-1, T), beta.reshape(-1, T - 1)):
                out[1:] = db.accumulate(b)
        # |z_k − ĉ_k| <= r̂_k + d s_k; ‖D_e⁻¹ z_k‖∞ <= zmax (the norm of :mod:`.rounding`)
        zmax = upper(ce + re + s * de_max + 2.0 * ETA, 4)
        # -- consistency of y[k] with C x + D_u u + F d (the loop's test rows) ----------------
        Du = ops.mats[3]
        yc = matrix_product(c, m.Cz.T)
        if nu and Du.any():
            yc += matrix_product(u, Du.T)
        yc += fc
        yc -= y
        np.abs(yc, out=yc)
        aC = np.abs(m.Cz)
        yr = upper(matrix_product(rad, aC.T), n) + fr  # (T, ny): data-free
        nC, nD = norm_inf(m.Cz), norm_inf(Du)
        pz = float(np.max(m.err.pz, initial=0.0)) + e * float(np.max(m.err.px, initial=0.0))
        nf = float(np.max(abs_max(fc)))
        slack = 2.0 * gamma(n + nu + 3) * (nC * cmax + nD * umax + nf) + f_err
        slack += pz * zmax + _U2 * ymax + (n + nu + 3) * ETA
        slack = upper(slack, 8)[..., None] + upper(s[..., None] * Cd, 1)
        slack += yr
        bad = yc > upper(slack, 4)
        del yc, slack
        fail = None
        if bad.any():
            if y.ndim == 2:
                return None
            fail = bad.reshape(bad.shape[0], -1).any(axis=1)
        # -- the boxes ---------------------------------------------------------------------------
        if ops.tr is None:
            sd = s[..., None] if unit else s[..., None] * d + ETA  # (exact but for underflow)
            lo, hi = _enclose(c, rad, sd)
        else:
            Si = ops.tr.Si
            aSi = np.abs(Si)
            xc = matrix_product(c, Si.T)
            xr = upper(matrix_product(rad, aSi.T), n)  # (T, n): data-free
            extra = (2.0 * gamma(n + 2) * cmax)[..., None] * sr + (e * zmax)[..., None] * ops.tr.rs
            extra = upper(extra, 3) + upper(s[..., None] * Sid, 1)
            lo, hi = _enclose(xc, xr, extra)
            lo[..., 0, :] = ops.x0.lo  # [Tang2019, eq. (42)]: the prior box at k = 0
            hi[..., 0, :] = ops.x0.hi
        if ops.window is not None and ops.memory:
            self._memory(u, y, lo, hi)
        if fail is not None:
            return redo_streams(est, u, y, t, lo, hi, fail)
        return lo, hi

    def _memory(self, u: np.ndarray, y: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
        """The boxes of ``x[k]``, ``k >= N``, met in place with the finite-memory bounds ``W_k``
        of the windows ``[y_j, u_j]``, ``j = k − N .. k − 1`` (:mod:`.window`: the loop's
        :func:`~.window.memory_box`, for every window at once)."""
        bound = self.ops.window
        assert bound is not None
        N, T = bound.N, y.shape[-2]
        # in blocks of steps: temporaries that stay in cache (fresh record-sized arrays cost
        # more in page faults than the arithmetic)
        size = max(1, _BLOCK // (int(np.prod(y.shape[:-2])) * max(lo.shape[-1], 1)))
        for a in range(N, T, size):
            b = min(T, a + size)
            wlo, whi = bound.boxes(y[..., a - N : b, :], u[..., a - N : b, :])
            lo[..., a:b, :], hi[..., a:b, :] = meet(lo[..., a:b, :], hi[..., a:b, :], wlo, whi)

    def _centre(
        self, u: np.ndarray, y: np.ndarray, c0: np.ndarray, gc: np.ndarray, tv: bool
    ) -> np.ndarray:
        """The centres ``ĉ`` ``(..., T, n)`` of the record or batch (one filter pass)."""
        m, n = self.ops.full, self.ops.nx
        if tv:
            filt = SplitFilter(m.Q, [m.Lz, m.Bz, np.eye(n)])
            sig = [y, u, gc]
        else:
            if self._filter is None:
                self._filter = SplitFilter(m.Q, [m.Lz, m.Bz], gc)
            filt, sig = self._filter, [y, u]
        (c,), shared = filt.run(sig, x0=c0)
        if shared is not None:
            c += shared[0]
        return c

    def _radius_of(
        self, T: int, r0: np.ndarray, gr: np.ndarray, di: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(r̂, ‖D⁻¹ τ‖∞)``: the computed radii ``(T, n)`` from ``r̂_0 = r0`` and the scaled
        norms of their deficits ``(T − 1,)`` (module docstring; ``di = 1 / d``); kept for the
        next record of the same length (constant bounds)."""
        tv = gr.ndim == 2
        if not tv and self._radius is not None and self._radius[0] == T:
            return self._radius[1], self._radius[2]
        m, n = self.ops.full, self.ops.nx
        aQ = np.abs(m.Q)
        if tv:
            rad = LinearFilter(aQ, [np.eye(n)]).run([gr], x0=r0)[0]
        else:
            rad = LinearFilter(aQ, [], gr).run([], T=T, x0=r0)[0]
        rad[0] = r0
        nxt = matrix_product(rad[:-1], aQ.T)
        nxt += gr[:-1] if tv else gr
        nxt *= di
        ev = 2.0 * gamma(n + 3) * abs_max(nxt) + (n + 3) * ETA * float(np.max(di, initial=1.0))
        nxt -= rad[1:] * di
        tau = upper((1.0 + _U2) * abs_max(np.maximum(nxt, 0.0)) + ev + 2.0 * ETA, 4)
        if not tv:
            self._radius = (T, rad, tau)
        return rad, tau
