"""The flow of ``T`` in the continuous-time KKL observer ([Dinh2024], sampled-data form).

With sampled measurements the observer carries ``T(t)``, which between samples follows
``dT/dt = A_z T - T A`` (the sampled-data form of (10.b), see
:mod:`ivobs.estimators.kkl.continuous`). That flow is the linear map ``T ↦ A_z T - T A`` whose
eigenvalues are ``λ_i(A_z) - λ_j(A)``, so it is stable iff (:func:`flow_gap`)::

    max Re λ(A_z) < min Re λ(A)          (every target mode faster than every plant mode)

This is *not* a condition of [Dinh2024, Proposition 1] (time-invariant: ``T`` is constant),
and a user's target need not obey it there: with an unstable flow the time-invariant observer
keeps ``T`` at its fixed point on a regular grid and brings it back after a missing sample
(:meth:`ivobs.estimators.kkl.sampled.ContinuousLTI.restart`). Where it is used:

* the default time-invariant target obeys it with a margin, ``a_max = min(-0.05 s,
  min Re λ(A) - 0.05 s)`` (:func:`flow_cap`, :data:`FLOW_MARGIN`), so that deviations of ``T``
  decay by themselves (at least like ``exp(-0.05 s t)``);
* time-varying systems (observer (10), ``T(t)`` integrated over the whole run; Proposition 3
  asks ``ell`` above an ``ell*`` that cannot be computed) check it with ``A(t)`` frozen at
  ``t = 0`` (:func:`check_flow`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...errors import DesignError
from ...linalg import spectral_radius

__all__ = ["CT_RANGE", "FLOW_MARGIN", "check_flow", "flow_cap", "flow_gap"]

CT_RANGE = (-20.0, -0.05)
"""Range of the diagonal of the default continuous-time ``A_z``, in units of ``max(1, ρ(A))``
(the upper end is lowered further by the flow rule, see :func:`flow_cap`)."""

FLOW_MARGIN = 0.05
"""Margin of the flow rule of the default continuous-time target, in units of ``max(1, ρ(A))``:
``max Re λ(A_z) <= min Re λ(A) - FLOW_MARGIN * max(1, ρ(A))``."""


def flow_gap(A_z: Any, A: Any) -> float:
    """``max Re λ(A_z) - min Re λ(A)``: the spectral abscissa of ``T ↦ A_z T - T A``.

    Negative iff the flow ``dT/dt = A_z T - T A`` of the continuous-time observer is stable (its
    eigenvalues are ``λ_i(A_z) - λ_j(A)``); see the module docstring.
    """
    ez = np.linalg.eigvals(np.asarray(A_z, dtype=float))
    ea = np.linalg.eigvals(np.asarray(A, dtype=float))
    return float(np.max(ez.real) - np.min(ea.real))


def flow_cap(A: Any) -> float:
    """Largest eigenvalue allowed for the default continuous-time target: ``min(-0.05 s,
    min Re λ(A) - 0.05 s)``, ``s = max(1, ρ(A))`` (the flow rule with margin, module docstring)."""
    A = np.asarray(A, dtype=float)
    s = max(1.0, spectral_radius(A))
    slowest_allowed = float(np.min(np.linalg.eigvals(A).real)) - FLOW_MARGIN * s
    return min(CT_RANGE[1] * s, slowest_allowed)


def check_flow(A_z: Any, A: Any, *, who: str = "A_z", frozen: str = "") -> float:
    """Raise :class:`DesignError` unless ``max Re λ(A_z) < min Re λ(A)`` (continuous time;
    used for time-varying systems, with ``A(t)`` frozen, see the module docstring).

    The sampled-data observer integrates ``dT/dt = A_z T - T A`` between samples; that flow is
    stable iff this holds (module docstring). ``frozen`` (e.g. ``" at t = 0"``) says where a
    time-varying ``A(t)`` was frozen. Returns the gap ``max Re λ(A_z) - min Re λ(A)``.
    """
    gap = flow_gap(A_z, A)
    ez = np.linalg.eigvals(np.asarray(A_z, dtype=float)).real
    ea = np.linalg.eigvals(np.asarray(A, dtype=float)).real
    s = max(1.0, spectral_radius(A))
    if not gap < -1e-9 * s:
        raise DesignError(
            f"{who}: the flow dT/dt = A_z T - T A{frozen} of the continuous-time observer is "
            f"unstable: max Re eig(A_z) = {ez.max():.4g} is not below min Re eig(A) = "
            f"{ea.min():.4g} (needed: every eigenvalue of A_z faster than every mode of the "
            "plant, else T(t) drifts and loses invertibility during the run); choose eig(A_z) "
            f"< {ea.min():.4g}" + (" (a larger ell)" if frozen else "")
        )
    return gap
