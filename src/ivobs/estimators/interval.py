"""Interval observers built on cooperative (monotone) error dynamics: one family, three members.

Papers: Tang, Wang, Wang, Raïssi, Shen, *Interval estimation methods for discrete-time LTI
systems*, IEEE TAC 2019 (``seeds/002_b3ef…``), Section V, Theorems 4–5, eqs. (36)–(48);
Efimov, Perruquetti, Raïssi, Zolghadri, *On interval observer design for time-invariant
discrete-time systems* (``seeds/003_f19a…``), Theorems 1–3, eqs. (3)–(8), Remark 1.

ivobs' model ``x+ = A x + B u + E d``, ``y = C x + D_u u + F d`` (one disturbance ``d`` in both
equations; ``D_u`` is the feedthrough) gives, for any gain ``L``,

    x+ = (A − LC) x + (B − L D_u) u + L y + (E − LF) d                          (*)

so with ``G = E − LF`` the Lemma-1 bounds ``G⁺ d_lo − G⁻ d_hi <= G d <= G⁺ d_hi − G⁻ d_lo``
play the role of 002's ``d̲, d̄`` (eq. 37: for ``d = [w; v]``, ``E = [E 0]``, ``F = [0 F]`` they
are exactly ``E⁺w̄ − E⁻w̲ + (−LF)⁺v̄ − (−LF)⁻v̲``) and of 003's ``b̲ − LV``, ``b̄ + LV``.

* ``interval`` — 002 eq. (36) = 003 eq. (3): ``A − LC`` nonnegative and Schur (Theorem 4 /
  Theorem 1);
* ``interval-transformed`` — 002 Theorem 5 (eqs. 42–43) = 003 Theorem 2: observer (36) for
  ``z = S x`` with ``R = S (A − LC) S⁻¹ >= 0``, bounds mapped back by Lemma 1;
* ``interval-split`` — 003 Theorem 3, eq. (5): same coordinates, ``D = A − LC = D⁺ − D⁻`` of any
  sign, stable iff ``|D| = D⁺ + D⁻`` is Schur.

All three propagate one recursion, the split form of (*) in coordinates ``z = S x``
(``S = I`` except for ``interval-transformed``), with ``Q = S (A − LC) S⁻¹``::

    z̄+ = Q⁺ z̄ − Q⁻ z̲ + S(B − L D_u) u + S L y + (SG)⁺ d_hi − (SG)⁻ d_lo
    z̲+ = Q⁺ z̲ − Q⁻ z̄ + S(B − L D_u) u + S L y + (SG)⁺ d_lo − (SG)⁻ d_hi

Soundness: multiply (*) by ``S``; Lemma 1 bounds ``Q z`` over ``[z̲, z̄]`` and ``SG d`` over the
``d`` box, so ``z̲ <= z <= z̄`` carries over by induction from ``z̲_0 <= S x_0 <= z̄_0`` (Lemma 1
on ``x0``). When ``Q >= 0`` (``Q⁻ = 0``) this *is* 002's (36)/(42) and 003's (3)/(4); for
``interval-split`` it is 003's (5). The midpoint obeys ``c+ = Q c + …`` and the radius
``r+ = |Q| r + radius(SG d)`` (``|Q| = Q⁺ + Q⁻``): bounded iff ``|Q|`` is Schur. (The stacked
bounds follow ``[[Q⁺, −Q⁻], [−Q⁻, Q⁺]]``, not 003's error matrix Σ; both are Schur iff
``|Q|`` is.) The vectorised path runs exactly these two linear recursions.

**Missing samples** (NaN in ``y[k]``): the gain's columns of the missing components are set to
zero for that step, ``L_k = L diag(observed)``; (*) holds for *any* gain, so the same Lemma-1
step with ``Q_k = S(A − L_k C)S⁻¹`` (which may have negative entries even when ``Q`` has none:
the split form covers it) stays sound; with every component missing it is the model's prediction
``x+ ∈ A[x̲, x̄] + B u + E[d]``. **Inconsistent data**: when ``y[k]`` lies outside
``C[x̲_k, x̄_k] + D_u u_k + F[d]`` no state in the box explains it (a fault); it is reported and
treated as missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._validate import as_matrix, as_vector
from ..design.cooperative import (
    abs_schur_gain,
    check_abs_schur,
    check_nonnegative_schur,
    fixed_radius,
    nonnegative_gain,
    refine_width,
    spectral_radius,
    steady_width,
)
from ..design.similarity import (
    check_transform,
    default_design,
    default_e1,
    nonnegative_realization,
    place_real_poles,
    similarity_transform,
    transformed_width,
)
from ..errors import DesignError, IvobsError
from ..model import LinearSystem
from ..sets import Box, image_bounds, neg, pos
from . import register
from .base import Design, Estimator

__all__ = [
    "IntervalDesign",
    "IntervalObserver",
    "SplitDesign",
    "SplitIntervalObserver",
    "TransformedDesign",
    "TransformedIntervalObserver",
]

CONSISTENCY_TOL = 1e-9
"""Relative slack of the consistency test ``y[k] ∈ C[x̲, x̄] + D_u u + F[d]`` (round-off)."""


@dataclass(frozen=True)
class IntervalDesign(Design):
    """``L``: gain; ``D = A − LC`` (003's notation; nonnegative); ``spectral_radius`` of ``D``;
    ``gain``: how ``L`` was obtained (``'lmi'``, ``'lmi+width'``, ``'given'``);
    ``steady_width``: ``(I − D)⁻¹ |E − LF| Δ``, the limit of the bounds' width for constant
    bounds (None for callable bounds)."""

    L: np.ndarray
    D: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None


@dataclass(frozen=True)
class SplitDesign(Design):
    """``L``: gain; ``D = A − LC`` (any sign); ``spectral_radius`` of ``|D| = D⁺ + D⁻``;
    ``gain``: ``'width'``, ``'margin'``, ``'lmi'`` or ``'given'``; ``steady_width``:
    ``(I − |D|)⁻¹ |E − LF| Δ`` (None for callable bounds)."""

    L: np.ndarray
    D: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None


@dataclass(frozen=True)
class TransformedDesign(Design):
    """``L``: gain (``A − LC`` Schur); ``poles``: eigenvalues of ``A − LC``; ``S``: the
    transformation ``z = S x``; ``R = S (A − LC) S⁻¹`` (nonnegative up to round-off; this is the
    matrix the observer propagates); ``e1``, ``e2``: the rows of eq. (48) (None when ``S`` was
    given); ``spectral_radius`` of ``|R|``; ``gain``: ``'search'`` (ivobs' default design),
    ``'given-poles'`` or ``'given'``; ``steady_width``: ``|S⁻¹|(I − |R|)⁻¹|S(E − LF)| Δ``."""

    L: np.ndarray
    R: np.ndarray
    S: np.ndarray
    e1: np.ndarray | None
    e2: np.ndarray | None
    poles: np.ndarray
    spectral_radius: float
    gain: str
    steady_width: np.ndarray | None


@dataclass(frozen=True)
class _StepMatrices:
    """What one step needs for a given set of observed components."""

    Qp: np.ndarray  # Q⁺
    Qn: np.ndarray  # Q⁻
    Bz: np.ndarray  # S (B − L_k D_u)
    Lz: np.ndarray  # S L_k
    Gz: np.ndarray  # S (E − L_k F)
    Gp: np.ndarray  # (S (E − L_k F))⁺
    Gn: np.ndarray  # (S (E − L_k F))⁻


def _hull(
    Mp: np.ndarray, Mn: np.ndarray, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Lemma 1 with precomputed ``M⁺``, ``M⁻`` (finite bounds)."""
    return Mp @ lo - Mn @ hi, Mp @ hi - Mn @ lo


def design_delta(sys: LinearSystem) -> np.ndarray:
    """Widths ``Δ`` of the ``d`` box used by the width objectives: constant bounds as they
    are, time-varying bounds their largest width per component, callable bounds (003 Remark 1)
    ones (no better information before the data arrive)."""
    box = sys.d
    if box is None:
        return np.zeros(0)
    if isinstance(box, Box):
        w = box.hi - box.lo
        return w.max(axis=0) if box.is_time_varying else w
    return np.ones(sys.nd)


def _time_recursion(M: np.ndarray, v: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """``x[0] = x0``, ``x[k+1] = M x[k] + v[k]`` along axis 0 of ``v`` (``(T, n)`` or time-major
    ``(T, B, n)``); returns ``(T + 1, …)``.

    A batch runs a loop over time on contiguous ``(B, n)`` slices. One long record is cut into
    ``nb`` blocks of ``K ≈ √T`` steps: the zero-state responses inside all blocks advance together
    (``K`` vectorised steps), the block starts follow ``s_{b+1} = M^K s_b + z_b`` (``nb`` small
    steps), then ``x[bK + j] = M^j s_b + z_b[j]``: about three passes over the data instead of
    ``log2 T`` (the doubling scan of :func:`ivobs._recursion.affine_recursion`); same values up
    to round-off (sums in another order)."""
    T = v.shape[0]
    out = np.empty((T + 1, *v.shape[1:]))
    out[0] = x0
    MT = M.T
    if v.ndim == 3 or T < 64:
        for k in range(T):
            out[k + 1] = out[k] @ MT + v[k]
        return out
    n = v.shape[1]
    K = int(np.sqrt(T))
    nb = -(-T // K)
    vp = np.zeros((nb * K, n))
    vp[:T] = v
    vp = vp.reshape(nb, K, n)
    Z = np.empty((K + 1, nb, n))  # Z[j, b] = Σ_{i<j} M^(j-1-i) v[bK + i]
    Z[0] = 0.0
    for j in range(K):
        Z[j + 1] = Z[j] @ MT + vp[:, j]
    MK_T = np.linalg.matrix_power(M, K).T
    S = np.empty((nb + 1, n))  # block starts x[bK]
    S[0] = x0
    for b in range(nb):
        S[b + 1] = S[b] @ MK_T + Z[K, b]
    P = np.empty((K, n, n))  # P[j] = (M^j)ᵀ
    P[0] = np.eye(n)
    for j in range(1, K):
        P[j] = P[j - 1] @ MT
    X = S[None, :nb] @ P + Z[:K]  # (K, nb, n): X[j, b] = x[bK + j]
    X = X.transpose(1, 0, 2).reshape(nb * K, n)
    out[1:] = np.concatenate([X[1:], S[nb:]])[:T]
    return out


class _CooperativeObserver(Estimator):
    """Shared machinery (module docstring): the split-form recursion in ``z = S x``."""

    needs_x0: ClassVar[bool] = True
    _S: np.ndarray | None = None
    _Si: np.ndarray | None = None

    def _setup(self, L: np.ndarray, S: np.ndarray | None = None) -> None:
        A, B, C, Du, E, F = self.sys.matrices_at(0)
        self._A, self._B, self._C, self._Du, self._E, self._F = A, B, C, Du, E, F
        self._L = L
        self._S = S
        self._Si = None if S is None else np.linalg.inv(S)
        self._Si_pm = None if S is None else (pos(self._Si), neg(self._Si))
        self._C_pm = (pos(C), neg(C))
        self._F_pm = (pos(F), neg(F))
        self._cache: dict[bytes, _StepMatrices] = {}
        self.valid_from = 0

    def _matrices(self, observed: np.ndarray) -> _StepMatrices:
        key = observed.tobytes()
        if key not in self._cache:
            Lk = self._L * observed[None, :]
            Q = self._A - Lk @ self._C
            Bz = self._B - Lk @ self._Du
            Gz = self._E - Lk @ self._F
            if self._S is not None:
                Q = self._S @ Q @ self._Si
                Bz, Lk, Gz = self._S @ Bz, self._S @ Lk, self._S @ Gz
            self._cache[key] = _StepMatrices(pos(Q), neg(Q), Bz, Lk, Gz, pos(Gz), neg(Gz))
        return self._cache[key]

    def _initial_state(self) -> dict[str, Any]:
        assert self.x0 is not None
        lo, hi = self.x0.lo.copy(), self.x0.hi.copy()
        if self._S is not None:
            lo, hi = image_bounds(self._S, lo, hi)  # 002 (42a-b)
        return {"lo": lo, "hi": hi}

    def _to_x(self, k: int, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self._Si is None:
            return lo, hi
        if k == 0:  # 002 (42): the prior box itself at k = 0
            assert self.x0 is not None
            return self.x0.lo.copy(), self.x0.hi.copy()
        assert self._Si_pm is not None
        return _hull(*self._Si_pm, lo, hi)  # 002 (42e-f)

    def _consistent(
        self,
        lo: np.ndarray,
        hi: np.ndarray,
        u: np.ndarray,
        y: np.ndarray,
        obs: np.ndarray,
        dbox: Box,
    ) -> bool:
        """``y`` (observed components) ∈ ``C[lo, hi] + D_u u + F[d]`` up to round-off."""
        plo, phi = _hull(*self._C_pm, lo, hi)
        flo, fhi = _hull(*self._F_pm, dbox.lo, dbox.hi)
        du = self._Du @ u
        plo, phi = plo + du + flo, phi + du + fhi
        tol = CONSISTENCY_TOL * (1.0 + np.abs(y) + (phi - plo))  # NaN (missing) compares False
        bad = ((y < plo - tol) | (y > phi + tol)) & obs
        return not bool(np.any(bad))

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        zlo, zhi = state["lo"], state["hi"]
        xlo, xhi = self._to_x(k, zlo, zhi)
        obs = ~np.isnan(y_k)
        dbox = self.sys.d_at(k, y_k)
        if obs.any() and not self._consistent(xlo, xhi, u_k, y_k, obs, dbox):
            state["_inconsistent"] = True
            obs = np.zeros_like(obs)
        m = self._matrices(obs)
        known = m.Bz @ u_k + m.Lz @ np.where(obs, y_k, 0.0)
        glo, ghi = _hull(m.Gp, m.Gn, dbox.lo, dbox.hi)
        state["hi"] = m.Qp @ zhi - m.Qn @ zlo + known + ghi
        state["lo"] = m.Qp @ zlo - m.Qn @ zhi + known + glo
        return xlo, xhi

    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Midpoint and radius recursions (module docstring), time-major; ``None`` (loop) for
        callable bounds, missing samples, time-varying bounds shorter than the record, or an
        inconsistent measurement (the loop reports it and predicts without it)."""
        box = self.sys.d
        T = y.shape[-2]
        if box is not None and not isinstance(box, Box):
            return None
        if box is not None and box.is_time_varying and box.lo.shape[0] < T:
            return None
        if np.isnan(y).any():
            return None
        n, ny = self.sys.nx, self.sys.ny
        m = self._matrices(np.ones(ny, dtype=bool))
        if box is None:
            glo = ghi = np.zeros(n)
            flo = fhi = np.zeros(ny)
        else:
            dlo, dhi = (box.lo[:T], box.hi[:T]) if box.is_time_varying else (box.lo, box.hi)
            glo, ghi = image_bounds(m.Gz, dlo, dhi)
            flo, fhi = image_bounds(self._F, dlo, dhi)
        gc, gr = 0.5 * (glo + ghi), 0.5 * (ghi - glo)
        fc, fr = 0.5 * (flo + fhi), 0.5 * (fhi - flo)
        batched = y.ndim == 3
        # time-major views: the recursions then run over contiguous (B, n) slices
        yt = y.transpose(1, 0, 2) if batched else y

        def per_step(a: np.ndarray) -> np.ndarray:  # (T, k) bounds against (T, B, k) data
            return a[:, None, :] if (batched and a.ndim == 2) else a

        def times(sig: np.ndarray, M: np.ndarray, steps: int) -> np.ndarray | float:
            """``sig[:steps] @ Mᵀ`` time-major, once for a batch sharing its input (stride 0)."""
            if not M.size or not np.any(M):
                return 0.0
            if batched and sig.strides[0] == 0:
                return (sig[0, :steps] @ M.T)[:, None, :]
            return (sig.transpose(1, 0, 2) if batched else sig)[:steps] @ M.T

        v = yt[: T - 1] @ m.Lz.T
        v += times(u, m.Bz, T - 1) + per_step(gc[: T - 1] if gc.ndim == 2 else gc)
        z0 = self._initial_state()
        c = _time_recursion(m.Qp - m.Qn, v, 0.5 * (z0["lo"] + z0["hi"]))
        del v
        rin = np.broadcast_to(gr[: T - 1] if gr.ndim == 2 else gr, (T - 1, n))
        r = _time_recursion(m.Qp + m.Qn, rin, 0.5 * (z0["hi"] - z0["lo"]))
        if self._Si is not None:
            assert self.x0 is not None
            c = c @ self._Si.T
            r = r @ np.abs(self._Si).T
            c[0] = self.x0.center
            r[0] = self.x0.radius
        # consistency of every measurement with the box it was used with (see _consistent;
        # in a batch the round-off slack uses the largest |y| of the whole batch)
        res = c @ self._C.T
        res -= yt
        res += times(u, self._Du, T) + per_step(fc)
        np.abs(res, out=res)
        pr = r @ np.abs(self._C).T + fr
        ymax = max(float(np.max(y)), -float(np.min(y))) if batched else np.abs(yt)
        slack = pr + CONSISTENCY_TOL * (1.0 + ymax + 2.0 * pr)
        if np.any(res > per_step(slack)):
            return None
        del res
        r_t = per_step(r)
        lo = c - r_t
        hi = c  # c is no longer needed: reuse its memory
        hi += r_t
        if batched:
            return lo.transpose(1, 0, 2), hi.transpose(1, 0, 2)
        return lo, hi

    # -- shared design helpers ------------------------------------------------------------
    def _check_gain(self, L: Any) -> np.ndarray:
        return as_matrix("L", L, self.sys.nx, self.sys.ny, vector="col")

    def _steady(self, D: np.ndarray, L: np.ndarray) -> np.ndarray | None:
        if self.sys.nd and not isinstance(self.sys.d, Box):
            return None
        return steady_width(D, self._E - L @ self._F, design_delta(self.sys))


@register
class IntervalObserver(_CooperativeObserver):
    """Interval observer with ``A − LC`` nonnegative and Schur (002 eqs. 36–37, Theorem 4;
    003 eq. 3, Theorem 1; bounds from measurements as in 003 Remark 1)::

        x̄[k+1] = A x̄ + B u + L (y − C x̄ − D_u u) + Ḡ,    Ḡ = G⁺ d_hi − G⁻ d_lo
        x̲[k+1] = A x̲ + B u + L (y − C x̲ − D_u u) + G̲,    G̲ = G⁺ d_lo − G⁻ d_hi,  G = E − LF

    Errors ``x̄ − x``, ``x − x̲`` obey ``e+ = (A − LC) e + (nonnegative input)``: a
    nonnegative ``A − LC`` keeps them nonnegative (002 Lemma 3), Schur keeps them bounded.
    ``d`` bounds may be callables ``(k, y_k) -> Box`` (003 Remark 1, the Hénon example).

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Gain** (``L=`` to give one; it must make ``A − LC`` nonnegative and Schur):
    ``gain="lmi"``: LMI (41) of 002 with diagonal ``P`` (a margin maximised,
    :func:`ivobs.design.cooperative.nonnegative_gain`); ``gain="width"`` (default): that gain
    refined by linear programs that lower the steady-state width ``(I − D)⁻¹|G|Δ`` while keeping
    ``D >= 0`` (:func:`ivobs.design.cooperative.refine_width`; never wider than the LMI gain).
    When no gain makes ``A − LC`` nonnegative and Schur (002 Example 2, 003 §IV.A) a
    :class:`~ivobs.DesignError` says so: use ``interval-split`` or ``interval-transformed``.

    Missing samples, inconsistent data and the vectorised path: see the module docstring.
    """

    name = "interval"
    summary = "interval observer, A − LC nonnegative and Schur (002 eq. 36, 003 Theorem 1)"
    reference = "002 Section V.A, eqs. (36)-(41); 003 Theorem 1, eq. (3)"

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        gain: str = "width",
        **base_options: Any,
    ):
        super().__init__(sys, x0, **base_options)
        A, _, C, _, E, F = sys.matrices_at(0)
        if L is None:
            if gain not in ("lmi", "width"):
                raise IvobsError(f"gain: expected 'lmi' or 'width', got {gain!r}")
            L = nonnegative_gain(A, C, self.name)
            if gain == "width":
                L = refine_width(A, C, E, F, design_delta(sys), L, nonnegative=True)
                gain = "lmi+width"
        else:
            L = self._check_gain(L)
            gain = "given"
        D = check_nonnegative_schur(A, C, L, self.name)
        self._setup(L)
        self.design = IntervalDesign(
            L=L,
            D=D,
            spectral_radius=spectral_radius(D),
            gain=gain,
            steady_width=self._steady(D, L),
        )


@register
class SplitIntervalObserver(_CooperativeObserver):
    """Interval observer in the original coordinates with ``D = A − LC = D⁺ − D⁻`` of any sign
    (003 Theorem 3, eq. 5; error system (6); Corollary 1)::

        x̄[k+1] = D⁺ x̄ − D⁻ x̲ + (B − L D_u) u + L y + Ḡ
        x̲[k+1] = D⁺ x̲ − D⁻ x̄ + (B − L D_u) u + L y + G̲        (Ḡ, G̲ as for ``interval``)

    Sound for every ``L`` (Lemma 1); bounded iff ``|D| = D⁺ + D⁻`` is Schur (003's copositive
    argument: the radius obeys ``r+ = |D| r + …``).

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Gain** (``L=`` to give one; ``|A − LC|`` must be Schur):
    ``gain="lmi"``: LMIs (7)–(8) of 003 (Corollary 1; they force ``D >= 0``, the same LMI as
    002's (41)); ``gain="margin"``: a local minimum of ``ρ(|A − LC|)`` by linear programs on
    ``|A − LC| v <= s v`` alternating with the Perron vector ``v``
    (:func:`ivobs.design.cooperative.abs_schur_gain`); ``gain="width"`` (default): that gain
    refined to lower the steady-state width ``(I − |D|)⁻¹|G|Δ``
    (:func:`ivobs.design.cooperative.refine_width`). :class:`~ivobs.DesignError` when no gain
    with ``ρ(|A − LC|) < 1`` is found.
    """

    name = "interval-split"
    summary = "interval observer with D⁺/D⁻, |A − LC| Schur (003 Theorem 3, eq. 5)"
    reference = "003 Theorem 3, eqs. (5)-(8), Corollary 1"

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        gain: str = "width",
        **base_options: Any,
    ):
        super().__init__(sys, x0, **base_options)
        A, _, C, _, E, F = sys.matrices_at(0)
        if L is None:
            if gain not in ("lmi", "margin", "width"):
                raise IvobsError(f"gain: expected 'width', 'margin' or 'lmi', got {gain!r}")
            if gain == "lmi":
                L = nonnegative_gain(A, C, self.name)
            else:
                L, rho = abs_schur_gain(A, C)
                if rho >= 1.0:
                    low = fixed_radius(A, C)
                    why = (
                        f"; no gain can do better than {low:.6g}: the unmeasured states (zero "
                        "columns of C) keep |A| on their block"
                        if low >= 1.0
                        else ""
                    )
                    raise DesignError(
                        f"{self.name}: no gain found with |A − LC| Schur: the best spectral "
                        f"radius of |A − LC| found is {rho:.6g} >= 1 (003 Theorem 3){why}; try "
                        "'interval-transformed' (needs only A − LC Schur)"
                    )
                if gain == "width":
                    L = refine_width(A, C, E, F, design_delta(sys), L, nonnegative=False)
        else:
            L = self._check_gain(L)
            gain = "given"
        D = check_abs_schur(A, C, L, self.name)
        self._setup(L)
        self.design = SplitDesign(
            L=L,
            D=D,
            spectral_radius=spectral_radius(np.abs(D)),
            gain=gain,
            steady_width=self._steady(D, L),
        )


@register
class TransformedIntervalObserver(_CooperativeObserver):
    """Interval observer in coordinates ``z = S x`` where ``R = S (A − LC) S⁻¹`` is nonnegative
    (002 Theorem 5, eqs. 42–43, 48; 003 Theorem 2, eq. 4)::

        z̲_0, z̄_0 = Lemma 1 of S on x0                                           (42a-b)
        z̄+ = R z̄ + S(B − L D_u) u + S L y + ḡ,  z̲+ = R z̲ + … + g̲,  g = bounds of S(E − LF) d
                                                                                 (42c-d, 43)
        x̲, x̄ = Lemma 1 of S⁻¹ on [z̲, z̄]  (k >= 1; the prior box at k = 0)       (42e-f)

    ``A − LC`` only needs to be Schur. ``S = O_R⁻¹ O_{A−LC}`` (eq. 48) with the observability
    matrices of ``(R, e2)`` and ``(A − LC, e1)``.

    **Data used:** the box of ``x[k]`` uses ``u[0..k−1]``, ``y[0..k−1]`` (and ``x0``).

    **Design** (each step can be given). ``L=``, or ``poles=`` (distinct real poles placed by
    SciPy's ``place_poles``). By default (:func:`ivobs.design.similarity.default_design`) ivobs
    places distinct poles in ``(0, 1)`` (then ``R = diag(λ)`` is a nonnegative realisation),
    lowers the steady-state width ``|V|(I − Λ)⁻¹|V⁻¹ G| Δ`` of the observer in modal coordinates
    by Nelder–Mead over ``L``, then searches ``(L, e1)`` jointly over every real spectrum the
    realisation below supports (a local search; ``design.gain == 'search'``). ``R=``: a
    nonnegative matrix with the spectrum of ``A − LC`` (default
    :func:`ivobs.design.similarity.nonnegative_realization`: diagonal/bidiagonal, Suleimanova
    companion blocks, 3×3 circulants for complex pairs; ``DesignError`` with the reason when the
    spectrum has no such realisation, e.g. 003's planar example with ``L = (0.3, 0.6)``:
    ``{0, −0.5}``, negative trace). ``e1=``, ``e2=``: the rows of eq. (48) (defaults: observable
    choices with the smallest steady-state width). ``S=``: the transformation itself.

    The observer propagates with ``S (A − LC) S⁻¹`` (``design.R``), which equals the requested
    ``R`` up to round-off; the split form makes any round-off-sized negative entry sound.
    """

    name = "interval-transformed"
    summary = "interval observer in z = S x with nonnegative R (002 Theorem 5, 003 Theorem 2)"
    reference = "002 Section V.B, Theorem 5, eqs. (42)-(48); 003 Theorem 2, eq. (4)"

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        L: Any = None,
        poles: Any = None,
        R: Any = None,
        S: Any = None,
        e1: Any = None,
        e2: Any = None,
        **base_options: Any,
    ):
        super().__init__(sys, x0, **base_options)
        A, _, C, _, E, F = sys.matrices_at(0)
        n, who = sys.nx, self.name
        delta = design_delta(sys)
        if L is not None and poles is not None:
            raise IvobsError("L, poles: give the gain L or the poles to place, not both")
        if S is not None and (e1 is not None or e2 is not None):
            raise IvobsError("e1, e2: they only serve to compute S by eq. (48); S was given")
        e1_search = None
        if L is not None:
            L, gain = self._check_gain(L), "given"
        elif poles is None:
            L, e1_search = default_design(A, C, lambda L_: E - L_ @ F, delta, who)
            gain = "search"
        else:
            poles = as_vector("poles", poles, n)
            if np.any(np.abs(poles) >= 1.0):
                raise IvobsError(f"poles: expected values inside (−1, 1), got {poles}")
            L, gain = place_real_poles(A, C, poles, who), "given-poles"
        M = A - L @ C
        rho = spectral_radius(M)
        if rho >= 1.0:
            raise DesignError(f"{who}: A − LC is not Schur: spectral radius {rho:.6g} >= 1")
        G = E - L @ F
        R_given = None if R is None else self._check_R(R)
        if S is not None:
            S = as_matrix("S", S, n, n)
            e1_, e2_ = None, None
        else:
            if R_given is None:
                R_t, e2_default = nonnegative_realization(np.linalg.eigvals(M))
                R_t = np.asarray(R_t)
            else:
                R_t, e2_default = R_given, None
            e2_ = (
                self._default_e2(R_t)
                if (e2 is None and e2_default is None)
                else (e2_default if e2 is None else as_vector("e2", e2, n))
            )
            if e1 is not None:
                e1_ = as_vector("e1", e1, n)
            elif e1_search is not None and R_given is None and e2 is None:
                e1_ = e1_search
            else:
                e1_ = default_e1(M, R_t, e2_, G, delta, who)
            S = similarity_transform(M, R_t, e1_, e2_, who)
            R_given = None  # S was built from R: check_transform checks nonnegativity only
        Rs = check_transform(M, S, who, R_given)
        self._setup(L, S)
        steady = None
        if not (sys.nd and not isinstance(sys.d, Box)):
            steady = transformed_width(M, G, delta, S)
        self.design = TransformedDesign(
            L=L,
            R=Rs,
            S=S,
            e1=e1_,
            e2=e2_,
            poles=np.linalg.eigvals(M),
            spectral_radius=spectral_radius(np.abs(Rs)),
            gain=gain,
            steady_width=steady,
        )

    def _check_R(self, R: Any) -> np.ndarray:
        R = as_matrix("R", R, self.sys.nx, self.sys.nx)
        if np.any(R < 0):
            i, j = np.unravel_index(int(np.argmin(R)), R.shape)
            raise DesignError(
                f"{self.name}: R is not nonnegative: entry ({i + 1}, {j + 1}) = {R[i, j]:.6g} "
                "< 0 (002 Theorem 5 / 003 Theorem 2 need R >= 0)"
            )
        return R

    @staticmethod
    def _default_e2(R: np.ndarray) -> np.ndarray:
        """A row making ``(R, e2)`` well observable: ones, then unit vectors (best conditioned)."""
        from ..linalg import observability_matrix

        n = R.shape[0]
        cands = [np.ones(n), *np.eye(n)]
        conds = [np.linalg.cond(observability_matrix(R, c[None, :])) for c in cands]
        return cands[int(np.argmin(conds))]
