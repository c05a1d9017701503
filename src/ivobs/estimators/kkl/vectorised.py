"""Observer (3) of [Dinh2024] over whole records and batches at once (discrete time,
time-invariant, every output measured, bounds of ``d`` known in advance): a different algorithm
from the step, with its own proof, whose bounds are those of the step within rounding.

**Algorithm.** ``A_z`` being nonnegative, (3.a) is two linear recursions in centre/radius form:
``c+ = A_z c + B_z y + L u + g_c`` and ``r+ = A_z r + g_r + ε`` (``[g_c ± g_r]`` encloses the
bounds of ``G d``; ``ε = |L - L̂| |u| + |X| |x|``: the coefficient error and the residual of (4)
of :mod:`.terms`). The centre, driven by the data, and the data-free radius are evaluated by
:class:`~ivobs.estimators._recursion.LinearFilter` (blocks of steps, sums in any order).

**Proof, a posteriori, componentwise.** Whatever order the filter summed in, its computed ``ĉ``
satisfies ``ĉ[k+1] = A_z ĉ[k] + B_z y[k] + L̂ u[k] + g_c[k] + δ[k]`` with the *defect* ``δ[k]``,
evaluated here over the whole record (one product per term) with the bound of that evaluation
([Higham2002, Lemma 3.1]): ``|δ| <= |δ̂| + 2 γ_{n+2} (|ĉ[k+1]| + A_z |ĉ[k]| + |B_z| |y| + |L̂|
|u| + |g_c|)``, ``n = n_z + n_y + n_u + 2``, entry by entry; the computed radius ``r̂`` likewise
has the defect ``ρ[k]``. The exact ``z[k]`` then lies in ``[ĉ[k] ± (r̂[k] + e[k])]`` for every
``e[k] >= |c[k] - ĉ[k]| + |r[k] - r̂[k]|`` (``c``, ``r`` the exact recursions), and ``A_z >= 0``
gives, entry by entry, ``e[k+1] <= A_z e[k] + |δ[k]| + |ρ[k]| + ε[k]``. The residual is bounded
on the box of the recovery of :func:`.observer.recover`, as in the step: ``|x| <= |x_c| + |P| R
+ c_e s + c_r ‖s‖∞ 1``, ``x_c = fl(P ĉ)``, ``R = r̂ + e``, ``s = |P| (|ĉ| + R)`` (``c_e``,
``c_r``: ``c_err``, ``c_resid``; at ``k = 0`` also ``|x| <= max(|x̲0|, |x̄0|)``, the prior), so
``ε[k] <= a'[k] + K e[k]`` with ``K = |X| ((1 + c_e) |P| + c_r 1 p̂ᵀ)`` (``p̂`` the column maxima
of ``|P|``: ``‖|P| e‖∞ <= p̂ᵀ e``) and ``a'`` the same bound with ``e = 0`` plus ``|L - L̂| |u|``,
known from the data. Hence ``e[k+1] <= M e[k] + a[k]`` with ``M = A_z + K >= 0`` and ``a = |δ| +
|ρ| + a'``, all evaluated as upper bounds (:func:`~ivobs.sets.rounding.upper`).

That nonnegative recursion is run by the same filter, ``ŵ``, from ``ŵ[0] = e[0]``; its own
defect is bounded the same way: ``ρ'[k] >= M ŵ[k] + a[k] - ŵ[k+1]``, ``ρ' >= 0``. By induction
(``M >= 0`` keeps the order) ``e[k] <= ŵ[k] + Σ_{j<k} M^{k-1-j} ρ'[j] + M^k (e[0] - ŵ[0])⁺``.
That remainder, rounding of the order ``u ŵ``, is bounded in the diagonally scaled norm ``‖v‖_S
= ‖S⁻¹ v‖∞``, ``S = diag(2^{σ_i})`` with ``2^{σ_i}`` near the largest ``ŵ_i`` over the record:
``S⁻¹ M S`` is computed exactly (powers of two; an entry that underflows is rounded up by the
smallest subnormal), and its proven decay ``‖(S⁻¹ M S)ⁱ‖∞ <= c λⁱ``
(:class:`~ivobs.sets.rounding.DecayBound`) gives ``S⁻¹ (remainder) <= q[k] 1``, ``q[k+1] = λ q[k]
+ c ‖S⁻¹ ρ'[k]‖∞``. So ``e[k] <= ŵ[k] + q[k] S 1``, entry by entry: the step's own
componentwise bound up to rounding, at every scale of the states. A batch runs ``ŵ`` per
stream and takes the largest ``‖S⁻¹ ρ'[k]‖∞`` over its streams. The box is the recovery of
:func:`.observer.recover` over the record, and the consistency test that of
:class:`.terms.Consistency`; a record with a measurement it flags goes to the loop (a batch:
those streams), which reports it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DesignError
from ...sets import image_bounds
from ...sets.rounding import ETA, UNIT_ROUNDOFF, DecayBound, gamma, mid_rad, up, upper
from .._recursion import LinearFilter, abs_max, redo_streams
from .discrete import Discrete
from .observer import prior_box
from .terms import factor, g_image

__all__ = ["VectorisedLTI"]

_TINY = float(np.finfo(float).tiny)


class VectorisedLTI:
    """The vectorised run of a discrete-time time-invariant KKL design (module docstring)."""

    def __init__(self, observer: Discrete):
        self.ob = observer
        self._decays: dict[bytes, DecayBound | None] = {}
        self._filters: dict[bytes, LinearFilter] = {}
        self._growth: tuple[Any, Any, np.ndarray] | None = None
        self._radius: tuple[int, np.ndarray, np.ndarray] | None = None

    def run(
        self, est: Any, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        """The bounds of the record (or batch), or None for the loop of ``est`` (missing
        samples, bounds computed from ``y``, an empty record, a flagged measurement)."""
        ob, sys = self.ob, self.ob.sys
        Tn = y.shape[-2]
        if not Tn or sys.bounds_depend_on_y or np.isnan(y).any():
            return None
        const = sys.has_constant_bounds
        if const:
            dd = sys.d_at(0)
            dlo, dhi = dd.lo, dd.hi
        else:
            dlo, dhi = sys.d_over(Tn)
        terms, _ = ob.terms(0, np.ones(sys.ny, dtype=bool))
        tr = ob.transform(0)
        Az, Bz = ob.design.A_z, ob.design.B_z
        Lu = terms.L
        # the bounds of G d in centre/radius form
        gc, gr = mid_rad(*g_image(terms.G, terms.Gerr, dlo, dhi))
        zlo0, zhi0 = ob.initial_z()
        c0, r0 = mid_rad(zlo0, zhi0)
        # (3.a): the centre (data) and the radius (data-free), by the filter
        if const:
            chat = self.filter(Az, [Bz, Lu], gc).run([y, u], x0=c0)[0]
        else:
            cf = self.filter(Az, [Bz, Lu, np.eye(Az.shape[0])])
            chat = cf.run([y, u, np.broadcast_to(gc, (*y.shape[:-1], gc.shape[-1]))], x0=c0)[0]
        rhat, rdef = self.radius(Tn, r0, gr, const)
        cabs = np.abs(chat)
        sP = cabs @ tr.absP.T  # |P| |ĉ[k]|
        del cabs
        xc = chat @ tr.P.T
        e = self.errors(chat, xc, rhat, rdef, y, u, gc, c0, sP, tr, terms)
        if e is None:
            return None
        rad = self.spread(sP, rhat + e, tr)
        bad = self.contradicted(xc, rad, u, y, terms.check, (dlo, dhi))
        lo = xc - rad
        np.nextafter(lo, -np.inf, out=lo)
        xc += rad
        hi = np.nextafter(xc, np.inf, out=xc)
        lo[..., 0, :], hi[..., 0, :] = prior_box(ob.x0, lo[..., 0, :], hi[..., 0, :])
        # the first measurement against the box with the prior, as the loop
        bad[..., 0] = self.first_contradicted(lo, hi, u, y, terms.check, (dlo, dhi))
        if not bad.any():
            return lo, hi
        if y.ndim != 3:
            return None  # the loop reports the step and predicts without it
        return redo_streams(est, u, y, t, lo, hi, np.asarray(bad.any(axis=-1)))

    def filter(
        self, M: np.ndarray, W: list[np.ndarray], g: np.ndarray | None = None
    ) -> LinearFilter:
        """The :class:`LinearFilter` of these matrices, kept (its block operators are built
        once)."""
        parts = [M, *W] if g is None else [M, *W, g]
        key = b"|".join(
            np.ascontiguousarray(p).tobytes() + bytes(str(p.shape), "ascii") for p in parts
        )
        hit = self._filters.get(key)
        if hit is None:
            if len(self._filters) >= 16:
                self._filters.clear()
            hit = self._filters[key] = LinearFilter(M, W, g)
        return hit

    def radius(
        self, Tn: int, r0: np.ndarray, gr: np.ndarray, const: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """``r̂[0..T-1]`` of ``r+ = A_z r + g_r`` and the bounds of its defects, entry by entry:
        ``|r̂[0] - r[0]|`` then ``|ρ[k]|``, ``(T, n_z)`` (kept for the next record of the same
        length, constant bounds of ``d``)."""
        if const and self._radius is not None and self._radius[0] == Tn:
            return self._radius[1], self._radius[2]
        Az = self.ob.design.A_z
        nz = Az.shape[0]
        if const:
            rhat = self.filter(Az, [], gr).run([], T=Tn, x0=r0)[0]
        else:
            rhat = self.filter(Az, [np.eye(nz)]).run([gr], x0=r0)[0]
        nxt = rhat[1:]
        prev = rhat[:-1] @ Az.T
        g = gr if const else gr[:-1]
        dfct = np.abs(nxt - prev - g)
        dfct += factor(nz + 2, nz + 3) * (np.abs(nxt) + np.abs(prev) + np.abs(g)) + (nz + 8) * ETA
        # |ρ̂[k]| + its evaluation error, k = 0..T-2, after |r̂[0] - r0| (one rounding)
        rdef = np.concatenate((up(np.abs(rhat[0] - r0))[None, :], dfct))
        if const:
            self._radius = (Tn, rhat, rdef)
        return rhat, rdef

    def errors(
        self,
        chat: np.ndarray,
        xc: np.ndarray,
        rhat: np.ndarray,
        rdef: np.ndarray,
        y: np.ndarray,
        u: np.ndarray,
        gc: np.ndarray,
        c0: np.ndarray,
        sP: np.ndarray,
        tr: Any,
        terms: Any,
    ) -> np.ndarray | None:
        """``e[0..T-1]`` (module docstring), ``(..., T, n_z)``, or None when the decay of the
        scaled ``M`` cannot be certified (then the loop). ``x_c = P ĉ``, ``sP = |P| |ĉ|`` per
        step."""
        Az, Bz, Lu = self.ob.design.A_z, self.ob.design.B_z, terms.L
        nz, ny, nu = Az.shape[0], Bz.shape[1], Lu.shape[1]
        nx = tr.P.shape[0]
        lead, Tn = chat.shape[:-2], chat.shape[-2]
        # δ[k] = ĉ[k+1] - A_z ĉ[k] - B_z y[k] - L̂ u[k] - g_c[k] over the record, entry by
        # entry, and the bound of its evaluation from the magnitudes of its terms
        g = gc[:-1] if gc.ndim == 2 else gc
        step = chat @ Az.T
        step += y @ Bz.T
        if nu:
            step += u @ Lu.T
        dfct = np.subtract(chat[..., 1:, :], step[..., :-1, :], out=step[..., :-1, :])
        dfct -= g
        a = np.abs(dfct, out=dfct)  # (..., T-1, n_z)
        del step, dfct
        cabs = np.abs(chat)
        mag = cabs[..., :-1, :] @ Az.T
        mag += cabs[..., 1:, :]
        del cabs
        mag += np.abs(y[..., :-1, :]) @ np.abs(Bz).T
        if nu:
            mag += np.abs(u[..., :-1, :]) @ np.abs(Lu).T
        mag += np.abs(g)
        n = nz + ny + nu + 2
        mag *= factor(n, n + 1)
        a += mag
        del mag
        if nu:  # |L - L̂| |u|
            a += np.abs(u[..., :-1, :]) @ terms.Lerr.T
        a += rdef[1:]
        # |X| |x| on the box of x: |x| <= |x_c| + spread(r̂ + e) <= h + K' e, the magnitude of
        # the box without e (at k = 0 also that of the prior, as the step) and K' e its growth
        if terms.x_used:
            h = self.spread(sP[..., :-1, :], rhat[:-1], tr)
            h += np.abs(xc[..., :-1, :])
            x0 = self.ob.x0
            if x0 is not None and Tn > 1:
                pabs = np.maximum(np.abs(x0.lo), np.abs(x0.hi))
                np.minimum(h[..., 0, :], pabs, out=h[..., 0, :])
            a += h @ terms.xmag.T
            del h
        a += (n + nz + 8) * ETA
        a = upper(a, nz + ny + nu + nx + 16)
        M = self.growth(terms, tr)
        # ŵ of ŵ+ = M ŵ + a from e[0] >= |ĉ[0] - c[0]| + |r̂[0] - r[0]|
        e0 = upper(up(np.abs(chat[..., 0, :] - c0)) + rdef[0], 2)
        zero = np.zeros((*lead, 1, nz))
        w = self.filter(M, [np.eye(nz)]).run([np.concatenate((a, zero), axis=-2)], x0=e0)[0]
        if not np.isfinite(w).all():
            return None
        # ρ'[k] >= M ŵ[k] + a[k] - ŵ[k+1], >= 0: its evaluation with the bound of [Higham2002,
        # Lemma 3.1] (n_z + 2 terms)
        wabs = np.abs(w)
        t = w[..., :-1, :] @ M.T
        t += a
        t -= w[..., 1:, :]
        mag = wabs[..., :-1, :] @ M.T
        mag += a
        mag += wabs[..., 1:, :]
        del a, wabs
        t += factor(nz + 2, nz + 3) * mag + (nz + 8) * ETA
        del mag
        np.maximum(t, 0.0, out=t)
        # the scaling S = diag(2^σ) (σ = ex), 2^σ_i >= the largest ŵ_i (σ a multiple of 8, so
        # that records of like magnitudes share it; within 600 of the largest, in the normal
        # range), and the decay of S⁻¹ M S
        wmax = np.max(np.abs(w).reshape(-1, nz), axis=0)
        ex = -8 * (-np.frexp(wmax)[1] // 8)
        ex = np.clip(ex, max(int(ex.max()) - 600, -1000), 1000)
        db = self._decay_of(M, ex)
        if db is None:
            return None
        inv = np.ldexp(1.0, -ex)  # 1 / s, exact
        rho = (t * inv).reshape(-1, Tn - 1, nz) if Tn > 1 else np.zeros((1, 0, nz))
        eta = rho.max(axis=(0, 2))  # ‖S⁻¹ ρ'[k]‖∞ over the streams (underflow: accumulate)
        del t, rho
        f0 = np.maximum(up(e0 - w[..., 0, :]), 0.0) * inv
        q = np.empty(Tn)
        q[0] = float(up(db.c * up(float(np.max(f0)) + ETA)))
        q[1:] = db.accumulate(eta, q[0])
        # e[k] <= ŵ[k] + S q[k] 1 (S q exact, or underflow: ETA)
        w += np.ldexp(q[:, None], ex[None, :]) + ETA
        out: np.ndarray = np.nextafter(w, np.inf, out=w)
        return out

    def growth(self, terms: Any, tr: Any) -> np.ndarray:
        """``M >= A_z + K``, ``K = |X| ((1 + c_e) |P| + c_r 1 p̂ᵀ)`` (module docstring; the
        factor ``1 + 4 γ_4`` of :meth:`spread` included), kept for these terms."""
        if self._growth is not None and self._growth[0] is terms and self._growth[1] is tr:
            return self._growth[2]
        Az = self.ob.design.A_z
        M = Az
        if terms.x_used:
            f = 1.0 + 4.0 * gamma(4)
            pmax = np.max(tr.absP, axis=0)
            J = up(1.0 + tr.c_err * f) * tr.absP + up(tr.c_resid * f) * pmax[None, :]
            K = upper(terms.xmag @ upper(J, 3), tr.P.shape[0])
            M = up(Az + K)
        self._growth = (terms, tr, M)
        return M

    def _decay_of(self, M: np.ndarray, ex: np.ndarray) -> DecayBound | None:
        """The decay of ``S⁻¹ M S``, ``S = diag(2^σ)``, ``σ = ex`` (kept per scaling): its
        entries scaled exactly (an entry that underflows is raised by the smallest subnormal:
        an upper bound, which for ``M >= 0`` bounds the norms of the powers)."""
        key = ex.tobytes()
        if key in self._decays:
            return self._decays[key]
        Ms = M * np.ldexp(1.0, ex[None, :] - ex[:, None])
        Ms = np.where((M > 0) & (Ms < _TINY), Ms + ETA, Ms)
        try:
            db: DecayBound | None = DecayBound.of(Ms) if np.isfinite(Ms).all() else None
        except DesignError:
            db = None
        if db is not None and not db.lam < 1.0:
            db = None
        if len(self._decays) >= 64:
            self._decays.clear()
        self._decays[key] = db
        return db

    def spread(self, sP: np.ndarray, R: np.ndarray, tr: Any) -> np.ndarray:
        """The radius of the recovery (:func:`.observer.recover`) of ``z ∈ [ĉ ± R]`` about
        ``x_c = P ĉ``: ``|P| R`` plus the bound of the evaluation of ``x_c`` and ``|P| R`` and of
        ``(I - P T) x``, ``c_err s + c_resid ‖s‖∞``, ``s = |P| (|ĉ| + R)``, entry by entry as in
        the step (the box is ``[x_c ± rad]`` rounded outward). ``sP = |P| |ĉ|``."""
        Rp = R @ tr.absP.T
        s = sP + Rp
        f = 1.0 + 4.0 * gamma(4)
        rad: np.ndarray = (tr.c_err * f) * s
        rad += (tr.c_resid * f * abs_max(s) + tr.eta)[..., None]
        rad += Rp
        return rad

    def first_contradicted(
        self, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, y: np.ndarray, check: Any, d: Any
    ) -> np.ndarray:
        """Whether ``y[0]`` contradicts the first box (intersected with the prior, as in the
        loop): :meth:`contradicted` on its proven centre and radius."""
        xc, rad = mid_rad(lo[..., :1, :], hi[..., :1, :])
        d0 = (d[0], d[1]) if d[0].ndim == 1 else (d[0][:1], d[1][:1])
        return self.contradicted(xc, rad, u[..., :1, :], y[..., :1, :], check, d0)[..., 0]

    def contradicted(
        self,
        xc: np.ndarray,
        rad: np.ndarray,
        u: np.ndarray,
        y: np.ndarray,
        check: Any,
        d: tuple[np.ndarray, np.ndarray],
    ) -> np.ndarray:
        """``(..., T)``: the measurements certainly outside ``C [x̲, x̄] + D u + F [d̲, d̄]``,
        in centre/radius form: the box ``[x_c ± r]`` before its outward rounding is widened by
        ``2 u (|x_c| + r)`` to contain the rounded one; then ``|y - C x_c - D u - f_c| >
        |C| r + f_r + err`` (``err``: the bound of the evaluation, as in
        :class:`.terms.Consistency`) means certainly outside."""
        C, D = check.C, check.D
        nx, nu = C.shape[1], D.shape[1]
        flo, fhi = image_bounds(check.F, *d)
        fc, fr = mid_rad(flo, fhi)
        e = y - xc @ C.T
        if nu:
            e -= u @ D.T
        e -= fc
        np.abs(e, out=e)
        # below the band of the exact box's data-free part: certainly consistent
        if np.all(e <= (rad @ np.abs(C).T + fr) * (1.0 - 2.0 * gamma(nx + 3))):
            return np.zeros(e.shape[:-1], dtype=bool)
        r = rad + (2.0 * UNIT_ROUNDOFF) * (np.abs(xc) + rad) + 4 * ETA
        band = r @ np.abs(C).T
        band += fr
        mag = np.abs(xc) @ np.abs(C).T
        mag += np.abs(y)
        mag += np.abs(fc)
        if nu:
            mag += np.abs(u) @ np.abs(D).T
        band += factor(2 * nx + nu + 2, 2 * nx + nu + 3) * mag + (2 * (nx + nu) + 8) * ETA
        out: np.ndarray = np.any(e > np.nextafter(band, np.inf, out=band), axis=-1)
        return out
