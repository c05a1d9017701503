"""The strip operations under the names ``nl-zonotope`` imports (``_add``, ``section_hull``,
``propagate_lists``, ``propagate_strip``): thin adapters over :mod:`ivobs.sets.strip`, where
each operation is implemented once. ``nl_zonotope`` can call :mod:`ivobs.sets.strip` directly
(then this module goes)."""

from __future__ import annotations

import numpy as np

from ..sets import strip as _strip

__all__ = ["propagate_lists", "propagate_strip", "section_hull"]

_add = np.add.reduce


def section_hull(
    z: np.ndarray,
    H: np.ndarray,
    s: np.ndarray,
    e: float,
    sigma: float = 0.0,
    absH: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`ivobs.sets.strip.section_hull` of ``<z, H> ∩ {|sᵀξ - e| <= σ}`` on every
    coordinate; ``absH``: ``|H| 1`` when the caller has it."""
    H = np.ascontiguousarray(H, dtype=np.float64)
    rows = _add(np.abs(H), axis=1) if absH is None else absH
    f64 = np.ascontiguousarray
    return _strip.section_hull(
        f64(z, np.float64), H, H.shape[1], H.shape[0], f64(s, np.float64), float(e),
        float(sigma), f64(rows, np.float64),
    )  # fmt: skip


def propagate_strip(
    h: np.ndarray, t: float, box: np.ndarray, sigma: float = 0.0, nz: np.ndarray | None = None
) -> np.ndarray | None:
    """:func:`ivobs.sets.strip.contract_box` of the box ``[box[0], box[1]]``, into a new
    ``(2, n)`` array; None when the strip certainly misses it (``nz`` is not needed)."""
    lo = np.array(box[0], dtype=np.float64)
    hi = np.array(box[1], dtype=np.float64)
    hc = np.ascontiguousarray(h, dtype=np.float64)
    if not _strip.contract_box(hc, float(t), float(sigma), lo, hi):
        return None
    return np.stack([lo, hi])


def propagate_lists(
    h: list[float], t: float, lo: list[float], hi: list[float], sigma: float = 0.0
) -> tuple[list[float], list[float]] | None:
    """:func:`propagate_strip` on the box ``[lo, hi]`` given as lists (new lists)."""
    out = propagate_strip(np.array(h, dtype=np.float64), t, np.array([lo, hi]), sigma)
    return None if out is None else (out[0].tolist(), out[1].tolist())
