"""The model's balanced coordinates, for methods whose criteria or rounding bounds mix the
states through norms or traces.

A plant whose states sit near ``1e6``, ``1`` and ``1e-3`` puts the large state's rounding (a
norm of the data) or its share of a trace on the small ones. In the coordinates ``x = S x̃``,
``S = diag(s)`` the powers of two of :func:`balancing`, the same plant is ``Ã = S⁻¹ A S``,
``B̃ = S⁻¹ B``, ``C̃ = C S``, ``Ẽ = S⁻¹ E`` (``D``, ``F`` unchanged) with the prior
``S⁻¹ x0``: every product is by a power of two, exact unless it leaves the normal range, which
is checked (:func:`balanced` then keeps ``S = I``). The model being the same, every bound
proven in ``x̃`` holds; the box of ``x`` is ``S`` times it, rounded outward only where a
product by ``s < 1`` may underflow (:func:`unbalanced`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..design.balance import state_scaling
from ..sets import Box
from ..sets.rounding import down, exactly_scaled, up

__all__ = ["balanced", "balancing", "unbalanced"]


def balancing(A: Any, C: Any, E: Any, F: Any) -> np.ndarray:
    """The powers of two ``s`` that balance the model ``(A, C, E, F)``
    (:func:`~ivobs.design.balance.state_scaling`), divided by the power of two nearest their
    geometric mean: a balanced model keeps ``s = 1``. Also the state scaling of the programs
    HiGHS sees (:class:`~ivobs.estimators.exact.program.TrajectoryLP`)."""
    mats = [np.asarray(m.toarray() if hasattr(m, "toarray") else m, dtype=float)
            for m in (A, C, E, F)]  # fmt: skip
    dv = state_scaling(*mats)
    if not dv.size:
        return dv
    out: np.ndarray = dv / np.exp2(np.round(np.mean(np.log2(dv))))
    return out


def balanced(
    mats: tuple[np.ndarray, ...], x0: Box
) -> tuple[tuple[np.ndarray, ...], Box, np.ndarray | None]:
    """``(A, B, C, D, E, F)`` and the prior in the balanced coordinates, and ``s``; the given
    ones and None where ``S = I`` or a product by ``S`` would not be exact."""
    A, B, C, D, E, F = mats
    s = balancing(A, C, E, F)
    if np.all(s == 1.0):
        return mats, x0, None
    inv = 1.0 / s
    As, Bs, Cs, Es, lo, hi = (
        exactly_scaled(A, inv[:, None] * s[None, :]),
        exactly_scaled(B, inv[:, None]),
        exactly_scaled(C, s[None, :]),
        exactly_scaled(E, inv[:, None]),
        exactly_scaled(x0.lo, inv),
        exactly_scaled(x0.hi, inv),
    )
    if As is None or Bs is None or Cs is None or Es is None or lo is None or hi is None:
        return mats, x0, None
    return (As, Bs, Cs, D, Es, F), Box(lo, hi), s


def unbalanced(
    lo: np.ndarray, hi: np.ndarray, s: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """The box ``S [lo, hi]`` of ``x`` from that of ``x̃`` (``s`` None: itself)."""
    if s is None:
        return lo, hi
    small = s < 1.0
    lo_s, hi_s = lo * s, hi * s
    return np.where(small, down(lo_s), lo_s), np.where(small, up(hi_s), hi_s)
