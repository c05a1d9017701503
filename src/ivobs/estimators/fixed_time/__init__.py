"""The fixed-time (parity-space) interval estimator of [Wang2020].

At every step ``k >= s`` the state is reconstructed from the last ``s + 1`` samples only::

    x̂_k = T (𝐲_k - Mu 𝐮_k)                 ([Wang2020, eq. (7)]),  T Mx = I  (eq. (8))
    x_k ∈ <x̂_k, -T Md blkdiag(Wd)>          (eq. (10))
    x̂_k - |T Md| 𝐫_k <= x_k <= x̂_k + |T Md| 𝐫_k    (eq. (11), 𝐫_k the stacked bound radii)

with the stacked matrices of eq. (6) and the optimal ``T`` of Theorem 1 (eq. (13)). There is no
recursion: errors do not propagate, and without disturbance ``x̂_k = x_k`` exactly from
``k = s`` on (Remark 3, "fixed-time convergence").

The parts, in the order of the paper:

* :mod:`.design`: the stacked matrices ``Mx, Mu, Md`` (eq. (6)), ``T`` (Theorem 1, eq. (13);
  Lemma 2), the output injection of Remark 1, per window for time-varying systems (Remark 4);
* :mod:`.gains`: the window gain ``x̂ = G w`` certified (its radius ``|T Md| 𝐫`` of eq. (11) and
  its rounding proven), per missing pattern, the box of a window (:func:`.gains.evaluate`), and
  the choice of the output injection by certified accuracy;
* :mod:`.window`: the model prediction and its intersection with a window's box (missing
  samples, inconsistent data);
* :mod:`.estimator`: :class:`FixedTimeEstimator` (the method ``fixed-time``: the step) and its
  state :class:`FixedTimeState`;
* :mod:`.batch`: every window of a record or batch at once.
"""

from __future__ import annotations

from .design import MAX_WINDOW, FixedTimeDesign
from .estimator import FixedTimeEstimator, FixedTimeState
from .gains import ACCURACY

__all__ = ["ACCURACY", "MAX_WINDOW", "FixedTimeDesign", "FixedTimeEstimator", "FixedTimeState"]
