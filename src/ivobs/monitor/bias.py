"""Fault estimation: a sensor fault as an unknown constant bias, estimated jointly with the state.

When the monitor traces a contradiction to outputs ``H``, it starts a *bias estimate*: the model
augmented with one constant unknown per faulty output,

::

    x[k+1] = f(x[k], u[k], d[k])        b[k+1] = b[k]
    y[k]   = h(x[k], u[k], d[k]) + S_H b[k]

(``S_H`` puts ``b_i`` on output ``i``), estimated by a constrained zonotope (``constrained-
zonotope`` for a linear model, exact or with interval matrices; ``nl-constrained-zonotope`` for
a nonlinear one) from the episode's first step on. Its prior is the reference estimate's
prediction ``P_s`` of ``x[s]`` (from the data before ``s`` only) and, for each faulty output,
``b_i ∈ y_i[s] − [band_i]``: the values that make the first faulty sample consistent. Since
``b`` has no disturbance, its interval can only shrink: the first faulty samples, which the
fault-free data had predicted, keep proving the fault for as long as it lasts, also where the
later data alone would be consistent with a model trajectory (a constant offset on a sensor of
an integrator, such as a servo's angle, is one).

Under the model's assumptions and a bias constant since ``s``, the augmented state is contained
at every step, so ``0 ∉ [b_i]`` proves that output ``i`` is faulty over the window since ``s``
(the window consistency test on which the monitor re-admits an output). When the fault changes
(it ends, or jumps), the augmented data become inconsistent and the estimate restarts at that
step, from the reference's prediction intersected with the old estimate's own prediction of
``x[k]`` (which used the faulty outputs through their bias, valid up to the step before): a bias
that has ended then gives an interval containing 0, and the output is re-admitted
``clear_after`` steps later; a bias that has jumped keeps excluding 0.

Supported models: time-invariant linear models with constant bounds, discrete-time nonlinear
models and sampled continuous-time nonlinear models (the bias augments the vector field with
``b' = 0``). Others are monitored without a bias estimate (the latch then clears on the trial
estimate alone).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..sets import Box
from ._codec import _decode, _encode, saved_entry
from .records import bias_intervals

__all__ = ["BiasEstimate", "augment_with_bias"]


def _augment_linear(sys: LinearSystem, outputs: tuple[int, ...]) -> LinearSystem | None:
    if sys.is_time_varying or not sys.has_constant_bounds or sys.bounds_depend_on_y:
        return None
    nx, nb, ny = sys.nx, len(outputs), sys.ny
    S = np.zeros((ny, nb))
    S[list(outputs), range(nb)] = 1.0

    def grow(M: np.ndarray, name: str) -> np.ndarray:
        M = np.asarray(M, dtype=float)
        if name == "A":
            return np.block([[M, np.zeros((nx, nb))], [np.zeros((nb, nx)), np.eye(nb)]])
        if name == "B":
            return np.vstack([M, np.zeros((nb, M.shape[1]))])
        if name == "C":
            return np.hstack([M, S])
        return M

    mats: dict[str, Any] = {}
    boxes = sys.interval_matrices()
    for name in "ABCD":
        if name in boxes:
            b = boxes[name]
            mats[name] = Box(grow(b.lo, name), grow(b.hi, name))
        else:
            mats[name] = grow(getattr(sys, f"{name}_at")(0), name)
    E = np.vstack([sys.E_at(0), np.zeros((nb, sys.nd))]) if sys.nd else None
    F = sys.F_at(0) if sys.nd else None
    return LinearSystem(
        mats["A"],
        mats["B"],
        mats["C"],
        D=mats["D"],
        E=E,
        F=F,
        d=sys.d if sys.nd else None,
        dt=sys.dt,
    )


def _bias_name(sys: NonlinearSystem, i: int) -> str:
    taken = set(sys.state_names) | set(sys.input_names) | set(sys.known_params)
    taken |= set(sys.param_bounds) | set(sys.signal_bounds)
    name = f"bias_{sys.output_names[i]}"
    while name in taken:
        name += "_"
    return name


def _augment_nonlinear(sys: NonlinearSystem, outputs: tuple[int, ...]) -> NonlinearSystem | None:
    from ..model.nonlinear.flow import FlowSystem

    base = sys.continuous if isinstance(sys, FlowSystem) else sys
    names = [_bias_name(base, i) for i in outputs]
    # a constant: b[k+1] = b[k] in discrete time, b' = 0 in continuous time
    f = list(base.f_text) + (["0"] * len(names) if base.is_continuous else names)
    h = list(base.h_text)
    for i, n in zip(outputs, names, strict=True):
        h[i] = f"({h[i]}) + {n}"
    params: dict[str, Any] = dict(base.known_params)
    params.update(base.param_bounds)
    aug = NonlinearSystem(
        f,
        h,
        states=list(base.state_names) + names,
        inputs=list(base.input_names),
        params=params,
        d=dict(base.signal_bounds),
        dt=base.dt,
        outputs=list(base.output_names),
    )
    if isinstance(sys, FlowSystem):
        return aug.discretize(
            sys.dt, order=sys.order, substeps=sys.substeps, disturbances=sys.disturbances
        )
    return aug


def augment_with_bias(
    sys: LinearSystem | NonlinearSystem, outputs: tuple[int, ...]
) -> LinearSystem | NonlinearSystem | None:
    """``sys`` with one constant unknown ``b_i`` added to each output of ``outputs`` (states
    appended after ``x``, in the order of ``outputs``); None for a model this cannot augment
    (time-varying matrices, bounds over time or computed from ``y``)."""
    if not outputs:
        return None
    if isinstance(sys, LinearSystem):
        return _augment_linear(sys, outputs)
    return _augment_nonlinear(sys, outputs)


class BiasEstimate:
    """The joint estimate of the state and of the biases of ``outputs`` since step ``start``
    (module docstring).

    ``prior`` is the box of ``[x[start]; b]``. :meth:`step` takes the data of one step (all the
    outputs, the faulty ones included) and says whether they are consistent with a constant
    bias; :attr:`lower`/:attr:`upper` are the biases' bounds (one per output of ``outputs``).
    """

    def __init__(
        self,
        aug: LinearSystem | NonlinearSystem,
        outputs: tuple[int, ...],
        start: int,
        prior: Box,
        nx: int,
    ):
        from ..estimators import make_estimator

        method = (
            "constrained-zonotope" if isinstance(aug, LinearSystem) else "nl-constrained-zonotope"
        )
        self.outputs, self.start, self.prior, self.nx = outputs, start, prior, nx
        self.estimator = make_estimator(method, aug, x0=prior)
        self.estimator.on_inconsistent = "ignore"
        self.state: Any = self.estimator.initial_state()
        self.lower = prior.lo[nx:].copy()
        self.upper = prior.hi[nx:].copy()

    @classmethod
    def begin(
        cls,
        sys: LinearSystem | NonlinearSystem,
        outputs: tuple[int, ...],
        start: int,
        pred: tuple[np.ndarray, np.ndarray] | None,
        band: tuple[np.ndarray, np.ndarray],
        y: np.ndarray,
    ) -> BiasEstimate | None:
        """The estimate from step ``start``: ``x`` in the reference's prediction ``pred``,
        ``b_i ∈ y_i − band_i``; None when it cannot start (no prediction, a faulty output not
        measured at this step, unbounded band, a model that cannot be augmented)."""
        idx = list(outputs)
        if pred is None or not outputs or np.isnan(y[idx]).any():
            return None
        b_lo, b_hi = y[idx] - band[1][idx], y[idx] - band[0][idx]
        if not (np.all(np.isfinite(b_lo)) and np.all(np.isfinite(b_hi))):
            return None
        aug = augment_with_bias(sys, outputs)
        if aug is None:
            return None
        # widen by the rounding of the subtraction (one ulp each way is enough: outward)
        b_lo, b_hi = np.nextafter(b_lo, -np.inf), np.nextafter(b_hi, np.inf)
        prior = Box(np.concatenate([pred[0], b_lo]), np.concatenate([pred[1], b_hi]))
        return cls(aug, outputs, start, prior, sys.nx)

    def step(self, u: np.ndarray | None, y: np.ndarray, t: float | None) -> bool:
        """The data of one step; False when they contradict a bias constant since
        :attr:`start` (the estimate is then no longer valid: restart it)."""
        new, box = self.estimator.advance(self.state, u, y, t)
        if new.inconsistent:
            return False
        self.state = new
        if not np.isnan(box.lo).any():
            self.lower = np.maximum(self.lower, box.lo[self.nx :])
            self.upper = np.minimum(self.upper, box.hi[self.nx :])
        return True

    def predict(
        self, u: np.ndarray | None, t: float | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The box of ``x[k]`` the estimate predicts from the data before ``k`` (None where
        it has none)."""
        try:
            box = self.estimator.advance(self.state, u, None, t, keep=False)[1]
        except IvobsError:
            return None
        if box.is_unknown:
            return None
        return box.lo[: self.nx].copy(), box.hi[: self.nx].copy()

    @property
    def excludes_zero(self) -> bool:
        """Some bias's interval excludes 0: the data since :attr:`start` prove the fault."""
        return bool(np.any((self.lower > 0) | (self.upper < 0)))

    def describe(self) -> str:
        """The estimate in a reason: ``bias of y1 in [0.4, 0.56] (estimated since step 300)``."""
        parts = bias_intervals(zip(self.outputs, self.lower, self.upper, strict=True))
        return f"bias of {parts} (estimated since step {self.start})"

    # -- persistence ------------------------------------------------------------------------
    def save(self) -> dict[str, Any]:
        return {
            "outputs": list(self.outputs),
            "start": self.start,
            "prior": {"lo": _encode(self.prior.lo), "hi": _encode(self.prior.hi)},
            "bias": {"lo": _encode(self.lower), "hi": _encode(self.upper)},
            "estimator": self.estimator.save_state(self.state),
        }

    @classmethod
    def restore(
        cls, sys: LinearSystem | NonlinearSystem, saved: Any, k: int
    ) -> BiasEstimate | None:
        """From :meth:`save`, every entry checked (the monitor at step ``k``)."""
        if saved is None:
            return None
        with saved_entry("bias: expected the bias estimate saved by the monitor"):
            outputs = tuple(saved["outputs"])
            start = saved["start"]
            if (
                not outputs
                or not all(type(i) is int and 0 <= i < sys.ny for i in outputs)
                or type(start) is not int
                or not 0 <= start < max(k, 1)
            ):
                raise ValueError
            n = sys.nx + len(outputs)
            lo, hi = _decode(saved["prior"]["lo"]), _decode(saved["prior"]["hi"])
            b_lo, b_hi = _decode(saved["bias"]["lo"]), _decode(saved["bias"]["hi"])
            if lo.shape != (n,) or hi.shape != (n,) or b_lo.shape != b_hi.shape != (len(outputs),):
                raise ValueError
            aug = augment_with_bias(sys, outputs)
            if aug is None:
                raise ValueError
            est = cls(aug, outputs, start, Box(lo, hi), sys.nx)
            est.state = est.estimator.check_state(saved["estimator"])
        est.lower, est.upper = b_lo, b_hi
        return est
