"""The constrained zonotope ``<c, G, A, b>`` ([Scott2016, Definition 3]) and its set operations.

Linear map, Minkowski sum and (generalised) intersection are exact and cheap ([Scott2016,
Proposition 1]); evaluated in floating point, each adds the proven bound of its rounding
(:mod:`ivobs.sets.rounding`): a box of generators for the ``x`` part, a slack factor per new
constraint (``A ξ + diag(s) τ = b``), so the result contains the exact one. Questions (hull,
emptiness, membership) are the LPs of :mod:`.hull`; reduction is :mod:`.elimination` then
:mod:`.reduction`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._validate import as_float_array, as_matrix, as_vector, check_finite
from ...errors import InconsistentDataError, IvobsError
from ..box import Box
from ..lp import LinearProgram, csc
from ..rounding import UNIT_ROUNDOFF, product_error, up
from ..zonotope import Zonotope, box_generators, center_and_generators
from .elimination import Reduced, eliminate_constraints, rescale_factors
from .hull import certified_empty, hull_bounds, reaches
from .reduction import reduce_generators

__all__ = ["ConstrainedZonotope"]


class ConstrainedZonotope:
    """``<c, G, A, b> = {c + G ξ : ‖ξ‖∞ <= 1, A ξ = b}`` ([Scott2016, Definition 3]).

    Parameters
    ----------
    center : (n,)
    generators : (n, m), optional (``m = 0`` when omitted)
    A : (nc, m), optional (no constraint: a zonotope)
    b : (nc,), required with ``A``

    Notes
    -----
    Answers the verbs of :class:`~ivobs.Box` and :class:`~ivobs.Zonotope` (``M @ Z``, ``Z + W``,
    ``interval_hull()``, ``reduce()``, ``contains()``) plus ``intersect``, ``intersect_strip``,
    ``intersect_hyperplane`` and ``is_empty``.
    """

    __slots__ = ("A", "G", "b", "c")
    __array_priority__ = 100

    def __init__(self, center: Any, generators: Any = None, A: Any = None, b: Any = None):
        c, G = center_and_generators("ConstrainedZonotope", center, generators)
        m = G.shape[1]
        if (A is None) != (b is None):
            raise IvobsError("ConstrainedZonotope: give both A and b (A ξ = b), or neither")
        if A is None:
            A_ = np.zeros((0, m))
            b_ = np.zeros(0)
        else:
            A_ = as_float_array("ConstrainedZonotope A", A)
            if A_.ndim == 1:
                A_ = A_.reshape(1, -1)
            if A_.ndim != 2 or A_.shape[1] != m:
                raise IvobsError(
                    f"ConstrainedZonotope A: expected shape (nc, {m}) (one column per "
                    f"generator), got {A_.shape}"
                )
            check_finite("ConstrainedZonotope A", A_)
            b_ = as_vector("ConstrainedZonotope b", b, A_.shape[0]) if A_.shape[0] else np.zeros(0)
        self.c, self.G, self.A, self.b = c, G, A_, b_

    @classmethod
    def _trusted(
        cls, c: np.ndarray, G: np.ndarray, A: np.ndarray, b: np.ndarray
    ) -> ConstrainedZonotope:
        z = object.__new__(cls)
        z.c, z.G, z.A, z.b = c, G, A, b
        return z

    @classmethod
    def from_box(cls, box: Box) -> ConstrainedZonotope:
        """``<center, diag(radius)>`` with no constraint (constant bounded boxes)."""
        z = box.to_zonotope()
        keep = np.any(z.G != 0, axis=0)
        return cls._trusted(z.c, z.G[:, keep], np.zeros((0, int(keep.sum()))), np.zeros(0))

    @classmethod
    def from_zonotope(cls, z: Zonotope) -> ConstrainedZonotope:
        """The zonotope ``<c, G>`` (no constraint)."""
        return cls._trusted(z.c.copy(), z.G.copy(), np.zeros((0, z.G.shape[1])), np.zeros(0))

    # -- properties ---------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        return int(self.c.shape[0])

    @property
    def num_generators(self) -> int:
        return int(self.G.shape[1])

    @property
    def num_constraints(self) -> int:
        return int(self.A.shape[0])

    # -- exact operations ([Scott2016, Proposition 1]) ----------------------------------------
    def linear_map(self, M: Any) -> ConstrainedZonotope:
        """``M Z = <M c, M G, A, b>`` ([Scott2016, Proposition 1]), plus the box of generators
        of its rounding, ``product_error(|M| (|c| + |G| 1))``."""
        M = as_matrix("M", M, cols=self.dim, vector="row")
        n, m = self.G.shape
        e = product_error(np.abs(M) @ (np.abs(self.c) + np.abs(self.G).sum(axis=1)), n + m + 1)
        return ConstrainedZonotope._of(Reduced(M @ self.c, M @ self.G, self.A, self.b, e))

    def __rmatmul__(self, M: Any) -> ConstrainedZonotope:
        return self.linear_map(M)

    def __add__(self, other: Any) -> ConstrainedZonotope:
        """Minkowski sum ([Scott2016, Proposition 1]) with a constrained zonotope, zonotope or
        box; a vector translates."""
        other = _lift(other)
        if isinstance(other, ConstrainedZonotope):
            if other.dim != self.dim:
                raise IvobsError(f"Minkowski sum: dimensions differ ({self.dim}, {other.dim})")
            A = np.block(
                [
                    [self.A, np.zeros((self.num_constraints, other.num_generators))],
                    [np.zeros((other.num_constraints, self.num_generators)), other.A],
                ]
            )
            return ConstrainedZonotope._trusted(
                self.c + other.c, np.hstack([self.G, other.G]), A, np.concatenate([self.b, other.b])
            )._with_sum_error()
        v = as_vector("translation", other, self.dim)
        return ConstrainedZonotope._trusted(self.c + v, self.G, self.A, self.b)._with_sum_error()

    def _with_sum_error(self) -> ConstrainedZonotope:
        """The set with the box of the rounding of its centre, a sum: ``u |c|``."""
        e = up(UNIT_ROUNDOFF * np.abs(self.c))
        return ConstrainedZonotope._of(Reduced(self.c, self.G, self.A, self.b, e))

    def __radd__(self, other: Any) -> ConstrainedZonotope:
        """``other + Z`` for a box, zonotope or vector: the left operand's generators first, as
        in ``Box + Zonotope``."""
        other = _lift(other)
        return other + self if isinstance(other, ConstrainedZonotope) else self.__add__(other)

    def intersect(self, other: Any, R: Any = None) -> ConstrainedZonotope:
        """Generalised intersection ``Z ∩_R Y = {z ∈ Z : R z ∈ Y}`` ([Scott2016, Proposition
        1]); ``R = I`` (plain intersection) by default. ``Y`` may be a constrained zonotope,
        zonotope or box."""
        other = _lift(other)
        if not isinstance(other, ConstrainedZonotope):
            raise IvobsError(
                f"intersect: expected a ConstrainedZonotope, Zonotope or Box, "
                f"got {type(other).__name__}"
            )
        R_ = np.eye(self.dim) if R is None else as_matrix("R", R, other.dim, self.dim)
        if R is None and other.dim != self.dim:
            raise IvobsError(f"intersect: dimensions differ ({self.dim}, {other.dim})")
        m1, m2 = self.num_generators, other.num_generators
        # the new rows R G ξ − G_y η = c_y − R c, up to their rounding: a slack factor per row
        s = product_error(
            np.abs(R_) @ (np.abs(self.c) + np.abs(self.G).sum(axis=1)) + np.abs(other.c),
            m1 + self.dim + 1,
        )
        p = other.dim
        A = np.block(
            [
                [self.A, np.zeros((self.num_constraints, m2 + p))],
                [
                    np.zeros((other.num_constraints, m1)),
                    other.A,
                    np.zeros((other.num_constraints, p)),
                ],
                [R_ @ self.G, -other.G, np.diag(s)],
            ]
        )
        b = np.concatenate([self.b, other.b, other.c - R_ @ self.c])
        G = np.hstack([self.G, np.zeros((self.dim, m2 + p))])
        return ConstrainedZonotope._trusted(self.c, G, A, b)

    def intersect_hyperplane(self, h: Any, y: float) -> ConstrainedZonotope:
        """``{x ∈ Z : hᵀx = y}``: one constraint ``hᵀG ξ = y - hᵀc`` (``Y`` a point), with a
        slack factor of the size of its rounding."""
        h = as_vector("h", h, self.dim)
        return self.intersect(ConstrainedZonotope([float(y)]), R=h[None, :])

    def intersect_strip(self, h: Any, y: float, sigma: float) -> ConstrainedZonotope:
        """``{x ∈ Z : |hᵀx - y| <= σ}`` (``Z ∩_R Y`` with ``Y = <y, σ>``, ``R = hᵀ``): one
        constraint and one generator more."""
        if not np.isfinite(sigma) or sigma < 0:
            raise IvobsError(f"sigma: expected a half-width >= 0, got {sigma}")
        return self.intersect(ConstrainedZonotope([float(y)], [[float(sigma)]]), R=np.atleast_2d(h))

    # -- questions (linear programs) ----------------------------------------------------------
    def is_empty(self) -> bool:
        """Whether no ``ξ`` in the unit box meets ``A ξ = b``, certainly: one LP, whose dual
        certificate is checked in floating point with the margin :data:`EMPTY_TOL`
        (:func:`certified_empty`)."""
        return certified_empty(self.A, self.b)

    def interval_hull(self) -> Box:
        """The smallest box containing the set: ``2 n`` LPs with HiGHS, each bound certified by
        duality (see the module docstring). Raises :class:`~ivobs.InconsistentDataError` for an
        empty set."""
        out = hull_bounds(self.c, self.G, self.A, self.b)
        if out is None:
            raise InconsistentDataError("interval_hull: the constrained zonotope is empty")
        return Box._trusted(*out)

    def contains(self, x: Any, tol: float = 1e-9) -> bool:
        """Whether ``x`` is in the set (one LP: ``min ‖ξ‖∞`` with ``G ξ = x - c``, ``A ξ = b``)."""
        x = as_vector("x", x, self.dim)
        return reaches(np.vstack([self.G, self.A]), np.concatenate([x - self.c, self.b]), tol)

    # -- reduction ([Scott2016, Section 4]) ---------------------------------------------------
    def rescale(self) -> ConstrainedZonotope:
        """The set (a superset, by its rounding) with its factors rescaled to their propagated
        bounds ([Scott2016, Section 4.2]). Raises :class:`~ivobs.InconsistentDataError` when
        propagation proves it empty."""
        out = rescale_factors(self.c, self.G, self.A, self.b)
        if out is None:
            raise InconsistentDataError("rescale: the constrained zonotope is empty")
        return ConstrainedZonotope._of(out)

    @classmethod
    def _of(cls, r: Reduced) -> ConstrainedZonotope:
        """``<c, G, A, b> ⊕ box(e)`` as one constrained zonotope."""
        box = box_generators(r.e)
        A = np.concatenate([r.A, np.zeros((r.A.shape[0], box.shape[1]))], axis=1)
        return cls._trusted(r.c, np.concatenate([r.G, box], axis=1), A, r.b)

    def reduce(
        self, max_generators: int | None = None, max_constraints: int | None = None
    ) -> ConstrainedZonotope:
        """A constrained zonotope containing this one with at most ``max_constraints``
        constraints (eliminated first, [Scott2016, Section 4.2]) and ``max_generators``
        generators (lifted zonotope reduction, [Scott2016, Section 4.3]). ``None`` leaves that
        count alone."""
        c, G, A, b = self.c, self.G, self.A, self.b
        if max_constraints is not None:
            if max_constraints < 0:
                raise IvobsError(f"max_constraints: expected >= 0, got {max_constraints}")
            out = eliminate_constraints(c, G, A, b, int(max_constraints))
            if out is None:
                raise InconsistentDataError("reduce: the constrained zonotope is empty")
            z = ConstrainedZonotope._of(out)
            c, G, A, b = z.c, z.G, z.A, z.b
        if max_generators is not None:
            c, G, A, b = reduce_generators(c, G, A, b, int(max_generators))
        return ConstrainedZonotope._trusted(c, G, A, b)

    def to_zonotope(self) -> Zonotope:
        """A zonotope containing the set (every constraint eliminated)."""
        z = self.reduce(max_constraints=0)
        return Zonotope._trusted(z.c, z.G)

    def sample(self, size: int, rng: Any = None) -> np.ndarray:
        """Vertices of the set that maximise random linear objectives (one LP each; for tests
        and plots)."""
        rng = np.random.default_rng(rng)
        m, nc = self.num_generators, self.num_constraints
        if m == 0:
            return np.tile(self.c, (size, 1))
        lp = LinearProgram(presolve=True)
        ones = np.ones(m)
        lp.load(csc(self.A), nc, -ones, ones, self.b, self.b)
        pts = []
        for _ in range(size):
            lp.set_cost(np.arange(m), -(rng.normal(size=self.dim) @ self.G))
            if lp.solve() != "optimal":
                raise InconsistentDataError("sample: the constrained zonotope is empty")
            pts.append(self.c + self.G @ lp.primal())
        return np.array(pts)

    def __repr__(self) -> str:
        return (
            f"ConstrainedZonotope(n={self.dim}, generators={self.num_generators}, "
            f"constraints={self.num_constraints})"
        )


def _lift(other: Any) -> Any:
    """A box or zonotope as a constrained zonotope (anything else as it is)."""
    if isinstance(other, Box):
        return ConstrainedZonotope.from_box(other)
    if isinstance(other, Zonotope):
        return ConstrainedZonotope.from_zonotope(other)
    return other
