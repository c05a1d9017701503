"""Safe bounds of a linear program from approximate multipliers [Neumaier2004].

For any multipliers ``λ`` and any box ``l <= z <= u`` containing the feasible set of
``{z : b^lo <= M z <= b^hi}``, with ``r = c - M^T λ``,

::

    min c^T z  >=  Σ_i min(λ_i b_i^lo, λ_i b_i^hi) + Σ_j min(r_j l_j, r_j u_j).       (S)

(S) is evaluated in floating point and the rounding of that evaluation is subtracted, a bound
[Higham2002, §3.1] on dot products: with ``N`` the length of the longest sum,

::

    safe = fl(S) - γ_N ( Σ_i |λ_i| max|b_i| + Σ_j |r̂_j| w_j + Σ_i |λ_i| (|M| w)_i + |c|^T w )

(``w_j = max(|l_j|, |u_j|)``; the third term is the error of the reduced costs ``r̂`` computed
from ``λ``), rounded once more downwards. The bound holds in exact arithmetic whatever ``λ``
is. With ``c = 0``, a safe value ``> 0`` is a Farkas certificate that the program is infeasible
(``0 >= safe > 0`` for any feasible ``z``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...linalg import gamma
from .._uncertain import magnitude as mag

__all__ = ["SafeBoundData", "bound_data", "certifies_infeasibility", "gamma_n", "safe_min"]

EPS = float(np.finfo(float).eps)
TINY = float(np.finfo(float).smallest_subnormal)


def gamma_n(n: int) -> float:
    """``γ_n = n ε / (1 - n ε)``: relative error bound of a length-``n`` dot product
    [Higham2002, §3.1], ``ε = 2^-52`` (twice the unit roundoff, which also absorbs the
    rounding of the error terms themselves)."""
    return gamma(n, EPS)


@dataclass(frozen=True)
class SafeBoundData:
    """The data of (S) for one step, shared by the ``2 nx`` programs: the matrix ``M`` (COO:
    ``rows``, ``cols``, ``vals``), the free rows, the row ranges (0 on free rows), the variable
    bounds, their magnitudes ``w`` and ``|M| w``, and ``γ_N``."""

    rows: np.ndarray
    cols: np.ndarray
    vals: np.ndarray
    free: np.ndarray
    row_lo: np.ndarray
    row_hi: np.ndarray
    row_mag: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    w: np.ndarray
    Mw: np.ndarray
    gamma: float
    n_terms: int


def bound_data(
    rows: np.ndarray,
    cols: np.ndarray,
    vals: np.ndarray,
    row_lo: np.ndarray,
    row_hi: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    max_col_entries: int,
) -> SafeBoundData:
    """:class:`SafeBoundData` of the program ``row_lo <= M z <= row_hi`` (``±inf``: a free
    row), ``lo <= z <= hi``; ``max_col_entries``: a bound on the entries of a column of ``M``."""
    free = np.isinf(row_lo)
    r_lo = np.where(free, 0.0, row_lo)
    r_hi = np.where(free, 0.0, row_hi)
    w = mag(lo, hi)
    Mw = np.bincount(rows, weights=np.abs(vals) * w[cols], minlength=r_lo.size)
    # the longest sum of (S) and of its error terms
    n = max(r_lo.size, w.size, max_col_entries + 1) + 2
    return SafeBoundData(rows, cols, vals, free, r_lo, r_hi, mag(r_lo, r_hi), lo, hi, w, Mw,
                         gamma_n(n), n)  # fmt: skip


def safe_min(lam: np.ndarray, data: SafeBoundData, col: int | None, sense: float) -> float:
    """A lower bound on ``min c^T z`` (``c = sense e_col``; ``c = 0`` if ``col`` is None) that
    holds in exact arithmetic for every ``λ``: (S) minus the bound on its rounding (module
    docstring). ``-inf`` if it cannot be evaluated (non-finite multipliers)."""
    r = -np.bincount(data.cols, weights=data.vals * lam[data.rows], minlength=data.w.size)
    if col is not None:
        r[col] += sense
    with np.errstate(invalid="ignore", over="ignore"):
        value = (
            np.minimum(lam * data.row_lo, lam * data.row_hi).sum()
            + np.minimum(r * data.lo, r * data.hi).sum()
        )
        a = np.abs(lam)
        err = a @ data.row_mag + np.abs(r) @ data.w + a @ data.Mw
        if col is not None:
            err += abs(sense) * data.w[col]
        bound = value - (data.gamma * err + 4 * data.n_terms * TINY)
    if not np.isfinite(bound):
        return -np.inf
    return float(np.nextafter(bound, -np.inf))


def certifies_infeasibility(ray: np.ndarray, data: SafeBoundData) -> bool:
    """Farkas: ``λ`` proves the program infeasible if (S) with ``c = 0`` is safely ``> 0``
    (for a feasible ``z`` it would be ``<= 0``). Both signs of the solver's ray are tried."""
    lam = np.where(data.free, 0.0, ray)
    return any(safe_min(s * lam, data, None, 0.0) > 0.0 for s in (1.0, -1.0))
