"""Certification of a window gain of the fixed-time estimator ([Wang2020]; not in the paper).

The stacked matrices of [Wang2020, eq. (6)] come from inverses (eq. (4)), so a computed window
gain satisfies eqs. (8)-(9) only to rounding amplified by the conditioning of ``A`` (or of
``A - LC`` with the output injection of Remark 1). :func:`forward_window` writes the window
forward (products of the model matrices, no inverse) and :func:`window_bound` bounds, entry by
entry, what a given gain really does, with a ``γ_n`` rounding bound ([Higham2002, Lemma 3.1]),
and refines it once. No loops over time here: a window has a few steps, and that is all these
functions see.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..linalg import gamma
from ..sets.rounding import up, upper

__all__ = ["ForwardWindow", "WindowBound", "drop_outputs", "forward_window", "window_bound"]

_EPS = np.finfo(float).eps

_WORK = np.longdouble
"""Working precision of the certification (:func:`forward_window`, :func:`window_bound`): the
x87 extended format where the platform has it (``ε = 2⁻⁶³``), else ``float64``; every bound
uses the ``ε`` of the format actually used, so it holds either way."""

_EPS_WORK = float(np.finfo(_WORK).eps)


@dataclass(frozen=True)
class ForwardWindow:
    """The window of the fixed-time estimator written *forward*, without any inverse.

    Free variables ``ξ = [x_{k-a}; 𝐯; 𝛅]``: the state at the anchor lag ``a``, the known inputs
    ``v_{k-i} = [u_{k-i}; c_{k-i}]`` (``c`` the centre of ``d``, only with ``centre=True``) and
    the normalised disturbances ``δ_{k-i} = d_{k-i} - c_{k-i}``, both lag-major
    (``i = 0 … s``). ``Z`` maps ``ξ`` to the window vector ``w = [z_k; …; z_{k-s}]``,
    ``z = [u; y; c]`` (rows of missing outputs and of lags ``> a`` are zero), ``X`` maps ``ξ``
    to ``x_k``; ``Za``, ``Xa`` are the same recursions on absolute values (for the rounding
    bound). All four in the working precision :data:`_WORK`. ``y_rows``: the rows of ``w``
    holding available outputs of lags ``<= a``; ``v_rows``, ``v_cols``: the rows of ``w``
    holding ``u`` and ``c`` and the columns of ``ξ`` they equal; ``out_rows[i, j]``: the row of
    ``w`` of output ``j`` at lag ``i``.
    """

    Z: np.ndarray
    Za: np.ndarray
    X: np.ndarray
    Xa: np.ndarray
    lag: int
    n_rounds: int
    y_rows: np.ndarray
    v_rows: np.ndarray
    v_cols: np.ndarray
    x_cols: slice
    v_slice: slice
    d_slice: slice
    out_rows: np.ndarray


def drop_outputs(fw: ForwardWindow, missing: np.ndarray) -> ForwardWindow:
    """``fw`` with the outputs ``missing`` (``(s+1, ny)`` bool) zero in ``w`` and left out of
    ``y_rows`` (a missing sample is not data)."""
    rows = fw.out_rows[np.asarray(missing, dtype=bool)]
    if not rows.size:
        return fw
    Z, Za = fw.Z.copy(), fw.Za.copy()
    Z[rows] = 0.0
    Za[rows] = 0.0
    return replace(fw, Z=Z, Za=Za, y_rows=fw.y_rows[~np.isin(fw.y_rows, rows)])


def forward_window(
    mats: Sequence[tuple[np.ndarray, ...]], *, centre: bool, lag: int | None = None
) -> ForwardWindow:
    """The forward map of one window (see :class:`ForwardWindow`), used to certify a computed
    window gain (:func:`window_bound`).

    ``mats[i] = (A, B, C, D, E, F)`` of the *original* system at step ``k - i`` (no output
    injection, no inverse: ``x_{j+1} = A x_j + B u_j + E (c_j + δ_j)``,
    ``y_j = C x_j + D u_j + F (c_j + δ_j)``), ``i = 0 … s``; ``lag``: the anchor ``a``
    (default ``s``); outputs missing from a window: :func:`drop_outputs`.
    ``n_rounds`` bounds the roundings along any product path of ``X`` and of the output rows
    of ``Z``: per step one product of inner size ``nx`` and one addition.
    """
    s = len(mats) - 1
    a = s if lag is None else int(lag)
    _, B0, C0, _, E0, _ = mats[0]
    nx, nu, ny, nd = B0.shape[0], B0.shape[1], C0.shape[0], E0.shape[1]
    nc = nd if centre else 0
    nv, nz = nu + nc, nu + ny + nc
    nxi = nx + (s + 1) * (nv + nd)
    d0 = nx + (s + 1) * nv
    Z = np.zeros(((s + 1) * nz, nxi), dtype=_WORK)
    Za = np.zeros_like(Z)
    # P = [X; Xa]: the signed map and the same recursion on absolute values, in one array
    P = np.zeros((2 * nx, nxi), dtype=_WORK)
    P[:nx, :nx] = P[nx:, :nx] = np.eye(nx)
    y_rows: list[int] = []
    v_rows: list[int] = []
    v_cols: list[int] = []
    for i in range(a, -1, -1):
        A, B, C, D, E, F = (np.asarray(M, dtype=_WORK) for M in mats[i])
        r0, cu, cd = i * nz, nx + i * nv, d0 + i * nd
        cols_u, cols_c, cols_d = slice(cu, cu + nu), slice(cu + nu, cu + nv), slice(cd, cd + nd)
        Y = np.vstack([C @ P[:nx], np.abs(C) @ P[nx:]])
        Y[:, cols_u] += np.vstack([D, np.abs(D)])
        FF = np.vstack([F, np.abs(F)])
        Y[:, cols_d] += FF
        if nc:
            Y[:, cols_c] += FF
        Z[r0 + nu : r0 + nu + ny] = Y[:ny]
        Za[r0 + nu : r0 + nu + ny] = Y[ny:]
        y_rows.extend(range(r0 + nu, r0 + nu + ny))
        vr = list(range(r0, r0 + nu)) + list(range(r0 + nu + ny, r0 + nz))
        v_rows.extend(vr)
        v_cols.extend(range(cu, cu + nv))
        Z[vr, np.arange(cu, cu + nv)] = 1.0  # u_{k-i}, c_{k-i} are entries of ξ
        Za[vr, np.arange(cu, cu + nv)] = 1.0
        if i > 0:
            P = np.vstack([A @ P[:nx], np.abs(A) @ P[nx:]])
            P[:, cols_u] += np.vstack([B, np.abs(B)])
            EE = np.vstack([E, np.abs(E)])
            P[:, cols_d] += EE
            if nc:
                P[:, cols_c] += EE
    return ForwardWindow(
        Z=Z,
        Za=Za,
        X=P[:nx],
        Xa=P[nx:],
        lag=a,
        n_rounds=(a + 1) * (nx + 1),
        y_rows=np.array(y_rows, dtype=int),
        v_rows=np.array(v_rows, dtype=int),
        v_cols=np.array(v_cols, dtype=int),
        x_cols=slice(0, nx),
        v_slice=slice(nx, d0),
        d_slice=slice(d0, nxi),
        out_rows=np.arange(s + 1)[:, None] * nz + nu + np.arange(ny)[None, :],
    )


@dataclass(frozen=True)
class WindowBound:
    """A window gain ``G`` and its certified error (:func:`window_bound`).

    For the true trajectory, ``target - G w = R ξ`` exactly, with ``|R| <= [Rx, Rv, Rd]``
    elementwise (``ξ`` and the blocks as in :class:`ForwardWindow`, ``target`` is ``x_k`` for
    the first rows, ``0`` for parity rows); ``kappa`` and ``nu`` bound the anchor state:
    ``‖x_{k-a}‖_∞ <= kappa ‖w‖_∞ + nu · 𝐫`` (``𝐫`` the stacked radii, lag-major).
    ``kappa = inf`` when the window does not determine ``x_{k-a}``.
    """

    G: np.ndarray
    Rx: np.ndarray
    Rv: np.ndarray
    Rd: np.ndarray
    kappa: float
    nu: np.ndarray


def _residual(
    G: np.ndarray, target: np.ndarray, target_abs: np.ndarray, fw: ForwardWindow
) -> tuple[np.ndarray, np.ndarray]:
    """``(R, bound)``: ``R = target - G Z`` computed in the working precision (signed), and
    ``bound >= |target - G Z|`` in exact arithmetic, elementwise (``float64``).

    ``bound = |R| + γ_2N (|G| Za + |target|)``, converted to ``float64`` upward: ``γ`` of the
    working precision, ``N`` the roundings along the longest product path (the forward
    recursion, the product with ``G`` of inner size ``m``, the subtraction); the factor 2 in
    ``γ_2N`` covers the rounding of the bound itself (nonnegative terms). The conversion rounds
    to nearest, so the next double up (:func:`~ivobs.sets.rounding.up`) is an upper bound, also
    below the subnormal range."""
    Gw = np.asarray(G, dtype=_WORK)
    n = fw.n_rounds + G.shape[1] + 2
    R = target - Gw @ fw.Z
    B = np.abs(R) + gamma(2 * n, _EPS_WORK) * (np.abs(Gw) @ fw.Za + target_abs)
    return R, up(B.astype(float))


def _anchor(fw: ForwardWindow, nx: int) -> tuple[np.ndarray | None, float, np.ndarray]:
    """``(G', kappa, nu)``: ``G' = O⁺ (S_y - Z_yv S_v)`` estimates ``x_{k-a}`` from the window
    (``O`` the forward observability matrix of the available outputs), certified like any
    window gain: ``x_{k-a} - G' w = R' ξ``; with ``ρ' = ‖R'_x‖_∞ < 1/2``,
    ``‖x_{k-a}‖_∞ <= (‖G'‖_∞ (1 + γ) + ‖R'_v‖_∞) ‖w‖_∞ / (1 - ρ') + 1ᵀ R'_δ 𝐫 / (1 - ρ')``.
    ``(None, inf, 0)`` when ``O`` does not have full column rank."""
    nd_cols = fw.Z.shape[1] - fw.d_slice.start
    fail = (None, np.inf, np.zeros(nd_cols))
    O = np.asarray(fw.Z[fw.y_rows, fw.x_cols], dtype=float)
    if O.shape[0] < nx:
        return fail
    U, sv, Vt = np.linalg.svd(O, full_matrices=False)
    if not sv[-1] > 10.0 * max(O.shape) * _EPS * sv[0]:
        return fail
    Op = (Vt.T / sv) @ U.T
    Gp = np.zeros((nx, fw.Z.shape[0]))
    Gp[:, fw.y_rows] = Op
    Gp[:, fw.v_rows] = -Op @ np.asarray(fw.Z[np.ix_(fw.y_rows, fw.v_cols)], dtype=float)
    tgt = np.zeros((nx, fw.Z.shape[1]), dtype=_WORK)
    tgt[:, fw.x_cols] = np.eye(nx)
    _, Rp = _residual(Gp, tgt, np.abs(tgt), fw)
    rho = float(upper(Rp[:, fw.x_cols].sum(axis=1), nx).max())
    if not rho < 0.5:
        return fail
    gn = float(upper(np.abs(Gp).sum(axis=1), Gp.shape[1]).max())
    nv = fw.v_slice.stop - fw.v_slice.start
    rv = float(upper(Rp[:, fw.v_slice].sum(axis=1), nv).max(initial=0.0))
    # (1 - rho) is rounded: the quotients carry 1 + γ for it, the division and the product
    kappa = float(upper((gn + rv) / (1.0 - rho), 4))
    nu = upper(Rp[:, fw.d_slice].sum(axis=0) / (1.0 - rho), nx + 3)
    return Gp, kappa, nu


def window_bound(
    G: np.ndarray, nx_rows: int, fw: ForwardWindow, *, refine: bool = True
) -> WindowBound:
    """Certify a computed window gain ``G`` (rows ``0 … nx_rows - 1`` estimate ``x_k``, the
    others are parity rows with target 0) on the forward form of the window.

    Whatever rounding went into ``G`` (the inverses of eq. 4, an ill-conditioned ``A``, a large
    output injection, the SVDs of Theorem 1), ``target - G w`` is linear in
    ``ξ = [x_{k-a}; 𝐯; 𝛅]`` with coefficients ``R = target - G Z`` computed from products of
    the model matrices only, in extended precision, with the rounding bound of
    :func:`_residual`. The ``𝛅`` block is the disturbance gain (``-T Md`` of eq. 9 up to
    rounding); the ``x`` and ``𝐯`` blocks would be zero in exact arithmetic: they measure how
    far ``G`` is from ``T Mx = I`` and from cancelling the known inputs.

    ``refine``: one step of iterative refinement on those two blocks,
    ``G ← G + R_x G' + R_v S_v`` (``G'`` the anchor estimator of :func:`_anchor`, ``S_v`` the
    selection of the known entries of ``w``), kept if its certified error is smaller; it only
    moves ``G`` by the size of its error. The returned ``G`` is the one certified.
    """
    nx = fw.X.shape[0]
    m = G.shape[0]
    target = np.zeros((m, fw.Z.shape[1]), dtype=_WORK)
    target_abs = np.zeros_like(target)
    target[:nx_rows] = fw.X
    target_abs[:nx_rows] = fw.Xa
    Gp, kappa, nu = _anchor(fw, nx)
    R, Bd = _residual(G, target, target_abs, fw)

    def cost(b: np.ndarray) -> float:
        return float(np.max(b[:, fw.x_cols].sum(axis=1) * kappa + b[:, fw.v_slice].sum(axis=1)))

    if refine and Gp is not None and m:
        D = R[:, fw.x_cols] @ np.asarray(Gp, dtype=_WORK)
        D[:, fw.v_rows] += R[:, fw.v_cols]
        G2 = np.asarray(np.asarray(G, dtype=_WORK) + D, dtype=float)
        _, Bd2 = _residual(G2, target, target_abs, fw)
        if cost(Bd2) < cost(Bd):
            G, Bd = G2, Bd2
    return WindowBound(
        G=G, Rx=Bd[:, fw.x_cols], Rv=Bd[:, fw.v_slice], Rd=Bd[:, fw.d_slice], kappa=kappa, nu=nu
    )
