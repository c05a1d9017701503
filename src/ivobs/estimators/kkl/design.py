"""The KKL design of [Dinh2024]: the target pair ``(A_z, B_z)``, the transformation ``T`` and its
left inverse, decided offline (no data, no time loop over a record).

Time-invariant systems ([Dinh2024, Section 2, Algorithm 1]): ``T`` solves the Sylvester equation
``T A = A_z T + B_z C`` ([Dinh2024, eq. (4)]); the default target is searched by
:func:`ivobs.design.sylvester.default_target`. Time-varying systems ([Dinh2024, Section 3]): the
block target of (16.a)/(11.a) scaled by ``gamma`` (discrete time) or ``ell`` (continuous time),
and the data-free sequence ``T[k+1] = (A_z T[k] + B_z C[k]) A[k]⁻¹`` ([Dinh2024, eq. (15.b)])
from ``T[0]`` (:class:`TransformSequence`), whose first left-invertible ``T[k]`` is
``valid_from``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..._validate import as_matrix
from ...design._lmi import MAX_LMI_STATES
from ...design.sylvester import (
    block_target,
    check_flow,
    check_target,
    default_target,
    flow_cap,
    predicted_width,
    solve_transform,
)
from ...errors import DesignError, IvobsError
from ...linalg import gamma, is_observable, observability_rank
from ...model import LinearSystem
from ...sets import Box
from ...sets.rounding import ETA, product_error, up, upper
from ..base import Design

__all__ = [
    "KKLDesign",
    "Transform",
    "TransformSequence",
    "design_lti",
    "design_ltv",
    "left_inverse",
    "x0_required",
]


@dataclass(frozen=True)
class KKLDesign(Design):
    """The KKL design ([Dinh2024]'s symbols; its ``(A, B)`` target pair is ``(A_z, B_z)``).

    ``T``: the solution of (4) (time-invariant), or ``T(0)`` / ``T_0`` (time-varying).
    ``A_z`` is the target matrix used (``gamma Ã`` / ``ell Ã`` for time-varying systems, with
    ``A_tilde = Ã``). ``predicted_width``: steady-state width of the bounds (time-invariant,
    closed form; exact in discrete time). ``k_star``: first step with a left-invertible ``T``.
    """

    A_z: np.ndarray
    B_z: np.ndarray
    T: np.ndarray
    n_z: int
    k_star: int
    cond_T: float
    continuous: bool
    time_varying: bool
    predicted_width: np.ndarray | None = None
    A_tilde: np.ndarray | None = None
    indices: tuple[int, ...] | None = None
    gamma: float | None = None
    ell: float | None = None
    tuned: bool = False


@dataclass(frozen=True)
class Transform:
    """``T[k]``, its left inverse ``P`` (a float matrix, with ``|P|``), the condition number,
    whether it counts as left-invertible, and ``resid``: per row, an upper bound of the row
    sums of ``|I - P T|`` (exact, for the float matrices ``P`` and ``T``), which bounds the
    error of the recovery ``x = P z + (I - P T) x`` (:func:`.observer.recover`); ``W`` maps
    ``[z̲; z̄; |z|]`` to the Lemma-1 bounds of ``P z`` and ``|P| |z|``."""

    T: np.ndarray
    P: np.ndarray
    cond: float
    ok: bool
    absP: np.ndarray
    resid: np.ndarray
    W: np.ndarray
    c_err: float = 0.0
    c_norm: float = 0.0
    c_resid: float = 0.0
    eta: float = 0.0

    def __post_init__(self) -> None:
        """The constants of :func:`.observer.recover` for ``n_z`` rows of ``T``: ``c_err >=
        γ_{2 n_z}`` (the error of the Lemma-1 image ``P [z̲, z̄]``), ``c_norm >= 1 / (1 - max
        r)`` (``‖x‖∞`` from ``‖|P| |z|‖∞``) and ``c_resid >= max r c_norm``, each with a factor
        ``1 + 2 γ_{n_z + 6}`` that covers the rounding of ``|P| |z|`` and of the few operations
        that combine them; ``eta``: underflow."""
        nz = self.T.shape[0]
        slack = 1.0 + 2.0 * gamma(nz + 6)
        rho = float(np.max(self.resid)) if self.resid.size else 0.0
        object.__setattr__(self, "c_err", 2.0 * gamma(2 * nz + 2) * slack)
        object.__setattr__(self, "c_norm", slack * slack / (1.0 - min(rho, 0.5)))
        object.__setattr__(self, "c_resid", float(up(rho * self.c_norm * slack)))
        object.__setattr__(self, "eta", (2 * nz + 8) * ETA)


def left_inverse(T: np.ndarray, max_cond: float) -> Transform:
    """Left inverse of ``T`` through its row-normalised form ``N T``.

    ``z̲ <= T x <= z̄`` is equivalent to ``N z̲ <= N T x <= N z̄`` for a positive diagonal ``N``,
    so ``x = (N T)⁺ N z`` recovers the same box; rows that decayed (fast target modes, long
    gaps) then do not count as ill-conditioning. ``cond`` is that of ``N T``. ``resid`` bounds
    ``|I - P T|`` with the product bound of [Higham2002, Lemma 3.1] (:func:`product_error`).
    """
    norms = np.linalg.norm(T, axis=1)
    nz, nx = T.shape
    if np.count_nonzero(norms == 0) or not np.isfinite(norms).all():
        return _singular(T, float("inf"))
    U, s, Vt = np.linalg.svd(T / norms[:, None], full_matrices=False)
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else float("inf")
    ok = cond <= max_cond  # False for inf
    if not ok:
        return _singular(T, cond)
    P = ((Vt.T / s) @ U.T) / norms[None, :]
    absP = np.abs(P)
    # |I - P T| <= |fl(I - P T)| + error of that evaluation (nz + 1 terms per entry)
    E = np.abs(np.eye(nx) - P @ T) + product_error(absP @ np.abs(T) + np.eye(nx), nz + 1)
    resid = upper(E.sum(axis=1), nx + 1)
    ok = bool(np.max(resid) <= 0.25)  # a left inverse to working accuracy
    Pp, Pn = np.maximum(P, 0.0), np.maximum(-P, 0.0)
    W = np.zeros((3 * nx, 3 * nz))
    W[:nx, :nz], W[:nx, nz : 2 * nz] = Pp, -Pn
    W[nx : 2 * nx, :nz], W[nx : 2 * nx, nz : 2 * nz] = -Pn, Pp
    W[2 * nx :, 2 * nz :] = absP
    return Transform(T=T, P=P, cond=cond, ok=ok, absP=absP, resid=resid, W=W)


def _singular(T: np.ndarray, cond: float) -> Transform:
    """A :class:`Transform` that is not left-invertible (no recovery from it)."""
    nz, nx = T.shape
    P0 = np.zeros((nx, nz))
    W = np.zeros((3 * nx, 3 * nz))
    return Transform(T=T, P=P0, cond=cond, ok=False, absP=P0, resid=np.ones(nx), W=W)


def x0_required(x0: Box | None, why: str) -> Box:
    """The prior box on ``x[0]``, or an :class:`IvobsError` saying why it is needed."""
    if x0 is None:
        raise IvobsError(
            f"x0: the kkl method needs a prior box on x[0] here ({why}); "
            "pass x0=ivobs.Box(x0_lo, x0_hi)"
        )
    return x0


# -- time-invariant ----------------------------------------------------------------------------
def design_lti(
    sys: LinearSystem, x0: Box | None, A_z: Any, B_z: Any, T: Any, *, tune: bool, max_cond: float
) -> KKLDesign:
    """The target pair and ``T`` of (4) for a time-invariant system ([Dinh2024, Algorithm 1])."""
    ct = sys.is_continuous
    x0 = x0_required(x0, "z[0] is bounded from x[0] by (3.b)")
    if A_z is None and sys.nx > MAX_LMI_STATES:
        raise DesignError(
            f"kkl: the default target search solves many dense Sylvester equations (4) "
            f"(O(nx^3) each) and does not scale to nx = {sys.nx} > {MAX_LMI_STATES} states; "
            "give the target A_z, B_z (one solve), or use 'interval' / 'interval-split' "
            "with a gain L=... for large sparse systems (docs/scale.md)"
        )
    A, _, C, _, E, F = sys.matrices_at(0)
    if not is_observable(A, C):
        raise DesignError(
            f"pair (A, C) is not observable: rank {observability_rank(A, C)} of {sys.nx}; "
            "the kkl method needs observability ([Dinh2024, Assumption 1 (I)])"
        )
    delta = sys.d_widths()
    tuned = False
    if A_z is None:
        choice = default_target(
            A, C, E, F, delta, continuous=ct, w0=x0.hi - x0.lo, tune=bool(tune), max_cond=max_cond
        )
        Az, Bz, Tm, tuned = choice.A_z, choice.B_z, choice.T, choice.tuned
    else:
        Az, Bz = check_target(A_z, B_z, ct, A)
        if Az.shape[0] != sys.nx or Bz.shape[1] != sys.ny:
            raise IvobsError(
                f"A_z, B_z: expected shapes ({sys.nx}, {sys.nx}) and "
                f"({sys.nx}, {sys.ny}), got {Az.shape} and {Bz.shape}"
            )
        Tm = solve_transform(A, C, Az, Bz) if T is None else _checked_T(T, A, C, Az, Bz)
    cond = float(np.linalg.cond(Tm))
    # the recovery uses the row-normalised T (left_inverse): it must pass the threshold too
    worst = cond if cond > max_cond else left_inverse(Tm, max_cond).cond
    if not worst <= max_cond:
        raise DesignError(
            f"T: the Sylvester solution of (4) is singular or ill-conditioned: cond(T) = "
            f"{worst:.3e} > max_cond = {max_cond:.0e} ([Dinh2024, Proposition 1] needs T "
            "invertible); choose another (A_z, B_z)"
        )
    pw = None if sys.bounds_depend_on_y else predicted_width(Tm, Az, Bz, E, F, delta, ct)
    return KKLDesign(
        A_z=Az,
        B_z=Bz,
        T=Tm,
        n_z=sys.nx,
        k_star=0,
        cond_T=cond,
        continuous=ct,
        time_varying=False,
        predicted_width=pw,
        tuned=tuned,
    )


def _checked_T(T: Any, A: np.ndarray, C: np.ndarray, Az: np.ndarray, Bz: np.ndarray) -> np.ndarray:
    """A user's ``T``, checked to solve (4) to working accuracy."""
    n = A.shape[0]
    Tm = as_matrix("T", T, n, n)
    res = np.linalg.norm(Tm @ A - Az @ Tm - Bz @ C)
    scale = np.linalg.norm(Tm) * (np.linalg.norm(A) + 1) + np.linalg.norm(Bz @ C)
    if res > 1e-8 * scale:
        raise DesignError(
            f"T: does not solve T A = A_z T + B_z C (eq. 4): relative residual {res / scale:.2e}"
        )
    return Tm


# -- time-varying ------------------------------------------------------------------------------
def design_ltv(
    sys: LinearSystem,
    x0: Box | None,
    A_z: Any,
    B_z: Any,
    T0: Any,
    *,
    gamma: Any,
    ell: Any,
    max_cond: float,
) -> tuple[KKLDesign, TransformSequence | None]:
    """The block target of (16.a)/(11.a), ``T[0]`` and (discrete time) the sequence of (15.b)
    with its first left-invertible step ``k_star``."""
    ct = sys.is_continuous
    A_0 = sys.A_at(0)
    At, Bt, indices = _block_or_given(sys, A_z, B_z)
    if ct:
        factor = float(ell) if ell is not None else _default_ell(At, A_0)
    else:
        factor = float(gamma if gamma is not None else 1.0)
    Az, Bz = check_target(factor * At, Bt, ct)
    if ct:  # the flow rule, with A(t) frozen at t = 0 (ivobs.estimators.kkl.continuous)
        check_flow(Az, A_0, who="A_z" if ell is None else "ell", frozen=" (A frozen at t = 0)")
    T0m = _initial_transform(sys, T0, Az, Bz)
    if np.any(T0m) and x0 is None:
        x0_required(x0, "T0 is not zero, so z[0] is bounded from x[0] by (15.c)/(10.c)")
    seq = None
    if ct:
        tr = left_inverse(T0m, max_cond)
        if not tr.ok:
            raise DesignError(
                f"T0: cond(T(0)) = {tr.cond:.3e} > max_cond = {max_cond:.0e}; in "
                "continuous time T(0) must be left-invertible; choose another A_z, B_z or ell"
            )
        k_star, cond = 0, tr.cond
    else:
        seq = TransformSequence(sys, Az, Bz, T0m, max_cond)
        k_star, cond = seq.first_left_invertible()
    design = KKLDesign(
        A_z=Az,
        B_z=Bz,
        T=T0m,
        n_z=Az.shape[0],
        k_star=k_star,
        cond_T=cond,
        continuous=ct,
        time_varying=True,
        A_tilde=At,
        indices=indices,
        gamma=None if ct else factor,
        ell=factor if ct else None,
    )
    return design, seq


def _block_or_given(
    sys: LinearSystem, A_z: Any, B_z: Any
) -> tuple[np.ndarray, np.ndarray, tuple[int, ...] | None]:
    """``(Ã, B̃)`` of (16.a)/(11.a) with the observability indices, or the user's pair."""
    if A_z is None:
        At, Bt, m = block_target(sys.A_at(0), sys.C_at(0), continuous=sys.is_continuous)
        return At, Bt, tuple(m)
    At = as_matrix("A_z", A_z)
    Bt = as_matrix("B_z", B_z, rows=At.shape[0], cols=sys.ny)
    if At.shape[0] < sys.nx:
        raise IvobsError(
            f"A_z: n_z = {At.shape[0]} < nx = {sys.nx}; T[k] (n_z x nx) "
            "can only be left-invertible with n_z >= nx"
        )
    return At, Bt, None


def _initial_transform(sys: LinearSystem, T0: Any, Az: np.ndarray, Bz: np.ndarray) -> np.ndarray:
    """``T[0]``: ``"zero"`` (discrete-time default), ``"sylvester"`` ((4) frozen at the first
    step; continuous-time default) or the user's matrix."""
    ct = sys.is_continuous
    nz = Az.shape[0]
    if T0 is None:
        T0 = "sylvester" if ct else "zero"
    if not isinstance(T0, str):
        return as_matrix("T0", T0, nz, sys.nx)
    if T0 == "zero":
        if ct:
            raise IvobsError(
                "T0: 'zero' is not available in continuous time (the time T(t) becomes "
                "left-invertible would depend on the sample grid); use 'sylvester'"
            )
        return np.zeros((nz, sys.nx))
    if T0 == "sylvester":
        return solve_transform(sys.A_at(0), sys.C_at(0), Az, Bz)
    raise IvobsError(f"T0: expected 'zero', 'sylvester' or a matrix, got {T0!r}")


def _default_ell(A_tilde: np.ndarray, A_0: np.ndarray) -> float:
    """The CT factor of (11.a): 2 ([Dinh2024, Example 2]), or more if needed for the flow rule
    at ``t = 0``: ``ell max Re λ(Ã) <= min Re λ(A(0)) - FLOW_MARGIN max(1, ρ(A(0)))``."""
    top = float(np.max(np.linalg.eigvals(A_tilde).real))
    if not top < 0:
        return 2.0  # not Hurwitz: check_target names it
    return max(2.0, flow_cap(A_0) / top)


class TransformSequence:
    """``T[k]`` of [Dinh2024, eq. (15.b)] with its left inverses, computed forward once and
    kept (it does not depend on the data).

    The observer's transformation is the *exact* real sequence ``T[k+1] = (A_z T[k] + B_z
    C[k]) A[k]⁻¹`` from the float ``T[0]``; the float ``T̂[k]`` computed here is within ``τ[k]``
    of it (elementwise, :meth:`tau`): ``T[k+1] - T̂[k+1] = (A_z (T[k] - T̂[k]) + (A_z T̂[k] +
    B_z C - M̂) + (M̂ - T̂[k+1] A)) A⁻¹`` with ``M̂ = fl(A_z T̂[k] + B_z C)``, each term bounded
    by [Higham2002, Lemma 3.1] and ``|A⁻¹|`` by a float inverse and its residual. The recovery
    of :class:`Transform` adds ``|P| τ`` to its residual ``|I - P T|``."""

    def __init__(
        self, sys: LinearSystem, A_z: np.ndarray, B_z: np.ndarray, T0: np.ndarray, max_cond: float
    ):
        self.sys = sys
        self.A_z, self.B_z = A_z, B_z
        self.max_cond = max_cond
        self._seq = [left_inverse(T0, max_cond)]
        self._tau = [np.zeros_like(T0)]

    def at(self, k: int) -> Transform:
        """``T̂[k]`` and its left inverse (the residual of the recovery includes ``τ[k]``)."""
        while len(self._seq) <= k:
            self._extend()
        return self._seq[k]

    def tau(self, k: int) -> np.ndarray:
        """``τ[k] >= |T[k] - T̂[k]|`` elementwise."""
        self.at(k)
        return self._tau[k]

    def _extend(self) -> None:
        j = len(self._seq) - 1
        Aj, Cj = self.sys.A_at(j), self.sys.C_at(j)
        if not np.isfinite(Aj).all() or np.linalg.cond(Aj) > 1e13:
            raise DesignError(
                f"A[{j}] is singular (cond {np.linalg.cond(Aj):.2e}); the time-varying "
                "KKL observer (15.b) needs invertible A[k] ([Dinh2024, Assumption 3 (VIII)])"
            )
        Az, Bz, Tj = self.A_z, self.B_z, self._seq[j].T
        nz, nx = Tj.shape
        M = Az @ Tj + Bz @ Cj
        eM = product_error(Az @ np.abs(Tj) + np.abs(Bz) @ np.abs(Cj), nz + Bz.shape[1])
        Tn = np.linalg.solve(Aj.T, M.T).T
        res = np.abs(M - Tn @ Aj) + product_error(np.abs(M) + np.abs(Tn) @ np.abs(Aj), nx + 1)
        rhs = up(Az @ self._tau[j] + eM + res)
        tau = upper(rhs @ _inverse_bound(Aj), nx + nz + 4)
        tr = left_inverse(Tn, self.max_cond)
        if tr.ok and np.any(tau):
            resid = up(tr.resid + upper((tr.absP @ tau).sum(axis=1), nz + nx))
            tr = replace(tr, resid=resid, ok=bool(np.max(resid) <= 0.25))
        self._seq.append(tr)
        self._tau.append(tau)

    def first_left_invertible(self) -> tuple[int, float]:
        """Offline: the first ``k`` with ``cond(T[k]) <= max_cond``, and that condition number.

        ``T[k]`` needs ``A[0..k-1]`` and ``C[0..k-1]``: stacked matrices of ``N`` steps
        determine ``T[0..N]``, and all of them are checked; a :class:`DesignError` says so when
        none is left-invertible (the observer would never give a box within the horizon
        given)."""
        # stacked matrices (N, rows, cols): a time-varying matrix given for N steps
        stacks = [M.shape[0] for M in (self.sys.A, self.sys.C) if np.ndim(M) == 3]
        horizon = min(stacks) if stacks else None
        limit = horizon + 1 if horizon is not None else 100 + 20 * self._seq[0].T.shape[0]
        best = float("inf")
        for k in range(limit):
            tr = self.at(k)
            if tr.ok:
                return k, tr.cond
            best = min(best, tr.cond)
        advice = (
            "try a smaller gamma (faster forgetting), another A_z, B_z, or a larger max_cond "
            "if the pair (A[k], C[k]) is uniformly observable ([Dinh2024, Proposition 4])"
        )
        if horizon is not None:
            raise DesignError(
                f"kkl: the observer never becomes valid in the horizon given: T[k] (eq. 15.b) "
                f"is not left-invertible for any k = 0..{horizon} determined by the "
                f"{horizon} stacked matrices A[k], C[k] (smallest cond(T[k]) = {best:.3e} > "
                f"max_cond = {self.max_cond:.0e}); give more steps of A and C (a longer stack "
                f"or a function of k) if the pair becomes observable later, or {advice}"
            )
        raise DesignError(
            f"kkl: T[k] (eq. 15.b) did not become left-invertible within {limit} steps "
            f"(smallest cond(T[k]) = {best:.3e} > max_cond = {self.max_cond:.0e}): the pair "
            f"(A[k], C[k]) may not be uniformly observable; {advice}"
        )


def _inverse_bound(A: np.ndarray) -> np.ndarray:
    """An elementwise upper bound of ``|A⁻¹|`` (exact inverse of the float ``A``): with a float
    inverse ``X`` and ``F >= |I - A X|`` of row sums ``<= β < 1``, ``‖A⁻¹‖∞ <= ‖X‖∞ / (1 - β)``
    and ``|A⁻¹ - X| = |A⁻¹ (I - A X)| <= ‖A⁻¹‖∞ max_l F_lj``."""
    n = A.shape[0]
    X = np.linalg.inv(A)
    F = np.abs(np.eye(n) - A @ X) + product_error(np.abs(A) @ np.abs(X) + np.eye(n), n + 1)
    beta = float(upper(np.max(F.sum(axis=1)), n + 1))
    if not beta < 0.5:
        raise DesignError(
            f"A: the inverse of A[k] cannot be bounded (residual {beta:.2e}); the time-varying "
            "KKL observer (15.b) needs well-conditioned A[k]"
        )
    norm = float(upper(np.max(np.abs(X).sum(axis=1)), n)) / (1.0 - beta) * (1.0 + 1e-15)
    out: np.ndarray = up(np.abs(X) + up(norm * F.max(axis=0))[None, :])
    return out
