"""The finite-memory bound (:mod:`ivobs.design.finite_memory`) in the interval observers: every
box is met with the bound that the last ``N`` complete steps give alone, and after a gap the
observer's own bounds are met with it once.

**Why.** The interval recursion forgets its past only at the rate ``ρ(|Q|)`` of its width
dynamics. On the servo of [Tang2019] that is 0.9995 per step (``C`` does not read the current,
so no gain ``L`` corrects it in these coordinates): its boxes settle at a summed width of 254,
while ``N = 2`` steps of data bound the state to a summed width of 1.3 on their own. During a gap
the width may also grow (at ``ρ(|A − L_k C|)`` per step, wrapping included) and shrink back
only at that same rate.

**The box of x[k]** (``finite_memory=True``, the default). When the ``N`` steps before ``k``
(``N``: the observability index of ``(A, C)``) were complete and consistent, the box of
``x[k]`` is the intersection of the observer's box ``[x̲_k, x̄_k]`` and the finite-memory bound
``W_k`` of ``x[k]`` from ``y[k−N..k−1]``, ``u[k−N..k−1]`` ([Efimov2013, Lemma 1] on the
window's disturbances, every rounding bounded: :meth:`WindowBound.box`). Both contain ``x[k]``,
so their intersection (``max``/``min`` of floats: exact) does. The observer's recursion is not
changed by it: ``W_k`` depends on the record's last ``N`` steps only, so the loop and the
vectorised path (:mod:`.vectorised`: every ``W_k`` of a record in one product) compute the same
boxes, and the vectorised path stays two linear filters. Every step rather than every few: the
observer propagated from a met box widens again at its own rate (on the servo by 0.12 of
summed width per step, against ``W_k``'s 1.3), so a fresh ``W_k`` is the tighter bound at every
step, and in the vectorised path the cheaper one (no sequential pass).

**After a gap** (any missing or inconsistent sample; unchanged by ``finite_memory``) the
observer collects the next ``N`` complete steps and meets its own bounds of ``x[k+1]`` with the
bound those steps give (its image by Lemma 1 of ``S`` when the bounds are those of
``z = S x``): what happened before the window no longer counts, so the width after a gap of any
length is back within the finite-memory bound ``N`` steps after the outputs return, and then
follows the complete observer's recursion. This changes the recursion itself, so records with
missing samples run in the loop (as they do for their missing-output patterns anyway).

**Faulty data.** When the two bounds do not meet in some component, no state explains both the
window and the observer's bounds: the observer's bounds are kept (:func:`meet`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, TypeVar

import numpy as np

from ...design.finite_memory import WindowBound
from ...sets import image_bounds
from ..state import OnlineState, evolve

__all__ = ["CooperativeState", "empty_window", "meet", "memory_box", "remember"]


@dataclass(frozen=True)
class CooperativeState(OnlineState):
    """``lo``, ``hi``: the bounds ``z̲[k] <= z[k] <= z̄[k]`` of ``z = S x`` (``x`` itself when
    ``S = I``) at step ``k`` (before ``y[k]`` is used). ``window``: the ``[y, u]`` rows of the
    last ``filled`` complete steps, oldest first (the first ``filled`` rows until ``N`` are
    kept, then all of them); ``fresh``: the complete steps since the last missing or
    inconsistent sample while the observer's bounds wait to be met with the window's
    (``−1``: none pending)."""

    lo: np.ndarray
    hi: np.ndarray
    window: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    fresh: int = -1
    filled: int = 0

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"),)
    optional: ClassVar[tuple[str, ...]] = ("window", "fresh", "filled")  # (older states)


S = TypeVar("S", bound=CooperativeState)


def empty_window(bound: WindowBound | None, ny: int, nu: int) -> np.ndarray:
    """The window of a fresh state: ``(N, ny + nu)`` zeros (``(0, 0)`` without a bound)."""
    if bound is None:
        return np.zeros((0, 0))
    return np.zeros((bound.N, ny + nu))


def meet(
    lo: np.ndarray, hi: np.ndarray, wlo: np.ndarray, whi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``[lo, hi] ∩ [wlo, whi]`` (exact), for one box or a stack of them (``(..., n)``); a box
    whose intersection is empty in some component keeps ``[lo, hi]`` (faulty data: module
    docstring). ``wlo``, ``whi`` (the window's fresh bounds) are overwritten."""
    mlo, mhi = np.fmax(lo, wlo, out=wlo), np.fmin(hi, whi, out=whi)
    empty = mlo > mhi
    if np.count_nonzero(empty):
        empty = empty.any(axis=-1, keepdims=True)
        mlo, mhi = np.where(empty, lo, mlo), np.where(empty, hi, mhi)
    return mlo, mhi


def memory_box(
    bound: WindowBound, state: CooperativeState, lo: np.ndarray, hi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The box ``[lo, hi]`` of ``x[state.k]`` met with the window's bound when the state holds
    ``N`` complete steps (module docstring)."""
    if state.filled < bound.N:
        return lo, hi
    wlo, whi = bound.box(state.window.reshape(-1))
    return meet(lo, hi, wlo, whi)


def remember(
    bound: WindowBound,
    T: np.ndarray | None,
    new: S,
    old: S,
    u_k: np.ndarray,
    y_k: np.ndarray,
    complete: bool,
) -> S:
    """The next state ``new`` after step ``old.k`` with the window updated: emptied by a
    missing or inconsistent sample (a gap: the observer's bounds wait for ``N`` complete
    steps), else ``[y_k, u_k]`` appended; at the ``N``-th complete step after a gap the bounds
    are met with the window's (its image by Lemma 1 of ``T`` when the bounds are those of
    ``z = T x``)."""
    if not complete:
        return evolve(new, fresh=0, filled=0)
    N = bound.N
    # (a state saved before ``filled`` existed counts its pending rows in ``fresh`` only)
    j = min(max(old.filled, old.fresh), N)
    if j == N:  # full: the oldest row leaves
        old_rows = old.window.reshape(-1)[old.window.shape[1] :]
        buf = np.concatenate((old_rows, y_k, u_k)).reshape(old.window.shape)
        j -= 1
    else:
        buf = old.window.copy()
        ny = y_k.shape[0]
        buf[j, :ny] = y_k
        buf[j, ny:] = u_k
    fresh = old.fresh
    if fresh < 0 or fresh + 1 < N:
        return evolve(new, window=buf, filled=j + 1, fresh=fresh if fresh < 0 else fresh + 1)
    wlo, whi = bound.box(buf.reshape(-1))
    if T is not None:
        wlo, whi = image_bounds(T, wlo, whi)
    lo, hi = meet(new.lo, new.hi, wlo, whi)
    return evolve(new, lo=lo, hi=hi, window=buf, filled=N, fresh=-1)
