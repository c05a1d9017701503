"""Outward rounding of the bounds every estimator returns.

Soundness under floating point: every returned bound of ``x[k]`` is widened outwards by
``ROUNDING * (1 + |bound| + s_k)`` (:data:`ROUNDING` ``= 1e-10``, about ``4.5e5`` units of
rounding ``eps``), where ``s_k`` is the *data scale*: the largest magnitude of a data term seen up
to step ``k`` (``|y_j|``, ``|B| |u_j|``, ``|D| |u_j|``, ``|E| |d_j|``, ``|F| |d_j|``, ``j <= k``).
A recursion that combines terms of size ``s`` loses about ``eps s`` per operation, amplified by
the gain of the error dynamics; the margin covers amplifications up to ``~1e5`` relative to the
largest quantity involved, the bounds *and* the data (a measurement ``y = 1e8`` carrying a state
of size 1 is only known to ``eps 1e8``). This is a documented safety margin, not interval
arithmetic with directed rounding.
"""

from __future__ import annotations

import numpy as np

__all__ = ["ROUNDING", "lean_outward", "outward", "overflowed"]

ROUNDING = 1e-10
"""Relative outward widening of every bound (covers floating-point rounding)."""


def outward(
    lo: np.ndarray, hi: np.ndarray, scale: np.ndarray | float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Widen bounds by the rounding margin ``ROUNDING (1 + max(|lo|, |hi|) + scale)`` (NaN
    stays NaN), in place: pass arrays you own. ``scale``: the data scale per step, shaped like
    the bounds without their last axis (see the module docstring).

    Works through cache-sized slabs of rows with two reused buffers: on a long record of a
    large system, whole-array temporaries cost more in page faults than the arithmetic."""
    n = lo.shape[-1] if lo.ndim else 1
    flat = lo.ndim == 2 or (lo.flags.c_contiguous and hi.flags.c_contiguous)  # rows: views
    if lo.size <= _SLAB or not flat or n == 0 or lo.shape != hi.shape:
        with np.errstate(invalid="ignore"):
            m = np.maximum(np.abs(lo), np.abs(hi))
            if scale is not None:
                m += np.asarray(scale)[..., None] if np.ndim(scale) else scale
            m *= ROUNDING
            m += ROUNDING
            lo -= m
            hi += m
        return lo, hi
    L, H = lo.reshape(-1, n), hi.reshape(-1, n)
    rows = L.shape[0]
    # the part of the margin that does not depend on the bound: ROUNDING (1 + s) per row
    base = ROUNDING * (1.0 + (0.0 if scale is None else np.asarray(scale, dtype=float)))
    S = np.broadcast_to(base, lo.shape[:-1]).reshape(-1, 1)
    step = max(1, _SLAB // n)
    m = np.empty((min(step, rows), n))
    t = np.empty_like(m)
    with np.errstate(invalid="ignore"):
        for r0 in range(0, rows, step):
            r1 = min(rows, r0 + step)
            mm, tt = m[: r1 - r0], t[: r1 - r0]
            np.abs(L[r0:r1], out=mm)
            np.abs(H[r0:r1], out=tt)
            np.maximum(mm, tt, out=mm)
            mm *= ROUNDING
            mm += S[r0:r1]
            L[r0:r1] -= mm
            H[r0:r1] += mm
    return lo, hi


def lean_outward(
    lo: np.ndarray | list[float], hi: np.ndarray | list[float], scale: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """:func:`outward` of one step's bounds of a short vector (up to :data:`LEAN` entries) in
    Python floats, into new arrays: the same operations in the same order as :func:`outward`,
    so the same numbers bit for bit, without a dozen NumPy calls on three numbers. ``lo``,
    ``hi``: float64 vectors, or lists of Python floats (a method's fast step that computed its
    bounds in floats: no conversion to arrays and back). ``None`` (use :func:`outward` and its
    checks) for other arrays and for bounds that are not all finite after widening (NaN,
    infinities, overflow: their errors are raised by the caller)."""
    if type(lo) is list and type(hi) is list:
        a_s, b_s = lo, hi
    elif (
        type(lo) is np.ndarray
        and type(hi) is np.ndarray
        # the canonical descriptor first (cheap); an equal one (numba's results) next
        and (lo.dtype is _F64 or lo.dtype == _F64)
        and (hi.dtype is _F64 or hi.dtype == _F64)
        and lo.ndim == 1
        and hi.ndim == 1
    ):
        a_s, b_s = lo.tolist(), hi.tolist()
    else:
        return None
    n = len(a_s)
    if n != len(b_s) or n > LEAN or scale - scale != 0.0:  # (a non-finite scale: full path)
        return None
    R = ROUNDING
    los, his = [], []
    for a, b in zip(a_s, b_s):
        ma, mb = abs(a), abs(b)
        if not (ma < _BELOW and mb < _BELOW):  # NaN, an infinity, or near the end of the
            return None  # float range: the full path (below, with a finite scale: finite)
        m = ((mb if mb > ma else ma) + scale) * R + R  # max(|lo|, |hi|) + s, times R, plus R
        los.append(a - m)
        his.append(b + m)
    return np.array(los), np.array(his)


_F64 = np.dtype(np.float64)

_BELOW = 1e307
"""Bounds below this (and a finite scale, at most the float range) widen to finite bounds:
the margin is at most ``(1e307 + 1.8e308) ROUNDING + ROUNDING``."""


LEAN = 32
"""Longest bounds :func:`lean_outward` rounds in Python floats (beyond, NumPy is faster)."""


_SLAB = 1 << 15
"""Elements per slab of :func:`outward`."""


_HUGE = 1e300
"""A bound this large is one step of growth away from the end of the float range."""


def overflowed(*arrays: np.ndarray) -> bool:
    """Whether any array holds an infinity or a finite value beyond :data:`_HUGE` (the bounds
    ran out of the float range; NaN then comes from ``inf - inf``)."""
    with np.errstate(invalid="ignore"):
        return any(bool(np.any(np.abs(a) > _HUGE)) for a in arrays if a.dtype.kind == "f")
