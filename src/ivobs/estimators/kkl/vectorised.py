"""Observer (3) of [Dinh2024] over whole records and batches at once (discrete time,
time-invariant, every output measured, bounds of ``d`` known in advance): a different algorithm
from the step, with its own proof.

**Algorithm.** ``A_z`` being nonnegative, (3.a) is two linear recursions in centre/radius form:
``c+ = A_z c + B_z y + L u + g_c`` and ``r+ = A_z r + g_r + ε`` (``[g_c ± g_r]`` encloses the
bounds of ``G d``; ``ε = |L - L̂| |u| + |X| |x|``: the coefficient error and the residual of (4)
of :mod:`.terms`). The centre, driven by the data, and the data-free radius are evaluated by
:class:`~ivobs.estimators._recursion.LinearFilter` (blocks of steps, sums in any order).

**Proof, a posteriori.** Whatever order the filter summed in, its computed ``ĉ`` satisfies
``ĉ[k+1] = A_z ĉ[k] + b[k] + δ[k]`` with the *defect* ``δ[k]``, which is evaluated here over the
whole record (one product per term) with the bound of that evaluation ([Higham2002, Lemma
3.1]): ``|δ| <= |δ̂| + 2 γ_{n+2} (|ĉ[k+1]| + A_z |ĉ[k]| + |B_z| |y| + |L̂| |u| + |g_c|)``. The
exact centre then differs from ``ĉ[k]`` by ``Σ_j A_z^{k-1-j} δ[j]``; the radius likewise, and
the exact radius exceeds the data-free one by ``Σ_j A_z^{k-1-j} ε[j]``. With the proven decay
``‖A_zⁱ‖∞ <= c λⁱ`` (:class:`~ivobs.sets.rounding.DecayBound`) all of it is at most ``q[k]``,
``q[k+1] = λ q[k] + c η[k]``, ``η[k]`` the ∞-norm of the step's defects and ``ε`` (``ε`` needs
``|x[k]|``, itself bounded through ``q[k]``: ``η = a + b q``, so ``λ`` becomes ``λ + c b``):
``z[k] ∈ [ĉ[k] ± (r̂[k] + q[k])]``. A batch uses the largest ``η[k]`` over its streams. The box
is the recovery of :func:`.observer.recover` over the record, and the consistency test that of
:class:`.terms.Consistency`; a record with a measurement it flags goes to the loop (a batch:
those streams), which reports it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...sets import image_bounds
from ...sets.rounding import ETA, UNIT_ROUNDOFF, DecayBound, gamma, mid_rad, up, upper
from .._recursion import LinearFilter, abs_max, norm_inf, redo_streams
from .discrete import Discrete
from .observer import prior_box
from .terms import factor, g_image

__all__ = ["VectorisedLTI"]


class VectorisedLTI:
    """The vectorised run of a discrete-time time-invariant KKL design (module docstring)."""

    def __init__(self, observer: Discrete):
        self.ob = observer
        self._decay: DecayBound | None = None
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
            cf = LinearFilter(Az, [Bz, Lu], gc)
            chat = cf.run([y, u], x0=c0)[0]
        else:
            cf = LinearFilter(Az, [Bz, Lu, np.eye(Az.shape[0])])
            chat = cf.run([y, u, np.broadcast_to(gc, (*y.shape[:-1], gc.shape[-1]))], x0=c0)[0]
        rhat, rdef = self.radius(Tn, r0, gr, const)
        cabs = np.abs(chat)
        cP = abs_max(cabs @ tr.absP.T)  # ‖|P| |ĉ[k]|‖∞
        q = self.slack(chat, cabs, rhat, rdef, y, u, gc, c0, cP, tr, terms)
        del cabs
        if q is None:
            return None
        xc, rad = self.boxes(chat, cP, rhat, q, tr)
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

    def radius(
        self, Tn: int, r0: np.ndarray, gr: np.ndarray, const: bool
    ) -> tuple[np.ndarray, np.ndarray]:
        """``r̂[0..T-1]`` of ``r+ = A_z r + g_r`` and the bound of its defects (kept for the
        next record of the same length, constant bounds of ``d``)."""
        if const and self._radius is not None and self._radius[0] == Tn:
            return self._radius[1], self._radius[2]
        Az = self.ob.design.A_z
        nz = Az.shape[0]
        if const:
            rhat = LinearFilter(Az, [], gr).run([], T=Tn, x0=r0)[0]
        else:
            rhat = LinearFilter(Az, [np.eye(nz)]).run([gr], x0=r0)[0]
        nxt = rhat[1:]
        prev = rhat[:-1] @ Az.T
        g = gr if const else gr[:-1]
        dfct = np.abs(nxt - prev - g)
        dfct += factor(nz + 2, nz + 3) * (np.abs(nxt) + np.abs(prev) + np.abs(g)) + (nz + 8) * ETA
        rdef = np.max(dfct, axis=-1)  # ‖ρ̂[k]‖∞ + its evaluation error, k = 0..T-2
        rdef0 = float(np.max(np.abs(rhat[0] - r0)))
        rdef = np.concatenate(([rdef0], rdef))
        if const:
            self._radius = (Tn, rhat, rdef)
        return rhat, rdef

    def slack(
        self,
        chat: np.ndarray,
        cabs: np.ndarray,
        rhat: np.ndarray,
        rdef: np.ndarray,
        y: np.ndarray,
        u: np.ndarray,
        gc: np.ndarray,
        c0: np.ndarray,
        cP: np.ndarray,
        tr: Any,
        terms: Any,
    ) -> np.ndarray | None:
        """``q[0..T-1]`` (module docstring), or None when ``A_z``'s decay cannot be
        certified (then the loop). ``cabs = |ĉ|``, ``cP = ‖|P| |ĉ|‖∞`` per step."""
        ob = self.ob
        Az, Bz, Lu = ob.design.A_z, ob.design.B_z, terms.L
        nz, ny, nu = Az.shape[0], Bz.shape[1], Lu.shape[1]
        if self._decay is None:
            self._decay = DecayBound.of(Az)
        db = self._decay
        lead, Tn = chat.shape[:-2], chat.shape[-2]
        # δ[k] = ĉ[k+1] - A_z ĉ[k] - B_z y[k] - L̂ u[k] - g_c[k] over the record, and the bound
        # of its evaluation from the norms of its terms (and |L - L̂| |u|)
        g = gc[:-1] if gc.ndim == 2 else gc
        step = chat @ Az.T
        step += y @ Bz.T
        if nu:
            step += u @ Lu.T
        dfct = np.subtract(chat[..., 1:, :], step[..., :-1, :], out=step[..., :-1, :])
        dfct -= g
        eta = abs_max(np.abs(dfct, out=dfct))  # (..., T-1)
        del step, dfct
        c_abs = abs_max(cabs)
        mag = c_abs[..., 1:] + norm_inf(Az) * c_abs[..., :-1]
        mag += norm_inf(np.abs(Bz)) * abs_max(np.abs(y[..., :-1, :]))
        gmax = float(np.max(np.abs(gc)))
        fac = factor(nz + ny + nu + 2, nz + ny + nu + 3)
        ue = norm_inf(up(fac * np.abs(Lu) + terms.Lerr)) if nu else 0.0
        mag *= fac * (1.0 + 8.0 * gamma(8))
        eta += mag
        if nu:
            eta += ue * (1.0 + 4.0 * gamma(4)) * abs_max(np.abs(u[..., :-1, :]))
        eta += fac * gmax + (nz + ny + nu + 8) * ETA
        # |X| |x|: ‖x[k]‖∞ <= c_norm ‖|P| (|ĉ| + r̂ + q)‖∞ (recover); η = a + b q
        xr = float(upper(np.max(terms.xmag.sum(axis=1)), ob.sys.nx)) if terms.x_used else 0.0
        if xr:
            s = cP[..., :-1] + abs_max(rhat[:-1] @ tr.absP.T)
            eta += (xr * tr.c_norm) * s
        if lead:
            eta = eta.reshape(-1, eta.shape[-1]).max(axis=0)
        eta = upper(eta + rdef[1:], 8)
        b = xr * tr.c_norm * float(np.max(tr.absP.sum(axis=1))) * (1.0 + 1e-12)
        lam = float(up(db.lam + db.c * b))
        if not lam < 1.0:
            return None
        d0 = float(np.max(np.abs(chat[..., 0, :] - c0))) + float(rdef[0])
        q0 = float(up(db.c * up(d0 + ETA)))
        q = np.empty(Tn)
        q[0] = q0
        q[1:] = DecayBound(c=db.c, lam=lam).accumulate(eta, q0)
        return q

    def boxes(
        self, chat: np.ndarray, cP: np.ndarray, rhat: np.ndarray, q: np.ndarray, tr: Any
    ) -> tuple[np.ndarray, np.ndarray]:
        """The recovery (:func:`.observer.recover`) of ``z[k] ∈ [ĉ[k] ± (r̂[k] + q[k])]``
        over the record: ``x_c = P ĉ`` and the radius ``|P| (r̂ + q)`` plus the bound of their
        evaluation and of ``(I - P T) x``, ``(c_err + c_resid) ‖|P| (|ĉ| + r̂ + q)‖∞`` (the box
        is ``[x_c ± rad]`` rounded outward). ``cP = ‖|P| |ĉ|‖∞`` per step."""
        Rp = (rhat + q[:, None]) @ tr.absP.T  # (T, nx), shared by the streams of a batch
        xc = chat @ tr.P.T
        extra = up(tr.c_err + tr.c_resid) * (1.0 + 4.0 * gamma(4))
        rad = (extra * (cP + abs_max(Rp)) + tr.eta)[..., None] + Rp
        return xc, rad

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
