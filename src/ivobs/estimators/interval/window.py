"""Recovery after missing samples: the observer's bounds intersected once with a finite-memory
bound (:mod:`ivobs.design.finite_memory`) after ``N`` complete steps.

During a gap the interval recursion runs with the gain of the outputs present; its width may
grow (at ``ρ(|A − L_k C|)`` per step, wrapping included) and, once the outputs return, shrink
back only at the rate ``ρ(|A − LC|)`` of the complete observer (0.9995 on the servo of
[Tang2019]: its current is not corrected by any ``L`` in these coordinates). So after any
missing or inconsistent sample the observer collects the next ``N`` complete steps (``N``: the
observability index of ``(A, C)``) and intersects the bounds of ``x[k+1]`` with the bound that
those ``N`` steps give alone ([Efimov2013, Lemma 1] on the window's disturbances, module
:mod:`ivobs.design.finite_memory`). Both bounds contain ``x[k+1]``, so their intersection does;
what happened before the window no longer counts, so the width after a gap of any length is back
within the finite-memory bound ``N`` steps after the outputs return, and then follows the
complete observer's recursion. Records without missing samples never enter this path (the
vectorised path and the loop agree on them as before).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import ClassVar, TypeVar

import numpy as np

from ...design.finite_memory import WindowBound
from ...sets import image_bounds
from ..state import OnlineState

__all__ = ["CooperativeState", "after_gap", "empty_window"]


@dataclass(frozen=True)
class CooperativeState(OnlineState):
    """``lo``, ``hi``: the bounds ``z̲[k] <= z[k] <= z̄[k]`` of ``z = S x`` (``x`` itself when
    ``S = I``) at step ``k`` (before ``y[k]`` is used). After a missing or inconsistent sample
    (``S = I``, this module): ``fresh``, the complete steps since (``−1``: none pending), and
    ``window``, their ``[y, u]`` rows."""

    lo: np.ndarray
    hi: np.ndarray
    window: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))
    fresh: int = -1

    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"),)
    optional: ClassVar[tuple[str, ...]] = ("window", "fresh")  # (states saved before them)


S = TypeVar("S", bound=CooperativeState)


def empty_window(bound: WindowBound | None, ny: int, nu: int) -> np.ndarray:
    """The window of a fresh state: ``(N, ny + nu)`` zeros (``(0, 0)`` without a bound)."""
    if bound is None:
        return np.zeros((0, 0))
    return np.zeros((bound.N, ny + nu))


def after_gap(
    bound: WindowBound,
    T: np.ndarray | None,
    new: S,
    old: S,
    u_k: np.ndarray,
    y_k: np.ndarray,
    complete: bool,
) -> S:
    """The next state ``new`` after step ``old.k``: with ``complete`` False a window starts;
    while one is pending the step's ``[y, u]`` is kept, and at its ``N``-th complete step the
    bounds are intersected with the window's (its image by Lemma 1 of ``T`` when the bounds are
    those of ``z = T x``)."""
    if not complete:
        return replace(new, fresh=0) if new.fresh != 0 else new
    j = old.fresh
    if j < 0:
        return new
    buf = old.window.copy()
    ny = y_k.shape[0]
    buf[j, :ny] = y_k
    buf[j, ny:] = u_k
    if j + 1 < bound.N:
        return replace(new, window=buf, fresh=j + 1)
    wlo, whi = bound.box(buf[:, :ny].reshape(-1), buf[:, ny:].reshape(-1))
    if T is not None:
        wlo, whi = image_bounds(T, wlo, whi)
    lo = np.fmax(new.lo, wlo)
    hi = np.fmin(new.hi, whi)
    if not bool(np.all(lo <= hi)):
        # no state explains the window and the observer's bounds together (faulty data): keep
        # the observer's bounds
        lo, hi = new.lo, new.hi
    return replace(new, lo=lo, hi=hi, window=buf, fresh=-1)
