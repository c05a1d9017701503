"""The window chosen from the model (``window="auto"``): how far back the window program's
optimal multipliers still look.

For the window program of :mod:`.refresh` over ``N_max`` past steps, with data of a trajectory
on which every disturbance sits at the centre of its box and with the first state *free*, the
identity (D) of :mod:`.certificate` gives the optimum of the bound of ``x_i`` as

::

    max c^T x_k = c^T x_k,true + min_μ Σ_j |h_j|^T r        (c = e_i, r the radii of d)

(no data term survives: the program is the ℓ1-optimal filtering problem of the window, and
its optimal multipliers ``μ^(i)`` do not depend on the trajectory). Its adjoint ``q̂_p^(i)``
(:mod:`.certificate`) says how much the state at position ``p`` still matters: a window of
``N`` steps that starts at ``p = N_max − N`` from a box of widths ``w`` can keep the same
multipliers (``μ_j = 0`` before ``p``) and loses at most ``|q̂_p^(i)|^T w / 2`` against the long
window. With ``w`` the long window's own widths (``w_i = 2 Σ_j |h_j^(i)|^T r``), the relative
influence of the window's first state is

::

    η(N) = max_i |q̂_{N_max − N}^(i)|^T w / w_i

and the window chosen is the smallest ``N`` with ``η(N) <= tol`` (:data:`TOL`, 1 %), at least
:data:`MIN_WINDOW`, at most ``N_max`` (:func:`max_window`: :data:`MAX_WINDOW` steps, fewer when
the program of ``N_max`` steps would be large, :data:`MAX_COLUMNS`). The influence is that of
the window program itself, so it accounts for the noise as well as the decay of ``A``: a gain
that forgets fast but amplifies the noise is not what the hull does (the influence of a
stabilising observer ``‖(A − LC)^N‖`` is a bound for one such gain only). When the first state
cannot be left free (an unobservable mode over ``N_max`` steps) its box is ``x0``'s width.
"""

from __future__ import annotations

import math

import numpy as np

from .certificate import Layout
from .refresh import WindowLP

__all__ = ["MAX_COLUMNS", "MAX_WINDOW", "MIN_WINDOW", "TOL", "choose_window", "max_window"]

TOL = 0.01
"""Largest relative influence ``η(N)`` of the window's first state on its bounds."""

MIN_WINDOW = 20
"""Shortest window chosen (the former default): a short window costs little, and the program at
centred data underestimates how far back the hull of a real record looks (it uses the
realisation of the disturbances: CORA's vehicle, 1.06x the exact hull at the 7 steps the
rule gives, 1.03x at 20)."""

MAX_WINDOW = 200
"""Longest window chosen (the cost of a refresh grows with it: ``2 nx`` programs of ``N + 1``
blocks; of an evaluation: ``2 nx cache (N + 1)(ny + nu)`` numbers)."""

MAX_COLUMNS = 5_800
"""Largest program of the choice, in columns ``(N_max + 1)(nx + nd)``: the cost budget that
bounds ``N_max`` on large systems (CORA's 30-tank system, 81 columns a block: ``N_max = 70``;
its cost per record in BENCHMARKS.md)."""


def max_window(nx: int, nd: int) -> int:
    """``N_max``: :data:`MAX_WINDOW`, or fewer so that the program has at most
    :data:`MAX_COLUMNS` columns (never below :data:`MIN_WINDOW`)."""
    return max(MIN_WINDOW, min(MAX_WINDOW, MAX_COLUMNS // (nx + nd) - 1))


def choose_window(
    mats: tuple[np.ndarray, ...], d_lo: np.ndarray, d_hi: np.ndarray, x0_width: np.ndarray
) -> tuple[int, float]:
    """The window (module docstring) and the influence ``η`` of its first state."""
    A, B, C, _D, E, F = mats
    nx, nu, ny, nd = A.shape[0], B.shape[1], C.shape[0], E.shape[1]
    n_max = max_window(nx, nd)
    lay = Layout(nx, nu, ny, nd, n_max)
    lp = WindowLP(mats, d_lo, d_hi, lay)
    d_c, r = 0.5 * (d_lo + d_hi), 0.5 * (d_hi - d_lo)
    x = np.zeros((n_max + 1, nx))
    for p in range(n_max):  # the trajectory from 0 with d at the centre, u = 0
        x[p + 1] = A @ x[p] + E @ d_c
    y = x @ C.T + F @ d_c
    u = np.zeros((n_max + 1, nu))
    free = (np.full(nx, -np.inf), np.full(nx, np.inf))
    boxed = (-0.5 * x0_width, 0.5 * x0_width)
    replaced = np.zeros((n_max + 1, ny), dtype=bool)
    start = None  # the boxed programs start from the free ones' last basis
    for prior in (free, boxed):
        mu, ok, start = lp.solve(y, u, replaced, 0, prior, x, start, count=nx)
        if ok[:nx].all():
            break
    else:
        return n_max, math.inf
    q, h = _adjoint(A, C, E, F, mu[:nx])
    w = 2.0 * (np.abs(h) @ r).sum(axis=1)  # (nx,): the long window's widths
    if not (np.isfinite(w).all() and (w > 0.0).all()):
        return n_max, math.inf
    eta = (np.abs(q) @ w) / w[:, None]  # (nx, N_max + 1): influence of a start at p
    eta = eta.max(axis=0)[::-1]  # by window length N = N_max − p
    good = np.flatnonzero(eta[MIN_WINDOW:] <= TOL)
    N = MIN_WINDOW + int(good[0]) if good.size else n_max
    return N, float(eta[N])


def _adjoint(
    A: np.ndarray, C: np.ndarray, E: np.ndarray, F: np.ndarray, mu: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``q̂_p`` (nx, N+1, nx) and ``h_p`` (nx, N+1, nd) of the multipliers ``mu`` (nx, N+1, ny)
    for the objectives ``e_i`` (:mod:`.certificate`; no rounding: this only chooses ``N``)."""
    nx, n = mu.shape[0], mu.shape[1]
    muC = mu @ C
    q = np.empty((nx, n, A.shape[0]))
    q[:, -1] = np.eye(nx) - muC[:, -1]
    for p in range(n - 2, -1, -1):
        q[:, p] = q[:, p + 1] @ A - muC[:, p]
    qn = np.zeros_like(q)
    qn[:, :-1] = q[:, 1:]
    return q, qn @ E - mu @ F
