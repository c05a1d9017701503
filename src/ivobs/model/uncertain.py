"""Interval matrices: ``A``, ``B``, ``C``, ``D`` known only to lie in a box of matrices.

``LinearSystem(ivobs.Box(A_lo, A_hi), B, C, ...)`` means that at every step ``k`` the plant uses
*some* matrix ``A[k]`` with ``A_lo <= A[k] <= A_hi`` (entrywise; it may change from step to step,
e.g. a friction known to ±5 %). Following [Efimov2013]'s treatment of an uncertain state matrix
(``A = A0 + ΔA``, the observer designed for the nominal ``A0``, the term ``ΔA x`` bounded from
the current box), ivobs splits every interval matrix ``M ∈ [M_lo, M_hi]`` into

    M = M0 + ΔM,    M0 = (M_lo + M_hi) / 2  (the nominal matrix, used by every design),
                    |ΔM| <= R_M              (entrywise; R_M the radius, rounded up)

so that the plant is the nominal one with two extra, state-dependent bounded terms::

    x[k+1] = A0 x + B0 u + E d + w,   w = ΔA x + ΔB u,   |w| <= R_A |x| + R_B |u|
    y[k]   = C0 x + D0 u + F d + v,   v = ΔC x + ΔD u,   |v| <= R_C |x| + R_D |u|

with ``|x|`` the entrywise largest magnitude over the current enclosure of ``x[k]``: for the
symmetric interval matrix ``[-R, R]`` and ``x ∈ [x̲, x̄]`` the interval product is exactly
``[-R m, R m]``, ``m = max(|x̲|, |x̄|)`` (each entry ``ΔA_ij x_j`` ranges over
``±R_ij max |x_j|`` independently): the exact hull, so never wider than the interval-matrix
bound of [Efimov2012, Lemma 1] (the matrix form of [Efimov2013, Lemma 1]). The estimators that
accept interval matrices add these terms to their own recursion
(``ivobs.estimators._uncertain``, rounded upwards); docs/uncertain.md.

Only ``A``, ``B``, ``C``, ``D`` may be interval matrices (an uncertain ``E`` or ``F`` is a wider
box ``d``); the system must then be discrete-time, dense and time-invariant otherwise.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from .._validate import _shape_str, as_matrix
from ..errors import IvobsError
from ..sets import Box

if TYPE_CHECKING:
    from ._matrix import Matrix
    from .protocol import BoundsLike

__all__ = [
    "INTERVAL_MATRICES",
    "IntervalMatrices",
    "MatrixUncertainty",
    "interval_matrix",
    "realisation",
]

INTERVAL_MATRICES = ("A", "B", "C", "D")
"""The matrices that may be given as interval matrices (an ``ivobs.Box`` of matrices)."""


def _radius(lo: np.ndarray, mid: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``R >= max(hi - mid, mid - lo)`` in exact arithmetic: each difference of two floats is
    rounded to nearest, so one step up (``nextafter``) bounds it; exact entries stay 0."""
    r = np.maximum(hi - mid, mid - lo)
    out: np.ndarray = np.where(r > 0, np.nextafter(r, np.inf), 0.0)
    return out


def interval_matrix(
    name: str, box: Box, rows: int | None, cols: int | None, vector: str
) -> tuple[np.ndarray, np.ndarray, Box]:
    """Validate the interval matrix ``box`` given for ``name`` (its bounds read as matrices,
    a vector as a column or a row like an exact matrix); returns the nominal (midpoint)
    matrix ``M0``, the radius ``R`` (``|M - M0| <= R`` for every ``M`` in the box) and the box
    with matrix bounds."""
    if name not in INTERVAL_MATRICES:
        raise IvobsError(
            f"{name}: an interval matrix (ivobs.Box) is accepted for A, B, C and D only; "
            f"an uncertain {name} is a wider box of the disturbance d"
        )
    shape = tuple(int(s) for s in box.lo.shape)
    try:  # (as_matrix also refuses a bound that is not finite)
        lo = as_matrix(f"{name} (lower bound of the interval matrix)", box.lo, rows, cols,
                       vector=vector)  # fmt: skip
        hi = as_matrix(f"{name} (upper bound of the interval matrix)", box.hi, rows, cols,
                       vector=vector)  # fmt: skip
    except IvobsError as exc:
        raise IvobsError(
            f"{exc} (a Box in the place of {name} is an interval matrix: its bounds are the "
            f"entrywise lower and upper {name}, of shape {_shape_str(shape)})"
        ) from None
    mid = 0.5 * lo + 0.5 * hi  # no overflow; the radius below covers its rounding
    return mid, _radius(lo, mid, hi), Box._trusted(lo, hi)


@dataclass(frozen=True)
class MatrixUncertainty:
    """The radii ``R_A``, ``R_B``, ``R_C``, ``R_D`` of a system's interval matrices around its
    nominal matrices (zeros for the exact ones): ``|M - M0| <= R_M`` entrywise."""

    RA: np.ndarray
    RB: np.ndarray
    RC: np.ndarray
    RD: np.ndarray

    @property
    def acts_on_state(self) -> bool:
        """Whether ``w = ΔA x + ΔB u`` can be nonzero."""
        return bool(self.RA.any() or self.RB.any())

    @property
    def acts_on_output(self) -> bool:
        """Whether ``v = ΔC x + ΔD u`` can be nonzero."""
        return bool(self.RC.any() or self.RD.any())

    def exact_rows(self) -> np.ndarray:
        """Outputs whose rows of ``C`` and ``D`` are exact (no ``v`` in them)."""
        out = ~(self.RC.any(axis=1) | self.RD.any(axis=1))
        return np.asarray(out)


def realisation(
    boxes: dict[str, Box], nominal: dict[str, np.ndarray], kind: str, T: int, seed: Any = None
) -> dict[str, np.ndarray]:
    """Matrices inside the interval matrices at each of ``T`` steps, ``name -> (T, r, c)``:
    ``kind`` ``"vertex"`` (every uncertain entry at its lower or upper bound, redrawn at every
    step: the adversarial case), ``"uniform"``, ``"sinusoidal"`` (entry ``(i, j)`` moves as
    ``sin(ω k + φ)`` across its interval), or ``"nominal"`` (the midpoints)."""
    rng = np.random.default_rng(seed)
    out: dict[str, np.ndarray] = {}
    for n, (name, box) in enumerate(sorted(boxes.items())):
        lo, hi = box.lo[None], box.hi[None]
        shape = (T, *box.lo.shape)
        if kind == "vertex":
            out[name] = np.where(rng.integers(0, 2, size=shape).astype(bool), hi, lo)
        elif kind == "uniform":
            out[name] = rng.uniform(lo, hi, size=shape)
        elif kind == "sinusoidal":
            size = box.lo.size
            w = (0.21 + 0.37 * (np.arange(size) + 3 * n)).reshape(box.lo.shape)
            s = np.sin(np.arange(T)[:, None, None] * w[None] + 0.7 * n)
            out[name] = np.clip(nominal[name][None] + 0.5 * (hi - lo) * s, lo, hi)
        elif kind == "nominal":
            out[name] = np.broadcast_to(nominal[name], shape).copy()
        else:
            raise IvobsError(
                f"kind: unknown realisation {kind!r} of the interval matrices; expected "
                "'vertex', 'uniform', 'sinusoidal' or 'nominal'"
            )
    return out


class IntervalMatrices:
    """What :class:`~ivobs.LinearSystem` knows of its interval matrices (a mix-in: the
    validation of a Box given for ``A``, ``B``, ``C``, ``D``, and the members that expose it)."""

    nx: int
    nu: int
    ny: int
    nd: int
    dt: bool | float
    _d: BoundsLike
    _boxes: dict[str, tuple[Box, np.ndarray]]
    _uncertainty: MatrixUncertainty | None

    if TYPE_CHECKING:  # provided by LinearSystem

        def _mats(self) -> tuple[Matrix, ...]: ...

        @property
        def is_continuous(self) -> bool: ...

        @property
        def is_time_varying(self) -> bool: ...

    def _interval(
        self, name: str, value: Any, rows: int | None, cols: int | None, vector: str
    ) -> Any:
        """``value`` itself, or for an interval matrix its nominal (midpoint) matrix, the box
        and its radius kept in ``self._boxes``."""
        if not isinstance(value, Box):
            return value
        mid, radius, box = interval_matrix(name, value, rows, cols, vector)
        self._boxes[name] = (box, radius)
        return mid

    def _check_uncertain(self) -> MatrixUncertainty | None:
        """The radii of the interval matrices (None: exactly known matrices), after checking
        what an uncertain system must be."""
        if not self._boxes:
            return None
        self._boxes = {n: self._boxes[n] for n in INTERVAL_MATRICES if n in self._boxes}
        which = ", ".join(self._boxes)
        if self.is_continuous:
            raise IvobsError(
                f"{which}: interval matrices are supported in discrete time only (dt=True or a "
                "period > 0); this system is continuous-time (dt=0)"
            )
        if self.is_time_varying or any(m.sp is not None for m in self._mats()):
            raise IvobsError(
                f"{which}: a system with interval matrices needs its other matrices constant "
                "and dense (not stacked, callable or scipy.sparse)"
            )
        shapes = {"A": (self.nx, self.nx), "B": (self.nx, self.nu),
                  "C": (self.ny, self.nx), "D": (self.ny, self.nu)}  # fmt: skip
        radii = {n: self._boxes[n][1] if n in self._boxes else np.zeros(shapes[n])
                 for n in INTERVAL_MATRICES}  # fmt: skip
        return MatrixUncertainty(radii["A"], radii["B"], radii["C"], radii["D"])

    @property
    def is_uncertain(self) -> bool:
        """True when some of ``A``, ``B``, ``C``, ``D`` is an interval matrix."""
        return self._uncertainty is not None

    @property
    def uncertainty(self) -> MatrixUncertainty | None:
        """The radii ``R_A, R_B, R_C, R_D`` around the nominal matrices (None when exact)."""
        return self._uncertainty

    def interval_matrices(self) -> dict[str, Box]:
        """The interval matrices given, ``name -> Box`` with matrix bounds (empty when every
        matrix is exact)."""
        return {n: box for n, (box, _) in self._boxes.items()}

    @property
    def A_box(self) -> Box | None:
        """``A`` as an interval matrix (a Box with ``(nx, nx)`` bounds), or None when exact."""
        return self._boxes["A"][0] if "A" in self._boxes else None

    @property
    def B_box(self) -> Box | None:
        """``B`` as an interval matrix, or None when exact."""
        return self._boxes["B"][0] if "B" in self._boxes else None

    @property
    def C_box(self) -> Box | None:
        """``C`` as an interval matrix, or None when exact."""
        return self._boxes["C"][0] if "C" in self._boxes else None

    @property
    def D_box(self) -> Box | None:
        """``D`` as an interval matrix, or None when exact."""
        return self._boxes["D"][0] if "D" in self._boxes else None

    def nominal(self) -> Any:
        """The same system with the nominal (midpoint) matrices, exactly known (a
        :class:`~ivobs.LinearSystem`; the system itself when it is exact)."""
        if not self.is_uncertain:
            return self
        A, B, C, D, E, F = (m.at(0) for m in self._mats())
        system: Any = type(self)  # LinearSystem (this is its mix-in)
        return system(A, B, C, D=D, E=E if self.nd else None, F=F if self.nd else None,
                      d=self._d, dt=self.dt)  # fmt: skip

    def realisation(self, kind: str, T: int, seed: Any = None) -> dict[str, np.ndarray]:
        """Matrices inside the interval matrices for ``T`` steps, ``name -> (T, r, c)``, for
        :func:`ivobs.simulate` (``matrices=``): ``kind`` ``"vertex"`` (entries on their bounds,
        redrawn every step), ``"uniform"``, ``"sinusoidal"`` or ``"nominal"``
        (:func:`ivobs.model.uncertain.realisation`)."""
        nominal = {n: self._mats()["ABCD".index(n)].at(0) for n in self._boxes}
        return realisation(self.interval_matrices(), nominal, kind, int(T), seed)
