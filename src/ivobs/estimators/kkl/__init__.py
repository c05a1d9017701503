"""KKL / Sylvester interval observers of [Dinh2024] (method ``kkl``).

Notation map ([Dinh2024] → ivobs): ``F, H, D, W`` → ``A, C, E, F``; the paper's ``u`` is our
``B u``; its target pair ``(A, B)`` is ``(A_z, B_z)``; ``d`` and ``w`` are parts of our one ``d``.

A target pair ``(A_z, B_z)`` (nonnegative and Schur in discrete time, Metzler and Hurwitz in
continuous time) and a transformation ``T`` solving ``T A = A_z T + B_z C`` ([Dinh2024, eq. (4)])
make ``z = T x`` a cooperative system, whose interval bounds ``z̲ <= T x <= z̄`` propagate
exactly; the box of ``x`` is recovered through a left inverse of ``T``. The parts, as in the
paper:

* :mod:`.design`: the design (target, ``T`` of (4) or the sequence ``T[k]`` of (15.b) with the
  bound of its floating-point error, the left inverse), offline; the Sylvester machinery is
  :mod:`ivobs.design.sylvester`.
* :mod:`.observer`: what every recursion shares (the state ``z̲, z̄``, the recovery (3.c-d) with
  its proven rounding).
* :mod:`.terms`: the matrices of one discrete-time step per pattern of observed outputs, with
  the proven bound of every error the step makes, and the consistency test of a measurement.
* :mod:`.discrete`: observers (3) and (15), one step (observer (6) is (3) written in
  ``x̂ = T⁻¹ z``: the same bounds); :mod:`.vectorised`: (3) over whole records and batches,
  a different algorithm with its own proof.
* :mod:`.continuous`: observers (3)/(10) in sampled-data form (time-varying: an ODE flow);
  :mod:`.sampled` and :mod:`.periods`: the time-invariant flow in closed form.
* :mod:`.estimator`: the ``kkl`` estimator, which picks one of these observers once, when built.
"""

from __future__ import annotations

from .design import KKLDesign
from .estimator import KKL

__all__ = ["KKL", "KKLDesign"]
