"""Discrete-time KKL observers of [Dinh2024]: the recursion (3.a)/(15.a), written once.

Time-invariant systems ([Dinh2024, Section 2]). ``T`` solves ``T A = A_z T + B_z C`` (eq. 4), so
``z = T x`` obeys, with the feedthrough and the shared disturbance of the ivobs model,

    z[k+1] = A_z z[k] + B_z y[k] + (T B - B_z D) u[k] + (T E - B_z F) d[k]          (eq. 5)

and, ``A_z`` being nonnegative, observer (3.a) ``z̄+ = A_z z̄ + B_z y + (TB - B_zD) u + ḡ``
(``ḡ``, ``g̲`` the Lemma-1 bounds of ``(T E - B_z F) d``; one matrix for the correlated ``d``)
keeps ``z̲ <= T x <= z̄``; (3.c-d) give ``x = T⁻¹ z`` (:class:`ObserverZ`). Option
``coordinates="x"`` runs the same observer written in ``x`` (eq. 6, with ``L = T⁻¹ B_z``;
:class:`ObserverX`).

Time-varying systems ([Dinh2024, Section 3.2]; :class:`DiscreteLTV`). ``T[k+1] = (A_z T[k] +
B_z C[k]) A[k]⁻¹`` (eq. 15.b, needs invertible ``A[k]``), ``A_z = gamma Ã``, ``B_z = B̃``
block-diagonal with one block per output of size the observability index ``m_i`` (eq. 16.a),
``n_z = Σ m_i``; the bounds (15.a) with ``T[k+1]`` in place of ``T``, and ``x`` recovered by the
pseudo-inverse (15.d) once ``T[k]`` is left-invertible. ``T[k]`` does not depend on the data, so
``valid_from`` is decided offline: the first ``k`` with ``cond(N T[k]) = σ_max/σ_min <=
max_cond`` (default 1e7), ``N`` the positive diagonal scaling that gives ``T[k]`` unit rows (the
recovery uses ``x = (N T)⁺ N z``, the same box; rows that merely decayed do not count as
ill-conditioning). A later ``T[k]`` failing the threshold gets the previous box propagated
through the model. The default ``T0 = 0`` makes ``z[0] = 0`` exactly: no prior on ``x[0]`` is
needed ([Dinh2024, Example 3]: ``valid_from = 2``). ``T0="sylvester"`` (the frozen-time solution
of (4)) uses ``x0`` by (15.c).

What is guaranteed: exact (the recursions are linear); rounding is covered by the base margin and
by the recovery margin ``16 (n_z + n_x) ε cond(T) |T⁺| |z|``.

Data used: the box at ``k`` comes from ``z[k]``, which uses ``y[0..k-1]`` (prediction form, as in
the paper); ``y[k]`` is used for the step to ``k+1`` and is checked against the box at ``k`` (an
inconsistent measurement is reported and not used).

Missing samples. The unknown ``B_m y_m = B_m (C_m x + D_m u + F_m d)`` is bounded with ``x[k] =
T[k]⁺ z[k]``: ``z+ ∈ (A_z + B_m C_m T⁺)[z̲, z̄] + ...`` by Lemma 1 (exact identity, ``T`` stays on
its data-independent sequence); before ``T[k]`` is left-invertible (time-varying) ``C_m x`` is
bounded on the open-loop box propagated from ``x0`` (needs ``x0``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, NamedTuple, TypeVar

import numpy as np

from ...errors import IvobsError
from ...sets import Box
from ..state import OnlineState, Step, evolve
from .design import ObserverMatrices, Transform, TransformSequence, every, finite, image
from .observer import Observer, Setting, ZState

__all__ = ["DiscreteLTV", "DiscreteLTVState", "ObserverX", "ObserverZ", "XHatState"]


@dataclass(frozen=True)
class XHatState(OnlineState):
    """Observer (6): ``T⁻¹ z̲`` and ``T⁻¹ z̄`` (``xh_lo``, ``xh_hi``). ``T⁻¹`` has entries of both
    signs, so the two are not ordered (``xh_lo > xh_hi`` in a component is normal): no
    ``lower <= upper`` check on restore."""

    xh_lo: np.ndarray
    xh_hi: np.ndarray

    bounds: ClassVar[tuple[tuple[str, str], ...]] = ()


@dataclass(frozen=True)
class DiscreteLTVState(ZState):
    """Observer (15): ``z̲ <= T[k] x[k] <= z̄`` and the open-loop box ``[xlo, xhi]`` of ``x[k]``
    propagated through the model (used while ``T[k]`` is not left-invertible)."""

    xlo: np.ndarray
    xhi: np.ndarray

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("zlo", "zhi"), ("xlo", "xhi"))


S = TypeVar("S", bound=OnlineState)


class StepData(NamedTuple):
    """What one step of (3.a)/(15.a) has computed before the update of ``z``."""

    k: int
    u: np.ndarray
    y: np.ndarray
    d: Box
    obs: np.ndarray  # the components of y[k] used
    lo: np.ndarray  # the box of x[k]
    hi: np.ndarray
    zlo: np.ndarray
    zhi: np.ndarray
    tk: Transform  # T[k]
    tn: Transform  # T[k+1]
    mats: tuple[np.ndarray, ...]  # (A, B, C, D, E, F) at k


class DiscreteObserver(Observer[S]):
    """The step of (3)/(15): the box of ``x[k]`` from ``z[k]``, the consistency of ``y[k]``,
    then ``z[k+1]``. Subclasses say where ``T[k]`` and the matrices come from and how ``z`` is
    stored and updated."""

    def matrices(self, k: int) -> tuple[np.ndarray, ...]:
        raise NotImplementedError

    def transform(self, k: int) -> Transform:
        raise NotImplementedError

    def z_bounds(self, state: S) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError

    def advance(self, state: S, s: StepData) -> S:
        raise NotImplementedError

    def box(
        self, state: S, k: int, tk: Transform, zlo: np.ndarray, zhi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The box of ``x[k]`` (3.c-d)/(15.d)."""
        return self.recover(tk, zlo, zhi)

    def step(self, state: S, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> Step[S]:
        k = state.k
        mats = self.matrices(k)
        tk, tn = self.transform(k), self.transform(k + 1)
        zlo, zhi = self.z_bounds(state)
        lo, hi = self.box(state, k, tk, zlo, zhi)
        if k == 0:
            lo, hi = self.first_box(lo, hi)
        d = self.bounds_d(k, y_k)
        obs, bad = self.usable(y_k, lo, hi, (mats[2], mats[3], mats[5]), u_k, d)
        s = StepData(k, u_k, y_k, d, obs, lo, hi, zlo, zhi, tk, tn, mats)
        return Step(self.advance(state, s), lo, hi, bad)

    def update_z(self, s: StepData) -> tuple[np.ndarray, np.ndarray]:
        """(3.a)/(15.a) with the observed outputs; missing ones bounded through ``x[k]``."""
        _, B, C, D, E, F = s.mats
        Az, Bz, obs = self.design.A_z, self.design.B_z, s.obs
        Bo, Bm = Bz[:, obs], Bz[:, ~obs]
        v = Bo @ s.y[obs] + (s.tn.T @ B - Bo @ D[obs]) @ s.u
        glo, ghi = image(s.tn.T @ E - Bo @ F[obs], s.d.lo, s.d.hi)
        if every(obs):
            mlo, mhi = Az @ s.zlo, Az @ s.zhi
        elif s.tk.ok:  # x[k] = T[k]⁺ z[k] exactly: B_m C_m x = B_m C_m T⁺ z
            mlo, mhi = image(Az + Bm @ C[~obs] @ s.tk.P, s.zlo, s.zhi)
        else:
            if not (finite(s.lo) and finite(s.hi)):
                raise IvobsError(
                    f"y: measurement missing at step {s.k}, before T[k] is left-invertible, and "
                    "no prior box on x[0]: pass x0 to predict through missing samples there"
                )
            clo, chi = image(Bm @ C[~obs], s.lo, s.hi)
            mlo, mhi = Az @ s.zlo + clo, Az @ s.zhi + chi
        return mlo + v + glo, mhi + v + ghi


class DiscreteLTI(DiscreteObserver[S]):
    """Time-invariant: one ``T`` and the constant matrices of :class:`ObserverMatrices`."""

    def __init__(self, setting: Setting, m: ObserverMatrices):
        super().__init__(setting)
        self.m = m

    def matrices(self, k: int) -> tuple[np.ndarray, ...]:
        return self.m.mats

    def transform(self, k: int) -> Transform:
        return self.m.tr

    def known(self, s: StepData) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """With every output observed: ``B_z y + L_u u`` and the bounds ``g̲, ḡ`` of ``G d``."""
        m = self.m
        v = self.design.B_z @ s.y + m.Lu @ s.u
        glo, ghi = m.g_const if m.g_const is not None else image(m.G, s.d.lo, s.d.hi)
        return v, glo, ghi


class ObserverZ(DiscreteLTI[ZState]):
    """Observer (3) of [Dinh2024]: the bounds of ``z = T x``."""

    def __init__(self, setting: Setting, m: ObserverMatrices):
        super().__init__(setting, m)
        self._fused = self._fuse()
        tr = m.tr  # recover()'s constants: P, |P| and the margin factor rec cond(T)
        self._recovery = (tr.P, tr.absP, self.rec * tr.cond)

    def _fuse(self) -> tuple[np.ndarray, ...] | None:
        """The step of a complete ``y`` with constant bounds as one product: ``W [z̲; z̄; y;
        u] + w = [z̲+; z̄+; D u + F d_c; z_c; z_r]`` ((3.a) and what (3.c-d) and the consistency
        test need); None otherwise (the general step)."""
        m, d = self.m, self._dfix
        if m.g_const is None or d is None:
            return None
        _, _, C, D, _, F = m.mats
        nz, ny, nu = self.design.n_z, C.shape[0], D.shape[1]
        Az, Bz, I2 = self.design.A_z, self.design.B_z, 0.5 * np.eye(nz)
        Zz, Zy, Zu = np.zeros((nz, nz)), np.zeros((nz, ny)), np.zeros((nz, nu))
        W = np.block(
            [
                [Az, Zz, Bz, m.Lu],
                [Zz, Az, Bz, m.Lu],
                [np.zeros((ny, 2 * nz + ny)), D],
                [I2, I2, Zy, Zu],
                [-I2, I2, Zy, Zu],
            ]
        )
        glo, ghi = m.g_const
        Fdc = F @ (0.5 * (d.lo + d.hi))
        w = np.concatenate([glo, ghi, Fdc, np.zeros(2 * nz)])
        Fdr = np.abs(F) @ (0.5 * (d.hi - d.lo))
        return W, w, Fdr.tolist(), C, np.abs(C)  # |F| d_r as floats: tested in floats

    def step(
        self, state: ZState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[ZState]:
        if self._fused is not None and state.k > 0:
            fast = self._fused_step(state, u_k, y_k)
            if fast is not None:
                return fast
        return super().step(state, u_k, y_k, t_k)

    def _fused_step(self, state: ZState, u_k: np.ndarray, y_k: np.ndarray) -> Step[ZState] | None:
        """:meth:`step` for ``k >= 1``, a complete ``y[k]`` inside its bounds and constant
        bounds (:meth:`_fuse`): (3.c-d) as :meth:`recover`, the consistency test, (3.a), in a
        few products; ``None`` (the general step) otherwise."""
        W, w, Fdr, C, absC = self._fused  # type: ignore[misc]
        nz, ny = state.zlo.shape[0], y_k.shape[0]
        out = W.dot(np.concatenate((state.zlo, state.zhi, y_k, u_k)))
        out += w
        zc, zr = out[2 * nz + ny : 3 * nz + ny], out[3 * nz + ny :]
        P, absP, rc = self._recovery
        a = np.abs(zc)  # (3.c-d) with the recovery margin, as recover()
        a += zr
        xr = absP.dot(zr)
        xr += rc * absP.dot(a)
        xc = P.dot(zc)
        # |y - C x_c - D u - F d_c| - (|C| x_r + |F| d_r), in floats (the same operations)
        dev = zip(y_k.tolist(), C.dot(xc).tolist(), out.tolist()[2 * nz : 2 * nz + ny])
        for (yv, cx, du), ax, f in zip(dev, absC.dot(xr).tolist(), Fdr):
            if not abs(yv - cx - du) - ax - f <= 0.0:  # maybe inconsistent (or NaN): the
                return None  # general step decides
        new = evolve(state, zlo=out[:nz], zhi=out[nz : 2 * nz])
        lo, hi = [], []  # (a loop: cheaper than comprehensions on three numbers)
        for c, r in zip(xc.tolist(), xr.tolist()):
            lo.append(c - r)
            hi.append(c + r)
        return Step(new, lo, hi, False)

    def initial_state(self) -> ZState:
        zlo, zhi = self.initial_z()  # (3.b)
        return ZState(zlo=zlo, zhi=zhi)

    def z_bounds(self, state: ZState) -> tuple[np.ndarray, np.ndarray]:
        return state.zlo, state.zhi

    def advance(self, state: ZState, s: StepData) -> ZState:
        if every(s.obs):
            v, glo, ghi = self.known(s)
            Az = self.design.A_z
            nlo, nhi = Az @ s.zlo + v + glo, Az @ s.zhi + v + ghi  # (3.a)
        else:
            nlo, nhi = self.update_z(s)
        return ZState(
            zlo=nlo, zhi=nhi, k=state.k, scale=state.scale, inconsistent=state.inconsistent
        )


class ObserverX(DiscreteLTI[XHatState]):
    """Observer (6) of [Dinh2024]: the same bounds written in ``x̂ = T⁻¹ z``, with
    ``x̂+ = (A - L C) x̂ + T⁻¹ (B_z y + L_u u + g)``, ``L = T⁻¹ B_z``."""

    def initial_state(self) -> XHatState:
        zlo, zhi = self.initial_z()
        P = self.m.tr.P
        return XHatState(xh_lo=P @ zlo, xh_hi=P @ zhi)  # (6.b-c)

    def z_bounds(self, state: XHatState) -> tuple[np.ndarray, np.ndarray]:
        T = self.design.T
        return T @ state.xh_lo, T @ state.xh_hi  # (6.d-e)

    def advance(self, state: XHatState, s: StepData) -> XHatState:
        P = self.m.tr.P
        if every(s.obs):
            v, glo, ghi = self.known(s)
            Mx = self.m.Mx
            assert Mx is not None
            xh_lo = Mx @ state.xh_lo + P @ (v + glo)  # (6.a)
            xh_hi = Mx @ state.xh_hi + P @ (v + ghi)
        else:
            nlo, nhi = self.update_z(s)
            xh_lo, xh_hi = P @ nlo, P @ nhi
        return XHatState(
            xh_lo=xh_lo, xh_hi=xh_hi, k=state.k, scale=state.scale, inconsistent=state.inconsistent
        )


class DiscreteLTV(DiscreteObserver[DiscreteLTVState]):
    """Observer (15) of [Dinh2024] on the data-free sequence ``T[k]`` of (15.b)."""

    def __init__(self, setting: Setting, seq: TransformSequence):
        super().__init__(setting)
        self.seq = seq

    def initial_state(self) -> DiscreteLTVState:
        zlo, zhi = self.initial_z()  # (15.c); z[0] = 0 exactly for T0 = 0
        xlo, xhi = self.initial_x()
        return DiscreteLTVState(zlo=zlo, zhi=zhi, xlo=xlo, xhi=xhi)

    def matrices(self, k: int) -> tuple[np.ndarray, ...]:
        return self.sys.matrices_at(k)

    def transform(self, k: int) -> Transform:
        return self.seq.at(k)

    def z_bounds(self, state: DiscreteLTVState) -> tuple[np.ndarray, np.ndarray]:
        return state.zlo, state.zhi

    def box(
        self, state: DiscreteLTVState, k: int, tk: Transform, zlo: np.ndarray, zhi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(15.d), or the open-loop box while ``T[k]`` is not left-invertible."""
        if tk.ok:
            return self.recover(tk, zlo, zhi)
        lo, hi = state.xlo.copy(), state.xhi.copy()
        if k >= self.design.k_star and not (finite(lo) and finite(hi)):
            raise IvobsError(
                f"kkl: T[{k}] is not left-invertible (cond {tk.cond:.2e}) and no finite "
                "prior is available; pass x0 so the observer can bridge such steps"
            )
        return lo, hi

    def advance(self, state: DiscreteLTVState, s: StepData) -> DiscreteLTVState:
        nlo, nhi = self.update_z(s)
        # the open-loop box, for steps where T[k+1] is not left-invertible
        A, B, _, _, E, _ = s.mats
        alo, ahi = image(A, s.lo, s.hi)
        elo, ehi = image(E, s.d.lo, s.d.hi)
        Bu = B @ s.u
        return DiscreteLTVState(
            zlo=nlo,
            zhi=nhi,
            xlo=alo + Bu + elo,
            xhi=ahi + Bu + ehi,
            k=state.k,
            scale=state.scale,
            inconsistent=state.inconsistent,
        )
