"""Exact trajectories of a linear model, for soundness checks that rely on no rounding margin.

A float64 simulation is not a trajectory of the model: ``fl(A x + B u + E d)`` differs from the
exact value, and a sound estimator may rightly exclude the float state. :class:`ExactLinear`
keeps every state *exactly*, as integers over a power of two (a double is ``m 2^e``; sums and
products of such numbers stay such numbers), with the disturbances and the inputs given as
doubles. Each measurement is then the double nearest to the exact ``C x + D u + F d``, as a data
logger records it. A record keeps each exact state as the two adjacent doubles around it
(:class:`ExactStates`): for a double ``a``, ``a <= x`` exactly when ``a`` is at most the lower
one, and ``a >= x`` when it is at least the upper one, so a box is checked against the exact
state by exact comparison, on arrays of doubles.

The integers grow by the mantissa length of the matrices at every step, so runs of a few
thousand steps are cheap, not millions: long campaigns use many runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["ExactLinear", "ExactStates", "exact_misses", "exact_run"]

Dyadic = tuple[list[int], int]
"""A vector ``N 2^s``: integers ``N`` over one power of two."""


def _split(v: float) -> tuple[int, int]:
    """``v = M 2^e`` exactly (``M`` an integer)."""
    m, e = math.frexp(v)
    return int(m * (1 << 53)), e - 53


def _dyadic(values: Sequence[float]) -> Dyadic:
    parts = [_split(float(v)) for v in values]
    s = min((e for m, e in parts if m), default=0)
    return [m << (e - s) if m else 0 for m, e in parts], s


def _matrix(M: np.ndarray) -> tuple[list[list[int]], int]:
    rows, s = _dyadic(np.asarray(M, dtype=float).ravel().tolist())
    n = M.shape[1] if M.ndim == 2 else 0
    return [rows[i * n : (i + 1) * n] for i in range(M.shape[0])], s


def _apply(M: tuple[list[list[int]], int], x: Dyadic) -> Dyadic:
    rows, s = M
    X, t = x
    return [sum(a * b for a, b in zip(row, X)) for row in rows], s + t


def _add(*terms: Dyadic) -> Dyadic:
    live = [t for t in terms if t[0]]
    s = min((t[1] for t in live), default=0)
    n = max(len(t[0]) for t in terms)
    out = [0] * n
    for N, e in live:
        for i, v in enumerate(N):
            out[i] += v << (e - s)
    return out, s


def _nearest(N: int, s: int) -> float:
    """The double nearest to ``N 2^s`` (Python's integer division rounds correctly)."""
    return float(N << s) if s >= 0 else N / (1 << -s)


_MAX = float(np.finfo(np.float64).max)


def _around(N: int, s: int) -> tuple[float, float]:
    """The doubles ``a <= N 2^s <= b`` next to it (``a = b`` when it is a double; beyond the
    largest double, that one and an infinity)."""
    try:
        q = _nearest(N, s)
    except OverflowError:
        return (_MAX, math.inf) if N > 0 else (-math.inf, -_MAX)
    c = _sign(q, N, s)
    if c > 0:
        return math.nextafter(q, -math.inf), q
    return (q, q) if c == 0 else (q, math.nextafter(q, math.inf))


@dataclass(frozen=True)
class ExactStates:
    """The exact states ``x[0..T-1]`` of a record, each component between two adjacent doubles:
    ``lo <= x <= hi`` (``lo = hi`` where ``x`` is a double), arrays ``(T, nx)``. For a double
    ``a``, ``a <= x`` exactly when ``a <= lo`` (``lo`` is the largest double not above ``x``)
    and ``a >= x`` when ``a >= hi``. Slicing takes steps (``X[:n]``)."""

    lo: np.ndarray
    hi: np.ndarray

    def __len__(self) -> int:
        return int(self.lo.shape[0])

    def __getitem__(self, steps: slice) -> ExactStates:
        return ExactStates(self.lo[steps], self.hi[steps])


def _sign(a: float, N: int, s: int) -> int:
    """The sign of ``a − N 2^s``, exactly (``a`` a double, possibly infinite)."""
    if math.isinf(a):
        return 1 if a > 0 else -1
    m, e = _split(a)
    t = min(e, s)
    diff = (m << (e - t)) - (N << (s - t))
    return (diff > 0) - (diff < 0)


class ExactLinear:
    """``x[k+1] = A x + B u + E d``, ``y[k] = C x + D u + F d`` in exact arithmetic.

    Parameters
    ----------
    sys : a discrete-time :class:`~ivobs.LinearSystem` (time-varying matrices are evaluated at
        each step)
    x0 : the true initial state (doubles, taken exactly)
    """

    def __init__(self, sys: Any, x0: Any) -> None:
        self.sys = sys
        self.k = 0
        self.x: Dyadic = _dyadic(np.asarray(x0, dtype=float).tolist())
        self._cache: dict[int, tuple[Any, ...]] = {}

    def _mats(self) -> tuple[Any, ...]:
        key = 0 if not self.sys.is_time_varying else self.k
        if key not in self._cache:
            if len(self._cache) > 4:
                self._cache.clear()
            self._cache[key] = tuple(
                _matrix(np.atleast_2d(np.asarray(M, dtype=float)))
                for M in self.sys.matrices_at(key)
            )
        return self._cache[key]

    def step(self, u: Any = None, d: Any = None) -> np.ndarray:
        """Advance one step with input ``u[k]`` and disturbance ``d[k]`` (doubles, exact);
        returns ``y[k]`` rounded to the nearest doubles."""
        A, B, C, D, E, F = self._mats()
        sys = self.sys
        uu = _dyadic(np.zeros(sys.nu).tolist() if u is None else np.ravel(u).tolist())
        dd = _dyadic(np.zeros(sys.nd).tolist() if d is None else np.ravel(d).tolist())
        y = _add(_apply(C, self.x), _apply(D, uu), _apply(F, dd))
        self.x = _add(_apply(A, self.x), _apply(B, uu), _apply(E, dd))
        self.k += 1
        return np.array([_nearest(v, y[1]) for v in y[0]], dtype=float).reshape(sys.ny)

    def around(self) -> tuple[list[float], list[float]]:
        """The doubles next to each component of the current state, below and above
        (:class:`ExactStates`)."""
        N, s = self.x
        pairs = [_around(v, s) for v in N]
        return [a for a, _ in pairs], [b for _, b in pairs]


def exact_run(sys: Any, x0: Any, u: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, ExactStates]:
    """A whole record: the measurements ``y`` ``(T, ny)`` (nearest doubles) and the exact
    states ``x[0..T-1]`` (for :func:`exact_misses`)."""
    sim = ExactLinear(sys, x0)
    T = d.shape[0] if d is not None and np.ndim(d) == 2 else len(u)
    Y = np.empty((T, sys.ny))
    lo, hi = np.empty((T, sys.nx)), np.empty((T, sys.nx))
    for k in range(T):
        lo[k], hi[k] = sim.around()
        Y[k] = sim.step(None if u is None else u[k], None if d is None else d[k])
    return Y, ExactStates(lo, hi)


def exact_misses(lower: np.ndarray, upper: np.ndarray, X: ExactStates) -> np.ndarray:
    """Steps ``k`` whose box ``[lower[k], upper[k]]`` misses the exact state ``X[k]`` (rows
    with NaN bounds, before a method's ``valid_from``, are skipped)."""
    T = len(X)
    lo, hi = np.asarray(lower, dtype=float)[:T], np.asarray(upper, dtype=float)[:T]
    skip = np.isnan(lo).any(axis=1) | np.isnan(hi).any(axis=1)
    bad = ((lo > X.lo) | (hi < X.hi)).any(axis=1) & ~skip
    return np.flatnonzero(bad)
