"""What the step and the whole-record path of the fixed-time estimator [Wang2020] share besides
the window box (:func:`.gains.evaluate`): the bounds of ``d`` as centre and radius, the model
prediction used where a window cannot give a box on its own, and how it is combined with a
window's box. Every function takes leading axes (one step, or many windows at once).
"""

from __future__ import annotations

import numpy as np

from ...errors import IvobsError
from ...sets import image_bounds
from ...sets.rounding import mid_rad

__all__ = ["centre_radius", "combine", "no_box_error", "predict"]


def centre_radius(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(c, r)`` with ``[lo, hi] ⊆ [c - r, c + r]`` exactly ([Wang2020, Section 2]: ``d = c + δ``,
    ``|δ| <= r``): ``c = 0``, ``r = hi`` for symmetric bounds (exact), else
    :func:`~ivobs.sets.rounding.mid_rad` (its rounding included in ``r``)."""
    c, r = mid_rad(lo, hi)
    sym = lo == -hi
    return np.where(sym, 0.0, c), np.where(sym, hi, r)


def predict(
    M: np.ndarray, lo: np.ndarray, hi: np.ndarray, u: np.ndarray, dlo: np.ndarray, dhi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``x_k ∈ [A B E] [x_{k-1}; u_{k-1}; d_{k-1}]`` for ``M = [A B E]`` of step ``k - 1``: the
    interval image of the previous box, the input (a point) and the bounds of ``d``
    ([Efimov2013, Lemma 1]; :func:`~ivobs.sets.image_bounds` contains the exact image, its
    rounding included)."""
    parts = np.broadcast_arrays(lo, hi)
    lead = parts[0].shape[:-1]
    u, dlo, dhi = (np.broadcast_to(a, (*lead, a.shape[-1])) for a in (u, dlo, dhi))
    return image_bounds(M, np.concatenate((lo, u, dlo), -1), np.concatenate((hi, u, dhi), -1))


def combine(
    lo: np.ndarray, hi: np.ndarray, bad: np.ndarray, plo: np.ndarray, phi: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The box of a window that uses the prediction ``[plo, phi]`` (rows of NaN: none): the
    prediction where the window gave no box (NaN) or inconsistent data (``bad``), else the
    intersection of the two (both contain ``x_k``); an empty intersection proves the data
    inconsistent (then the prediction). Without a prediction, the window's box as it is."""
    own = ~np.isnan(lo).any(axis=-1)
    prior = ~np.isnan(plo).any(axis=-1)
    ilo, ihi = np.maximum(lo, plo), np.minimum(hi, phi)
    bad = bad | (own & prior & (ilo > ihi).any(axis=-1))
    use_prior = (prior & (~own | bad))[..., None]
    use_both = (prior & own & ~bad)[..., None]
    lo = np.where(use_prior, plo, np.where(use_both, ilo, lo))
    hi = np.where(use_prior, phi, np.where(use_both, ihi, hi))
    return lo, hi, bad


def no_box_error(nx: int, s: int, k: int, rank: int) -> IvobsError:
    """The error for a window at step ``k`` without enough data and no earlier box."""
    why = (
        f"the available rows of Mx have rank {rank} < nx = {nx}"
        if rank < nx
        else "the available samples do not determine the oldest state of the window, so "
        "its gain cannot be certified (singular A)"
    )
    return IvobsError(
        f"y: at step {k} the window y[{k - s}..{k}] has too many missing samples "
        f"({why}) and no earlier box exists to predict from; give a prior "
        "x0=ivobs.Box(...) or a larger s"
    )
