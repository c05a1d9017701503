"""Streaming fault detection: a guaranteed estimator plus a consistency test at every step.

At step ``k`` the :class:`Monitor` predicts, *from the data before k only*, a box ``P_k`` that
contains ``x[k]``:

* the model's one-step prediction from the previous box ([Efimov2013, Lemma 1],
  [Dinh2024, Lemma 1], :func:`ivobs.image_bounds`; interval matrices and nonlinear models by
  their inclusions, :mod:`ivobs.monitor.bands`)::

      x[k] ∈ A_{k-1} [X_{k-1}] + B_{k-1} u[k-1] + E_{k-1} [d[k-1]]

  where ``X_{k-1}`` is the tightest box of ``x[k-1]`` known after step ``k - 1`` (the
  estimator's box intersected with the previous prediction); at ``k = 0``, the prior box ``x0``;
* intersected (``tight=True``) with the estimator's own prediction of ``x[k]``: the box the
  estimator returns when ``y[k]`` is missing (every method predicts through missing samples).
  For prediction-form observers this is their box itself; for zonotope or exact methods it is
  tighter than a box-wise prediction.

It then checks the measurement against the output band this predicts::

      y[k] ∈ C_k [P_k] + D_k u[k] + F_k [d[k]]

(``d[k-1]`` and ``d[k]`` are different samples with independent bounds, so using both boxes is
sound even though one disturbance enters both equations). An **alarm** is raised when a measured
component lies outside the band, when the estimator reports the measurement as inconsistent
(empty intersections in the exact, strip and constrained-zonotope methods), or when the
estimator's box and the prediction do not meet.

**Guarantee.** Under the model's assumptions (the matrices are right, ``d[k]`` stays in its
bounds, ``x[0]`` in its prior box) ``x[k] ∈ P_k`` and ``y[k]`` lies in the band at every step, so
an alarm is never false. Floating-point rounding is covered by widening the band by
``margin * (1 + |bound|)`` (``margin = 1e-9`` by default). An alarm therefore proves that the
data contradict the model: a sensor or actuator fault, a wrong model or wrong bounds.

**Faults that persist.** Inconsistent data never enter the estimate: the outputs outside the
band, or found inconsistent by the method (each measured output tried alone; all of them when
only their combination is), are treated as missing samples at that step and while the fault is
open (the policy is exclusion: the estimate continues from the fault-free data). The alarm is
latched: a fault episode opens at the first contradiction and stays open until the held outputs
have been consistent for ``clear_after`` consecutive steps with the *reference* (the estimate
without them: its band) and with a *trial* estimate that uses them again, started from the
reference (band, the method's check, boxes meeting the reference's); then the trial becomes the
estimate. A step where a held output is missing does not count; a contradiction restarts the
count. Data that obey the model are always consistent with an estimate that never used the
faulty samples, so a fault that ends is cleared ``clear_after`` measured steps later; a fault
that persists keeps the alarm raised as long as the other outputs and the model can tell. Each
step reports the episode's start, duration and outputs (:class:`MonitorStep`), a record lists
the episodes (:class:`Fault`).

The monitor uses the public estimator interface only (``initial_state``, ``advance`` and its
look-ahead form, ``save_state``/``check_state``, ``run``), keeping the estimator's online
state itself, so it works with every method; its state (``state()`` / ``restore()``) is
JSON-serialisable, so a restarted monitor continues with the same boxes and the same alarms as
one that never stopped.
"""

from __future__ import annotations

from .online import Monitor
from .records import Fault, MonitorRecord, MonitorStep

__all__ = ["Fault", "Monitor", "MonitorRecord", "MonitorStep"]
