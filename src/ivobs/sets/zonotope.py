"""Zonotopes ``<c, G> = {c + G b : ||b||_inf <= 1}``, and boxes of rounding errors as generators.

A zonotope answers the verbs of :class:`~ivobs.Box` ([Tang2019, Properties 1–4]): linear map
(``M @ Z``), Minkowski sum (``Z1 + Z2``, a box or a vector too), ``interval_hull()`` (exact),
``contains``, plus ``reduce`` (order reduction, [Combastel2015]). As in [Tang2019] and
[Wang2020], the *order* of a zonotope is its number of generators ``m`` (CORA calls ``m / n`` the
order).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .._validate import as_float_array, as_matrix, as_vector, check_finite
from ..errors import IvobsError
from ..linalg import UNIT_ROUNDOFF, gamma
from .box import Box
from .rounding import enclose, product_error, up, upper

__all__ = ["MAX_BASIS_CONDITION", "Zonotope", "box_generators", "reduce_girard"]


def _sum_error(c: np.ndarray) -> np.ndarray:
    """Generators of the box of the rounding of a centre ``c = fl(a + b)``: ``|c − (a + b)|
    <= u |c|`` (plus nothing where ``c`` is exact, i.e. zero)."""
    return box_generators(up(UNIT_ROUNDOFF * np.abs(c)))


def box_generators(r: np.ndarray) -> np.ndarray:
    """The box ``[-r, r]`` as generator columns ``diag(r)``, only the nonzero ones (a box of
    rounding errors appended to a zonotope's generators)."""
    out: np.ndarray = np.diag(r)[:, r > 0]
    return out


MAX_BASIS_CONDITION = 1e3
"""Largest condition estimate ``|R_11| / |R_nn|`` of a basis of generators into which the
parallelotope reductions absorb the others (:func:`ivobs.sets.reduction.reduce_parallelotope`,
:func:`ivobs.sets.czonotope.reduce_generators`; above it, Girard's box)."""


def reduce_girard(G: np.ndarray, order: int) -> np.ndarray:
    """At most ``order`` generators (``order >= n``) by [Girard2005]'s rule (CORA's default
    ``"girard"`` reduction): the ``m - order + n`` generators with the smallest
    ``‖g‖₁ - ‖g‖∞`` (what enclosing ``g`` in a box costs: nothing for a generator along an
    axis, such as the box of the previous reduction) are enclosed in the box
    ``diag(Σ |g|)``, its sums rounded up, so ``<0, G> ⊆ <0, G'>`` in exact arithmetic."""
    n, m = G.shape
    if m <= order:
        return G
    n_rm = m - order + n
    aG = np.abs(G)
    idx = np.argsort(aG.sum(axis=0) - aG.max(axis=0), kind="stable")
    box = aG[:, idx[:n_rm]].sum(axis=1) * (1.0 + gamma(n_rm + 1))
    return np.hstack([G[:, np.sort(idx[n_rm:])], np.diag(box)])


def center_and_generators(who: str, center: Any, generators: Any) -> tuple[np.ndarray, np.ndarray]:
    """The checked centre ``c`` (n,) and generator matrix ``G`` (n, m) of a zonotope-like set
    (``who``: the class named in errors); ``None`` generators: a point."""
    c = as_vector(f"{who} center", center)
    n = c.shape[0]
    if generators is None:
        return c, np.zeros((n, 0))
    G = as_float_array(f"{who} generators", generators)
    if G.ndim == 1 and n == 1:
        G = G.reshape(1, -1)
    if G.ndim != 2 or G.shape[0] != n:
        raise IvobsError(f"{who} generators: expected shape ({n}, m), got {G.shape}")
    check_finite(f"{who} generators", G)
    return c, G


class Zonotope:
    """``<c, G> = {c + G b : ||b||_inf <= 1}`` ([Tang2019, Definition 3], [Wang2020,
    Definition 3]).

    Parameters
    ----------
    center : array_like, shape ``(n,)``
    generators : array_like, shape ``(n, m)`` (``m`` may be 0)
    """

    __slots__ = ("G", "c")
    __array_priority__ = 100

    def __init__(self, center: Any, generators: Any = None) -> None:
        self.c, self.G = center_and_generators("Zonotope", center, generators)

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
        """Number of generators ``m`` (the zonotope's *order* in [Wang2020] and [Tang2019])."""
        return int(self.G.shape[1])

    def radius(self) -> np.ndarray:
        """Radius of the interval hull: ``sum_j |G_ij|`` ([Tang2019, Property 4, eq. (5)]),
        rounded up (an upper bound of the exact sum)."""
        out: np.ndarray = upper(np.abs(self.G).sum(axis=1), self.G.shape[1])
        return out

    def interval_hull(self) -> Box:
        """Smallest box containing the zonotope ([Tang2019, Property 4, eq. (5)]), its bounds
        rounded outward: it contains the exact hull."""
        return Box._trusted(*enclose(self.c, self.radius()))

    def linear_map(self, M: Any) -> Zonotope:
        """``M <c, G> = <M c, M G>`` ([Tang2019, Property 3, eq. (4b)]) evaluated in floating
        point, plus the box ``diag(e)`` of its proven rounding error, ``e >= |fl(M c) − M c| +
        Σ_j |fl(M G)_j − M G_j|`` (:func:`~ivobs.sets.rounding.product_error` of
        ``|M| (|c| + |G| 1)``), so the result contains the exact image."""
        M = as_matrix("M", M, cols=self.dim, vector="row")
        return self._map(M, np.abs(M))

    def _map(self, M: np.ndarray, absM: np.ndarray) -> Zonotope:
        """:meth:`linear_map` by a finite float matrix ``M`` of the right width, ``absM = |M|``
        (the estimators' maps at every step: checked and taken once)."""
        n, m = self.G.shape
        e = product_error(absM @ (np.abs(self.c) + np.abs(self.G).sum(axis=1)), n + m + 1)
        G = np.concatenate([M @ self.G, box_generators(e)], axis=1)
        return Zonotope._trusted(M @ self.c, G)

    def __rmatmul__(self, M: Any) -> Zonotope:
        return self.linear_map(M)

    def __add__(self, other: Any) -> Zonotope:
        """Minkowski sum ([Tang2019, Property 3, eq. (4a)]) with a zonotope or a box; a vector
        translates. A set of a richer kind (a constrained zonotope) answers through its
        ``__radd__``."""
        if isinstance(other, Box):
            other = other.to_zonotope()
        if isinstance(other, Zonotope):
            if other.dim != self.dim:
                raise IvobsError(
                    f"Zonotope + Zonotope: dimensions differ ({self.dim}, {other.dim})"
                )
            c = self.c + other.c
            return Zonotope._trusted(c, np.hstack([self.G, other.G, _sum_error(c)]))
        if hasattr(other, "interval_hull"):
            return NotImplemented
        v = as_vector("translation", other, self.dim)
        c = self.c + v
        return Zonotope._trusted(c, np.hstack([self.G, _sum_error(c)]))

    __radd__ = __add__

    def reduce(self, order: int, weight: Any = None) -> Zonotope:
        """Order reduction ``↓_{q,W}`` of [Tang2019, Remark 2] ([Combastel2015]'s operator).

        Keeps at most ``q = order`` generators (``q >= n``): the generators are sorted by the
        weighted norm ``h^T W h`` (``W`` positive definite, identity by default); the ``q - n``
        largest are kept and the others are enclosed in the box ``diag(sum_j |h_ij|)``. The
        result contains the original zonotope ([Tang2019, Remark 2]: ``<0, H> ⊆ <0, ↓H>``).
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
        rest = G[:, order_idx[q - n :]]
        box = upper(np.abs(rest).sum(axis=1), rest.shape[1])  # rounded up: contains the exact
        return Zonotope._trusted(self.c, np.concatenate([keep, np.diag(box)], axis=1))

    def contains(self, x: Any, tol: float = 1e-9) -> bool:
        """Whether ``x`` lies in the zonotope (one LP with HiGHS, ``min ‖ξ‖∞`` with ``G ξ = x -
        c``: the constrained zonotope's membership test with no constraint; for checks, not hot
        loops)."""
        from .czonotope.hull import reaches

        return reaches(self.G, as_vector("x", x, self.dim) - self.c, tol)

    def sample(self, size: int, rng: Any = None, *, vertices: bool = False) -> np.ndarray:
        """Points ``c + G b`` with ``b`` uniform in the cube (or on its vertices)."""
        rng = np.random.default_rng(rng)
        m = self.num_generators
        if vertices:
            b = rng.choice([-1.0, 1.0], size=(size, m))
        else:
            b = rng.uniform(-1.0, 1.0, size=(size, m))
        out: np.ndarray = self.c + b @ self.G.T
        return out

    def __repr__(self) -> str:
        return f"Zonotope(n={self.dim}, generators={self.num_generators})"


Box._zonotope = Zonotope  # Box.to_zonotope and Box + Zonotope (see Box._zonotope)
