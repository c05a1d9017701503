"""Trajectories of a :class:`~ivobs.LinearSystem` under bounded disturbances.

Discrete time: ``x[0] = x0``, ``y[k] = C x[k] + D u[k] + F d[k]``,
``x[k+1] = A x[k] + B u[k] + E d[k]`` for ``k = 0 .. T-1`` (``T`` rows of ``x``, ``y``, ``u``,
``d``).

Continuous time (``dt = 0``): on a grid ``t``; ``u`` and ``d`` given as arrays on the grid are held
constant between samples (zero-order hold, integrated exactly with ``expm`` for time-invariant
systems), or given as callables ``u(t)``, ``d(t, x)`` and integrated with SciPy (DOP853, tight
tolerances). ``y[k]`` is the output at ``t[k]``.

Disturbance generators: :func:`sinusoidal_disturbance` (the papers' kind of signal),
:func:`uniform_disturbance`, and :func:`vertex_disturbance` (bang-bang on the vertices of the
bounds: the adversarial case for guaranteed estimators).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._validate import as_float_array, as_int, as_signal, as_vector
from .errors import IvobsError
from .model import LinearSystem
from .sets import Box

__all__ = [
    "Trajectory",
    "disturbance",
    "simulate",
    "sinusoidal_disturbance",
    "uniform_disturbance",
    "vertex_disturbance",
]


@dataclass
class Trajectory:
    """A simulated record: rows are steps (``x``, ``y``, ``u``, ``d`` each ``(T, n)``)."""

    x: np.ndarray
    y: np.ndarray
    u: np.ndarray
    d: np.ndarray
    t: np.ndarray
    p: np.ndarray | None = None
    """Nonlinear systems: the unknown parameters at each step ``(T, np)``
    (:func:`~ivobs.simulate_nonlinear`); None otherwise."""

    @property
    def T(self) -> int:
        """Number of steps (a batch from :func:`~ivobs.simulate_batch` is ``(B, T, ·)``)."""
        return int(self.x.shape[-2])

    @property
    def has_truth(self) -> bool:
        """Whether the record holds its true state (CORA's recorded 2-D record stores none:
        ``x`` is all NaN)."""
        return not bool(np.isnan(self.x).all())

    def __repr__(self) -> str:  # shapes, not every array (a record has thousands of rows)
        nx, ny, nu, nd = (a.shape[-1] for a in (self.x, self.y, self.u, self.d))
        truth = "" if self.has_truth else ", no true state"
        return f"Trajectory(T={self.T}, nx={nx}, ny={ny}, nu={nu}, nd={nd}{truth})"

    def to_pandas(self) -> Any:
        """A wide ``pandas.DataFrame`` indexed by step ``k``: columns ``t``, ``x1..``, ``y1..``,
        ``u1..``, ``d1..`` (needs pandas: ``ivobs[pandas]``)."""
        from .frames import _import

        pd = _import("pandas", "pandas")
        if self.x.ndim != 2:
            raise IvobsError("to_pandas: a batch of records; take one, e.g. Trajectory of x[b]")
        signals = (("x", self.x), ("y", self.y), ("u", self.u), ("d", self.d))
        cols = {f"{name}{i + 1}": arr[:, i] for name, arr in signals for i in range(arr.shape[-1])}
        return pd.DataFrame({"t": self.t, **cols}, index=pd.RangeIndex(self.T, name="k"))


def _bounds_rows(box: Box, T: int) -> tuple[np.ndarray, np.ndarray]:
    if not isinstance(box, Box):
        raise IvobsError(f"bounds: expected an ivobs.Box, got {type(box).__name__}")
    if not box.is_bounded:
        raise IvobsError("bounds: need finite bounds to generate a disturbance")
    if box.is_time_varying:
        if box.lo.shape[0] < T:
            raise IvobsError(f"bounds: time-varying bounds cover {box.lo.shape[0]} < {T} steps")
        return box.lo[:T], box.hi[:T]
    return np.broadcast_to(box.lo, (T, box.dim)), np.broadcast_to(box.hi, (T, box.dim))


def _rng(seed: Any) -> np.random.Generator:
    """NumPy's generator for ``seed``: None (fresh entropy), an integer >= 0, or a
    ``numpy.random.Generator`` (used as is; also a ``BitGenerator`` or ``SeedSequence``)."""
    if isinstance(seed, (np.random.Generator, np.random.BitGenerator, np.random.SeedSequence)):
        return np.random.default_rng(seed)
    if seed is not None and (
        isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0
    ):
        raise IvobsError(
            f"seed: expected None, an integer >= 0 or a numpy.random.Generator, got {seed!r}"
        )
    return np.random.default_rng(seed)


def sinusoidal_disturbance(
    box: Box, T: int, *, freqs: Any = None, phases: Any = None
) -> np.ndarray:
    """``d[k, i] = c_i + r_i sin(ω_i k + φ_i)``: inside the bounds, smooth, deterministic.

    Default frequencies ``ω_i = 0.3 + 0.47 i`` (distinct, incommensurate) and phases ``0.9 i``.
    """
    T = as_int("T", T, 0)
    lo, hi = _bounds_rows(box, T)
    n = box.dim
    w = 0.3 + 0.47 * np.arange(n) if freqs is None else as_vector("freqs", freqs, n)
    ph = 0.9 * np.arange(n) if phases is None else as_vector("phases", phases, n)
    k = np.arange(T)[:, None]
    out: np.ndarray = 0.5 * (lo + hi) + 0.5 * (hi - lo) * np.sin(w * k + ph)
    return out


def uniform_disturbance(box: Box, T: int, seed: Any = None) -> np.ndarray:
    """Independent uniform samples inside the bounds (``seed``: None, an integer >= 0 or a
    ``numpy.random.Generator``)."""
    T = as_int("T", T, 0)
    rng = _rng(seed)
    lo, hi = _bounds_rows(box, T)
    return rng.uniform(lo, hi)


def vertex_disturbance(box: Box, T: int, seed: Any = None, hold: int = 1) -> np.ndarray:
    """Bang-bang disturbance on the vertices of the bounds (each component at ``lo`` or ``hi``).

    The sign of every component is redrawn every ``hold`` steps. Vertex disturbances push a
    guaranteed estimator hardest: the true state reaches the boundary of the reachable set.
    """
    T = as_int("T", T, 0)
    hold = as_int("hold", hold, 1)
    rng = _rng(seed)
    lo, hi = _bounds_rows(box, T)
    n_draw = -(-T // hold)
    bits = rng.integers(0, 2, size=(n_draw, box.dim)).astype(bool)
    bits = np.repeat(bits, hold, axis=0)[:T]
    return np.where(bits, hi, lo)


def disturbance(kind: str, box: Box, T: int, seed: Any = None) -> np.ndarray:
    """``kind`` in ``{"sinusoidal", "uniform", "vertex", "zero"}`` (zero: the bounds' center).
    ``seed`` (random kinds): None, an integer >= 0 or a ``numpy.random.Generator``."""
    _rng(seed)  # checked for every kind: a bad seed is a mistake even where it is unused
    if kind == "sinusoidal":
        return sinusoidal_disturbance(box, T)
    if kind == "uniform":
        return uniform_disturbance(box, T, seed)
    if kind == "vertex":
        return vertex_disturbance(box, T, seed)
    if kind in ("zero", "center"):
        lo, hi = _bounds_rows(box, T)
        return np.array(0.5 * (lo + hi))
    raise IvobsError(
        f"kind: unknown disturbance kind {kind!r}; expected 'sinusoidal', 'uniform', "
        "'vertex' or 'zero'"
    )


def simulate(
    sys: LinearSystem,
    x0: Any,
    u: Any = None,
    d: Any = None,
    *,
    T: int | None = None,
    t: Any = None,
    check_bounds: bool = True,
    matrices: Any = None,
) -> Trajectory:
    """Simulate ``sys`` from the true initial state ``x0``.

    Parameters
    ----------
    x0 : (nx,) true initial state.
    u : (T, nu) known inputs (``None`` when ``nu = 0``); in continuous time also a callable
        ``t -> u``.
    d : (T, nd) disturbance sequence, or a callable ``(k, x_k) -> d_k`` for disturbances that
        depend on the state (nonlinear terms treated as bounded disturbances, [Efimov2013]); in
        continuous time a callable ``(t, x) -> d``. ``None`` means zero.
    T : number of steps when neither ``u`` nor ``d`` is an array.
    t : continuous time only: increasing sample times ``(T,)``.
    check_bounds : raise :class:`IvobsError` if ``d`` leaves the system's bounds (constant or
        time-varying Box bounds; a callable bound is checked against the simulated ``y``).
    matrices : systems with interval matrices: the matrices the plant uses at each step, a dict
        ``name -> (T, r, c)`` (e.g. ``sys.realisation("vertex", T, seed)``), checked inside
        their boxes (with ``check_bounds``); default: the nominal matrices.
    """
    if not isinstance(sys, LinearSystem):
        hint = (
            "; simulate a NonlinearSystem with ivobs.simulate_nonlinear"
            if type(sys).__name__ == "NonlinearSystem"
            else ""
        )
        raise IvobsError(f"sys: expected an ivobs.LinearSystem, got {type(sys).__name__}{hint}")
    x0 = as_vector("x0", x0, sys.nx)
    if sys.is_continuous:
        return _simulate_ct(sys, x0, u, d, t, check_bounds)
    T = _infer_T(T, u, d)
    u_arr = as_signal("u", u, sys.nu, T, allow_batch=False)
    d_fn, d_arr = _d_signal(sys, d, T)
    x = np.empty((T, sys.nx))
    y = np.empty((T, sys.ny))
    dd = np.empty((T, sys.nd))
    xk = x0.copy()
    real = _realised(sys, matrices, T, check_bounds)
    for k in range(T):
        A, B, C, D, E, F = (real[n][k] if n in real else m
                            for n, m in zip("ABCDEF", sys.matrices_at(k)))  # fmt: skip
        dk = d_arr[k] if d_fn is None else as_vector(f"d({k}, x)", d_fn(k, xk.copy()), sys.nd)
        x[k], dd[k] = xk, dk
        y[k] = C @ xk + D @ u_arr[k] + F @ dk
        xk = A @ xk + B @ u_arr[k] + E @ dk
        if not np.all(np.isfinite(xk)):
            raise IvobsError(f"simulate: the state diverged to non-finite values at step {k + 1}")
    if check_bounds:
        _check_d(sys, dd, y)
    return Trajectory(x=x, y=y, u=u_arr, d=dd, t=np.arange(T) * sys.sampling_period)


def _realised(sys: LinearSystem, matrices: Any, T: int, check: bool) -> dict[str, np.ndarray]:
    """The stacks of ``matrices=`` (:func:`simulate`), checked against the interval matrices."""
    if matrices is None:
        return {}
    boxes = sys.interval_matrices()
    if not isinstance(matrices, dict) or not set(matrices) <= set(boxes):
        raise IvobsError(
            f"matrices: expected a dict of stacked matrices for the interval matrices of the "
            f"system ({', '.join(boxes) or 'none: every matrix is exact'}), got {matrices!r:.80}"
        )
    out = {}
    for name, stack in matrices.items():
        box = boxes[name]
        arr = as_float_array(f"matrices[{name!r}]", stack)
        if arr.ndim != 3 or arr.shape[0] < T or arr.shape[1:] != box.lo.shape:
            raise IvobsError(
                f"matrices[{name!r}]: expected shape ({T}, {box.lo.shape[0]}, "
                f"{box.lo.shape[1]}), got {arr.shape}"
            )
        if check and not np.all((box.lo <= arr[:T]) & (arr[:T] <= box.hi)):
            k = int(np.argwhere(~((box.lo <= arr[:T]) & (arr[:T] <= box.hi)))[0][0])
            raise IvobsError(f"matrices[{name!r}]: step {k} leaves the interval matrix {name}")
        out[name] = arr
    return out


def _d_signal(sys: LinearSystem, d: Any, T: int) -> tuple[Any, np.ndarray]:
    """``d`` as ``(callable or None, (T, nd) samples)`` (the samples unused with a callable)."""
    if callable(d) or d is None:
        return (d if callable(d) else None), np.zeros((T, sys.nd))
    return None, as_signal("d", d, sys.nd, T, allow_batch=False)


def _infer_T(T: Any, *signals: Any) -> int:
    """The number of steps: the rows of the first array among ``signals``, else ``T``."""
    for sig in signals:
        if sig is not None and not callable(sig):
            arr = np.asarray(sig)
            if arr.ndim >= 1:
                n = arr.shape[0]
                if T is not None and int(T) != n:
                    raise IvobsError(f"T: {T} disagrees with the signals' {n} rows")
                return int(n)
    if T is None:
        raise IvobsError("T: give the number of steps (no array signal to infer it from)")
    return as_int("T", T, 1)


def _check_d(sys: LinearSystem, d: np.ndarray, y: np.ndarray) -> None:
    if sys.nd == 0:
        return
    T = d.shape[0]
    if isinstance(sys.d, Box):
        lo, hi = _bounds_rows(sys.d, T)
    else:  # bounds computed from the measurement ([Efimov2013, Remark 1])
        boxes = [sys.d_at(k, y[k]) for k in range(T)]
        lo = np.array([b.lo for b in boxes])
        hi = np.array([b.hi for b in boxes])
    hint = "; pass check_bounds=False to simulate outside the model on purpose (faults)"
    _check_within("d", d, lo, hi, hint)


def _check_within(
    what: str, arr: np.ndarray, lo: np.ndarray, hi: np.ndarray, hint: str = "", tol: float = 1e-12
) -> None:
    """Raise :class:`IvobsError` naming the first step and component of ``arr`` (T, n) outside
    ``[lo, hi]`` (broadcast to it) by more than ``tol`` relative."""
    slack = tol * (1.0 + np.abs(arr))
    lo, hi = np.broadcast_to(lo, arr.shape), np.broadcast_to(hi, arr.shape)
    bad = (arr < lo - slack) | (arr > hi + slack)
    if np.any(bad):
        k, i = (int(v) for v in np.argwhere(bad)[0])
        raise IvobsError(
            f"{what}: the value at step {k} leaves its bounds in component {i}: "
            f"{arr[k, i]} not in [{lo[k, i]}, {hi[k, i]}]{hint}"
        )


def _simulate_ct(
    sys: LinearSystem, x0: np.ndarray, u: Any, d: Any, t: Any, check_bounds: bool
) -> Trajectory:
    from scipy.integrate import solve_ivp
    from scipy.linalg import expm

    if t is None:
        raise IvobsError("t: continuous-time simulation needs the sample times t (increasing)")
    t = as_float_array("t", t).ravel()
    if t.size < 1 or np.any(np.diff(t) <= 0):
        raise IvobsError("t: expected strictly increasing sample times")
    T = t.size
    u_fn: Callable[[float], np.ndarray] | None = None
    if callable(u):
        u_fn = u
        u_arr = np.array([as_vector(f"u({tk})", u(tk), sys.nu) for tk in t]).reshape(T, sys.nu)
    else:
        u_arr = as_signal("u", u, sys.nu, T, allow_batch=False)
    d_fn, d_arr = _d_signal(sys, d, T)
    x = np.empty((T, sys.nx))
    dd = np.empty((T, sys.nd))
    x[0] = x0
    cache: dict[float, tuple[np.ndarray, np.ndarray]] = {}
    n, m = sys.nx, sys.nu + sys.nd
    for k in range(T):
        xk = x[k]
        dd[k] = as_vector("d", d_fn(t[k], xk.copy()), sys.nd) if d_fn else d_arr[k]
        if k == T - 1:
            break
        h = float(t[k + 1] - t[k])
        if not sys.is_time_varying and u_fn is None and d_fn is None:
            key = round(h, 15)
            if key not in cache:
                Mx = np.zeros((n + m, n + m))
                Mx[:n, :n] = sys.A
                Mx[:n, n:] = np.hstack([sys.B, sys.E])
                Me = expm(Mx * h)
                cache[key] = (Me[:n, :n], Me[:n, n:])
            Ad, BEd = cache[key]
            x[k + 1] = Ad @ xk + BEd @ np.concatenate([u_arr[k], dd[k]])
            continue
        uk, dk = u_arr[k], dd[k]

        def rhs(tt: float, xx: np.ndarray, uk: np.ndarray = uk, dk: np.ndarray = dk) -> np.ndarray:
            A, B, _, _, E, _ = sys.matrices_at(tt)
            uu = as_vector("u", u_fn(tt), sys.nu) if u_fn else uk
            dv = as_vector("d", d_fn(tt, xx), sys.nd) if d_fn else dk
            dx: np.ndarray = A @ xx + B @ uu + E @ dv
            return dx

        sol = solve_ivp(rhs, (t[k], t[k + 1]), xk, method="DOP853", rtol=1e-10, atol=1e-12)
        if not sol.success:
            raise IvobsError(f"simulate: integration failed on [{t[k]}, {t[k + 1]}]: {sol.message}")
        x[k + 1] = sol.y[:, -1]
    y = np.empty((T, sys.ny))
    for k in range(T):
        _, _, C, D, _, F = sys.matrices_at(t[k])
        y[k] = C @ x[k] + D @ u_arr[k] + F @ dd[k]
    if check_bounds:
        _check_d(sys, dd, y)
    return Trajectory(x=x, y=y, u=u_arr, d=dd, t=t)
