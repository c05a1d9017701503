"""The online step of the fixed-time estimator [Wang2020], written once.

At every step ``k >= s`` the box of ``x_k`` comes from the last ``s + 1`` samples only: the
window gain of :mod:`.gains` gives ``x̂_k = T(𝐲_k - Mu 𝐮_k)`` [Wang2020, eq. (7)] and the radius
``|T Md| 𝐫_k`` of eq. (11). Nothing propagates from one box to the next, except where the window
cannot give a box on its own: a window with missing samples is intersected with the model
prediction from the previous box, ``x_k ∈ A[x_{k-1}] + B u_{k-1} + E[d_{k-1}]``
([Efimov2013, Lemma 1], :func:`predict`), and a window without enough data, or whose parity
test fails, is that prediction.

The state keeps the last ``s + 2`` samples in ring buffers (the window plus the sample before
it, for the prediction even when ``s = 0``) and the previous box; a step returns new arrays.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from ...errors import IvobsError
from ...model import LinearSystem
from ...sets import Box, image_bounds
from ..rounding import ROUNDING
from ..state import OnlineState, Step, evolve
from .gains import WindowGains, evaluate_window

__all__ = ["FixedTimeRecursion", "FixedTimeState", "combine", "no_box_error", "predict"]

Bounds = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True, kw_only=True)
class FixedTimeState(OnlineState):
    """Ring buffers of the last ``s + 2`` samples (slot ``k mod (s + 2)`` holds step ``k``):
    ``z`` the samples ``[u; y; c]`` (``y`` zero where missing, ``c`` the centre of ``d``),
    ``ymiss`` 1 where ``y`` is missing, ``dlo``, ``dhi`` the bounds of ``d``; and the previous
    box ``[lo, hi]`` of ``x`` (outward rounded; meaningful once ``has_box``)."""

    z: np.ndarray
    ymiss: np.ndarray
    dlo: np.ndarray
    dhi: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    has_box: bool = False

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"), ("dlo", "dhi"))


def predict(
    sys: LinearSystem,
    lo: np.ndarray,
    hi: np.ndarray,
    u_prev: np.ndarray,
    dlo: np.ndarray,
    dhi: np.ndarray,
    k: int,
) -> Bounds:
    """``x_k ∈ A[x_{k-1}] + B u_{k-1} + E[d_{k-1}]`` ([Efimov2013, Lemma 1], model at
    ``k - 1``); leading axes allowed (many windows at once, time-invariant systems)."""
    A, B, _, _, E, _ = sys.matrices_at(k - 1)
    a_lo, a_hi = image_bounds(A, lo, hi)
    e_lo, e_hi = image_bounds(E, dlo, dhi)
    bu = u_prev @ B.T
    return a_lo + bu + e_lo, a_hi + bu + e_hi


def combine(raw: Bounds | None, incons: bool, prior: Bounds) -> tuple[Bounds, bool]:
    """The box of a window with missing samples (or none usable, or inconsistent), given the
    prediction ``prior`` from the previous box: the prediction when there is no usable
    window box or the data are inconsistent, else the intersection of the two (both
    contain ``x_k``); an empty intersection means inconsistent data."""
    if raw is None or incons:
        return prior, incons
    lo, hi = np.maximum(raw[0], prior[0]), np.minimum(raw[1], prior[1])
    if bool((lo > hi).any()):
        return prior, True
    return (lo, hi), False


def no_box_error(nx: int, s: int, k: int, rank: int) -> IvobsError:
    """The error for a window at step ``k`` without enough data and no earlier box."""
    why = (
        f"the available rows of Mx have rank {rank} < nx = {nx}"
        if rank < nx
        else "the available samples do not determine the oldest state of the window, so "
        "its gain cannot be certified (singular A)"
    )
    return IvobsError(
        f"y: at step {k} the window y[{k - s}..{k}] has too many missing samples "
        f"({why}) and no earlier box exists to predict from; give a prior "
        "x0=ivobs.Box(...) or a larger s"
    )


class FixedTimeRecursion:
    """The step ``(state, u_k, y_k) -> (state', box of x_k)`` for the window gains ``gains``
    and the optional prior ``x0`` (used only to predict before the first box)."""

    def __init__(self, gains: WindowGains, x0: Box | None):
        self.gains = gains
        self.sys = gains.sys
        self.s = gains.s
        self.x0 = x0
        self.nc = gains.designer.nc
        self.nz = gains.designer.nz
        # s + 2 slots: the window z_k .. z_(k-s) plus z_(k-1) kept for the prediction through a
        # missing sample even when s = 0 (u_(k-1) and the bounds of d_(k-1))
        self.slots = self.s + 2
        self.ring = [(p - np.arange(self.s + 1)) % self.slots for p in range(self.slots)]
        self._fast: tuple[list[np.ndarray], list[float], list[float]] | None = None
        self._fast_ok = not gains.designer.tv and self.sys.has_constant_bounds
        self._clean: np.ndarray | None = None  # a ring of missing flags known to be all zero

    def _fast_operators(self) -> tuple[list[np.ndarray], list[float], list[float]]:
        """For a time-invariant system with constant bounds: the complete window's ``GQ`` with
        its columns placed on the ring buffer of each slot ``p`` (``GQ_p z.ravel() = GQ w``, the
        slot outside the window a zero block), the radius ``|T Md| 𝐫`` and the parity bound
        (constant ``𝐫``), and ``rad_coef``, ``tol_coef`` stacked (these two as lists of
        floats: the fast step's arithmetic on them is in Python floats)."""
        gain = self.gains.complete(self.s)
        assert gain.GQ is not None and gain.HP is not None
        assert gain.rad_coef is not None and gain.tol_coef is not None
        nz, nx = self.nz, gain.nx
        box = self.sys.d_at(0)
        rhp = gain.HP @ np.tile(0.5 * (box.hi - box.lo), self.s + 1)
        per_slot = []
        for p in range(self.slots):
            G = np.zeros((gain.GQ.shape[0], self.slots * nz))
            for j, q in enumerate(self.ring[p]):
                G[:, q * nz : (q + 1) * nz] = gain.GQ[:, j * nz : (j + 1) * nz]
            per_slot.append(G)
        const = np.concatenate([rhp[:nx], rhp[nx:] * (1.0 + 1e-9) + 1e-9])
        coef = np.concatenate([gain.rad_coef, gain.tol_coef])
        return per_slot, const.tolist(), coef.tolist()

    def initial_state(self) -> FixedTimeState:
        s, nx, ny, nd = self.s, self.sys.nx, self.sys.ny, self.sys.nd
        return FixedTimeState(
            z=np.zeros((s + 2, self.nz)),
            ymiss=np.ones((s + 2, ny)),
            dlo=np.zeros((s + 2, nd)),
            dhi=np.zeros((s + 2, nd)),
            lo=np.zeros(nx),
            hi=np.zeros(nx),
            has_box=False,
        )

    def step(self, state: FixedTimeState, u_k: np.ndarray, y_k: np.ndarray) -> Step[FixedTimeState]:
        if self._fast_ok and state.k >= self.slots:
            fast = self._fast_step(state, u_k, y_k)
            if fast is not None:
                return fast
        k, s, nu, ny = state.k, self.s, self.sys.nu, self.sys.ny
        p = k % self.slots
        miss = np.isnan(y_k)
        dbox = self.sys.d_at(k, y_k)
        z, ymiss, dlo, dhi = state.z.copy(), state.ymiss.copy(), state.dlo.copy(), state.dhi.copy()
        z[p, :nu] = u_k
        z[p, nu : nu + ny] = np.where(miss, 0.0, y_k) if miss.any() else y_k
        if self.nc:
            z[p, nu + ny :] = 0.5 * (dbox.lo + dbox.hi)
        ymiss[p] = miss
        dlo[p] = dbox.lo
        dhi[p] = dbox.hi
        new = replace(state, z=z, ymiss=ymiss, dlo=dlo, dhi=dhi)
        raw: Bounds | None = None
        incons = False
        if k < s:
            if self.x0 is not None:
                raw = (self.x0.lo, self.x0.hi) if k == 0 else self._prediction(new, k)
        else:
            raw, incons = self._window_box(new, k, p)
        if raw is None:
            nan = np.full(self.sys.nx, np.nan)
            return Step(new, nan, nan.copy(), incons)
        lo, hi = np.asarray(raw[0], dtype=float), np.asarray(raw[1], dtype=float)
        m = ROUNDING * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))  # as the base's outward()
        return Step(replace(new, lo=lo - m, hi=hi + m, has_box=True), lo, hi, incons)

    def _fast_step(
        self, state: FixedTimeState, u_k: np.ndarray, y_k: np.ndarray
    ) -> Step[FixedTimeState] | None:
        """:meth:`step` for ``k >= s + 2`` (every slot written), constant bounds, a complete
        window (no missing sample in the ring) passing the parity test: eqs. (7), (11) as one
        product on the ring buffer (:meth:`_fast_operators`); ``None``: the general step.

        Only that product is NumPy's; the rest is a few operations on ``nx + n_par`` numbers,
        done in Python floats (each the same IEEE operation as NumPy's, so the same bits)."""
        if state.ymiss is not self._clean and not self._remember_clean(state.ymiss):
            return None
        total = sum(y_k.tolist())
        if total != total:  # a missing sample (NaN): the general step
            return None
        if self._fast is None:
            self._fast = self._fast_operators()
        per_slot, const, coef = self._fast
        nu, ny, nx, nz = self.sys.nu, self.sys.ny, self.sys.nx, self.nz
        p = state.k % self.slots
        z = state.z.copy()
        z[p, :nu] = u_k
        z[p, nu : nu + ny] = y_k
        # (the centre of d and the bounds in slot p are the constant ones already)
        flat = z.ravel()
        w = flat.tolist()
        q = (p + 1) % self.slots * nz
        del w[q : q + nz]  # the slot outside the window
        wmax = max(map(abs, w))  # max |w| over the window
        out = per_slot[p].dot(flat).tolist()
        # (loops, not comprehensions: on three numbers, building the comprehension costs more)
        for o, cf, ct in zip(out[nx:], coef[nx:], const[nx:]):
            if not abs(o) - (cf * wmax + ct) <= 0.0:  # the parity test fails (or NaN): the
                return None  # general step
        R = ROUNDING
        lo, hi, klo, khi = [], [], [], []
        for c, cf, ct in zip(out[:nx], coef, const):
            r = cf * wmax + ct  # the radius (11)
            m = (abs(c) + r) * R + R  # the kept box's rounding margin, as the base's outward()
            a, b = c - r, c + r  # (max(|c - r|, |c + r|) <= |c| + r)
            lo.append(a)
            hi.append(b)
            klo.append(a - m)
            khi.append(b + m)
        new = evolve(state, z=z, lo=np.array(klo), hi=np.array(khi), has_box=True)
        return Step(new, lo, hi, False)  # lists of floats: rounded by the base as they are

    def _remember_clean(self, ymiss: np.ndarray) -> bool:
        """Whether the ring's missing flags ``ymiss`` are all zero; if so, remember the array
        (made read-only: the fast step passes it on unchanged, so later states holding the same
        object need no new test) and return True."""
        if np.count_nonzero(ymiss):
            return False
        ymiss.flags.writeable = False
        self._clean = ymiss
        return True

    def _window_box(self, state: FixedTimeState, k: int, p: int) -> tuple[Bounds | None, bool]:
        """The box of the window ending at ``k`` (eqs. 7, 11), combined with the prediction
        where the window has missing samples, none usable, or fails the parity test."""
        idx = self.ring[p]
        ymiss = state.ymiss[idx]
        gain = self.gains.get(k, ymiss > 0.5)
        incons = False
        raw: Bounds | None = None
        if gain.ok:
            w = state.z[idx].ravel()
            r = 0.5 * (state.dhi[idx] - state.dlo[idx]).ravel()
            lo, hi, incons = evaluate_window(gain, w, r)
            raw = (lo, hi)
        if raw is None or incons or bool(ymiss.any()):
            prior = None
            if state.has_box:
                prior = self._prediction(state, k)
            elif k == 0 and self.x0 is not None:
                prior = (self.x0.lo, self.x0.hi)  # s = 0: the prior box of x[0] itself
            if prior is None and raw is None:
                raise no_box_error(self.sys.nx, self.s, k, gain.rank)
            if prior is not None:
                raw, incons = combine(raw, incons, prior)
        return raw, incons

    def _prediction(self, state: FixedTimeState, k: int) -> Bounds:
        """:func:`predict` from the previous box and the sample of step ``k - 1``."""
        q = (k - 1) % self.slots  # never the slot of step k (s + 2 slots)
        u_prev = state.z[q, : self.sys.nu]
        return predict(self.sys, state.lo, state.hi, u_prev, state.dlo[q], state.dhi[q], k)
