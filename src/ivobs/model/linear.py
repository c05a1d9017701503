"""The linear model of ivobs, :class:`LinearSystem`, and its validation.

::

    x[k+1] = A x[k] + B u[k] + E d[k]          d[k] ∈ d   (unknown, bounded)
    y[k]   = C x[k] + D u[k] + F d[k]

One disturbance vector ``d`` enters both equations ([Wang2020] is exactly this: ``E = D1``,
``F = D2``). [Tang2019]'s separate process disturbance ``w`` and noise ``v`` are ``d = [w; v]``,
``E = [E 0]``, ``F = [0 F]``: see :meth:`LinearSystem.from_process_measurement`. [Efimov2013]
writes ``b(t)`` for ``B u + E d`` with interval bounds; [Dinh2024] writes ``(F, H, D, W)`` for
``(A, C, E, F)`` with ``u`` already multiplied by ``B``. The full mapping is in
``docs/notation.md``.

``dt=True`` or ``dt > 0`` is discrete time, ``dt=0`` continuous time (python-control's
convention): then ``x' = A x + B u + E d``. Matrices may be callables of the step ``k`` (of the
time ``t`` in continuous time) or stacked arrays ``(T, rows, cols)``: the system is then
time-varying. The bounds ``d`` may be a :class:`~ivobs.Box`, a box whose bounds are arrays over the
steps, or a callable ``(k, y_k) -> Box`` (bounds computed from the measurement, [Efimov2013,
Remark 1] and its Hénon example).

A :class:`LinearSystem` is a :class:`~ivobs.model.LinearModel` (the members estimators use).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from .. import linalg
from .._validate import _shape_str, as_float_array, as_matrix, check_finite
from ..errors import IvobsError
from ..sets import Box
from ._matrix import Matrix, MatrixLike, is_scipy_sparse
from .protocol import BoundsLike
from .statespace import SignalNames, from_statespace, is_statespace
from .uncertain import IntervalMatrices

if TYPE_CHECKING:
    from .protocol import LinearModel

__all__ = ["BoundsLike", "LinearSystem", "MatrixLike"]


def _radius_box(name: str, value: Any, n: int, matrix: str) -> Box:
    """``value`` as the bounds of the ``n`` components multiplied by ``matrix``: a Box of
    dimension ``n``, or ``n`` radii ``r`` meaning ``|.| <= r``."""
    if isinstance(value, Box):
        if value.dim != n:
            raise IvobsError(
                f"{name}: expected a Box of dimension {n} (the columns of {matrix}), got "
                f"dimension {value.dim}"
            )
        return value
    arr = as_float_array(name, value)
    if arr.ndim == 2 and 1 in arr.shape:
        arr = arr.ravel()
    if arr.ndim != 1 or arr.shape[0] != n:
        got = "a scalar" if arr.ndim == 0 else f"shape {_shape_str(arr.shape)}"
        raise IvobsError(
            f"{name}: expected a vector of {n} bound(s) (|{name}_i| <= r_i, one per column of "
            f"{matrix}) or an ivobs.Box of dimension {n}, got {got}"
        )
    check_finite(name, arr)
    if np.any(arr < 0):
        i = int(np.argmax(arr < 0))
        raise IvobsError(
            f"{name}: expected nonnegative bounds (|{name}_i| <= r_i), got {arr[i]} at index {i}"
        )
    return Box._trusted(0.0 - arr, 0.0 + arr)  # as Box.symmetric: no -0.0


def check_dt(dt: Any) -> bool | float:
    """The time base of a model (``LinearSystem``, ``NonlinearSystem``): ``True``, a sampling
    period ``> 0``, or ``0`` (continuous time)."""
    if dt is True:
        return True
    if dt is None or isinstance(dt, (str, bool)):
        raise IvobsError(
            f"dt: expected True or a period > 0 (discrete time) or 0 (continuous), got {dt!r}"
        )
    try:
        val = float(dt)
    except (TypeError, ValueError):
        raise IvobsError(f"dt: expected a number or True, got {dt!r}") from None
    if not np.isfinite(val) or val < 0:
        raise IvobsError(f"dt: expected True, a period > 0, or 0; got {dt!r}")
    return val


class TimeBase:
    """What the time base ``dt`` of a model says (:class:`LinearSystem`, ``NonlinearSystem``)."""

    dt: bool | float

    @property
    def is_continuous(self) -> bool:
        """``dt == 0``."""
        return self.dt is not True and self.dt == 0

    @property
    def is_discrete(self) -> bool:
        return not self.is_continuous

    @property
    def sampling_period(self) -> float:
        """The sampling period (1 for ``dt=True``, 0 in continuous time)."""
        return 1.0 if self.dt is True else float(self.dt)


class LinearSystem(IntervalMatrices, TimeBase):
    """``x+ = A x + B u + E d``, ``y = C x + D u + F d``, ``d ∈ d``.

    Parameters
    ----------
    A : (nx, nx) array, stacked ``(T, nx, nx)`` array, or callable ``k -> (nx, nx)``; or an
        interval matrix ``ivobs.Box(A_lo, A_hi)`` (bounds of shape ``(nx, nx)``): ``A[k]`` may
        be any matrix in the box, changing from step to step (see below)
    B : (nx, nu), optional (no known input when omitted); or an interval matrix
    C : (ny, nx), required; or an interval matrix
    D : (ny, nu), optional (zero); or an interval matrix
    E : (nx, nd), optional; requires ``d``
    F : (ny, nd), optional; requires ``d``
    d : Box of dimension ``nd`` (constant or with ``(T, nd)`` bounds), or callable
        ``(k, y_k) -> Box``. Required when ``E`` or ``F`` is given, and one of them must be given
        when ``d`` is.
    dt : ``True`` or a sampling period ``> 0`` for discrete time, ``0`` for continuous time.

    Notes
    -----
    **Interval matrices** (:mod:`ivobs.model.uncertain`, docs/uncertain.md): a :class:`~ivobs.Box`
    in the place of ``A``, ``B``, ``C`` or ``D`` makes the system *uncertain*
    (:attr:`is_uncertain`): ``sys.A`` etc. are then the nominal (midpoint) matrices, which every
    design uses, :attr:`A_box` etc. the interval matrices, :attr:`uncertainty` their radii.

    Raises
    ------
    IvobsError
        Non-finite matrices, shape mismatches, ``lo > hi`` in the bounds, a disturbance matrix
        without bounds (or bounds without a matrix), an invalid ``dt``.
    """

    names: SignalNames = SignalNames()
    """Names of states, inputs, outputs and disturbances (plots and tables); unnamed by default."""
    sampling: dict[str, Any] | None = None
    """How a continuous-time system was sampled (``Ts``, ``disturbances``, ``pieces``), set
    by :meth:`discretize`."""

    def __init__(
        self,
        A: MatrixLike,
        B: MatrixLike = None,
        C: MatrixLike = None,
        D: MatrixLike = None,
        E: MatrixLike = None,
        F: MatrixLike = None,
        d: BoundsLike = None,
        dt: bool | float = True,
    ) -> None:
        if is_statespace(A):  # callable, so it would be taken for a time-varying A(k)
            raise IvobsError(
                "A: got a control.StateSpace; use ivobs.LinearSystem.from_statespace(ss, "
                "disturbances=[...], d=ivobs.Box(...)) (make_estimator also accepts it directly)"
            )
        self.dt = check_dt(dt)
        self._boxes: dict[str, tuple[Box, np.ndarray]] = {}
        self._A = Matrix("A", self._interval("A", A, None, None, "col"), None, None, "col")
        nx = int(self._A.shape[0])
        if self._A.shape != (nx, nx) or nx == 0:
            raise IvobsError(
                "A: expected a square matrix with at least one row, got shape "
                f"{_shape_str(self._A.given)}"
            )
        if C is None:
            raise IvobsError("C: the output matrix is required (y = C x + D u + F d)")
        self._C = Matrix("C", self._interval("C", C, None, nx, "row"), None, nx, "row")
        ny = self._C.shape[0]
        B = np.zeros((nx, 0)) if B is None else self._interval("B", B, nx, None, "col")
        self._B = Matrix("B", B, nx, None, "col")
        nu = self._B.shape[1]
        D = np.zeros((ny, nu)) if D is None else self._interval("D", D, ny, nu, "col")
        self._D = Matrix("D", D, ny, nu, "col")
        for name, value in (("E", E), ("F", F)):
            self._interval(name, value, None, None, "col")  # refused: a wider d instead
        self._d, nd = self._check_bounds(d, E, F)
        self._E = Matrix("E", np.zeros((nx, nd)) if E is None else E, nx, nd, "col")
        self._F = Matrix("F", np.zeros((ny, nd)) if F is None else F, ny, nd, "row")
        if self._E.shape[1] != self._F.shape[1]:
            raise IvobsError(
                f"E and F: both act on the same disturbance d, so they need the same number of "
                f"columns; got E {self._E.shape} and F {self._F.shape}"
            )
        self.nx, self.nu, self.ny = nx, nu, ny
        self.nd = self._E.shape[1]
        if isinstance(self._d, Box) and self._d.dim != self.nd:
            raise IvobsError(
                f"d: expected a Box of dimension {self.nd} (columns of E and F), got {self._d.dim}"
            )
        self._uncertainty = self._check_uncertain()

    # -- validation helpers ---------------------------------------------------------------
    @staticmethod
    def _check_bounds(d: Any, E: Any, F: Any) -> tuple[BoundsLike, int]:
        if d is None:
            if E is not None or F is not None:
                which = "E" if E is not None else "F"
                raise IvobsError(
                    f"{which}: a disturbance matrix was given without bounds d; pass "
                    "d=ivobs.Box(d_lo, d_hi) (the method needs to know how large d can be)"
                )
            return None, 0
        if E is None and F is None:
            raise IvobsError(
                "d: bounds were given but neither E nor F says where the disturbance enters; "
                "pass E (state equation) and/or F (output equation)"
            )
        if isinstance(d, Box):
            if not d.is_bounded:
                raise IvobsError("d: disturbance bounds must be finite")
            return d, d.dim
        if callable(d):
            ref = E if E is not None else F
            if callable(ref):
                ref = ref(0)
            if is_scipy_sparse(ref):
                return d, int(ref.shape[1])
            arr = np.asarray(ref, dtype=float)
            nd = arr.shape[-1] if arr.ndim >= 2 else (1 if E is not None else arr.shape[0])
            return d, nd
        raise IvobsError(
            f"d: expected an ivobs.Box or a callable (k, y_k) -> Box, got {type(d).__name__}; "
            "for symmetric bounds |d| <= r use ivobs.Box.symmetric(r)"
        )

    # -- public accessors -------------------------------------------------------------------
    @property
    def A(self) -> Any:
        """State matrix (array, stack or callable)."""
        return self._A.public()

    @property
    def B(self) -> Any:
        """Input matrix."""
        return self._B.public()

    @property
    def C(self) -> Any:
        """Output matrix."""
        return self._C.public()

    @property
    def D(self) -> Any:
        """Feedthrough matrix."""
        return self._D.public()

    @property
    def E(self) -> Any:
        """Disturbance matrix, state equation."""
        return self._E.public()

    @property
    def F(self) -> Any:
        """Disturbance matrix, output equation."""
        return self._F.public()

    @property
    def d(self) -> BoundsLike:
        """The disturbance bounds as given (Box, time-varying Box, callable, or None)."""
        return self._d

    @property
    def is_time_varying(self) -> bool:
        """True when any matrix is a callable or a stack."""
        return not all(m.is_constant for m in self._mats())

    @property
    def has_constant_bounds(self) -> bool:
        """True when ``d`` is absent or a constant Box."""
        return self._d is None or (isinstance(self._d, Box) and not self._d.is_time_varying)

    @property
    def bounds_depend_on_y(self) -> bool:
        """True when ``d`` is a callable ``(k, y_k) -> Box`` (bounds known only with the
        measurement, [Efimov2013, Remark 1]); then :meth:`d_at` needs ``y_k``."""
        return callable(self._d)

    def d_over(self, T: int) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``d[0..T-1]`` as ``(lo, hi)`` arrays ``(T, nd)`` (constant or time-varying
        bounds; a time-varying Box shorter than ``T`` is an error naming the step). For a
        callable ``d`` (:attr:`bounds_depend_on_y`) use :meth:`d_at` step by step."""
        if self.bounds_depend_on_y:
            raise IvobsError("d: the bounds depend on y[k] (a callable): evaluate d_at(k, y_k)")
        if self._d is None:
            return np.zeros((T, 0)), np.zeros((T, 0))
        d = self._d
        assert isinstance(d, Box)
        if not d.is_time_varying:
            return np.broadcast_to(d.lo, (T, self.nd)), np.broadcast_to(d.hi, (T, self.nd))
        if d.lo.shape[0] < T:
            raise IvobsError(
                f"d: the time-varying bounds cover {d.lo.shape[0]} steps, the record has {T}"
            )
        return d.lo[:T], d.hi[:T]

    def d_widths(self) -> np.ndarray:
        """Widths ``Δ`` of the bounds of ``d`` for design objectives: constant bounds as they
        are, time-varying bounds their largest width per component, bounds computed from the
        measurement ([Efimov2013, Remark 1]) ones (no better information before the data)."""
        if not self.nd:
            return np.zeros(0)
        if self.bounds_depend_on_y:
            return np.ones(self.nd)
        d = self._d
        assert isinstance(d, Box)
        w = np.asarray(d.hi - d.lo, dtype=float)
        return np.max(w, axis=0) if w.ndim == 2 else w

    @property
    def is_sparse(self) -> bool:
        """True when ``A`` was given as a ``scipy.sparse`` matrix (large systems)."""
        return self._A.sp is not None

    def sparse(self, name: str) -> Any:
        """``A``, ``B``, ``C``, ``D``, ``E`` or ``F`` as a ``scipy.sparse`` CSR matrix
        (converted when given dense; time-invariant systems only). Methods that exploit sparsity
        use this; ``sys.A`` etc. give dense arrays (built on first access)."""
        from scipy.sparse import csr_matrix

        mats = dict(zip("ABCDEF", self._mats()))
        if name not in mats:
            raise IvobsError(f"name: expected one of A, B, C, D, E, F, got {name!r}")
        m = mats[name]
        if m.sp is not None:
            return m.sp
        if not m.is_constant:
            raise IvobsError(f"sparse: {name} is time-varying")
        return csr_matrix(m.at(0))

    def _mats(self) -> tuple[Matrix, ...]:
        return (self._A, self._B, self._C, self._D, self._E, self._F)

    def A_at(self, k: Any) -> np.ndarray:
        """``A`` at step ``k`` (time ``t`` in continuous time)."""
        return self._A.at(k)

    def B_at(self, k: Any) -> np.ndarray:
        return self._B.at(k)

    def C_at(self, k: Any) -> np.ndarray:
        return self._C.at(k)

    def D_at(self, k: Any) -> np.ndarray:
        return self._D.at(k)

    def E_at(self, k: Any) -> np.ndarray:
        return self._E.at(k)

    def F_at(self, k: Any) -> np.ndarray:
        return self._F.at(k)

    def matrices_at(self, k: Any) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, E, F)`` at step ``k``."""
        return tuple(m.at(k) for m in self._mats())

    def d_at(self, k: Any, y: Any = None) -> Box:
        """Bounds of ``d[k]``. A callable ``d`` receives ``(k, y_k)`` (``y_k`` may hold NaN for a
        missing sample, or be None when no measurement is available)."""
        if self._d is None:
            return Box._trusted(np.zeros(0), np.zeros(0))
        if isinstance(self._d, Box):
            return self._d.at(int(k)) if self._d.is_time_varying else self._d
        try:
            box = self._d(k, y)
        except IvobsError:
            raise
        except Exception as exc:
            raise IvobsError(f"d: calling d({k}, y) failed: {exc!r}") from None
        if not isinstance(box, Box) or box.dim != self.nd or box.is_time_varying:
            raise IvobsError(
                f"d: the callable must return an ivobs.Box of dimension {self.nd}, got {box!r}"
            )
        if not box.is_bounded:
            raise IvobsError(f"d({k}, y): returned unbounded disturbance bounds {box!r}")
        return box

    # -- structural facts ---------------------------------------------------------------
    def _require_lti(self, what: str) -> None:
        if self.is_time_varying:
            raise IvobsError(f"{what}: defined for time-invariant systems; evaluate at a step")

    def observability_rank(self) -> int:
        """Rank of ``[C; CA; ...; CA^(nx-1)]`` (time-invariant systems)."""
        self._require_lti("observability_rank")
        return linalg.observability_rank(self.A, self.C)

    def is_observable(self) -> bool:
        """Whether ``(A, C)`` is observable (time-invariant systems)."""
        return self.observability_rank() == self.nx

    def observability_indices(self) -> list[int]:
        """Observability indices ``m_i`` per output (:func:`ivobs.linalg.observability_indices`)."""
        self._require_lti("observability_indices")
        return linalg.observability_indices(self.A, self.C)

    def is_stable(self) -> bool:
        """Schur (discrete) or Hurwitz (continuous) stability of ``A`` (time-invariant)."""
        self._require_lti("is_stable")
        return linalg.is_hurwitz(self.A) if self.is_continuous else linalg.is_schur(self.A)

    # -- constructors and conversions ---------------------------------------------------
    @classmethod
    def from_process_measurement(
        cls,
        A: MatrixLike,
        B: MatrixLike,
        C: MatrixLike,
        E: MatrixLike,
        F: MatrixLike,
        w: Box | Any,
        v: Box | Any,
        D: MatrixLike = None,
        dt: bool | float = True,
    ) -> LinearSystem:
        """[Tang2019]'s form ``x+ = Ax + Bu + E w``, ``y = Cx + Du + F v``, ``w ∈ w``, ``v ∈ v``.

        Builds ``d = [w; v]``, ``E_d = [E 0]``, ``F_d = [0 F]``. ``w`` and ``v`` are boxes, or
        vectors ``w̄``, ``v̄`` meaning ``|w| <= w̄``, ``|v| <= v̄`` ([Tang2019, eq. (9)]).
        """
        Ew = as_matrix("E", E)
        Fv = as_matrix("F", F)
        wb = _radius_box("w", w, Ew.shape[1], "E")
        vb = _radius_box("v", v, Fv.shape[1], "F")
        nx, ny = Ew.shape[0], Fv.shape[0]
        E_d = np.hstack([Ew, np.zeros((nx, vb.dim))])
        F_d = np.hstack([np.zeros((ny, wb.dim)), Fv])
        d = Box(np.concatenate([wb.lo, vb.lo]), np.concatenate([wb.hi, vb.hi]))
        return cls(A, B, C, D=D, E=E_d, F=F_d, d=d, dt=dt)

    @classmethod
    def from_statespace(
        cls,
        ss: Any,
        E: MatrixLike = None,
        F: MatrixLike = None,
        d: BoundsLike = None,
        *,
        disturbances: Any = (),
    ) -> LinearSystem:
        """From a ``control.StateSpace`` (python-control): ``disturbances`` names the inputs of
        ``ss`` that are bounded unknown disturbances (indices or labels) with bounds ``d`` (a
        Box of that many components), the other inputs are the known ``u``; or ``E``, ``F``,
        ``d`` give disturbances outside ``ss``. Names are kept in ``sys.names``."""
        sys: LinearSystem = from_statespace(cls, ss, disturbances=disturbances, d=d, E=E, F=F)
        return sys

    def to_statespace(self) -> Any:
        """A ``control.StateSpace`` with inputs ``[u; d]`` (needs python-control)."""
        self._require_lti("to_statespace")  # what the model is, before what is installed
        if self.is_uncertain:
            raise IvobsError(
                "to_statespace: the system has interval matrices; python-control has no such "
                "model. Use sys.nominal().to_statespace() for the nominal (midpoint) system"
            )
        try:
            import control
        except ImportError:
            raise IvobsError(
                "to_statespace: python-control is not installed; pip install 'ivobs[control]'"
            ) from None
        return control.ss(
            self.A, np.hstack([self.B, self.E]), self.C, np.hstack([self.D, self.F]), self.dt
        )

    def discretize(
        self,
        Ts: float,
        *,
        disturbances: str = "varying",
        pieces: int | None = None,
        interval_matrices: bool = False,
    ) -> LinearSystem:
        """The discrete-time model sampled every ``Ts``, inputs ``u`` held over each period
        (zero-order hold), time-invariant continuous-time systems only
        (:mod:`ivobs.model.sampling`, docs/continuous.md).

        ``disturbances="varying"`` (default): sound for every measurable ``d(t)`` in its box
        between samples: ``x+ = e^{A Ts} x + Γ B u + Σ_k Ĝ_k d̄_k + ρ``, one disturbance per
        piece of the period (``pieces``, a power of two; chosen when None, possibly with the
        pieces' first moments, ``sys.sampling`` says) and a remainder per state, so ``nd``
        grows. ``disturbances="held"``: ``d`` constant over each period
        (``[B_d E_d] = ∫_0^Ts e^{A s} ds [B E]``), for signals that really are held.
        ``interval_matrices=True``: ``A_d``, ``B_d`` as interval matrices containing the exact
        exponential and integral (rounding included), for the methods that accept them.
        """
        from dataclasses import replace

        from .sampling import check_options, sample

        if not self.is_continuous:
            raise IvobsError("discretize: the system is already discrete-time")
        self._require_lti("discretize")
        Ts = check_options(Ts, disturbances, pieces, interval_matrices)
        A, B, C, D, E, F = self.matrices_at(0)  # dense (a sparse matrix densified)
        m = sample(A, B, E, F, self._d, Ts, disturbances, pieces, interval_matrices, self.names)
        out = LinearSystem(m.A, m.B, C, D=D, E=m.E, F=m.F, d=m.d, dt=Ts)
        out.names = self.names
        if m.disturbance_names is not None:
            out.names = replace(self.names, disturbances=m.disturbance_names)
        out.sampling = m.sampling
        return out

    def _repr_html_(self) -> str:
        """Jupyter: dimensions, time base, the disturbance bounds and the signal names."""
        from .._html import summary_html, vector

        d = self.d
        if isinstance(d, Box) and not d.is_time_varying:
            bounds = f"{vector(d.lo)} … {vector(d.hi)}"
        else:
            bounds = "none" if d is None else "per step"
        kind = "time-varying" if self.is_time_varying else "constant"
        rows = [
            ("states / inputs / outputs / d", f"{self.nx} / {self.nu} / {self.ny} / {self.nd}"),
            ("time", "continuous" if self.is_continuous else f"discrete, dt = {self.dt}"),
            ("matrices", "interval" if self.is_uncertain else kind),
            ("d bounds", bounds),
        ]
        if self.names.states:
            rows.append(("states", ", ".join(self.names.state_labels() or ())))
        return summary_html("ivobs LinearSystem", rows)

    def __repr__(self) -> str:
        kind = "continuous" if self.is_continuous else "discrete"
        tv = ", time-varying" if self.is_time_varying else ""
        if self._boxes:
            tv += f", interval {', '.join(self._boxes)}"
        return f"LinearSystem({kind}{tv}, nx={self.nx}, nu={self.nu}, ny={self.ny}, nd={self.nd})"


if TYPE_CHECKING:

    def _is_a_linear_model(sys: LinearSystem) -> LinearModel:
        return sys  # mypy checks that LinearSystem has every member estimators use
