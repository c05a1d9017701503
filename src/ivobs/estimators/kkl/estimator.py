"""The ``kkl`` method: the estimator that designs once, picks the observer of the system's kind
and hands it every step (see :mod:`ivobs.estimators.kkl`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

import numpy as np

from ...model import LinearSystem
from ...sets import Box
from .. import register
from ..base import Estimator
from ..state import OnlineState, Step
from .continuous import ContinuousLTV
from .design import KKLDesign, TransformSequence, design_lti, design_ltv
from .discrete import Discrete
from .observer import Observer
from .options import check_options
from .sampled import ContinuousLTI
from .vectorised import VectorisedLTI

__all__ = ["KKL"]


@register
class KKL(Estimator):
    """KKL / Sylvester interval observer of [Dinh2024] (LTI and LTV, discrete and continuous).

    The parameters are keyword-only, all optional.

    Parameters
    ----------
    A_z, B_z : target pair. Time-invariant: ``(A_z, B_z)`` of [Dinh2024, Proposition 1]
        (default: a tuned diagonal target, see :mod:`ivobs.design.sylvester`). Time-varying:
        ``Ã``, ``B̃`` of (16.a)/(11.a) (default: blocks from the observability indices); the
        matrix used is ``gamma * A_z`` (DT) or ``ell * A_z`` (CT).
    T : time-invariant only: an explicit solution of (4) for the given ``A_z``, ``B_z``.
    T0 : time-varying only: ``"zero"`` (DT default: ``z[0] = 0``, no prior needed),
        ``"sylvester"`` (CT default; (4) frozen at the first step, uses ``x0``), or a matrix.
    gamma : DT time-varying factor of (16.a), default 1 ([Dinh2024, Example 3]). ell : CT factor
        of (11.a), default 2 ([Dinh2024, Example 2]).
    max_cond : largest ``cond(T)`` accepted (LTI: else :class:`DesignError`; LTV: the threshold of
        left-invertibility that decides ``valid_from``). Default 1e7.
    tune : refine the default time-invariant target by gradient descent on the predicted width.
    input_hold : continuous time: ``u`` between samples: ``"zero"`` (default: zero-order hold, as
        a digital controller), ``"linear"`` or a callable ``t -> u(t)`` (the known input signal
        itself, written with :mod:`ivobs.nlmath` so that it can be bounded between samples).

    Notes
    -----
    The observer is chosen once, from the system: :class:`~.discrete.Discrete` (observers (3)
    and (15); discrete-time LTI with the vectorised run of :mod:`.vectorised`),
    :class:`~.sampled.ContinuousLTI` and :class:`~.continuous.ContinuousLTV` (observers (3)/(10)
    in sampled-data form). Their modules give the equations, what is guaranteed, the data used
    at each step and the treatment of missing samples. Every floating-point error is bounded by
    a proven model (``proven_rounding``), in continuous time the flows between samples too
    (validated exponentials and interval Taylor steps, :mod:`.flow`).
    """

    name = "kkl"
    order = 70
    summary = "Sylvester/KKL transformation, LTI and LTV, discrete and continuous time"
    reference = "[Dinh2024, observers (3), (6), (10), (15)]"
    supports_continuous: ClassVar[bool] = True
    supports_time_varying: ClassVar[bool] = True
    needs_x0: ClassVar[bool] = False
    proven_rounding: ClassVar[bool] = True
    design: KKLDesign

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        A_z: Any = None,
        B_z: Any = None,
        T: Any = None,
        T0: Any = None,
        gamma: float | None = None,
        ell: float | None = None,
        max_cond: float = 1e7,
        tune: bool = True,
        input_hold: str | Callable[[float], Any] = "zero",
        **options: Any,
    ):
        super().__init__(sys, x0, **options)
        check_options(
            sys,
            A_z=A_z,
            B_z=B_z,
            T=T,
            T0=T0,
            gamma=gamma,
            ell=ell,
            max_cond=max_cond,
            tune=tune,
            input_hold=input_hold,
        )
        self.max_cond = float(max_cond)
        seq: TransformSequence | None = None
        if sys.is_time_varying:
            self.design, seq = design_ltv(
                sys, self.x0, A_z, B_z, T0, gamma=gamma, ell=ell, max_cond=self.max_cond
            )
        else:
            self.design = design_lti(sys, self.x0, A_z, B_z, T, tune=tune, max_cond=self.max_cond)
        self.valid_from = self.design.k_star
        self._vector: VectorisedLTI | None = None
        self._observer = self._choose(seq, input_hold)

    def _choose(
        self, seq: TransformSequence | None, hold: str | Callable[[float], Any]
    ) -> Observer[Any]:
        """The observer of the system's kind (and, discrete-time LTI, the vectorised run)."""
        sys, x0, design = self.sys, self.x0, self.design
        if sys.is_continuous:
            cls = ContinuousLTV if sys.is_time_varying else ContinuousLTI
            return cls(sys, x0, design, self.max_cond, hold)
        observer = Discrete(sys, x0, design, self.max_cond, seq)
        if seq is None:
            assert x0 is not None  # design_lti requires it
            self._vector = VectorisedLTI(observer)
        return observer

    def _initial_state(self) -> OnlineState:
        state: OnlineState = self._observer.initial_state()
        return state

    def _step(
        self, state: OnlineState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[Any]:
        return self._observer.step(state, u_k, y_k, t_k)

    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, ...] | None:
        if self._vector is None:
            return None  # time-varying or continuous time: the loop
        return self._vector.run(self, u, y, t)
