"""The equations of the trajectory program, each kept up to the rounding of its evaluation.

The data are floating-point numbers, so each equation of the model is a range
``|a_i^T z - b_i| <= tau_i`` with (``γ_n`` of :func:`~.safe.gamma_n`)

::

    dynamics:     tau = γ_{nx+nu+nd} (|A| x̄ + |B| |u| + |E| d̄) + γ_{nu} |B| |u|
    measurement:  tau = γ_{nx+nu+nd} (|C| x̄ + |D| |u| + |F| d̄) + γ_{nu+1} (|y| + |D| |u|)

(``x̄``, ``d̄``: bounds on ``|x[j]|``, ``|d[j]|``). The second term covers the computation of the
right-hand side ``B u`` or ``y - D u``; the first lets the data be a floating-point simulation of
the model (a trajectory from :func:`ivobs.simulate`, a logger's rounding of ``y``).

Also here: the interval prediction of ``x[j+1]`` from the box of ``x[j]`` [Efimov2013, Lemma 1]
(a variable bound of the program) and the interval test that certifies a gross fault before any
linear program is solved.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ...model import LinearSystem
from ...sets import image_bounds
from .._uncertain import magnitude as mag
from .safe import gamma_n

__all__ = [
    "VAR_MARGIN",
    "Dynamics",
    "Measurement",
    "dynamics",
    "measurement",
    "outside_prediction",
    "prediction",
    "widen",
]

VAR_MARGIN = 1e-9
"""Relative widening of the proven boxes when they become variable bounds of later programs (not
needed for soundness: it keeps the optimum off those implied bounds, which helps the simplex)."""


class Dynamics(NamedTuple):
    """The dynamics rows of step ``j``: ``x[j+1] - A x[j] - E d[j] ∈ B u ± tau``."""

    A: np.ndarray
    E: np.ndarray
    bu: np.ndarray
    tau: np.ndarray


class Measurement(NamedTuple):
    """The measurement rows of step ``j``: ``C x[j] + F d[j] ∈ (y - D u) ± tau`` (``rhs`` NaN:
    a free row, for a missing or dropped sample)."""

    C: np.ndarray
    F: np.ndarray
    rhs: np.ndarray
    tau: np.ndarray


def widen(lo: np.ndarray, hi: np.ndarray, rel: float = VAR_MARGIN) -> tuple[np.ndarray, np.ndarray]:
    """``[lo, hi]`` widened by ``rel (1 + max(|lo|, |hi|))`` on each side."""
    m = rel * (1.0 + np.maximum(np.abs(lo), np.abs(hi)))
    return lo - m, hi + m


def dynamics(
    sys: LinearSystem,
    j: int,
    u_j: np.ndarray,
    x_lo: np.ndarray,
    x_hi: np.ndarray,
    d_lo: np.ndarray,
    d_hi: np.ndarray,
) -> Dynamics:
    """The dynamics rows of step ``j`` with ``tau = γ_{nx+nu+nd} (|A| x̄ + |B| |u| + |E| d̄) +
    γ_{nu} |B| |u|``; ``x̄``, ``d̄`` from the boxes of ``x[j]`` and ``d[j]``."""
    A, B, _, _, E, _ = sys.matrices_at(j)
    bu_mag = np.abs(B) @ np.abs(u_j)
    tau = (
        gamma_n(sys.nx + sys.nu + sys.nd)
        * (np.abs(A) @ mag(x_lo, x_hi) + bu_mag + np.abs(E) @ mag(d_lo, d_hi))
        + gamma_n(sys.nu) * bu_mag
    )
    return Dynamics(A, E, B @ u_j, tau)


def measurement(
    sys: LinearSystem,
    j: int,
    u_j: np.ndarray,
    y_j: np.ndarray,
    used: bool,
    x_lo: np.ndarray,
    x_hi: np.ndarray,
    d_lo: np.ndarray,
    d_hi: np.ndarray,
) -> Measurement:
    """The measurement rows of step ``j`` (all free if not ``used``) with
    ``tau = γ_{nx+nu+nd} (|C| x̄ + |D| |u| + |F| d̄) + γ_{nu+1} (|y| + |D| |u|)``, ``x̄`` from
    the interval prediction of ``x[j]``. NaN components of ``y_j`` (missing) are free rows."""
    _, _, C, D, _, F = sys.matrices_at(j)
    if not used:
        return Measurement(C, F, np.full(sys.ny, np.nan), np.zeros(sys.ny))
    du_mag = np.abs(D) @ np.abs(u_j)
    tau = gamma_n(sys.nx + sys.nu + sys.nd) * (
        np.abs(C) @ mag(x_lo, x_hi) + du_mag + np.abs(F) @ mag(d_lo, d_hi)
    ) + gamma_n(sys.nu + 1) * (np.abs(y_j) + du_mag)
    return Measurement(C, F, y_j - D @ u_j, tau)


def prediction(
    sys: LinearSystem,
    j: int,
    u_j: np.ndarray,
    prev: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    tau: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of ``x[j+1]`` implied by the box of ``x[j]`` and ``d[j]`` (``prev = (x_lo, x_hi,
    d_lo, d_hi)``) [Efimov2013, Lemma 1] and the dynamics rows (range ``tau``), widened by the
    rounding of their evaluation (``γ_{nx+nd+nu+3} (|A| x̄ + |E| d̄ + |B| |u|)``) and by
    :data:`VAR_MARGIN`."""
    A, B, _, _, E, _ = sys.matrices_at(j)
    x_lo, x_hi, d_lo, d_hi = prev
    lo, hi = image_bounds(A, x_lo, x_hi)
    dlo, dhi = image_bounds(E, d_lo, d_hi)
    bu = B @ u_j
    n = sys.nx + sys.nd + sys.nu + 3
    err = gamma_n(n) * (np.abs(A) @ mag(x_lo, x_hi) + np.abs(E) @ mag(d_lo, d_hi)
                        + np.abs(B) @ np.abs(u_j)) + tau  # fmt: skip
    return widen(lo + dlo + bu - err, hi + dhi + bu + err)


def outside_prediction(
    meas: Measurement, p_lo: np.ndarray, p_hi: np.ndarray, d_lo: np.ndarray, d_hi: np.ndarray
) -> bool:
    """A measurement row certainly violated over the interval prediction of ``x[k]`` (which
    contains every state consistent with the model and the past data) and the box of ``d[k]``:
    ``|y − D u − (C x + F d)| > tau`` for every such ``x``, ``d`` ([Efimov2013, Lemma 1], with
    the rounding of its evaluation, ``γ (|C| x̄ + |F| d̄)``, subtracted). A certificate of
    inconsistency that needs no linear program, and one HiGHS could not give for right-hand
    sides beyond its infinite bound (``1e20``), which it treats as free rows."""
    C, F, rhs, tau = meas
    lo_c, hi_c = image_bounds(C, p_lo, p_hi)
    lo_f, hi_f = image_bounds(F, d_lo, d_hi)
    n = C.shape[1] + F.shape[1] + 2
    err = gamma_n(n) * (np.abs(C) @ mag(p_lo, p_hi) + np.abs(F) @ mag(d_lo, d_hi))
    with np.errstate(invalid="ignore"):  # NaN (missing) compares False
        above = rhs - tau > hi_c + hi_f + 2.0 * err
        below = rhs + tau < lo_c + lo_f - 2.0 * err
    return bool(np.any(above | below))
