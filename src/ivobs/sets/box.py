"""Boxes (interval vectors), the set every method reports, and the interval image of a box.

``Box(lo, hi) = {x : lo <= x <= hi}`` ([Tang2019, Definition 1]); its bounds may be arrays over
time, shape ``(T, n)`` (a time-varying bound), read at a step with :meth:`Box.at`. A box answers
the verbs of the other sets (:mod:`ivobs.sets`), as CORA's ``@interval`` does: linear map
(``M @ S``), Minkowski sum (``S1 + S2``), ``interval_hull()``, ``contains``, plus ``intersect``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .._validate import as_float_array, as_matrix, check_finite
from ..errors import InconsistentDataError, IvobsError
from .rounding import down, mid_rad, product_error, up

if TYPE_CHECKING:
    from .zonotope import Zonotope

__all__ = ["Box", "image_bounds", "neg", "pos"]


def pos(M: np.ndarray) -> np.ndarray:
    """``M⁺ = max(0, M)`` elementwise ([Tang2019, Section II], [Efimov2013, Section II.A];
    ``M^⊕`` in [Dinh2024])."""
    out: np.ndarray = np.maximum(M, 0.0)
    return out


def neg(M: np.ndarray) -> np.ndarray:
    """``M⁻ = M⁺ - M`` (nonnegative), so that ``M = M⁺ - M⁻``."""
    out: np.ndarray = np.maximum(-M, 0.0)
    return out


def image_bounds(M: Any, lo: Any, hi: Any) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of ``M x`` for ``lo <= x <= hi`` ([Efimov2013, Lemma 1], [Dinh2024, Lemma 1],
    [Tang2019, Lemma 2]).

    ``M⁺ lo - M⁻ hi <= M x <= M⁺ hi - M⁻ lo``: the interval hull of the image ``M [lo, hi]``,
    exact componentwise in real arithmetic; evaluated in floating point and widened by the
    proven bound of that evaluation (``2 γ_{n+3} (M⁺ |hi| + M⁻ |lo|)`` for the upper bound)
    (:mod:`ivobs.sets.rounding`), then rounded outward, so the result contains the exact image.
    ``lo`` and ``hi`` may carry leading axes (time, batch): shapes ``(..., n)`` give ``(..., m)``.
    """
    M = np.asarray(M, dtype=float)
    lo = np.asarray(lo, dtype=float)
    hi = np.asarray(hi, dtype=float)
    Mp, Mn = pos(M), neg(M)
    # Infinite bounds times zero coefficients must contribute 0, not NaN.
    with np.errstate(invalid="ignore"):
        new_lo = _safe_matvec(Mp, lo) - _safe_matvec(Mn, hi)
        new_hi = _safe_matvec(Mp, hi) - _safe_matvec(Mn, lo)
        alo, ahi, n = np.abs(lo), np.abs(hi), M.shape[-1] + 1
        err_lo = product_error(_safe_matvec(Mp, alo) + _safe_matvec(Mn, ahi), n)
        err_hi = product_error(_safe_matvec(Mp, ahi) + _safe_matvec(Mn, alo), n)
        return down(new_lo - err_lo), up(new_hi + err_hi)


def _safe_matvec(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v @ M.T`` for nonnegative ``M``, treating ``0 * inf`` as 0."""
    if np.all(np.isfinite(v)):
        prod: np.ndarray = v @ M.T
        return prod
    out = np.where(M[None, ...] > 0, M[None, ...] * v.reshape(-1, 1, v.shape[-1]), 0.0).sum(-1)
    shaped: np.ndarray = out.reshape(*v.shape[:-1], M.shape[0])
    return shaped


class Box:
    """An interval vector ``[lo, hi]`` ([Tang2019, Definition 1]), possibly time-varying.

    Parameters
    ----------
    lo, hi : array_like
        Bounds of shape ``(n,)``, or ``(T, n)`` for bounds that vary with the step ``k``.
        Infinite bounds are allowed (no information); NaN is not; ``lo <= hi`` is required.
    """

    __slots__ = ("hi", "lo")
    __array_priority__ = 100  # so that ``M @ box`` reaches ``Box.__rmatmul__``
    _zonotope: ClassVar[type[Zonotope]]
    """The zonotope type, set by :mod:`ivobs.sets.zonotope` when it defines it (that module
    imports this one; importing it back would be a cycle). :mod:`ivobs.sets` imports both, so it
    is set before any box exists."""

    def __init__(self, lo: Any, hi: Any) -> None:
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
        return cls._trusted(np.full(n, np.nan), np.full(n, np.nan))

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
        out: np.ndarray = 0.5 * (self.lo + self.hi)
        return out

    @property
    def radius(self) -> np.ndarray:
        """Half-width ``(hi - lo) / 2``."""
        out: np.ndarray = 0.5 * (self.hi - self.lo)
        return out

    @property
    def width(self) -> np.ndarray:
        """``hi - lo``."""
        out: np.ndarray = self.hi - self.lo
        return out

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
        """Interval hull of ``M [lo, hi]`` ([Efimov2013, Lemma 1]; exact per component, then
        widened by its proven rounding: :func:`image_bounds`)."""
        M = as_matrix("M", M, cols=self.dim, vector="row")
        return Box._trusted(*image_bounds(M, self.lo, self.hi))

    def __rmatmul__(self, M: Any) -> Box:
        return self.linear_map(M)

    def __add__(self, other: Any) -> Any:
        """Minkowski sum with a box (a box), or with a zonotope (a zonotope, the box's generators
        first); a vector translates. A set of a richer kind (a constrained zonotope) answers
        through its ``__radd__``."""
        if isinstance(other, Box._zonotope):
            return self.to_zonotope() + other
        if isinstance(other, Box):
            if other.dim != self.dim:
                raise IvobsError(f"Box + Box: dimensions differ ({self.dim} and {other.dim})")
            return Box._trusted(down(self.lo + other.lo), up(self.hi + other.hi))
        if hasattr(other, "interval_hull"):
            return NotImplemented
        v = as_float_array("translation", other)
        return Box._trusted(down(self.lo + v), up(self.hi + v))

    __radd__ = __add__

    def interval_hull(self) -> Box:
        """The box itself."""
        return self

    def to_zonotope(self) -> Zonotope:
        """``<center, diag(radius)>`` (only for constant, bounded boxes)."""
        if self.is_time_varying or not self.is_bounded:
            raise IvobsError("to_zonotope: needs a constant box with finite bounds")
        c, r = mid_rad(self.lo, self.hi)  # contains the box exactly (c, r rounded)
        return Box._zonotope(c, np.diag(r))

    def vertices(self) -> np.ndarray:
        """All ``2^n`` vertices, shape ``(2^n, n)`` (``n <= 20``)."""
        if self.dim > 20 or self.is_time_varying or not self.is_bounded:
            raise IvobsError("vertices: needs a constant bounded box of dimension <= 20")
        bits = (np.arange(2**self.dim)[:, None] >> np.arange(self.dim)[None, :]) & 1
        return np.where(bits == 1, self.hi, self.lo)

    def sample(self, size: int, rng: Any = None) -> np.ndarray:
        """``size`` points drawn uniformly in the (constant, bounded) box."""
        rng = np.random.default_rng(rng)
        out: np.ndarray = rng.uniform(self.lo, self.hi, size=(size, self.dim))
        return out

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, Box)
            and np.array_equal(self.lo, other.lo, equal_nan=True)
            and np.array_equal(self.hi, other.hi, equal_nan=True)
        )

    __hash__ = None  # type: ignore[assignment]

    def _repr_html_(self) -> str:
        """Jupyter: the bounds and widths."""
        from .._html import summary_html, vector

        if self.is_time_varying:
            return summary_html(
                "ivobs Box", [("time-varying", f"T = {self.lo.shape[0]}, n = {self.dim}")]
            )
        rows = [
            ("lower", vector(self.lo)),
            ("upper", vector(self.hi)),
            ("width", vector(self.hi - self.lo)),
        ]
        return summary_html("ivobs Box", rows)

    def __repr__(self) -> str:
        if self.is_time_varying:
            return f"Box(time-varying, T={self.lo.shape[0]}, n={self.dim})"
        lo = np.array2string(self.lo, precision=4)
        hi = np.array2string(self.hi, precision=4)
        return f"Box(lo={lo}, hi={hi})"
