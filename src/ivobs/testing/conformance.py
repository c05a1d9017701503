"""The conformance checks every estimation method passes (scikit-learn's ``check_estimator``).

:func:`check_estimator` runs a method on a few seeded plants — stable, unstable with states that
grow to ``1e6``, badly scaled, with asymmetric bounds and a feedthrough — on trajectories that
are *exact* (:mod:`.exact`: no float simulation error), disturbances on the vertices of their
bounds, and the measurements rounded once to doubles as a data logger records them. It checks:

* **containment**: every box contains the exact state, with ``run()`` (its vectorised path and
  its loop), with ``step()``, and with ``step()`` through a ``state()``/``restore()`` round trip
  in JSON every few steps;
* **agreement**: both paths of ``run()`` and ``step()`` give the same boxes within rounding,
  relative to each state's own magnitude (on the badly scaled plant, the small states' boxes
  are as tight on every path), and a restored estimator continues as the original;
* **missing samples**: with output components missing at random the boxes still contain the
  state and stay finite;
* **consistency**: no admissible measurement is flagged inconsistent;
* **bad input**: a measurement of the wrong shape is refused with an :class:`~ivobs.IvobsError`;
* **metadata**: the class attributes ``ivobs methods`` and the docs read.

A plant the method does not accept (a refusal naming the reason) is skipped, not failed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np

from ..errors import DesignError, IvobsError
from ..model import LinearSystem
from ..sets import Box
from ..simulate import vertex_disturbance
from .exact import ExactStates, exact_misses, exact_run

__all__ = ["CheckReport", "check_estimator", "conformance_plants"]


@dataclass
class CheckReport:
    """What :func:`check_estimator` did: the plants it ran (``checked``), the ones the method
    refused (``skipped``, with the reason), and the steps it checked in all."""

    method: str
    checked: list[str] = field(default_factory=list)
    skipped: dict[str, str] = field(default_factory=dict)
    steps: int = 0


def conformance_plants(seed: int = 0) -> dict[str, tuple[LinearSystem, Box]]:
    """The seeded plants of :func:`check_estimator`, by name: ``(system, prior box)``."""
    rng = np.random.default_rng(seed)
    plants: dict[str, tuple[LinearSystem, Box]] = {}

    def draw(nx: int, ny: int, rho: float) -> tuple[np.ndarray, np.ndarray]:
        for _ in range(200):
            A = rng.normal(size=(nx, nx))
            A *= rho / max(np.max(np.abs(np.linalg.eigvals(A))), 1e-9)
            C = rng.normal(size=(ny, nx))
            O = np.vstack([C @ np.linalg.matrix_power(A, i) for i in range(nx)])
            if np.linalg.matrix_rank(O) == nx and np.linalg.cond(O) < 1e4:
                return A, C
        raise RuntimeError("no observable draw")  # pragma: no cover

    A, C = draw(3, 2, 0.85)
    plants["stable"] = (
        LinearSystem(
            A,
            rng.normal(size=(3, 1)),
            C,
            E=np.eye(3, 5) * 0.2,
            F=np.eye(2, 5, 3) * 0.1,
            d=Box(-np.ones(5), np.ones(5)),
        ),
        Box(-np.ones(3), np.ones(3)),
    )
    A, C = draw(2, 1, 1.04)
    plants["unstable"] = (  # states grow from 1 to about 1e3 over 200 steps
        LinearSystem(A, None, C, E=np.eye(2, 3), F=np.eye(1, 3, 2), d=Box([-0.1] * 3, [0.1] * 3)),
        Box(-np.ones(2), np.ones(2)),
    )
    A, C = draw(3, 2, 0.9)
    S = np.diag([1e6, 1.0, 1e-3])  # badly scaled coordinates: x = S z
    Si = np.diag([1e-6, 1.0, 1e3])
    plants["scaled"] = (
        LinearSystem(
            S @ A @ Si,
            S @ rng.normal(size=(3, 1)),
            C @ Si,
            E=S @ np.eye(3, 5) * 0.1,
            F=np.eye(2, 5, 3) * 0.01,
            d=Box(-np.ones(5), np.ones(5)),
        ),
        Box(-np.array([1e6, 1.0, 1e-3]), np.array([1e6, 1.0, 1e-3])),
    )
    A, C = draw(2, 2, 0.7)
    lo = np.array([-0.3, 0.1, -0.05, 0.0])
    hi = lo + np.array([0.5, 0.4, 0.1, 0.3])
    plants["asymmetric"] = (
        LinearSystem(
            A,
            rng.normal(size=(2, 1)),
            C,
            D=rng.normal(size=(2, 1)),
            E=np.hstack([np.eye(2), np.zeros((2, 2))]) * 0.5,
            F=np.hstack([np.zeros((2, 2)), np.eye(2)]) * 0.2,
            d=Box(lo, hi),
        ),
        Box([5.0, -3.0], [7.0, -1.0]),
    )
    return plants


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal within rounding relative to each state's own magnitude over the record (columns of
    ``a``, ``b``; NaN where both are NaN): a badly scaled plant's small states are compared at
    their own scale, not at the largest state's."""
    both = np.abs(np.concatenate([a, b]))
    scale = np.nanmax(np.where(np.isfinite(both), both, 0.0), axis=0, initial=1e-300)
    return bool(np.allclose(a, b, rtol=1e-7, atol=1e-9 * scale, equal_nan=True))


def _fail(method: str, plant: str, what: str) -> AssertionError:
    return AssertionError(f"{method} on the {plant!r} plant: {what}")


def check_estimator(
    method: Any,
    *,
    steps: int = 150,
    seed: int = 0,
    options: dict[str, Any] | None = None,
    plants: dict[str, tuple[LinearSystem, Box]] | None = None,
) -> CheckReport:
    """Run the conformance checks (module docstring) on ``method``: a registered name
    (``"strip"``) or an :class:`~ivobs.estimators.base.Estimator` subclass. Raises
    ``AssertionError`` naming the method, the plant and the first failed check; returns a
    :class:`CheckReport`.

    ``steps`` per plant and path; ``options`` passed to the method; ``plants`` replaces the
    seeded ones (:func:`conformance_plants`) with your own ``{name: (system, x0)}``."""
    from ..estimators import get

    options = dict(options or {})
    plants = conformance_plants(seed) if plants is None else plants
    name = method if isinstance(method, str) else getattr(method, "name", repr(method))
    report = CheckReport(str(name))
    cls = get(method) if isinstance(method, str) else method
    _check_metadata(cls, report.method)
    rng = np.random.default_rng(seed)
    for plant, (sys, x0) in plants.items():
        try:
            est = cls(sys, x0, **options)
        except (DesignError, IvobsError) as exc:
            report.skipped[plant] = str(exc).splitlines()[0]
            continue
        x_true0 = np.where(rng.integers(0, 2, sys.nx).astype(bool), x0.hi, x0.lo)
        U = rng.uniform(-1, 1, size=(steps, sys.nu))
        Dv = vertex_disturbance(sys.d_at(0), steps, rng) if sys.nd else np.zeros((steps, 0))
        Y, X = exact_run(sys, x_true0, U, Dv)
        _check_record(est, partial(cls, sys, x0, **options), plant, U, Y, X)
        _check_missing(est, plant, U, Y, X, rng)
        _check_bad_input(est, plant, sys)
        report.checked.append(plant)
        report.steps += 3 * steps
    if not report.checked:
        raise AssertionError(
            f"{report.method}: no conformance plant was accepted: {report.skipped}"
        )
    return report


def _check_metadata(cls: Any, name: str) -> None:
    for attr in ("name", "summary", "reference"):
        if not isinstance(getattr(cls, attr, None), str) or not getattr(cls, attr):
            raise AssertionError(f"{name}: class attribute {attr!r} must be a non-empty string")
    if cls.data_used not in ("filter", "prediction"):
        raise AssertionError(f"{name}: data_used must be 'filter' or 'prediction'")


def _check_record(
    est: Any, make: Any, plant: str, U: np.ndarray, Y: np.ndarray, X: ExactStates
) -> None:
    name = est.name
    runs = {vec: est.run(U, Y, vectorize=vec) for vec in (True, False)}
    for vec, res in runs.items():
        what = f"run(vectorize={vec})"
        _check_contains(
            name, plant, what + ": {} boxes miss the exact state", res.lower, res.upper, X
        )
        if np.any(res.inconsistent):
            k = int(np.flatnonzero(res.inconsistent)[0])
            raise _fail(
                name,
                plant,
                f"{what}: the admissible measurement of step {k} was flagged inconsistent",
            )
    est.reset()
    lo = np.empty_like(res.lower)
    hi = np.empty_like(res.upper)
    fresh = None
    for k in range(Y.shape[0]):
        if k % 7 == 3:  # a round trip of the online state through JSON, into a new estimator
            saved = json.loads(json.dumps(est.state()))
            fresh = fresh or make()
            fresh.restore(saved)
            est, fresh = fresh, est
        box = est.step(U[k], Y[k])
        lo[k], hi[k] = box.lo, box.hi
    _check_contains(name, plant, "step() with state round trips: {} boxes miss", lo, hi, X)
    for vec, res in runs.items():
        if not (_close(lo, res.lower) and _close(hi, res.upper)):
            k = int(np.argmax(np.any(~np.isclose(lo, res.lower, equal_nan=True), axis=1)))
            raise _fail(
                name,
                plant,
                f"step() and run(vectorize={vec}) disagree beyond rounding, first at step {k}",
            )


def _check_missing(
    est: Any, plant: str, U: np.ndarray, Y: np.ndarray, X: ExactStates, rng: np.random.Generator
) -> None:
    Ym = Y.copy()
    Ym[rng.uniform(size=Y.shape) < 0.1] = np.nan
    res = est.run(U, Ym)
    _check_contains(est.name, plant, "missing samples: {} boxes miss", res.lower, res.upper, X)
    vf = est.valid_from
    if not np.all(np.isfinite(res.lower[vf:])) or not np.all(np.isfinite(res.upper[vf:])):
        raise _fail(est.name, plant, "missing samples: non-finite bounds after valid_from")


def _check_contains(
    name: str, plant: str, what: str, lo: np.ndarray, hi: np.ndarray, X: ExactStates
) -> None:
    """Every box ``[lo, hi]`` contains the exact state; else ``what`` (its ``{}``: the number
    of boxes that miss) and the first step."""
    bad = exact_misses(lo, hi, X)
    if bad.size:
        raise _fail(name, plant, f"{what.format(bad.size)}, first at step {bad[0]}")


def _check_bad_input(est: Any, plant: str, sys: LinearSystem) -> None:
    try:
        est.run(None if not sys.nu else np.zeros((3, sys.nu)), np.zeros((3, sys.ny + 1)))
    except IvobsError:
        return
    raise _fail(est.name, plant, "a measurement with a wrong number of columns was accepted")
