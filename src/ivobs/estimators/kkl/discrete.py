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
by the recovery margin ``ρ |T⁺| |z|``, ``ρ = 16 (n_z + n_x) ε cond(T)``; the one-product step of
:class:`ObserverZ` (and the vectorised run) add the rounding bound of that evaluation
(``ρ' = (ρ + γ̃_{5 n_z}) (1 + γ̃_{3 n_z + 4})``, derived in :meth:`ObserverZ._fused_step`).

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


class Fused(NamedTuple):
    """:meth:`ObserverZ._fused_step`'s matrix, the constant ``1`` of ``ξ``, ``n_z`` and where
    ``x_c``, ``x_r``, ``e`` and ``e_r`` are in ``W ξ``."""

    W: np.ndarray
    one: np.ndarray
    nz: int
    xc: slice
    xr: slice
    e: slice
    er: int


class ObserverZ(DiscreteLTI[ZState]):
    """Observer (3) of [Dinh2024]: the bounds of ``z = T x``."""

    def __init__(self, setting: Setting, m: ObserverMatrices):
        super().__init__(setting, m)
        self._fused = self._fuse()

    def _fuse(self) -> Fused | None:
        """The matrix ``W`` of :meth:`_fused_step` (constant bounds of ``d``; None otherwise,
        the general step): columns ``[z̲; z̄; y; u; a; 1]``, rows ``[z̲+; z̄+; x_c; x_r; e;
        e_r]``."""
        m, d = self.m, self._dfix
        if m.g_const is None or d is None:
            return None
        _, _, C, D, _, F = m.mats
        nz, ny, nu, nx = self.design.n_z, C.shape[0], D.shape[1], C.shape[1]
        Az, Bz = self.design.A_z, self.design.B_z
        h, ah = 0.5 * m.tr.P, 0.5 * m.tr.absP  # (halving is exact)
        M = m.margin  # ρ' |P|
        absC, glo, ghi = np.abs(C), *m.g_const
        Fdc, Fdr = F @ (0.5 * (d.lo + d.hi)), np.abs(F) @ (0.5 * (d.hi - d.lo))
        zz, zx, zy = np.zeros((nz, nz)), np.zeros((nx, ny + nu)), np.zeros((ny, ny + nu))
        W = np.block(
            [
                [Az, zz, Bz, m.Lu, zz, glo[:, None]],
                [zz, Az, Bz, m.Lu, zz, ghi[:, None]],
                [h, h, zx, np.zeros((nx, nz + 1))],
                [-ah, ah, zx, M, np.zeros((nx, 1))],
                [-C @ h, -C @ h, np.eye(ny), -D, np.zeros((ny, nz)), -Fdc[:, None]],
                [-absC @ ah, absC @ ah, zy, absC @ M, Fdr[:, None]],
            ]
        )
        i, j, e = 2 * nz, 2 * nz + nx, 2 * nz + 2 * nx
        return Fused(W, np.ones(1), nz, slice(i, j), slice(j, e), slice(e, e + ny), e + ny)

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
        bounds of ``d``, in one product; ``None`` (the general step) otherwise.

        With ``a = max(|z̲|, |z̄|)`` (exact; ``= |z_c| + z_r`` for ``z̲ <= z̄``) and ``ξ = [z̲;
        z̄; y; u; a; 1]``, ``W ξ`` gives (3.a) ``z̲+ = A_z z̲ + B_z y + L_u u + g̲`` and ``z̄+``,
        the recovery (3.c-d) ``x_c = (P/2) z̲ + (P/2) z̄``, ``x_r = (|P|/2) (z̄ - z̲) + ρ' |P|
        a``, and the consistency test's ``e = y - C x_c - D u - F d_c`` and ``e_r = |C| x_r +
        |F| d_r`` (``y`` is used when ``|e| <= e_r``). The box is ``[x_c - x_r, x_c + x_r]``.

        Rounding of the recovery ([Higham2002, Lemma 3.1]; products by zero coefficients and
        additions of exact zeros are exact, so a row of ``m`` nonzero coefficients errs by at
        most ``γ_m`` times the sum of its terms' magnitudes, in any order of summation, with
        or without FMA; ``(|z̲| + |z̄|)/2 <= a``): ``|x̂_c - x_c| <= γ_{2 n_z} |P| a`` and
        ``x̂_r >= |P| z_r + (1 - γ_{3 n_z}) ρ' |P| a - γ_{3 n_z} |P| a``. So the computed box
        holds ``P z_c ± (|P| z_r + ρ |P| a)``, the enclosure of :meth:`recover` with its
        margin ``ρ = rec cond(T)`` (which covers ``P`` being only a computed left inverse)
        intact, when ``ρ' = (ρ + γ̃_{5 n_z}) (1 + γ̃_{3 n_z + 4})`` (:func:`.fused_margin`;
        ``γ̃`` with unit ``ε = 2u`` also absorbs the rounding of ``ρ'`` and of ``ρ' |P|``).
        The rounding of ``x_c ± x_r`` and of the ``z`` recursion is covered by the base
        margin, as in the general step. The test's rows only decide between this step and the
        general one (which tests with its own tolerance), not the bounds."""
        W, one, nz, sc, sr, se, er = self._fused  # type: ignore[misc]
        zlo, zhi = state.zlo, state.zhi
        a = np.abs(zlo)
        np.maximum(a, np.abs(zhi), out=a)
        out = W.dot(np.concatenate((zlo, zhi, y_k, u_k, a, one)))
        v = out.tolist()
        for e, r in zip(v[se], v[er:]):
            if not abs(e) <= r:  # maybe inconsistent (or NaN): the general step decides
                return None
        lo, hi = [], []  # (a loop: cheaper than comprehensions on three numbers)
        for c, r in zip(v[sc], v[sr]):
            lo.append(c - r)
            hi.append(c + r)
        return Step(evolve(state, zlo=out[:nz], zhi=out[nz : 2 * nz]), lo, hi, False)

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
