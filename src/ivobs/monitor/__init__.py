"""Streaming fault detection: a guaranteed estimator plus a consistency test at every step.

At step ``k`` the :class:`Monitor` predicts, *from the data before k only*, a box ``P_k`` of
``x[k]``: the model's one-step prediction from ``X_{k-1}``, the tightest box of ``x[k-1]`` known
([Efimov2013, Lemma 1], [Dinh2024, Lemma 1]; interval matrices and nonlinear models by their
inclusions, :mod:`ivobs.monitor.bands`; at ``k = 0`` the prior box), intersected
(``tight=True``) with the estimator's own prediction (its box with ``y[k]`` missing)::

      x[k] ∈ A_{k-1} [X_{k-1}] + B_{k-1} u[k-1] + E_{k-1} [d[k-1]],
      y[k] ∈ C_k [P_k] + D_k u[k] + F_k [d[k]]

(``d[k-1]`` and ``d[k]`` are different samples with independent bounds). An **alarm** is
raised when a measured component leaves this band, when the estimator finds the measurement
inconsistent, or when its box and the prediction do not meet. Under the model's assumptions
``x[k] ∈ P_k`` and ``y[k]`` lies in the band (widened by ``margin * (1 + |bound|)`` against
rounding), so an alarm is never false: it proves that the data contradict the model.

Inconsistent outputs never enter the estimate; the alarm is latched until the held outputs
have been consistent for ``clear_after`` steps (with the reference estimate without them and a
trial estimate with them), and each episode is reported (:class:`MonitorStep`, :class:`Fault`).
The monitor uses the public estimator interface only, so it works with every method, and its
state is JSON-serialisable. The policy, the bias estimate and the isolation in detail:
docs/operating.md, "The streaming monitor and its alarms".
"""

from __future__ import annotations

from .online import Monitor
from .records import Fault, MonitorRecord, MonitorStep

__all__ = ["Fault", "Monitor", "MonitorRecord", "MonitorStep"]
