"""The papers' example systems, ready to run: ``ivobs.scenarios.get(name)``.

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
from functools import partial
from typing import Any

import numpy as np

from .errors import IvobsError
from .model import LinearSystem
from .sets import Box
from .simulate import Trajectory, _rng, disturbance, simulate

__all__ = [
    "DISTURBANCES",
    "Scenario",
    "get",
    "heat_gain",
    "henon_bounds",
    "kkl_ltv_A",
    "names",
    "pendulum_A",
    "register_scenario",
]

DisturbanceFactory = Callable[[str, Any, int], Any]

#: The disturbance kinds of :meth:`Scenario.simulate` (``"center"`` is accepted for ``"zero"``).
DISTURBANCES = ("paper", "vertex", "uniform", "sinusoidal", "zero", "recorded")


@dataclass
class Scenario:
    """A paper example: system, prior box, true initial state, signals, horizon, provenance."""

    name: str
    system: LinearSystem
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
    _u_fn: Callable[[float], np.ndarray] | None = None
    recorded: Trajectory | None = None

    @property
    def u_fn(self) -> Callable[[float], np.ndarray] | None:
        """Continuous time: the known input as a function of ``t`` (between samples too), when
        the scenario defines one (``u`` holds its samples on the grid ``t``)."""
        return self._u_fn

    @property
    def d(self) -> Any:
        """The paper's disturbance signal: a ``(T, nd)`` array, or a callable ``(k, x) -> d``
        when it depends on the state (nonlinear terms, paper 003)."""
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
        if self.system.is_continuous:
            u = self._u_fn if self._u_fn is not None else self.u
            return simulate(self.system, self.x_true0, u, d, t=self.t)
        return simulate(self.system, self.x_true0, self.u, d, T=self.horizon)

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


def get(name: str, **options: Any) -> Scenario:
    """The scenario ``name`` (options such as ``horizon=`` or ``seed=`` where supported)."""
    if name not in _BUILDERS:
        raise IvobsError(f"scenario: unknown scenario {name!r}; known: {', '.join(names())}")
    fn = _BUILDERS[name][0]
    try:
        return fn(**options)
    except TypeError as exc:
        import inspect

        params = [p for p in inspect.signature(fn).parameters]
        raise IvobsError(
            f"scenario {name!r}: bad options {sorted(options)} ({exc}); accepted: {params}"
        ) from None


def _const_u(u: Any, T: int) -> np.ndarray:
    u = np.atleast_1d(np.asarray(u, dtype=float))
    return np.tile(u, (T, 1))


def _check_horizon(horizon: Any) -> int:
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
        raise IvobsError(f"horizon: expected a positive integer, got {horizon!r}")
    return int(horizon)


# --------------------------------------------------------------------------------------------
# Paper 001 (Wang, Dinh, Zhang, Raïssi, Shen, IFAC 2020), Section 4: example of Dinh et al. 2019
# --------------------------------------------------------------------------------------------
@register_scenario("dinh2019", "001 §4: 2 states, 1 output, d in both equations (fixed-time)")
def _dinh2019(horizon: int = 50) -> Scenario:
    T = _check_horizon(horizon)
    A = np.array([[5 / 4, 1.0], [-3 / 8, 1 / 8]])
    B = np.array([[1 / 4, 0.0], [0.0, 1 / 8]])
    C = np.array([[1.0, 0.0]])
    E = np.array([[1 / 9, 0.0], [1 / 9, 0.0]])  # D1
    F = np.array([[0.0, 1 / 9]])  # D2
    sys = LinearSystem(A, B, C, E=E, F=F, d=Box(-np.ones(2), np.ones(2)))
    k = np.arange(T)
    d_paper = np.column_stack([np.sin(k), np.sin(k.astype(float) ** 2)])
    x_true0 = np.array([2.3, 1.0])

    def dist(kind: str, seed: Any, T: int) -> Any:
        return d_paper if kind == "paper" else None

    ref = {
        "s": 2,
        "Mx": np.array([[1, 0], [0.2353, -1.8824], [-1.2734, -4.8720]]),
        "Mu": np.array(
            [
                [0, 0, 0, 0, 0, 0],
                [0, 0, -0.0588, 0.2353, 0, 0],
                [0, 0, 0.3183, 0.6090, -0.0588, 0.2353],
            ]
        ),
        "Md": np.array(
            [
                [0, 0.1111, 0, 0, 0, 0],
                [0, 0, 0.1830, 0.1111, 0, 0],
                [0, 0, 0.6828, 0, 0.1830, 0.1111],
            ]
        ),
        "Mx_pinv": np.array([[0.6848, 0.4334, -0.1674], [-0.1446, -0.1605, -0.1432]]),
        "Mx_perp": np.array(
            [[0.3152, -0.4334, 0.1674], [-0.4334, 0.5959, -0.2302], [0.1674, -0.2302, 0.0890]]
        ),
        "U1": np.array([-0.5614, 0.7719, -0.2982]),
        "S1": 0.1386,
        "V1": np.array([0, -0.45, -0.45, 0.6187, -0.3937, -0.2391]),
        "T": np.array([[0.7975, 0.2784, -0.1076], [0.1290, -0.5367, 0.0021]]),
    }
    return Scenario(
        name="dinh2019",
        system=sys,
        x0=Box(x_true0 - 1.0, x_true0 + 1.0),
        x_true0=x_true0,
        u=_const_u([1.0, 1.0], T),
        horizon=T,
        source="paper 001 (Wang et al., IFAC 2020), Section 4, eq. (1); example of Dinh et al. "
        "2019",
        description="x+ = Ax + Bu + D1 d, y = Cx + D2 d, |d| <= 1, u = (1, 1), "
        "d = (sin k, sin k^2)",
        reference=ref,
        _disturbance=dist,
        notes="prior box x0 = x_true0 ± 1 chosen by ivobs (the fixed-time method does not use it); "
        "the paper's Mu prints a 5-entry first row, read as 6 zeros",
    )


# --------------------------------------------------------------------------------------------
# Paper 002 (Tang, Wang, Wang, Raïssi, Shen, IEEE TAC 2019), Section VII
# --------------------------------------------------------------------------------------------
@register_scenario("servo-motor", "002 §VII Ex. 1: DC servo motor, 3 states, 2 outputs")
def _servo(horizon: int = 100) -> Scenario:
    T = _check_horizon(horizon)
    A = np.array([[1, 0.1, 0], [0, 0.8495, 0.4977], [0, -0.0357, 0.9995]])
    B = np.array([[0.0], [0.0], [0.0729]])
    C = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    w_bar = np.array([0.0225, 0.0225, 0.0404])
    v_bar = np.array([0.0564, 0.0564])
    sys = LinearSystem.from_process_measurement(A, B, C, np.eye(3), np.eye(2), w_bar, v_bar)
    ref = {
        "L1": np.array([[0.9998, 0.1000], [0.0157, 1.5371], [0.0315, 1.3453]]),
        "L2": np.array([[0.7582, 0.0784], [-2.5012, 0.6764], [-0.0040, -0.0360]]),
        "p0": np.zeros(3),
        "H0": 0.2 * np.eye(3),
    }
    return Scenario(
        name="servo-motor",
        system=sys,
        x0=Box.symmetric(0.2 * np.ones(3)),
        x_true0=np.array([0.0015, 0.0148, 0.0]),
        u=_const_u([2.0], T),
        horizon=T,
        source="paper 002 (Tang et al., IEEE TAC 2019), Section VII, Example 1",
        description="Euler-discretised DC servo motor (Ts = 0.1 s), x = (θ, n, i), "
        "|w| <= (0.0225, 0.0225, 0.0404), |v| <= 0.0564, u = 2 V",
        reference=ref,
        state_names=("θ (rad)", "n (rad/s)", "i (A)"),
        _disturbance=lambda kind, seed, T: (
            disturbance("sinusoidal", sys.d, T) if kind == "paper" else None
        ),
        notes="the paper does not give its disturbance signals: 'paper' uses sinusoids filling "
        "the bounds (ivobs.sinusoidal_disturbance); horizon 100 steps chosen by ivobs",
    )


@register_scenario("tang-example2", "002 §VII Ex. 2: no nonnegative A - LC exists")
def _tang2(horizon: int = 50) -> Scenario:
    T = _check_horizon(horizon)
    A = np.array([[1.0, 0.5], [-0.5, 1.0]])
    B = np.array([[0.0], [1.0]])
    C = np.array([[0.0, 1.0]])
    sys = LinearSystem.from_process_measurement(A, B, C, np.eye(2), np.eye(1), [0.1, 0.1], [0.1])
    ref = {
        "L": np.array([[-0.8479], [1.6739]]),
        "eig": np.array([0.3258, 0.0003]),
        "R": np.array([[0.3258, 0.2000], [0.0, 0.0003]]),
        "S": np.array([[5.1686, 6.3352], [1.5843, 3.1676]]),
        "e1": np.array([1.0, 0.0]),
        "e2": np.array([0.5, -1.0]),
        "p0": np.array([1.0, 1.0]),
        "H0": 0.5 * np.eye(2),
        "x_t0": (np.array([0.5, 0.5]), np.array([1.5, 1.5])),
    }
    return Scenario(
        name="tang-example2",
        system=sys,
        x0=Box([0.5, 0.5], [1.5, 1.5]),
        x_true0=np.array([1.2, 0.9]),
        u=np.zeros((T, 1)),
        horizon=T,
        source="paper 002 (Tang et al., IEEE TAC 2019), Section VII, Example 2",
        description="A = [[1, .5], [-.5, 1]], C = [0 1], |w| <= 0.1, |v| <= 0.1",
        reference=ref,
        _disturbance=lambda kind, seed, T: (
            disturbance("sinusoidal", sys.d, T) if kind == "paper" else None
        ),
        notes="the paper prints F = I2, which does not fit its scalar output y = x2 + F v; "
        "ivobs uses one noise channel F = 1 (this reproduces the paper's H∞ gain "
        "L = (-0.8479, 1.6739) to 5e-4); u = 0 and sinusoidal disturbances chosen by ivobs",
    )


# --------------------------------------------------------------------------------------------
# Paper 003 (Efimov, Perruquetti, Raïssi, Zolghadri), Section IV
# --------------------------------------------------------------------------------------------
@register_scenario("efimov-planar", "003 §IV.A: planar system, no nonnegative A - LC")
def _efimov_planar(horizon: int = 50) -> Scenario:
    T = _check_horizon(horizon)
    A = np.array([[0.3, -0.7], [0.6, -0.5]])
    C = np.array([[1.0, 0.0]])
    delta, V = 0.5, 0.1
    # d = (δb1, δb2, v): b = b0(t) + δb(t, x) with b0 a known input (B = I), v the noise
    E = np.hstack([np.eye(2), np.zeros((2, 1))])
    F = np.array([[0.0, 0.0, 1.0]])
    sys = LinearSystem(A, np.eye(2), C, E=E, F=F, d=Box([-delta, -delta, -V], [delta, delta, V]))
    k = np.arange(T)
    u = np.column_stack([np.sin(0.1 * k), np.cos(0.2 * k)])  # b0(t)

    def d_paper(kk: int, x: np.ndarray) -> np.ndarray:
        return np.array([delta * np.sin(0.5 * kk * x[1]), delta * np.sin(0.3 * kk), V * np.sin(kk)])

    ref = {
        "L": np.array([[0.3], [0.6]]),
        "eig_D": np.array([0.0, -0.5]),
        "R": np.array([[-0.5, 0.0], [1.0, 0.0]]),
        "S": np.array([[0.609, 0.814], [-1.162, 0.581]]),
    }
    return Scenario(
        name="efimov-planar",
        system=sys,
        x0=Box([-2.0, -2.0], [2.0, 2.0]),
        x_true0=np.array([1.0, -1.0]),
        u=u,
        horizon=T,
        source="paper 003 (Efimov et al.), Section IV.A, observers (4) and (5)",
        description="x+ = Ax + b0(t) + δb(t, x), y = x1 + v, |δb| <= 0.5, |v| <= 0.1",
        reference=ref,
        _disturbance=lambda kind, seed, T: d_paper if kind == "paper" else None,
        notes="initial state (1, -1) and prior box [-2, 2]^2 chosen by ivobs; the paper's printed "
        "R = [[-0.5, 0], [1, 0]] is not nonnegative (no nonnegative matrix has the "
        "spectrum {0, -0.5}: its trace would be negative)",
    )


def henon_bounds(k: Any, y: Any, *, a_lo: float, a_hi: float, V: float, delta: float) -> Box:
    """Bounds of (b, v) with b = 1 - a x1^2 + d from the measurement y = x1 + v (003 Remark 1).

    ``x1 ∈ [y - V, y + V]`` so ``x1^2 ∈ [max(0, |y| - V)^2, (|y| + V)^2]``. The paper prints
    ``(|y| - V)^2`` for the lower end, which is unsound when ``|y| < V`` (then ``x1`` may be 0).
    A module-level function (bound to its parameters with ``functools.partial``) so that system
    files can name it: ``d = { python = "ivobs.scenarios:henon_bounds", params = {...} }``.
    """
    y0 = np.nan if y is None else float(np.ravel(y)[0])
    if np.isnan(y0):
        raise IvobsError(
            "henon: the nonlinear term is bounded from the measurement y[k], which is missing "
            f"at step {k}; this scenario cannot predict through a missing sample"
        )
    sq_lo = max(0.0, abs(y0) - V) ** 2
    sq_hi = (abs(y0) + V) ** 2
    return Box([1.0 - a_hi * sq_hi - delta, -V], [1.0 - a_lo * sq_lo + delta, V])


@register_scenario("henon", "003 §IV.B: Hénon map, uncertain a(t), bounds from y (Remark 1)")
def _henon(horizon: int = 200) -> Scenario:
    T = _check_horizon(horizon)
    A = np.array([[0.0, 1.0], [0.3, 0.0]])
    C = np.array([[1.0, 0.0]])
    a_lo, a_hi, V, delta = 1.0, 1.4, 0.1, 0.015
    # d = (b, v), b = 1 - a(t) x1^2 + d(t) enters through r = (1, 0); v is the output noise
    E = np.array([[1.0, 0.0], [0.0, 0.0]])
    F = np.array([[0.0, 1.0]])
    bounds = partial(henon_bounds, a_lo=a_lo, a_hi=a_hi, V=V, delta=delta)
    sys = LinearSystem(A, None, C, E=E, F=F, d=bounds)

    def factory(kind: str, seed: Any, T: int) -> Any:
        rng = _rng(seed)
        if kind == "paper":

            def d_fn(k: int, x: np.ndarray) -> np.ndarray:
                a = 1.2 + 0.2 * np.sin(0.05 * k)
                return np.array([1.0 - a * x[0] ** 2 + delta * np.sin(0.3 * k), V * np.sin(k)])

            return d_fn
        if kind in ("vertex", "uniform"):
            draws: dict[int, tuple[float, float, float]] = {}

            def d_adv(k: int, x: np.ndarray) -> np.ndarray:
                if k not in draws:
                    if kind == "vertex":
                        a = float(rng.choice([a_lo, a_hi]))
                        dist, v = rng.choice([-delta, delta]), rng.choice([-V, V])
                    else:
                        a = rng.uniform(a_lo, a_hi)
                        dist, v = rng.uniform(-delta, delta), rng.uniform(-V, V)
                    # Assumption 1 (bounded state): keep the orbit on the attractor by taking
                    # the other vertex of a(t) when this one would throw x1 out of [-1.3, 1.3]
                    if abs(1.0 - a * x[0] ** 2 + x[1] + dist) > 1.3:
                        a = a_lo + a_hi - a
                    draws[k] = (a, dist, v)
                a, dist, v = draws[k]
                return np.array([1.0 - a * x[0] ** 2 + dist, v])

            return d_adv
        raise IvobsError(
            f"henon: disturbance kind {kind!r} is not available "
            "(use 'paper', 'vertex' or 'uniform')"
        )

    return Scenario(
        name="henon",
        system=sys,
        x0=Box([-1.5, -1.5], [1.5, 1.5]),
        x_true0=np.array([0.1, 0.1]),
        u=np.zeros((T, 0)),
        horizon=T,
        source="paper 003 (Efimov et al.), Section IV.B, Theorem 1 with L = (-0.1, 0.1)",
        description="x+ = Ax + r(1 - a(t) x1^2 + d), y = x1 + v, a in [1, 1.4], |d| <= 0.015, "
        "|v| <= 0.1; the nonlinear term is bounded from y (Remark 1)",
        reference={"L": np.array([[-0.1], [0.1]]), "a": (a_lo, a_hi), "V": V, "delta": delta},
        _disturbance=factory,
        notes="a(t) = 1.2 + 0.2 sin(0.05k), d = 0.015 sin(0.3k), v = 0.1 sin k chosen by ivobs "
        "(the paper gives none); adversarial runs take a(t) on its vertices but switch "
        "vertex when the orbit would leave [-1.3, 1.3] (the paper assumes a bounded state: "
        "random vertex switching makes the Hénon map escape to infinity)",
    )


# --------------------------------------------------------------------------------------------
# Paper 004 (Dinh & Tran, arXiv 2405.06445)
# --------------------------------------------------------------------------------------------
@register_scenario("kkl-random8", "004 Ex. 1: random observable 8 states, 6 outputs")
def _kkl_random8(
    horizon: int = 200,
    seed: int = 1,
    continuous: bool = False,
    t_final: float = 10.0,
    dt: float = 0.01,
) -> Scenario:
    rng = np.random.default_rng(seed)
    from .linalg import is_observable

    while True:  # Matlab's randi: small integer entries
        Fm = rng.integers(-3, 4, size=(8, 8)).astype(float)
        Dm = rng.integers(-2, 3, size=(8, 2)).astype(float)
        Hm = rng.integers(-2, 3, size=(6, 8)).astype(float)
        Wm = rng.integers(1, 3, size=(6, 1)).astype(float)
        if is_observable(Fm, Hm):
            break
    E = np.hstack([Dm, np.zeros((8, 1))])
    F = np.hstack([np.zeros((6, 2)), Wm])
    bounds = Box([-0.5, -0.5, -0.3], [0.5, 0.5, 0.3])
    x_true0 = rng.uniform(-1, 1, 8)
    ref = {"F": None, "D": Dm, "H": Hm, "W": Wm}
    if continuous:
        shift = np.max(np.linalg.eigvals(Fm).real) + 0.5
        Fc = Fm - shift * np.eye(8)  # Hurwitz, so that the figure's states stay bounded
        sys = LinearSystem(Fc, np.eye(8), Hm, E=E, F=F, d=bounds, dt=0)
        t = np.arange(0.0, t_final + dt / 2, dt)
        ref["F"] = Fc

        def d_ct(tt: float, x: np.ndarray) -> np.ndarray:
            return np.array([0.5 * np.sin(2 * tt), 0.5 * np.cos(tt), 0.3 * np.sin(tt)])

        def factory(kind: str, seed_: Any, T: int) -> Any:
            if kind == "paper":
                return d_ct
            return disturbance(kind, bounds, t.size, seed_)

        return Scenario(
            name="kkl-random8",
            system=sys,
            x0=Box(x_true0 - 1.0, x_true0 + 1.0),
            x_true0=x_true0,
            u=np.ones((t.size, 8)),
            horizon=int(t.size),
            source="paper 004 (Dinh & Tran), Example 1 (continuous time)",
            description="random observable CT system, 8 states, 6 outputs, u = 1, "
            "d = 0.5(sin 2t, cos t), w = 0.3 sin t",
            reference=ref,
            t=t,
            _disturbance=factory,
            _u_fn=lambda tt: np.ones(8),
            notes=f"random integer matrices (seed {seed}) shifted to be Hurwitz by ivobs",
        )
    T = _check_horizon(horizon)
    Fd = 0.8 * Fm / np.max(np.abs(np.linalg.eigvals(Fm)))  # spectral radius 0.8
    sys = LinearSystem(Fd, np.eye(8), Hm, E=E, F=F, d=bounds)
    ref["F"] = Fd
    k = np.arange(T)
    d_paper = np.column_stack([0.5 * np.sin(2 * k), 0.5 * np.cos(k), 0.3 * np.sin(k)])
    return Scenario(
        name="kkl-random8",
        system=sys,
        x0=Box(x_true0 - 1.0, x_true0 + 1.0),
        x_true0=x_true0,
        u=np.ones((T, 8)),
        horizon=T,
        source="paper 004 (Dinh & Tran), Example 1, discrete-time version",
        description="random observable DT system, 8 states, 6 outputs, u = 1, "
        "d = 0.5(sin 2k, cos k), w = 0.3 sin k",
        reference=ref,
        _disturbance=lambda kind, seed_, T: d_paper if kind == "paper" else None,
        notes=f"random integer matrices (seed {seed}), A scaled to spectral radius 0.8 by ivobs",
    )


def pendulum_A(t: float, *, L0: float, L1: float, omega: float) -> np.ndarray:
    """``A(t) = [[0, 1], [-g / L(t), -c]]``, ``L(t) = L0 + L1 sin(ωt)``, ``g = 9.8``, ``c = 1``
    (004 Example 2; module-level so that system files can name it)."""
    c, g = 1.0, 9.8
    return np.array([[0.0, 1.0], [-g / (L0 + L1 * np.sin(omega * t)), -c]])


@register_scenario("pendulum", "004 Ex. 2: pendulum with varying length (continuous-time LTV)")
def _pendulum(
    t_final: float = 15.0, dt: float = 0.01, L0: float = 1.0, L1: float = 0.5, omega: float = 1.0
) -> Scenario:
    if not 0 < L1 < L0:
        raise IvobsError(f"L0, L1: expected 0 < L1 < L0, got L0={L0}, L1={L1}")
    A_t = partial(pendulum_A, L0=L0, L1=L1, omega=omega)
    E = np.hstack([np.eye(2), np.zeros((2, 1))])
    F = np.array([[0.0, 0.0, 1.0]])
    bounds = Box([-0.04, -0.04, -0.02], [0.04, 0.04, 0.02])
    sys = LinearSystem(
        A_t, np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]]), E=E, F=F, d=bounds, dt=0
    )
    t = np.arange(0.0, t_final + dt / 2, dt)

    def u_fn(tt: float) -> np.ndarray:
        return np.array([0.15 * np.sin(3 * tt)])

    def d_ct(tt: float, x: np.ndarray) -> np.ndarray:
        return np.array([0.04 * np.sin(1.2 * tt), 0.04 * np.sin(1.2 * tt), 0.02 * np.cos(20 * tt)])

    def factory(kind: str, seed: Any, T: int) -> Any:
        return d_ct if kind == "paper" else disturbance(kind, bounds, t.size, seed)

    return Scenario(
        name="pendulum",
        system=sys,
        x0=Box([-1.0, -1.0], [1.0, 1.0]),
        x_true0=np.array([0.5, 0.0]),
        u=np.array([u_fn(tt) for tt in t]),
        horizon=int(t.size),
        source="paper 004 (Dinh & Tran), Example 2 (continuous-time LTV)",
        description="θ'' + cθ' + g/L(t) θ = u, L(t) = L0 + L1 sin(ωt), y = θ + w, "
        "d = 0.04(sin 1.2t, sin 1.2t), w = 0.02 cos 20t",
        reference={
            "A_tilde": np.diag([-1.0, -2.0]),
            "B_tilde": np.array([[1.0], [1.0]]),
            "ell": 2.0,
        },
        t=t,
        state_names=("θ", "θ'"),
        _disturbance=factory,
        _u_fn=u_fn,
        notes=f"L0 = {L0}, L1 = {L1}, ω = {omega}, θ(0) = 0.5 and the prior box chosen by ivobs "
        "(the paper gives none)",
    )


def kkl_ltv_A(k: int) -> np.ndarray:
    """``F_k = [[1.2, -1 + 0.5 cos k], [0, 0.5 + 0.2 sin k]]`` (004 Example 3; module-level so
    that system files can name it)."""
    return np.array([[1.2, -1.0 + 0.5 * np.cos(k)], [0.0, 0.5 + 0.2 * np.sin(k)]])


@register_scenario("kkl-ltv-dt", "004 Ex. 3: discrete-time LTV system, F_k with cos/sin entries")
def _kkl_ltv_dt(horizon: int = 30) -> Scenario:
    T = _check_horizon(horizon)

    E = np.hstack([np.eye(2), np.zeros((2, 1))])
    F = np.array([[0.0, 0.0, 1.0]])
    sys = LinearSystem(
        kkl_ltv_A,
        None,
        np.array([[1.0, 0.0]]),
        E=E,
        F=F,
        d=Box([-0.1, -0.1, -0.02], [0.1, 0.1, 0.02]),
    )
    k = np.arange(T)
    d_paper = np.column_stack([0.1 * np.sin(2 * k), -0.1 * np.sin(2 * k), 0.02 * np.cos(20 * k)])
    return Scenario(
        name="kkl-ltv-dt",
        system=sys,
        x0=Box([-2.0, -2.0], [2.0, 2.0]),
        x_true0=np.array([1.0, 0.5]),
        u=np.zeros((T, 0)),
        horizon=T,
        source="paper 004 (Dinh & Tran), Example 3 (discrete-time LTV)",
        description="F_k = [[1.2, -1 + .5 cos k], [0, .5 + .2 sin k]], H = [1 0], "
        "d = 0.1(sin 2k, -sin 2k), w = 0.02 cos 20k",
        reference={
            "A_tilde": np.diag([0.1, 0.2]),
            "B_tilde": np.array([[1.0], [1.0]]),
            "gamma": 1.0,
            "k_star": 2,
        },
        _disturbance=lambda kind, seed, T: d_paper if kind == "paper" else None,
        notes="initial state (1, 0.5) and prior box [-2, 2]^2 chosen by ivobs (the paper gives "
        "none); F_k has an eigenvalue 1.2, so the state grows: horizon 30",
    )


# --------------------------------------------------------------------------------------------
# Large systems (not from a paper): a discretised heat equation with a few point sensors
# --------------------------------------------------------------------------------------------
def heat_gain(system: LinearSystem, share: float = 0.5) -> np.ndarray:
    """A gain for the ``heat-1d`` scenario that keeps ``A - LC`` nonnegative: each sensor feeds
    back only into its own node, ``L[s_j, j] = share * A[s_j, s_j]`` (``0 <= share <= 1``).
    Then ``A - LC >= 0`` and its row sums are at most ``1 - cooling``: Schur without any LMI,
    for any ``nx`` (``interval`` and ``interval-split`` with ``L=``)."""
    C = system.sparse("C").tocoo()
    A = system.sparse("A")
    L = np.zeros((system.nx, system.ny))
    L[C.col, C.row] = share * A.diagonal()[C.col] / C.data
    return L


@register_scenario("heat-1d", "ivobs: 1-D heat equation, nx states (sparse A), point sensors")
def _heat_1d(
    nx: int = 50,
    sensors: int = 3,
    horizon: int = 500,
    alpha: float = 0.4,
    cooling: float = 0.01,
) -> Scenario:
    """A rod heated in its middle, explicit-Euler discretised on ``nx`` interior nodes::

        x_i+ = x_i + alpha (x_(i-1) - 2 x_i + x_(i+1)) - cooling x_i + b_i u + q + w_i

    (``alpha = κ Δt / h²``; the end nodes see the boundary temperatures ``d_0``, ``d_1`` in place
    of ``x_(-1)``, ``x_nx``). ``A = (1 - 2 alpha - cooling) I + alpha (shifts)`` is sparse
    (tridiagonal), nonnegative when ``2 alpha + cooling <= 1`` (the explicit scheme's stability
    condition) and Schur with radius ``<= 1 - cooling``. ``d = (d_0, d_1, q, v)``: boundary
    temperatures in ``[0, 0.2]``, an unknown uniform heat source ``|q| <= 0.005`` and the sensor
    noise ``|v| <= 0.02``; ``sensors`` point sensors at equal spacing; heater profile ``b``
    around the middle, input ``u[k] = 1 + 0.5 sin(2 pi k / 100)``.
    """
    from scipy.sparse import csr_matrix, diags

    T = _check_horizon(horizon)
    if isinstance(nx, bool) or not isinstance(nx, (int, np.integer)) or nx < 3:
        raise IvobsError(f"nx: expected an integer >= 3, got {nx!r}")
    if isinstance(sensors, bool) or not isinstance(sensors, (int, np.integer)):
        raise IvobsError(f"sensors: expected an integer, got {sensors!r}")
    if not 1 <= sensors <= nx:
        raise IvobsError(f"sensors: expected 1..{nx} point sensors, got {sensors}")
    alpha, cooling = float(alpha), float(cooling)
    if not (alpha > 0 and cooling >= 0 and 2 * alpha + cooling <= 1):
        raise IvobsError(
            f"alpha, cooling: expected alpha > 0, cooling >= 0 and 2 alpha + cooling <= 1 (the "
            f"explicit scheme's stability and nonnegativity), got alpha = {alpha}, "
            f"cooling = {cooling}"
        )
    n, ny = int(nx), int(sensors)
    off = np.full(n - 1, alpha)
    A = diags([off, np.full(n, 1 - 2 * alpha - cooling), off], [-1, 0, 1], format="csr")
    z = (np.arange(n) + 1.0) / (n + 1)
    heater = np.exp(-(((z - 0.5) / 0.05) ** 2))
    B = (0.05 * np.where(heater > 1e-3, heater, 0.0))[:, None]
    where = np.round((np.arange(ny) + 1.0) * (n + 1) / (ny + 1)).astype(int) - 1
    C = csr_matrix((np.ones(ny), (np.arange(ny), where)), shape=(ny, n))
    E = np.zeros((n, 3 + ny))
    E[0, 0] = E[n - 1, 1] = alpha
    E[:, 2] = 1.0
    F = np.hstack([np.zeros((ny, 3)), np.eye(ny)])
    lo = np.concatenate([[0.0, 0.0, -0.005], np.full(ny, -0.02)])
    hi = np.concatenate([[0.2, 0.2, 0.005], np.full(ny, 0.02)])
    sys = LinearSystem(A, B, C, E=E, F=F, d=Box(lo, hi))
    k = np.arange(T)
    u = (1.0 + 0.5 * np.sin(2 * np.pi * k / 100))[:, None]
    x_true0 = 0.5 + 0.3 * np.sin(np.pi * z)
    return Scenario(
        name="heat-1d",
        system=sys,
        x0=Box(np.zeros(n), np.full(n, 1.2)),
        x_true0=x_true0,
        u=u,
        horizon=T,
        source="ivobs (not from a paper): explicit-Euler 1-D heat equation for large systems",
        description=f"rod on {n} nodes, alpha = {alpha}, cooling = {cooling}, heater in the "
        f"middle, {ny} point sensors at nodes {where.tolist()}, boundary temperatures in "
        "[0, 0.2], |q| <= 0.005, |v| <= 0.02",
        reference={"L": heat_gain(sys), "sensors": where},
        _disturbance=lambda kind, seed, T: (
            disturbance("sinusoidal", sys.d, T) if kind == "paper" else None
        ),
        notes="reference['L'] = heat_gain(system): each sensor feeds back into its own node with "
        "half the diagonal of A, so A - LC >= 0 and Schur for any nx (interval, interval-split "
        "with L=...; docs/scale.md lists which methods suit which nx); 'paper' uses sinusoids",
    )


from . import scenarios_cora  # noqa: E402,F401  (registers the CORA benchmark scenarios)
