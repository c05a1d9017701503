"""Sets that every method speaks: boxes (interval vectors) and zonotopes.

Both answer the same verbs, as in CORA's ``@interval`` and ``@zonotope``: linear map (``M @ S``),
Minkowski sum (``S1 + S2``), ``interval_hull()``, plus ``contains``. Zonotopes also ``reduce``.

Conventions (papers 002 Definition 1-3, Properties 1-4; 001 Definition 3):

* ``Box(lo, hi) = {x : lo <= x <= hi}``; its bounds may be arrays over time, shape ``(T, n)``
  (a time-varying bound), read at a step with :meth:`Box.at`.
* ``Zonotope(c, G) = <c, G> = {c + G b : b in [-1, 1]^m}``. As in papers 001/002, the *order* of a
  zonotope is its number of generators ``m`` (CORA calls ``m / n`` the order).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import linprog

from ._validate import as_float_array, as_matrix, as_vector, check_finite
from .errors import InconsistentDataError, IvobsError

__all__ = ["Box", "Zonotope", "image_bounds", "neg", "pos"]


def pos(M: np.ndarray) -> np.ndarray:
    """``M⁺ = max(0, M)`` elementwise (002 Section II, 003 Section II.A, 004 ``M^⊕``)."""
    return np.maximum(M, 0.0)


def neg(M: np.ndarray) -> np.ndarray:
    """``M⁻ = M⁺ - M`` (nonnegative), so that ``M = M⁺ - M⁻``."""
    return np.maximum(-M, 0.0)


def image_bounds(M: Any, lo: Any, hi: Any) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of ``M x`` for ``lo <= x <= hi`` (Lemma 1 of 003 and 004, Lemma 2 of 002).

    ``M⁺ lo - M⁻ hi <= M x <= M⁺ hi - M⁻ lo``. ``lo`` and ``hi`` may carry leading axes
    (time, batch): shapes ``(..., n)`` give ``(..., m)``. These bounds are the interval hull of the
    image ``M [lo, hi]``, so they are exact componentwise.
    """
    M = np.asarray(M, dtype=float)
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    Mp, Mn = pos(M), neg(M)
    # Infinite bounds times zero coefficients must contribute 0, not NaN.
    with np.errstate(invalid="ignore"):
        new_lo = _safe_matvec(Mp, lo) - _safe_matvec(Mn, hi)
        new_hi = _safe_matvec(Mp, hi) - _safe_matvec(Mn, lo)
    return new_lo, new_hi


def _safe_matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v @ M.T`` for nonnegative ``M``, treating ``0 * inf`` as 0."""
    if np.all(np.isfinite(v)):
        return v @ M.T
    out = np.where(M[None, ...] > 0, M[None, ...] * v.reshape(-1, 1, v.shape[-1]), 0.0).sum(-1)
    return out.reshape(*v.shape[:-1], M.shape[0])


class Box:
    """An interval vector ``[lo, hi]`` (002 Definition 1), possibly time-varying.

    Parameters
    ----------
    lo, hi : array_like
        Bounds of shape ``(n,)``, or ``(T, n)`` for bounds that vary with the step ``k``.
        Infinite bounds are allowed (no information); NaN is not; ``lo <= hi`` is required.
    """

    __slots__ = ("hi", "lo")
    __array_priority__ = 100  # so that ``M @ box`` reaches ``Box.__rmatmul__``

    def __init__(self, lo: Any, hi: Any):
        lo_a = as_float_array("Box lo", lo)
        hi_a = as_float_array("Box hi", hi)
        if lo_a.ndim == 0:
            lo_a = lo_a.reshape(1)
        if hi_a.ndim == 0:
            hi_a = hi_a.reshape(1)
        if lo_a.shape != hi_a.shape:
            raise IvobsError(
                f"Box: lo and hi must have the same shape, got {lo_a.shape} and {hi_a.shape}"
            )
        if lo_a.ndim not in (1, 2):
            raise IvobsError(
                f"Box: expected bounds of shape (n,) or (T, n) (time-varying), got {lo_a.shape}"
            )
        check_finite("Box lo", lo_a, allow_inf=True)
        check_finite("Box hi", hi_a, allow_inf=True)
        if np.any(lo_a > hi_a):
            idx = tuple(int(i) for i in np.argwhere(lo_a > hi_a)[0])
            raise IvobsError(
                f"Box: lower bound above upper bound at index {idx}: "
                f"lo={lo_a[idx]} > hi={hi_a[idx]}"
            )
        self.lo = lo_a
        self.hi = hi_a

    # -- constructors -------------------------------------------------------------------------
    @classmethod
    def from_center(cls, center: Any, radius: Any) -> Box:
        """``[center - radius, center + radius]`` (``radius >= 0``)."""
        c = as_float_array("center", center)
        r = np.broadcast_to(as_float_array("radius", radius), c.shape)
        if np.any(r < 0):
            raise IvobsError(f"radius: expected nonnegative values, got {r}")
        return cls(c - r, c + r)

    @classmethod
    def symmetric(cls, radius: Any) -> Box:
        """``[-radius, radius]``."""
        r = as_float_array("radius", radius)
        return cls.from_center(np.zeros_like(r), r)

    @classmethod
    def unknown(cls, n: int) -> Box:
        """A box with NaN bounds: "no estimate yet" (steps before an estimator's ``valid_from``)."""
        box = object.__new__(cls)
        box.lo = np.full(n, np.nan)
        box.hi = np.full(n, np.nan)
        return box

    @classmethod
    def _trusted(cls, lo: np.ndarray, hi: np.ndarray) -> Box:
        """Build without validation (internal: bounds already computed soundly)."""
        box = object.__new__(cls)
        box.lo = lo
        box.hi = hi
        return box

    # -- properties ---------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        """Dimension ``n``."""
        return int(self.lo.shape[-1])

    @property
    def is_time_varying(self) -> bool:
        """True when the bounds are given per step (shape ``(T, n)``)."""
        return self.lo.ndim == 2

    @property
    def is_unknown(self) -> bool:
        """True for the NaN box returned before an estimate is valid."""
        return bool(np.all(np.isnan(self.lo)))

    @property
    def center(self) -> np.ndarray:
        """Midpoint ``(lo + hi) / 2``."""
        return 0.5 * (self.lo + self.hi)

    @property
    def radius(self) -> np.ndarray:
        """Half-width ``(hi - lo) / 2``."""
        return 0.5 * (self.hi - self.lo)

    @property
    def width(self) -> np.ndarray:
        """``hi - lo``."""
        return self.hi - self.lo

    @property
    def is_bounded(self) -> bool:
        """True when every bound is finite."""
        return bool(np.all(np.isfinite(self.lo)) and np.all(np.isfinite(self.hi)))

    def at(self, k: int) -> Box:
        """The box at step ``k`` (itself when the bounds are constant)."""
        if not self.is_time_varying:
            return self
        if not 0 <= k < self.lo.shape[0]:
            raise IvobsError(
                f"Box.at: step {k} is outside the {self.lo.shape[0]} steps these time-varying "
                "bounds cover; give bounds for every step of the record"
            )
        return Box._trusted(self.lo[k], self.hi[k])

    # -- operations ---------------------------------------------------------------------------
    def contains(self, x: Any, tol: float = 0.0) -> Any:
        """Whether ``lo - tol <= x <= hi + tol`` (over the last axis; leading axes kept)."""
        x = np.asarray(x, dtype=float)
        if x.shape[-1] != self.dim:
            raise IvobsError(f"contains: expected points of dimension {self.dim}, got {x.shape}")
        ok = (x >= self.lo - tol) & (x <= self.hi + tol)
        return np.all(ok, axis=-1)

    def intersects(self, other: Box) -> bool:
        """Whether the two boxes have a common point."""
        return bool(np.all(np.maximum(self.lo, other.lo) <= np.minimum(self.hi, other.hi)))

    def intersect(self, other: Box) -> Box:
        """The intersection ``[max(lo), min(hi)]``.

        An empty intersection raises :class:`~ivobs.InconsistentDataError`: two guaranteed
        enclosures of the same state that do not meet mean the data contradict the model.
        """
        if not isinstance(other, Box):
            raise IvobsError(f"intersect: expected a Box, got {type(other).__name__}")
        if other.dim != self.dim:
            raise IvobsError(f"intersect: dimensions differ ({self.dim} and {other.dim})")
        lo = np.maximum(self.lo, other.lo)
        hi = np.minimum(self.hi, other.hi)
        if np.any(lo > hi):
            i = int(np.argwhere(lo > hi)[0][-1])
            raise InconsistentDataError(
                f"intersect: the boxes do not meet in component {i} "
                f"([{self.lo.flat[i]}, {self.hi.flat[i]}] and "
                f"[{other.lo.flat[i]}, {other.hi.flat[i]}])"
            )
        return Box._trusted(lo, hi)

    def linear_map(self, M: Any) -> Box:
        """Interval hull of ``M [lo, hi]`` (Lemma 1 of 003/004; exact per component)."""
        M = as_matrix("M", M, cols=self.dim, vector="row")
        return Box._trusted(*image_bounds(M, self.lo, self.hi))

    def __rmatmul__(self, M: Any) -> Box:
        return self.linear_map(M)

    def __add__(self, other: Any) -> Any:
        if isinstance(other, Zonotope):
            return self.to_zonotope() + other
        if isinstance(other, Box):
            if other.dim != self.dim:
                raise IvobsError(f"Box + Box: dimensions differ ({self.dim} and {other.dim})")
            return Box._trusted(self.lo + other.lo, self.hi + other.hi)
        v = as_float_array("translation", other)
        return Box._trusted(self.lo + v, self.hi + v)

    __radd__ = __add__

    def interval_hull(self) -> Box:
        """The box itself."""
        return self

    def to_zonotope(self) -> Zonotope:
        """``<center, diag(radius)>`` (only for constant, bounded boxes)."""
        if self.is_time_varying or not self.is_bounded:
            raise IvobsError("to_zonotope: needs a constant box with finite bounds")
        return Zonotope(self.center, np.diag(self.radius))

    def vertices(self) -> np.ndarray:
        """All ``2^n`` vertices, shape ``(2^n, n)`` (``n <= 20``)."""
        if self.dim > 20 or self.is_time_varying or not self.is_bounded:
            raise IvobsError("vertices: needs a constant bounded box of dimension <= 20")
        bits = (np.arange(2**self.dim)[:, None] >> np.arange(self.dim)[None, :]) & 1
        return np.where(bits == 1, self.hi, self.lo)

    def sample(self, size: int, rng: Any = None) -> np.ndarray:
        """``size`` points drawn uniformly in the (constant, bounded) box."""
        rng = np.random.default_rng(rng)
        return rng.uniform(self.lo, self.hi, size=(size, self.dim))

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Box)
            and np.array_equal(self.lo, other.lo, equal_nan=True)
            and np.array_equal(self.hi, other.hi, equal_nan=True)
        )

    __hash__ = None  # type: ignore[assignment]

    def __repr__(self) -> str:
        if self.is_time_varying:
            return f"Box(time-varying, T={self.lo.shape[0]}, n={self.dim})"
        lo = np.array2string(self.lo, precision=4)
        hi = np.array2string(self.hi, precision=4)
        return f"Box(lo={lo}, hi={hi})"


class Zonotope:
    """``<c, G> = {c + G b : ||b||_inf <= 1}`` (002 Definition 3, 001 Definition 3).

    Parameters
    ----------
    center : array_like, shape ``(n,)``
    generators : array_like, shape ``(n, m)`` (``m`` may be 0)
    """

    __slots__ = ("G", "c")
    __array_priority__ = 100

    def __init__(self, center: Any, generators: Any = None):
        c = as_vector("Zonotope center", center)
        n = c.shape[0]
        if generators is None:
            G = np.zeros((n, 0))
        else:
            G = as_float_array("Zonotope generators", generators)
            if G.ndim == 1 and n == 1:
                G = G.reshape(1, -1)
            if G.ndim != 2 or G.shape[0] != n:
                raise IvobsError(f"Zonotope generators: expected shape ({n}, m), got {G.shape}")
            check_finite("Zonotope generators", G)
        self.c = c
        self.G = G

    @classmethod
    def _trusted(cls, c: np.ndarray, G: np.ndarray) -> Zonotope:
        z = object.__new__(cls)
        z.c = c
        z.G = G
        return z

    @property
    def center(self) -> np.ndarray:
        return self.c

    @property
    def generators(self) -> np.ndarray:
        return self.G

    @property
    def dim(self) -> int:
        return int(self.c.shape[0])

    @property
    def num_generators(self) -> int:
        """Number of generators ``m`` (the zonotope's *order* in papers 001/002)."""
        return int(self.G.shape[1])

    def radius(self) -> np.ndarray:
        """Radius of the interval hull: ``sum_j |G_ij|`` (002 Property 4, eq. 5)."""
        return np.abs(self.G).sum(axis=1)

    def interval_hull(self) -> Box:
        """Smallest box containing the zonotope (002 Property 4, eq. 5; exact)."""
        r = self.radius()
        return Box._trusted(self.c - r, self.c + r)

    def linear_map(self, M: Any) -> Zonotope:
        """``M <c, G> = <M c, M G>`` (002 Property 3, eq. 4b)."""
        M = as_matrix("M", M, cols=self.dim, vector="row")
        return Zonotope._trusted(M @ self.c, M @ self.G)

    def __rmatmul__(self, M: Any) -> Zonotope:
        return self.linear_map(M)

    def __add__(self, other: Any) -> Zonotope:
        """Minkowski sum (002 Property 3, eq. 4a); a vector translates."""
        if isinstance(other, Box):
            other = other.to_zonotope()
        if isinstance(other, Zonotope):
            if other.dim != self.dim:
                raise IvobsError(
                    f"Zonotope + Zonotope: dimensions differ ({self.dim}, {other.dim})"
                )
            return Zonotope._trusted(self.c + other.c, np.hstack([self.G, other.G]))
        v = as_vector("translation", other, self.dim)
        return Zonotope._trusted(self.c + v, self.G)

    __radd__ = __add__

    def reduce(self, order: int, weight: Any = None) -> Zonotope:
        """Order reduction ``↓_{q,W}`` of paper 002, Remark 2 (Combastel's operator).

        Keeps at most ``q = order`` generators (``q >= n``): the generators are sorted by the
        weighted norm ``h^T W h`` (``W`` positive definite, identity by default); the ``q - n``
        largest are kept and the others are enclosed in the box ``diag(sum_j |h_ij|)``. The
        result contains the original zonotope (002 Remark 2: ``<0, H> ⊆ <0, ↓H>``).
        """
        q = int(order)
        n = self.dim
        if q < n:
            raise IvobsError(
                f"reduce: order (number of generators kept) must be >= n = {n}, got {q}"
            )
        G = self.G[:, np.any(self.G != 0.0, axis=0)]
        if G.shape[1] <= q:
            return Zonotope._trusted(self.c, G)
        if weight is None:
            norms = np.einsum("ij,ij->j", G, G)
        else:
            W = as_matrix("weight", weight, n, n)
            norms = np.einsum("ij,ik,kj->j", G, W, G)
        order_idx = np.argsort(-norms, kind="stable")
        keep = G[:, order_idx[: q - n]]
        box = np.abs(G[:, order_idx[q - n :]]).sum(axis=1)
        return Zonotope._trusted(self.c, np.hstack([keep, np.diag(box)]))

    def contains(self, x: Any, tol: float = 1e-9) -> bool:
        """Whether ``x`` lies in the zonotope (one LP with HiGHS; for checks, not hot loops)."""
        x = as_vector("x", x, self.dim)
        m = self.num_generators
        if m == 0:
            return bool(np.all(np.abs(x - self.c) <= tol))
        # min s  s.t.  G b = x - c, -1 - s <= b <= 1 + s  ->  inside iff s <= tol
        A_eq = np.hstack([self.G, np.zeros((self.dim, 1))])
        A_ub = np.vstack(
            [np.hstack([np.eye(m), -np.ones((m, 1))]), np.hstack([-np.eye(m), -np.ones((m, 1))])]
        )
        b_ub = np.ones(2 * m)
        cost = np.zeros(m + 1)
        cost[-1] = 1.0
        res = linprog(
            cost,
            A_ub=A_ub,
            b_ub=b_ub,
            A_eq=A_eq,
            b_eq=x - self.c,
            bounds=[(None, None)] * m + [(0, None)],
            method="highs",
        )
        return bool(res.status == 0 and res.x[-1] <= tol)

    def sample(self, size: int, rng: Any = None, *, vertices: bool = False) -> np.ndarray:
        """Points ``c + G b`` with ``b`` uniform in the cube (or on its vertices)."""
        rng = np.random.default_rng(rng)
        m = self.num_generators
        if vertices:
            b = rng.choice([-1.0, 1.0], size=(size, m))
        else:
            b = rng.uniform(-1.0, 1.0, size=(size, m))
        return self.c + b @ self.G.T

    def __repr__(self) -> str:
        return f"Zonotope(n={self.dim}, generators={self.num_generators})"
