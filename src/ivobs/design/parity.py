"""Parity-space design of the fixed-time estimator (paper 001, Wang et al., IFAC 2020).

For ``x[k+1] = A x + B v + E d``, ``y = C x + D v + F d`` with invertible ``A``, the backward
propagation (001 eqs. 4-5), with ``Ã = A⁻¹``, ``B̃ = -A⁻¹B``, ``Ẽ = -A⁻¹E``, stacks the last
``s + 1`` outputs ``𝐲_k = [y_k; …; y_{k-s}]`` as (001 eq. 6)::

    𝐲_k = Mx x_k + Mu 𝐮_k + Md 𝐝_k,     𝐮_k = [u_k; …; u_{k-s}],  𝐝_k = [d_k; …; d_{k-s}]

    Mx = [C; C Ã; …; C Ã^s]
    Mu block (i, j) = C Ã^{i-j} B̃  (1 <= j <= i),  + D on the diagonal (i = j, also i = j = 0)
    Md block (i, j) = C Ã^{i-j} Ẽ  (1 <= j <= i),  + F on the diagonal

(the paper has ``D = 0``; ``D u_{k-i}`` enters row block ``i`` directly). Any ``T`` with
``T Mx = I`` (eq. 8) gives ``x̂_k = T(𝐲_k - Mu 𝐮_k) = x_k + T Md 𝐝_k`` (eqs. 7, 9); the
general solution is ``T = Mx† + S Mx⊥`` (Lemma 1, Lemma 2), and Theorem 1 (eq. 13) gives the
one minimising ``‖T Md‖_F``.

Time-varying systems (001 Remark 4): :func:`stack_window` takes the matrices of each step of the
window. Non-invertible ``A`` (001 Remark 1): :func:`injection_candidates` and
:func:`invertible_injection` find small gains ``L`` with ``A - LC`` well-conditioned; ``L y``
then enters as a known input.

Certification (not in the paper): the stacked matrices come from inverses, so a computed window
gain satisfies eqs. (8)-(9) only to rounding amplified by the conditioning of ``A``.
:func:`forward_window` writes the window forward (products of the model matrices, no inverse)
and :func:`window_bound` bounds, entry by entry, what a given gain really does, with a ``γ_n``
rounding bound (:func:`gamma`), and refines it once. No loops over time here: a window has
``s + 1`` steps, and that is all these functions see.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import DesignError, IvobsError
from ..linalg import gamma as _gamma

__all__ = [
    "SINGULAR_RCOND",
    "ForwardWindow",
    "OptimalT",
    "WindowBound",
    "forward_window",
    "gamma",
    "general_T",
    "injection_candidates",
    "invertible_injection",
    "optimal_T",
    "pinv_perp",
    "stack_matrices",
    "stack_window",
    "width_optimal_T",
    "window_bound",
]

SINGULAR_RCOND = 1e-8
"""``A`` counts as non-invertible when ``σ_min(A) <= SINGULAR_RCOND · max(1, σ_max(A))``."""

_EPS = np.finfo(float).eps


def gamma(n: int) -> float:
    """``γ_n`` with ``ε = 2⁻⁵²`` (twice the unit roundoff, so conservative):
    :func:`ivobs.linalg.gamma` with ``unit = ε`` (Higham, Lemma 3.1 and §3.5)."""
    return _gamma(n, _EPS)


def _rcond(M: np.ndarray) -> float:
    if M.size == 0:
        return 1.0
    sv = np.linalg.svd(M, compute_uv=False)
    return float(sv[-1] / max(1.0, sv[0]))


def is_invertible(A: np.ndarray) -> bool:
    """``σ_min(A) > SINGULAR_RCOND · max(1, σ_max(A))`` (the test that triggers Remark 1)."""
    return _rcond(np.asarray(A, dtype=float)) > SINGULAR_RCOND


def stack_window(
    mats: Sequence[tuple[np.ndarray, ...]],
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Stacked matrices ``(Mx, Mu, Md)`` of 001 eq. (6) for one window of ``s + 1`` steps.

    ``mats[i] = (A, B, C, D, E, F)`` at step ``k - i`` for ``i = 0 … s`` (most recent first);
    ``A`` at step ``k`` itself is not used. Time-varying form (Remark 4): with
    ``Ψ(k-i, k) = A_{k-i}⁻¹ ⋯ A_{k-1}⁻¹``,

    * row block ``i`` of ``Mx`` is ``C_{k-i} Ψ(k-i, k)``,
    * block ``(i, j)`` of ``Mu`` (``1 <= j <= i``) is ``-C_{k-i} Ψ(k-i, k-j+1) B_{k-j}``, plus
      ``D_{k-i}`` when ``j = i``; likewise ``Md`` with ``E`` and ``F``.

    For constant matrices these are ``C Ã^i``, ``C Ã^{i-j} B̃`` and ``C Ã^{i-j} Ẽ`` (eq. 5-6).
    Raises :class:`DesignError` if an ``A`` of the window is not invertible.
    """
    s = len(mats) - 1
    _, B0, C0, _, E0, _ = mats[0]
    nx, nu, ny, nd = B0.shape[0], B0.shape[1], C0.shape[0], E0.shape[1]
    Mx = np.zeros(((s + 1) * ny, nx))
    Mu = np.zeros(((s + 1) * ny, (s + 1) * nu))
    Md = np.zeros(((s + 1) * ny, (s + 1) * nd))
    P = np.eye(nx)  # Ψ(k-i, k)
    RB: list[np.ndarray] = []  # Ψ(k-i, k-j+1) B_{k-j}, j = 1..i
    RE: list[np.ndarray] = []
    for i, (_, _, C, D, _, F) in enumerate(mats):
        if i > 0:
            A_prev, B_prev, _, _, E_prev, _ = mats[i]  # matrices at step k-i
            if not is_invertible(A_prev):
                raise DesignError(
                    f"A at lag {i} of the window is not invertible (reciprocal condition number "
                    f"{_rcond(A_prev):.1e}); the backward propagation (001 eq. 4) needs A⁻¹: "
                    "use an output injection L (001 Remark 1)"
                )
            Ainv = np.linalg.inv(A_prev)
            P = Ainv @ P
            RB = [Ainv @ M for M in RB] + [Ainv @ B_prev]
            RE = [Ainv @ M for M in RE] + [Ainv @ E_prev]
        r = slice(i * ny, (i + 1) * ny)
        Mx[r] = C @ P
        for j in range(1, i + 1):
            Mu[r, j * nu : (j + 1) * nu] = -C @ RB[j - 1]
            Md[r, j * nd : (j + 1) * nd] = -C @ RE[j - 1]
        Mu[r, i * nu : (i + 1) * nu] += D
        Md[r, i * nd : (i + 1) * nd] += F
    return Mx, Mu, Md


_WORK = np.longdouble
"""Working precision of the certification (:func:`forward_window`, :func:`window_bound`): the
x87 extended format where the platform has it (``ε = 2⁻⁶³``), else ``float64``; every bound
uses the ``ε`` of the format actually used, so it holds either way."""

_EPS_WORK = float(np.finfo(_WORK).eps)


def _gamma_work(n: int) -> float:
    ne = n * _EPS_WORK
    return ne / (1.0 - ne) if ne < 0.5 else np.inf


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
    holding ``u`` and ``c`` and the columns of ``ξ`` they equal.
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


def forward_window(
    mats: Sequence[tuple[np.ndarray, ...]],
    *,
    centre: bool,
    lag: int | None = None,
    missing: np.ndarray | None = None,
) -> ForwardWindow:
    """The forward map of one window (see :class:`ForwardWindow`), used to certify a computed
    window gain (:func:`window_bound`).

    ``mats[i] = (A, B, C, D, E, F)`` of the *original* system at step ``k - i`` (no output
    injection, no inverse: ``x_{j+1} = A x_j + B u_j + E (c_j + δ_j)``,
    ``y_j = C x_j + D u_j + F (c_j + δ_j)``), ``i = 0 … s``; ``lag``: the anchor ``a``
    (default ``s``); ``missing``: ``(s+1, ny)`` bool, those outputs are zero in ``w``.
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
        if missing is not None and np.any(missing[i]):
            avail = ~np.asarray(missing[i], dtype=bool)
            Y[:ny][~avail] = 0.0
            Y[ny:][~avail] = 0.0
        else:
            avail = np.ones(ny, dtype=bool)
        Z[r0 + nu : r0 + nu + ny] = Y[:ny]
        Za[r0 + nu : r0 + nu + ny] = Y[ny:]
        y_rows.extend((r0 + nu + np.nonzero(avail)[0]).tolist())
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
    X, Xa = P[:nx], P[nx:]
    return ForwardWindow(
        Z=Z,
        Za=Za,
        X=X,
        Xa=Xa,
        lag=a,
        n_rounds=(a + 1) * (nx + 1),
        y_rows=np.array(y_rows, dtype=int),
        v_rows=np.array(v_rows, dtype=int),
        v_cols=np.array(v_cols, dtype=int),
        x_cols=slice(0, nx),
        v_slice=slice(nx, d0),
        d_slice=slice(d0, nxi),
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

    ``bound = (|R| + γ_2N (|G| Za + |target|)) (1 + ε₆₄)``: ``γ`` of the working precision,
    ``N`` the roundings along the longest product path (the forward recursion, the product with
    ``G`` of inner size ``m``, the subtraction); the factor 2 in ``γ_2N`` covers the rounding of
    the bound itself (nonnegative terms), ``1 + ε₆₄`` its conversion to ``float64``."""
    Gw = np.asarray(G, dtype=_WORK)
    n = fw.n_rounds + G.shape[1] + 2
    R = target - Gw @ fw.Z
    B = np.abs(R) + _gamma_work(2 * n) * (np.abs(Gw) @ fw.Za + target_abs)
    return R, B.astype(float) * (1.0 + _EPS)


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
    rho = float(Rp[:, fw.x_cols].sum(axis=1).max())
    if not rho < 0.5:
        return fail
    gn = float(np.abs(Gp).sum(axis=1).max()) * (1.0 + gamma(Gp.shape[1] + 2))
    rv = float(Rp[:, fw.v_slice].sum(axis=1).max(initial=0.0))
    kappa = (gn + rv) / (1.0 - rho) * (1.0 + gamma(4))
    nu = Rp[:, fw.d_slice].sum(axis=0) / (1.0 - rho) * (1.0 + gamma(nx + 4))
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
        G=G,
        Rx=Bd[:, fw.x_cols],
        Rv=Bd[:, fw.v_slice],
        Rd=Bd[:, fw.d_slice],
        kappa=kappa,
        nu=nu,
    )


def stack_matrices(
    A: Any, B: Any, C: Any, D: Any = None, E: Any = None, F: Any = None, *, s: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(Mx, Mu, Md)`` of 001 eq. (6) for a time-invariant system (``D``, ``E``, ``F`` default
    to zero blocks of the right size)."""
    A = np.atleast_2d(np.asarray(A, dtype=float))
    C = np.atleast_2d(np.asarray(C, dtype=float))
    nx, ny = A.shape[0], C.shape[0]
    B = np.zeros((nx, 0)) if B is None else np.asarray(B, dtype=float).reshape(nx, -1)
    nu = B.shape[1]
    D = np.zeros((ny, nu)) if D is None else np.asarray(D, dtype=float).reshape(ny, nu)
    if E is None and F is None:
        E, F = np.zeros((nx, 0)), np.zeros((ny, 0))
    elif E is None:
        F = np.asarray(F, dtype=float).reshape(ny, -1)
        E = np.zeros((nx, F.shape[1]))
    else:
        E = np.asarray(E, dtype=float).reshape(nx, -1)
        F = np.zeros((ny, E.shape[1])) if F is None else np.asarray(F, dtype=float)
    if int(s) < 0:
        raise IvobsError(f"s: expected an integer >= 0, got {s}")
    return stack_window([(A, B, C, D, E, F)] * (int(s) + 1))


def pinv_perp(Mx: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """``(Mx†, Mx⊥, N, rank)``: ``Mx† = (MxᵀMx)⁻¹Mxᵀ``, ``Mx⊥ = I - Mx Mx†`` (001 Notation),
    and ``N`` an orthonormal basis of the left null space (``N Mx = 0``, ``NᵀN = Mx⊥``).

    From one SVD ``Mx = U Σ Vᵀ``: ``Mx† = V Σ⁻¹ U₁ᵀ`` and ``Mx⊥ = U₂ U₂ᵀ`` (exactly symmetric
    and idempotent up to rounding, unlike ``I - Mx Mx†`` formed by subtraction). ``rank`` counts
    singular values above ``max(m, n) · ε · σ_max``; ``Mx†`` is only meaningful at full column
    rank (checked by the callers).
    """
    m, n = Mx.shape
    U, sv, Vt = np.linalg.svd(Mx, full_matrices=True)
    tol = max(m, n) * _EPS * (sv[0] if sv.size else 0.0)
    rank = int(np.sum(sv > tol))
    r = min(rank, n)
    with np.errstate(divide="ignore"):
        inv = np.where(sv[:r] > 0, 1.0 / sv[:r], 0.0)
    Mx_pinv = (Vt[:r].T * inv) @ U[:, :r].T
    U2 = U[:, r:]
    return Mx_pinv, U2 @ U2.T, U2.T.copy(), rank


@dataclass(frozen=True)
class OptimalT:
    """Theorem 1 of 001: ``T``, and the quantities of eq. (13)."""

    T: np.ndarray
    Mx_pinv: np.ndarray
    Mx_perp: np.ndarray
    U1: np.ndarray
    S1: np.ndarray
    V1: np.ndarray
    rank: int


def _check_full_rank(Mx: np.ndarray, rank: int) -> None:
    nx = Mx.shape[1]
    if rank < nx:
        raise DesignError(
            f"T Mx = I (001 eq. 8) has no solution: the stacked observability matrix Mx has rank "
            f"{rank} < nx = {nx}; the window must observe the state (001 Lemma 2: observable "
            "(A, C) and s >= nx - 1)"
        )


def optimal_T(Mx: Any, Md: Any, W: Any = None) -> OptimalT:
    """``T`` minimising ``‖T Md W‖_F`` subject to ``T Mx = I`` (001 Theorem 1, eq. 13).

    ``T = Mx† - Mx† Md V1ᵀ S1⁻¹ U1ᵀ Mx⊥`` with ``Mx⊥ Md = U1 S1 V1`` the compact SVD
    (eq. 17). The paper's criterion is ``W = I`` (the default); ``W`` (a nonnegative vector, the
    bound radii per column of ``Md``) weighs the disturbance by its size.

    Rank decision: ``‖Mx⊥‖₂ = 1``, so the rounding level of the computed ``Mx⊥ Md`` is about
    ``ε ‖Md‖₂``; singular values at or below ``10 · max(m, n) · ε · ‖Md‖₂`` are rounding, not
    signal, and are dropped. Keeping one would divide by it and blow up ``T``; dropping a genuine
    one only forfeits optimality, never ``T Mx = I`` (any ``X`` in ``Mx† + X Mx⊥`` satisfies it).
    The result is verified: ``T Mx = I`` to rounding and ``‖T Md‖ <= ‖Mx† Md‖`` (the ``S = 0``
    solution), else :class:`DesignError`.
    """
    Mx = np.asarray(Mx, dtype=float)
    Md = np.asarray(Md, dtype=float)
    m = Mx.shape[0]
    Mx_pinv, Mx_perp, N, rank = pinv_perp(Mx)
    _check_full_rank(Mx, rank)
    Mdw = Md if W is None else Md * np.asarray(W, dtype=float)[None, :]
    if Mdw.shape[1] == 0 or N.shape[0] == 0:
        empty = np.zeros((m, 0))
        return OptimalT(
            Mx_pinv, Mx_pinv, Mx_perp, empty, np.zeros((0, 0)), np.zeros((0, Mdw.shape[1])), 0
        )
    # Mx⊥ Md = Nᵀ (N Md): the SVD of the small factor N Md carries the same singular values.
    Uh, sv, V = np.linalg.svd(N @ Mdw, full_matrices=False)
    md_norm = float(np.linalg.norm(Mdw, 2))
    tol = 10.0 * max(m, Mdw.shape[1]) * _EPS * md_norm
    r = int(np.sum(sv > tol))
    U1 = N.T @ Uh[:, :r]
    S1 = np.diag(sv[:r])
    V1 = V[:r]
    T = Mx_pinv - (Mx_pinv @ Mdw @ V1.T / sv[:r]) @ U1.T @ Mx_perp
    _verify(T, Mx, Mdw, Mx_pinv)
    return OptimalT(T, Mx_pinv, Mx_perp, U1, S1, V1, r)


def _verify(T: np.ndarray, Mx: np.ndarray, Mdw: np.ndarray, Mx_pinv: np.ndarray) -> None:
    nx = Mx.shape[1]
    cond = np.linalg.cond(Mx)
    resid = float(np.max(np.abs(T @ Mx - np.eye(nx))))
    if not resid <= 1e-8 * max(1.0, cond):
        raise DesignError(
            f"optimal T: T Mx = I (001 eq. 8) holds only to {resid:.1e} (cond(Mx) = {cond:.1e}); "
            "the stacked matrices are too ill-conditioned: reduce s or rescale the states"
        )
    base = float(np.linalg.norm(Mx_pinv @ Mdw))
    if not float(np.linalg.norm(T @ Mdw)) <= base * (1 + 1e-8) + 1e-12:
        raise DesignError(
            "optimal T: ‖T Md‖_F exceeds that of T = Mx† (001 Theorem 1 violated by rounding); "
            "the stacked matrices are too ill-conditioned: reduce s or rescale the states"
        )


def general_T(Mx: Any, S: Any) -> np.ndarray:
    """The general solution ``T = Mx† + S Mx⊥`` of ``T Mx = I`` (001 Lemma 1, Lemma 2)."""
    Mx = np.asarray(Mx, dtype=float)
    Mx_pinv, Mx_perp, _, rank = pinv_perp(Mx)
    _check_full_rank(Mx, rank)
    S = np.asarray(S, dtype=float)
    if S.shape != (Mx.shape[1], Mx.shape[0]):
        raise IvobsError(
            f"S: expected shape ({Mx.shape[1]}, {Mx.shape[0]}) (nx, (s+1)·ny), got {S.shape}"
        )
    return Mx_pinv + S @ Mx_perp


def width_optimal_T(Mx: Any, Md: Any, W: Any = None) -> np.ndarray:
    """``T`` minimising each box width of eq. (11), ``Σ_j |(T Md Wd)_ij|``, s.t. ``T Mx = I``.

    Not in paper 001 (whose Theorem 1 minimises ``‖T Md‖_F``): one linear program per state
    (HiGHS), ``min Σ a`` s.t. ``-a <= (Md W)ᵀ t_i <= a``, ``Mxᵀ t_i = e_i``. The LP solution
    satisfies ``T Mx = I`` only to the solver's tolerance, so it is projected back,
    ``T ← T + (I - T Mx) Mx†``, which restores ``T Mx = I`` to rounding.
    """
    from scipy.optimize import linprog

    Mx = np.asarray(Mx, dtype=float)
    Md = np.asarray(Md, dtype=float)
    Mx_pinv, _, _, rank = pinv_perp(Mx)
    _check_full_rank(Mx, rank)
    P = Md if W is None else Md * np.asarray(W, dtype=float)[None, :]
    m, nx = Mx.shape
    p = P.shape[1]
    if p == 0:
        return Mx_pinv
    c = np.concatenate([np.zeros(m), np.ones(p)])
    A_ub = np.block([[P.T, -np.eye(p)], [-P.T, -np.eye(p)]])
    A_eq = np.hstack([Mx.T, np.zeros((nx, p))])
    bounds = [(None, None)] * m + [(0, None)] * p
    T = np.empty((nx, m))
    for i in range(nx):
        res = linprog(
            c,
            A_ub=A_ub,
            b_ub=np.zeros(2 * p),
            A_eq=A_eq,
            b_eq=np.eye(nx)[i],
            bounds=bounds,
            method="highs",
        )
        if res.status != 0:
            raise DesignError(
                f"width-optimal T: the linear program for state {i} failed ({res.message})"
            )
        T[i] = res.x[:m]
    T = T + (np.eye(nx) - T @ Mx) @ Mx_pinv
    return T


def _place(A: np.ndarray, C: np.ndarray, poles: np.ndarray) -> np.ndarray | None:
    """``L`` with the eigenvalues of ``A - LC`` at ``poles`` (``scipy.signal.place_poles`` on
    the dual pair ``(Aᵀ, C_rᵀ)``, ``C_r`` an orthonormal-row factor of ``C``: place_poles needs
    full column rank), or None when the placement fails."""
    from scipy.signal import place_poles

    U, sv, Vt = np.linalg.svd(C, full_matrices=False)
    r = int(np.sum(sv > max(C.shape) * _EPS * (sv[0] if sv.size else 0.0)))
    if r == 0:
        return None
    Cr = sv[:r, None] * Vt[:r]  # C = U_r C_r
    try:
        Lr = place_poles(A.T, Cr.T, poles).gain_matrix.T
    except Exception:  # scipy raises ValueError/LinAlgError with its own wording
        return None
    L = Lr @ U[:, :r].T
    return L if np.all(np.isfinite(L)) else None


def injection_candidates(A: Any, C: Any) -> list[np.ndarray]:
    """Gains ``L`` with ``A - LC`` invertible (001 Remark 1), from the least to the most
    intrusive; the caller picks one (:func:`invertible_injection`, or by the resulting design).

    1. *Minimal-norm* gains that only lift the small singular directions of ``A``: with
       ``A = U Σ Vᵀ`` and ``V₀``, ``U₀`` the directions with ``σ <= 10⁻³ σ_max``,
       ``L = -α U₀ (C V₀)⁺`` gives ``(A - LC) V₀ = U₀ (Σ₀ + α)`` (``C V₀`` has full column rank
       when ``(A, C)`` is observable: a null vector of ``A`` not seen by ``C`` is unobservable),
       for ``α`` equal to the largest, the smallest remaining and their geometric mean of the
       other singular values.
    2. Pole placement keeping the eigenvalues of ``A`` larger than ``10⁻³ ρ(A)`` and moving
       the others to distinct reals of magnitude ``ρ(A) / 2``.
    3. Pole placement at ``0.5 … 0.9`` (distinct, nonzero, moderate).

    A large gain (poles moved far, e.g. from ``-0.99`` to ``0.9``) makes the stacked matrices
    of ``A - LC`` large and their rounding large (audit finding A3b), hence this order.
    """
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    nx = A.shape[0]
    out: list[np.ndarray] = []
    U, sv, Vt = np.linalg.svd(A)
    small = sv <= 1e-3 * max(sv[0], np.finfo(float).tiny)
    if small.any() and not small.all():
        U0, V0 = U[:, small], Vt[small].T
        CV = C @ V0
        if np.linalg.matrix_rank(CV) == V0.shape[1]:
            big = sv[~small]
            for alpha in sorted({big[0], float(np.sqrt(big[0] * big[-1])), big[-1]}):
                out.append(-alpha * U0 @ np.linalg.pinv(CV))
    lam = np.linalg.eigvals(A)
    rho = float(np.max(np.abs(lam))) if lam.size else 0.0
    if rho > 0:
        keep = np.abs(lam) > 1e-3 * rho
        moved = int(np.sum(~keep))
        if 0 < moved < nx:
            kept = lam[keep]
            new = 0.5 * rho * np.linspace(1.0, 0.6, moved) if moved > 1 else np.array([0.5 * rho])
            while np.any(np.abs(kept[:, None] - new[None, :]) < 1e-3 * rho):
                new = new * 0.9
            L = _place(A, C, np.concatenate([kept, new]))
            if L is not None:
                out.append(L)
    poles = np.linspace(0.5, 0.9, nx) if nx > 1 else np.array([0.7])
    L = _place(A, C, poles)
    if L is not None:
        out.append(L)
    return [L for L in out if is_invertible(A - L @ C)]


def _injection_score(A: np.ndarray, C: np.ndarray, L: np.ndarray) -> float:
    """``cond(A - LC) (1 + ‖L C‖₂ / ‖A‖₂)``: the inverse of eq. (4) stays accurate and the
    known input ``L y`` stays small against the dynamics."""
    Ap = A - L @ C
    return float(
        np.linalg.cond(Ap) * (1.0 + np.linalg.norm(L @ C, 2) / max(np.linalg.norm(A, 2), 1e-300))
    )


def invertible_injection(A: Any, C: Any) -> np.ndarray:
    """A gain ``L`` with ``A - LC`` invertible (001 Remark 1): among
    :func:`injection_candidates`, the one with the smallest ``cond(A - LC) (1 + ‖LC‖/‖A‖)``
    (a well-conditioned ``A - LC`` reached with a small gain). Output injection keeps
    ``(A - LC, C)`` observable whenever ``(A, C)`` is. Raises :class:`DesignError` when no
    candidate works (``C = 0``, unobservable pair)."""
    A = np.asarray(A, dtype=float)
    C = np.asarray(C, dtype=float)
    if not np.any(C):
        raise DesignError("output injection (001 Remark 1): C = 0, no gain can change A")
    cands = injection_candidates(A, C)
    if not cands:
        raise DesignError(
            "output injection (001 Remark 1): found no L with A - LC invertible (is (A, C) "
            "observable?); pass an explicit L"
        )
    return min(cands, key=lambda L: _injection_score(A, C, L))
