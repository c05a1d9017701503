"""The names ``nl-constrained-zonotope`` (:mod:`.nl_czonotope`) imports from the nonlinear family
until it moves into :mod:`ivobs.estimators.nonlinear` (then it imports
:mod:`ivobs.estimators.nonlinear.meanvalue` directly and this module goes)."""

from __future__ import annotations

import numpy as np

from .nonlinear.meanvalue import Linearisation, contract_back, linearise

__all__ = ["Linearisation", "TermwiseMargin", "contract_back", "linearise"]


class TermwiseMargin:
    """Mixin of ``nl-constrained-zonotope``: no data scale ``s_k`` in the returned bounds'
    margin (:mod:`ivobs.estimators.rounding`), which stays ``ROUNDING (1 + |bound|)``: the data
    margin is in its recursion, relative to the terms it combines."""

    def _step_scale(self, k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None) -> float:
        return 0.0

    def _data_scale(self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None) -> np.ndarray:
        return np.zeros(y.shape[:-1])
