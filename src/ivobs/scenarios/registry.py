"""The scenario registry: :class:`Scenario`, :func:`register_scenario`, :func:`get`, :func:`names`.

The example modules of this package (one per paper, the large systems, the CORA benchmarks)
register their builders here; this module imports none of them.

Each :class:`Scenario` carries the system, the prior box ``x0`` on the initial state, the true
initial state, the known inputs, the paper's disturbance signal, the horizon, where it comes
from, and the numbers the paper prints (``reference``) so that tests and users can compare.
Where a paper leaves a value unspecified (initial state, horizon, the disturbance signal of an
example) the scenario says what ivobs chose in ``notes``.

Disturbance kinds for :meth:`Scenario.simulate`: ``"paper"`` (the paper's signal),
``"vertex"`` (bang-bang on the bounds' vertices: adversarial), ``"uniform"``, ``"sinusoidal"``,
``"zero"`` (the bounds' center), ``"recorded"`` (the stored record of the CORA scenarios).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem
from ..model.nonlinear import NonlinearSystem
from ..sets import Box
from ..simulate import Trajectory, disturbance, simulate
from ..simulate_nonlinear import simulate_nonlinear

__all__ = [
    "DISTURBANCES",
    "Scenario",
    "bounds_box",
    "check_horizon",
    "constant_input",
    "get",
    "names",
    "options",
    "paper_signal",
    "register_scenario",
    "summaries",
]

DisturbanceFactory = Callable[[str, Any, int], Any]

#: The disturbance kinds of :meth:`Scenario.simulate` (``"center"`` is accepted for ``"zero"``).
DISTURBANCES = ("paper", "vertex", "uniform", "sinusoidal", "zero", "recorded")


@dataclass
class Scenario:
    """A paper example: system, prior box, true initial state, signals, horizon, provenance."""

    name: str
    system: LinearSystem | NonlinearSystem
    x0: Box
    x_true0: np.ndarray
    u: np.ndarray
    horizon: int
    source: str
    description: str = ""
    reference: dict[str, Any] = field(default_factory=dict)
    notes: str = ""
    t: np.ndarray | None = None
    state_names: tuple[str, ...] | None = None
    _disturbance: DisturbanceFactory | None = None
    u_fn: Callable[[float], np.ndarray] | None = None
    """Continuous time: the known input as a function of ``t`` (between samples too), when
    the scenario defines one (``u`` holds its samples on the grid ``t``)."""
    recorded: Trajectory | None = None
    _matrices: DisturbanceFactory | None = None
    """Systems with interval matrices: ``(kind, seed, T) -> {name: (T, r, c)}``, the matrices
    the plant uses at each step under a disturbance of that kind (``simulate(matrices=)``)."""

    @property
    def d(self) -> Any:
        """The paper's disturbance signal: a ``(T, nd)`` array, or a callable ``(k, x) -> d``
        when it depends on the state (nonlinear terms, [Efimov2013, Remark 1])."""
        return self.disturbance("paper")

    def disturbance(self, kind: str = "paper", seed: Any = None) -> Any:
        """A disturbance signal of the given kind (array or state-dependent callable)."""
        if self._disturbance is not None:
            out = self._disturbance(kind, seed, self.horizon)
            if out is not None:
                return out
        if kind == "paper":
            raise IvobsError(f"scenario {self.name!r} has no paper disturbance signal")
        box = self.system.d
        if not isinstance(box, Box):
            raise IvobsError(f"scenario {self.name!r}: no generic {kind!r} disturbance")
        return disturbance(kind, box, self.horizon, seed)

    def simulate(self, disturbance: str = "paper", seed: Any = None) -> Trajectory:
        """The true trajectory under a disturbance of the given kind."""
        if disturbance not in (*DISTURBANCES, "center"):
            raise IvobsError(
                f"disturbance: unknown kind {disturbance!r}; expected one of "
                f"{', '.join(DISTURBANCES)}"
            )
        if disturbance == "recorded":
            if self.recorded is None:
                with_record = [n for n in names() if n.startswith("cora-")]
                raise IvobsError(
                    f"disturbance 'recorded': scenario {self.name!r} has no recorded trajectory "
                    f"(only the scenarios with stored data have one: {', '.join(with_record)})"
                )
            return self.recorded
        d = self.disturbance(disturbance, seed)
        if isinstance(self.system, NonlinearSystem):  # parameters of the same kind as d
            kind = "uniform" if disturbance == "paper" else disturbance
            return simulate_nonlinear(
                self.system, self.x_true0, self.u, d, p=kind, T=self.horizon, seed=seed
            )
        if self.system.is_continuous:
            u = self.u_fn if self.u_fn is not None else self.u
            return simulate(self.system, self.x_true0, u, d, t=self.t)
        kw = {}
        if self._matrices is not None:  # interval matrices: the plant's at each step
            kw["matrices"] = self._matrices(disturbance, seed, self.horizon)
        return simulate(self.system, self.x_true0, self.u, d, T=self.horizon, **kw)

    def __repr__(self) -> str:
        return f"Scenario({self.name!r}, {self.system!r}, horizon={self.horizon}, {self.source})"


_BUILDERS: dict[str, tuple[Callable[..., Scenario], str]] = {}


def register_scenario(
    name: str, summary: str
) -> Callable[[Callable[..., Scenario]], Callable[..., Scenario]]:
    """Decorator: register a scenario builder (keyword options allowed) under ``name``."""

    def deco(fn: Callable[..., Scenario]) -> Callable[..., Scenario]:
        _BUILDERS[name] = (fn, summary)
        return fn

    return deco


def names() -> list[str]:
    """Names of the available scenarios."""
    return list(_BUILDERS)


def options(name: str) -> list[str]:
    """Keyword options the scenario ``name`` accepts (e.g. ``horizon``, ``seed``)."""
    import inspect

    if name not in _BUILDERS:
        raise IvobsError(f"scenario: unknown scenario {name!r}; known: {', '.join(names())}")
    return list(inspect.signature(_BUILDERS[name][0]).parameters)


def summaries() -> dict[str, str]:
    """``name -> one-line description``."""
    return {k: v[1] for k, v in _BUILDERS.items()}


def get(name: str, **opts: Any) -> Scenario:
    """The scenario ``name`` (options such as ``horizon=`` or ``seed=`` where supported)."""
    accepted = options(name)  # refuses an unknown name
    try:
        return _BUILDERS[name][0](**opts)
    except TypeError as exc:
        raise IvobsError(
            f"scenario {name!r}: bad options {sorted(opts)} ({exc}); accepted: {accepted}"
        ) from None


def constant_input(u: Any, T: int) -> np.ndarray:
    """The input ``u`` held constant over ``T`` steps, shape ``(T, nu)``."""
    u = np.atleast_1d(np.asarray(u, dtype=float))
    return np.tile(u, (T, 1))


def bounds_box(system: LinearSystem | NonlinearSystem) -> Box:
    """The system's disturbance bounds ``d`` when they are one constant box (the generic
    disturbance signals fill it); an :class:`~ivobs.IvobsError` otherwise."""
    box = system.d
    if not isinstance(box, Box):
        raise IvobsError("scenario: the disturbance bounds are not a constant box")
    return box


def paper_signal(kind: str, system: LinearSystem | NonlinearSystem) -> DisturbanceFactory:
    """The ``"paper"`` disturbance of a scenario whose paper gives no signal: the generic
    ``kind`` signal (``"sinusoidal"`` or ``"uniform"``, seed 0 unless one is given) filling the
    system's bounds (:func:`bounds_box`); other kinds are left to :meth:`Scenario.disturbance`."""

    def factory(name: str, seed: Any, T: int) -> Any:
        if name != "paper":
            return None
        seed = 0 if seed is None else seed
        return disturbance(kind, bounds_box(system), T, seed if kind == "uniform" else None)

    return factory


def check_horizon(horizon: Any) -> int:
    """``horizon`` as a positive ``int``, or an :class:`~ivobs.IvobsError`."""
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
        raise IvobsError(f"horizon: expected a positive integer, got {horizon!r}")
    return int(horizon)
