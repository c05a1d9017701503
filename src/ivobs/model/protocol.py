"""What an estimator may ask of a model, as typing protocols.

Estimators depend on these members, never on a model's internals, so that a second kind of model
(a nonlinear system) can sit beside :class:`~ivobs.LinearSystem` behind the same estimator
protocol. :class:`SystemModel` is what every model answers: dimensions, time base, the bounds of
the unknown disturbance ``d``. :class:`LinearModel` adds the matrices of

    x[k+1] = A x[k] + B u[k] + E d[k],   y[k] = C x[k] + D u[k] + F d[k]

at each step (all of today's estimators use them; a nonlinear model may provide them for a
linearisation with the remainder bounded in ``d``, as [Efimov2013, Remark 1] treats nonlinear
terms). :class:`~ivobs.LinearSystem` satisfies both (checked statically in
:mod:`ivobs.model.linear`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from ..sets import Box

__all__ = ["BoundsLike", "LinearModel", "SystemModel"]

BoundsLike = Box | Callable[[Any, Any], Box] | None
"""Disturbance bounds as given: a Box (constant or with ``(T, nd)`` bounds), a callable
``(k, y_k) -> Box`` (bounds computed from the measurement), or None (no disturbance)."""


class SystemModel(Protocol):
    """Dimensions, time base and disturbance bounds: what every model answers."""

    @property
    def nx(self) -> int:
        """Number of states."""
        ...

    @property
    def nu(self) -> int:
        """Number of known inputs ``u``."""
        ...

    @property
    def ny(self) -> int:
        """Number of measured outputs ``y``."""
        ...

    @property
    def nd(self) -> int:
        """Number of components of the unknown, bounded disturbance ``d``."""
        ...

    @property
    def dt(self) -> bool | float:
        """``True`` or a sampling period ``> 0`` (discrete time), ``0`` (continuous time)."""
        ...

    @property
    def is_continuous(self) -> bool:
        """``dt == 0``."""
        ...

    @property
    def is_discrete(self) -> bool: ...

    @property
    def sampling_period(self) -> float:
        """The sampling period (1 for ``dt=True``, 0 in continuous time)."""
        ...

    @property
    def is_time_varying(self) -> bool:
        """Whether the model changes with the step (its matrices or functions depend on ``k``)."""
        ...

    @property
    def has_constant_bounds(self) -> bool:
        """Whether ``d`` is absent or one constant Box."""
        ...

    @property
    def d(self) -> BoundsLike:
        """The disturbance bounds as given."""
        ...

    def d_at(self, k: Any, y: Any = None) -> Box:
        """Bounds of ``d[k]`` (a callable bound receives ``(k, y_k)``)."""
        ...


class LinearModel(SystemModel, Protocol):
    """A model with matrices ``(A, B, C, D, E, F)`` at each step."""

    @property
    def bounds_depend_on_y(self) -> bool:
        """Whether ``d`` is a callable of ``(k, y_k)``."""
        ...

    def d_widths(self) -> np.ndarray:
        """Widths of the bounds of ``d`` for design objectives (largest over the steps; ones
        for bounds computed from the measurement)."""
        ...

    def d_over(self, T: int) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of ``d[0..T-1]`` as ``(T, nd)`` arrays (not for a callable ``d``)."""
        ...

    def matrices_at(self, k: Any) -> tuple[np.ndarray, ...]:
        """``(A, B, C, D, E, F)`` at step ``k`` (time ``t`` in continuous time); ``A_at(k)``
        etc. one of them."""
        ...

    def A_at(self, k: Any) -> np.ndarray: ...
    def B_at(self, k: Any) -> np.ndarray: ...
    def C_at(self, k: Any) -> np.ndarray: ...
    def D_at(self, k: Any) -> np.ndarray: ...
    def E_at(self, k: Any) -> np.ndarray: ...
    def F_at(self, k: Any) -> np.ndarray: ...

    @property
    def A(self) -> Any:
        """``A`` as given: an array (time-invariant), a stack or a callable (``B`` ... ``F``
        likewise)."""
        ...

    @property
    def B(self) -> Any: ...
    @property
    def C(self) -> Any: ...
    @property
    def D(self) -> Any: ...
    @property
    def E(self) -> Any: ...
    @property
    def F(self) -> Any: ...

    @property
    def is_sparse(self) -> bool:
        """Whether ``A`` is a ``scipy.sparse`` matrix (large systems)."""
        ...

    def sparse(self, name: str) -> Any:
        """Matrix ``name`` (``"A"``, ..., ``"F"``) as a ``scipy.sparse`` CSR matrix."""
        ...
