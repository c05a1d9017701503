"""KKL / Sylvester interval observers (paper 004: Dinh & Tran, arXiv 2405.06445).

Notation map (paper 004 → ivobs): ``F, H, D, W`` → ``A, C, E, F``; the paper's ``u`` is our
``B u``; its target pair ``(A, B)`` is ``(A_z, B_z)``; ``d`` and ``w`` are parts of our one ``d``.

Time-invariant systems (Section 2, Algorithm 1). ``T`` solves ``T A = A_z T + B_z C`` (eq. 4), so
``z = T x`` obeys, with the feedthrough and the shared disturbance of the ivobs model,

    z[k+1] = A_z z[k] + B_z y[k] + (T B - B_z D) u[k] + (T E - B_z F) d[k]          (eq. 5)

and, ``A_z`` being nonnegative, observer (3.a) ``z̄+ = A_z z̄ + B_z y + (TB - B_zD) u + ḡ``
(``ḡ``, ``g̲`` the Lemma-1 bounds of ``(T E - B_z F) d``; one matrix for the correlated ``d``)
keeps ``z̲ <= T x <= z̄``; (3.c-d) give ``x = T⁻¹ z``. Option ``coordinates="x"`` runs the same
observer written in ``x`` (eq. 6, with ``L = T⁻¹ B_z``).

Discrete-time time-varying systems (Section 3.2). ``T[k+1] = (A_z T[k] + B_z C[k]) A[k]⁻¹``
(eq. 15.b, needs invertible ``A[k]``), ``A_z = gamma Ã``, ``B_z = B̃`` block-diagonal with one
block per output of size the observability index ``m_i`` (eq. 16.a), ``n_z = Σ m_i``; the
bounds (15.a) with ``T[k+1]`` in place of ``T``, and ``x`` recovered by the pseudo-inverse (15.d)
once ``T[k]`` is left-invertible. ``T[k]`` does not depend on the data, so ``valid_from`` is
decided offline: the first ``k`` with ``cond(N T[k]) = σ_max/σ_min <= max_cond`` (default 1e7),
``N`` the positive diagonal scaling that gives ``T[k]`` unit rows (the recovery uses
``x = (N T)⁺ N z``, the same box; rows that merely decayed do not count as ill-conditioning).
A later ``T[k]`` failing the threshold gets the previous box propagated through the model.
The default ``T0 = 0`` makes ``z[0] = 0`` exactly: no prior on ``x[0]`` is needed (Example 3:
``valid_from = 2``). ``T0="sylvester"`` (the frozen-time solution of (4)) uses ``x0`` by (15.c).

Continuous time (Sections 2 and 3.1), sampled measurements. Between samples only ``y[k]`` is
known, and observers (3)/(10) integrate ``B_z y(t)``. ivobs runs their *sampled-data* form,
which is exact for any ``y(t)``: the measurement enters at the sample instants,

    T(t_k+) = T(t_k-) + h_k B_z C(t_k),   z(t_k+) = z(t_k-) + h_k B_z (y_k - D u_k - F d(t_k))

(``h_k = t_k - t_{k-1}``, the rectangle rule of ``∫ B_z y``; ``y_0`` gets weight 0), and between
samples ``Ṫ = A_z T - T A(t)`` (eq. 10.b without the ``B_z C`` term) and the bounds (10.a)
without ``B_z y``: ``dz̄/dt = A_z z̄ + T B u + (T E)⁺ d̄ - (T E)⁻ d̲`` (``A_z`` Metzler:
comparison principle). Then ``z(t) = T(t) x(t)`` holds exactly whatever ``y`` does between samples;
as the sampling period tends to 0 this is observer (3)/(10). ``T(0)`` is the solution of (4)
(time-invariant) or of (4) frozen at ``t = 0`` (time-varying), so the bounds hold from the first
sample given ``x0`` (``valid_from = 0``).

What is guaranteed. Discrete time: exact (the recursions are linear; rounding is covered by the
base margin and by a recovery margin ``16 (n_z + n_x) ε cond(T) |T⁺| |z|``). Continuous time: the
flows are integrated numerically (SciPy DOP853, ``rtol=1e-10``, ``atol=1e-12``); the bounds are
sound up to that integration error, which is covered heuristically (``z`` bounds widened by
``10 (atol + rtol |z|)`` per interval, recovery margin ``+100 rtol cond(T)``). Assumptions between
samples: ``u`` follows ``input_hold`` (``"zero"``-order hold by default, as a digital controller
and :func:`ivobs.simulate` with array inputs do; ``"linear"`` interpolation of the samples; or a
callable ``t -> u(t)``, integrated by 8-point Gauss-Legendre per interval (time-invariant) or by
the ODE solver (time-varying)); the bounds of ``d`` are the hull of their values at the two ends
of the interval (exact for constant bounds). Nothing is assumed about ``y`` between samples.
Time-invariant systems use closed forms (``expm``) on each interval: ``T`` and the ``u`` term are
exact, the ``d`` integral is enclosed by midpoint sums plus a rigorous bound of their variation.

Data used (time convention). Discrete time: the box at ``k`` comes from ``z[k]``, which uses
``y[0..k-1]`` (prediction form, as in the paper); ``y[k]`` is used for the step to ``k+1`` and
is checked against the box at ``k`` (an inconsistent measurement is reported and not used).
Continuous time: the box at ``t_k`` uses ``y`` up to ``t_k``.

Missing samples. Discrete time: the unknown ``B_m y_m = B_m (C_m x + D_m u + F_m d)`` is bounded
with ``x[k] = T[k]⁺ z[k]``: ``z+ ∈ (A_z + B_m C_m T⁺)[z̲, z̄] + ...`` by Lemma 1 (exact identity,
``T`` stays on its data-independent sequence); before ``T[k]`` is left-invertible
(time-varying) ``C_m x`` is bounded on the open-loop box propagated from ``x0`` (needs ``x0``).
Continuous time: the missing rows are left out of the jump (``T`` and ``z`` jump by
``h B_o C_o``, ``h B_o y_o`` only), which is exact.
"""

from __future__ import annotations

import numbers
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .._recursion import (
    LinearFilter,
    SplitFilter,
    matrix_product,
    redo_streams,
    scratch,
    within_band,
)
from .._validate import as_matrix, as_vector
from ..design._lmi import MAX_LMI_STATES
from ..design.sylvester import (
    block_target,
    check_flow,
    check_target,
    condition_number,
    default_target,
    flow_cap,
    predicted_width,
    solve_transform,
)
from ..errors import DesignError, IvobsError
from ..linalg import is_observable
from ..model import LinearSystem
from ..sets import Box, image_bounds
from . import register
from .base import Design, Estimator

__all__ = ["KKL", "KKLDesign"]

_EPS = np.finfo(float).eps
_ANCHOR_TOL = 1e-9
"""Relative distance of ``T`` to the constant ``T_h`` of a regular grid below which the state is
moved onto ``T_h`` (continuous time; the cost is ``|T_h - T| |x|``, see ``KKL._to_anchor``)."""
_CACHE_SIZE = 256
"""Sampling periods whose interval matrices are kept (continuous time)."""


@dataclass(frozen=True)
class KKLDesign(Design):
    """The KKL design (paper 004's symbols; its ``(A, B)`` target pair is ``(A_z, B_z)``).

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
    coordinates: str = "z"
    predicted_width: np.ndarray | None = None
    A_tilde: np.ndarray | None = None
    indices: tuple[int, ...] | None = None
    gamma: float | None = None
    ell: float | None = None
    tuned: bool = False


@dataclass(frozen=True)
class _Transform:
    """``T[k]``, its pseudo-inverse, condition number and whether it counts as left-invertible."""

    T: np.ndarray
    P: np.ndarray
    cond: float
    ok: bool


def _pinv(T: np.ndarray, max_cond: float) -> _Transform:
    """Left inverse of ``T`` through its row-normalised form ``N T``.

    ``z̲ <= T x <= z̄`` is equivalent to ``N z̲ <= N T x <= N z̄`` for a positive diagonal ``N``,
    so ``x = (N T)⁺ N z`` recovers the same box; rows that decayed (fast target modes, long
    gaps) then do not count as ill-conditioning. ``cond`` is that of ``N T``.
    """
    norms = np.linalg.norm(T, axis=1)
    nz, nx = T.shape
    if np.any(norms == 0) or not np.all(np.isfinite(norms)):
        return _Transform(T=T, P=np.zeros((nx, nz)), cond=float("inf"), ok=False)
    U, s, Vt = np.linalg.svd(T / norms[:, None], full_matrices=False)
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else float("inf")
    ok = bool(np.isfinite(cond) and cond <= max_cond)
    P = ((Vt.T / s) @ U.T) / norms[None, :] if ok else np.zeros((nx, nz))
    return _Transform(T=T, P=P, cond=cond, ok=ok)


def _number(
    name: str,
    val: Any,
    *,
    above: float | None = None,
    at_least: float | None = None,
    below: float | None = None,
    why: str = "",
) -> float:
    """A real, finite scalar option within its range, else :class:`IvobsError` naming it."""
    if isinstance(val, np.ndarray) and val.ndim == 0 and val.dtype.kind in "fiu":
        val = val.item()
    if isinstance(val, (bool, np.bool_)) or not isinstance(val, numbers.Real):
        raise IvobsError(f"{name}: expected a real number, got {val!r} ({type(val).__name__})")
    v = float(val)
    rng = []
    if above is not None:
        rng.append(f"> {above:g}")
    if at_least is not None:
        rng.append(f">= {at_least:g}")
    if below is not None:
        rng.append(f"< {below:g}")
    if (
        not np.isfinite(v)
        or (above is not None and not v > above)
        or (at_least is not None and not v >= at_least)
        or (below is not None and not v < below)
    ):
        raise IvobsError(f"{name}: expected a finite number {' and '.join(rng)}{why}, got {val!r}")
    return v


def _d_delta(sys: LinearSystem) -> np.ndarray:
    """Widths of the bounds of ``d`` for scoring designs (ones for bounds computed from y)."""
    if sys.nd == 0:
        return np.zeros(0)
    d = sys.d
    if isinstance(d, Box):
        w = d.hi - d.lo
        return np.max(w, axis=0) if w.ndim == 2 else w
    return np.ones(sys.nd)


@register
class KKL(Estimator):
    """KKL / Sylvester interval observer of paper 004 (LTI and LTV, discrete and continuous time).

    Parameters (keyword-only, all optional)
    ----------------------------------------
    A_z, B_z : target pair. Time-invariant: ``(A_z, B_z)`` of Proposition 1 (default: a tuned
        diagonal target, see :mod:`ivobs.design.sylvester`). Time-varying: ``Ã``, ``B̃`` of
        (16.a)/(11.a) (default: blocks from the observability indices); the matrix used is
        ``gamma * A_z`` (DT) or ``ell * A_z`` (CT).
    T : time-invariant only: an explicit solution of (4) for the given ``A_z``, ``B_z``.
    T0 : time-varying only: ``"zero"`` (DT default: ``z[0] = 0``, no prior needed),
        ``"sylvester"`` (CT default; (4) frozen at the first step, uses ``x0``), or a matrix.
    gamma : DT time-varying factor of (16.a), default 1 (Example 3). ell : CT factor of (11.a),
        default 2 (Example 2).
    coordinates : ``"z"`` (observer (3), default) or ``"x"`` (observer (6); discrete-time LTI).
    max_cond : largest ``cond(T)`` accepted (LTI: else :class:`DesignError`; LTV: the threshold of
        left-invertibility that decides ``valid_from``). Default 1e7.
    tune : refine the default time-invariant target by gradient descent on the predicted width.
    input_hold : continuous time: ``u`` between samples: ``"zero"`` (default), ``"linear"`` or a
        callable ``t -> u(t)`` (e.g. the known input signal itself).
    rtol, atol : continuous time: integration tolerances.

    See the module docstring for the equations, what is guaranteed, the data used at each step
    and the treatment of missing samples.
    """

    name = "kkl"
    order = 70
    summary = "KKL/Sylvester interval observer z = T x (004): LTI and LTV, discrete and continuous"
    reference = "004 (Dinh & Tran, arXiv 2405.06445), observers (3), (6), (10), (15)"
    supports_continuous: ClassVar[bool] = True
    supports_time_varying: ClassVar[bool] = True
    needs_x0: ClassVar[bool] = False

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        A_z: Any = None,
        B_z: Any = None,
        T: Any = None,
        T0: Any = None,
        gamma: float | None = None,
        ell: float | None = None,
        coordinates: str = "z",
        max_cond: float = 1e7,
        tune: bool = True,
        input_hold: str | Callable[[float], Any] = "zero",
        rtol: float = 1e-10,
        atol: float = 1e-12,
        on_inconsistent: str = "warn",
    ):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)
        self._ct = sys.is_continuous
        self._tv = sys.is_time_varying
        self._mode = "ct" if self._ct else ("dt-ltv" if self._tv else "dt-lti")
        self._check_options(
            A_z, B_z, T, T0, gamma, ell, coordinates, max_cond, tune, input_hold, rtol, atol
        )
        self.max_cond = float(max_cond)
        self.coordinates = coordinates
        self._hold = input_hold
        self._rtol, self._atol = float(rtol), float(atol)
        if self._tv:
            design = self._design_ltv(A_z, B_z, T0, gamma, ell)
        else:
            design = self._design_lti(A_z, B_z, T, tune)
        self.design = design
        self._Az, self._Bz = design.A_z, design.B_z
        self._rec = 16 * (design.n_z + sys.nx) * _EPS + (100 * self._rtol if self._ct else 0.0)
        self.valid_from = design.k_star
        if self._mode == "dt-lti":
            self._prepare_lti()

    # -- validation ----------------------------------------------------------------------
    def _check_options(
        self,
        A_z: Any,
        B_z: Any,
        T: Any,
        T0: Any,
        gamma: Any,
        ell: Any,
        coordinates: Any,
        max_cond: Any,
        tune: Any,
        input_hold: Any,
        rtol: Any,
        atol: Any,
    ) -> None:
        """Every option checked before use: an :class:`IvobsError` naming the argument."""
        if (A_z is None) != (B_z is None):
            raise IvobsError("A_z, B_z: give both target matrices or neither")
        if T is not None and (self._tv or A_z is None):
            raise IvobsError(
                "T: an explicit transformation is for time-invariant systems, together with the "
                "A_z and B_z it solves (4) for"
                + ("; use T0 for time-varying systems" if self._tv else "")
            )
        if T0 is not None and not self._tv:
            raise IvobsError("T0: only for time-varying systems (time-invariant: T solves (4))")
        if gamma is not None and self._mode != "dt-ltv":
            raise IvobsError(
                "gamma: the factor of (16.a) is for discrete-time time-varying "
                "systems" + ("; use ell" if self._ct and self._tv else "")
            )
        if ell is not None and not (self._ct and self._tv):
            raise IvobsError(
                "ell: the factor of (11.a) is for continuous-time time-varying "
                "systems" + ("; use gamma" if self._mode == "dt-ltv" else "")
            )
        for nm, val in (("gamma", gamma), ("ell", ell)):
            if val is not None:
                _number(nm, val, above=0.0)
        _number("max_cond", max_cond, at_least=1.0, why="; cond(T) >= 1 for every T")
        _number("rtol", rtol, above=0.0, below=1.0)
        _number("atol", atol, above=0.0)
        if not isinstance(tune, (bool, np.bool_)):
            raise IvobsError(f"tune: expected True or False, got {tune!r}")
        if not isinstance(coordinates, str) or coordinates not in ("z", "x"):
            raise IvobsError(f"coordinates: expected 'z' or 'x', got {coordinates!r}")
        if coordinates == "x" and self._mode != "dt-lti":
            raise IvobsError(
                "coordinates: 'x' (observer (6)) needs a constant T, i.e. a "
                "discrete-time time-invariant system; use 'z'"
            )
        hold_ok = isinstance(input_hold, str) and input_hold in ("linear", "zero")
        if not (callable(input_hold) or hold_ok):
            raise IvobsError(
                f"input_hold: expected 'linear', 'zero' or a callable t -> u(t), got {input_hold!r}"
            )

    def _x0_required(self, why: str) -> Box:
        if self.x0 is None:
            raise IvobsError(
                f"x0: the kkl method needs a prior box on x[0] here ({why}); "
                "pass x0=ivobs.Box(x0_lo, x0_hi)"
            )
        return self.x0

    # -- design: time-invariant ----------------------------------------------------------
    def _design_lti(self, A_z: Any, B_z: Any, T: Any, tune: bool) -> KKLDesign:
        sys = self.sys
        self._x0_required("z[0] is bounded from x[0] by (3.b)")
        if A_z is None and sys.nx > MAX_LMI_STATES:
            raise DesignError(
                f"kkl: the default target search solves many dense Sylvester equations (4) "
                f"(O(nx^3) each) and does not scale to nx = {sys.nx} > {MAX_LMI_STATES} states; "
                "give the target A_z, B_z (one solve), or use 'interval' / 'interval-split' "
                "with a gain L=... for large sparse systems (docs/scale.md)"
            )
        A, C, E, F = sys.A, sys.C, sys.E, sys.F
        if not is_observable(A, C):
            from ..linalg import observability_rank

            raise DesignError(
                f"pair (A, C) is not observable: rank {observability_rank(A, C)} of {sys.nx}; "
                "the kkl method needs observability (004 Assumption 1 (I))"
            )
        delta = _d_delta(sys)
        tuned = False
        if A_z is None:
            choice = default_target(
                A,
                C,
                E,
                F,
                delta,
                continuous=self._ct,
                w0=self.x0.hi - self.x0.lo if self.x0 else None,
                tune=bool(tune),
                max_cond=self.max_cond,
            )
            Az, Bz, Tm, tuned = choice.A_z, choice.B_z, choice.T, choice.tuned
        else:
            Az, Bz = check_target(A_z, B_z, self._ct, A)
            if Az.shape[0] != sys.nx or Bz.shape[1] != sys.ny:
                raise IvobsError(
                    f"A_z, B_z: expected shapes ({sys.nx}, {sys.nx}) and "
                    f"({sys.nx}, {sys.ny}), got {Az.shape} and {Bz.shape}"
                )
            if T is None:
                Tm = solve_transform(A, C, Az, Bz)
            else:
                Tm = as_matrix("T", T, sys.nx, sys.nx)
                res = np.linalg.norm(Tm @ A - Az @ Tm - Bz @ C)
                scale = np.linalg.norm(Tm) * (np.linalg.norm(A) + 1) + np.linalg.norm(Bz @ C)
                if res > 1e-8 * scale:
                    raise DesignError(
                        f"T: does not solve T A = A_z T + B_z C (eq. 4): relative "
                        f"residual {res / scale:.2e}"
                    )
        cond = condition_number(Tm)
        if cond > self.max_cond:
            raise DesignError(
                f"T: the Sylvester solution of (4) is singular or ill-conditioned: cond(T) = "
                f"{cond:.3e} > max_cond = {self.max_cond:.0e} (004 Proposition 1 needs T "
                "invertible); choose another (A_z, B_z)"
            )
        pw = None
        if sys.has_constant_bounds or isinstance(sys.d, Box):
            pw = predicted_width(Tm, Az, Bz, E, F, delta, self._ct)
        return KKLDesign(
            A_z=Az,
            B_z=Bz,
            T=Tm,
            n_z=sys.nx,
            k_star=0,
            cond_T=cond,
            continuous=self._ct,
            time_varying=False,
            coordinates=self.coordinates,
            predicted_width=pw,
            tuned=tuned,
        )

    def _prepare_lti(self) -> None:
        sys, dz = self.sys, self.design
        A, B, C, D, E, F = sys.matrices_at(0)
        self._mats = (A, B, C, D, E, F)
        self._tr = _pinv(dz.T, self.max_cond)
        self._Lu = dz.T @ B - dz.B_z @ D
        self._G = dz.T @ E - dz.B_z @ F
        P = self._tr.P
        self._margin = self._rec * self._tr.cond * np.abs(P)
        self._g_const = None
        if sys.d is None or (isinstance(sys.d, Box) and not sys.d.is_time_varying):
            dd = sys.d_at(0)
            self._g_const = image_bounds(self._G, dd.lo, dd.hi)
        if self.coordinates == "x":
            self._L = P @ dz.B_z
            self._Mx = A - self._L @ C

    # -- design: time-varying ------------------------------------------------------------
    def _design_ltv(self, A_z: Any, B_z: Any, T0: Any, gamma: Any, ell: Any) -> KKLDesign:
        sys = self.sys
        A0, C0 = sys.A_at(0), sys.C_at(0)
        if A_z is None:
            At, Bt, m = block_target(A0, C0, continuous=self._ct)
            indices: tuple[int, ...] | None = tuple(m)
        else:
            At = as_matrix("A_z", A_z)
            Bt = as_matrix("B_z", B_z, rows=At.shape[0], cols=sys.ny)
            indices = None
            if At.shape[0] < sys.nx:
                raise IvobsError(
                    f"A_z: n_z = {At.shape[0]} < nx = {sys.nx}; T[k] (n_z x nx) "
                    "can only be left-invertible with n_z >= nx"
                )
        if self._ct:
            factor = float(ell) if ell is not None else _default_ell(At, A0)
        else:
            factor = float(gamma if gamma is not None else 1.0)
        Az, Bz = check_target(factor * At, Bt, self._ct)
        if self._ct:  # the flow rule, with A(t) frozen at t = 0 (module docstring)
            check_flow(Az, A0, who="A_z" if ell is None else "ell", frozen=" (A frozen at t = 0)")
        self._Az, self._Bz = Az, Bz
        nz = Az.shape[0]
        if T0 is None:
            T0 = "sylvester" if self._ct else "zero"
        if isinstance(T0, str):
            if T0 == "zero":
                if self._ct:
                    raise IvobsError(
                        "T0: 'zero' is not available in continuous time (the time T(t) becomes "
                        "left-invertible would depend on the sample grid); use 'sylvester'"
                    )
                T0m = np.zeros((nz, sys.nx))
            elif T0 == "sylvester":
                T0m = solve_transform(A0, C0, Az, Bz)
            else:
                raise IvobsError(f"T0: expected 'zero', 'sylvester' or a matrix, got {T0!r}")
        else:
            T0m = as_matrix("T0", T0, nz, sys.nx)
        if np.any(T0m) and self.x0 is None:
            self._x0_required("T0 is not zero, so z[0] is bounded from x[0] by (15.c)/(10.c)")
        if self._ct:
            tr = _pinv(T0m, self.max_cond)
            if not tr.ok:
                raise DesignError(
                    f"T0: cond(T(0)) = {tr.cond:.3e} > max_cond = {self.max_cond:.0e}; in "
                    "continuous time T(0) must be left-invertible; choose another A_z, B_z or ell"
                )
            k_star, cond = 0, tr.cond
        else:
            self._Tseq: list[_Transform] = [_pinv(T0m, self.max_cond)]
            k_star, cond = self._first_left_invertible()
        return KKLDesign(
            A_z=Az,
            B_z=Bz,
            T=T0m,
            n_z=nz,
            k_star=k_star,
            cond_T=cond,
            continuous=self._ct,
            time_varying=True,
            A_tilde=At,
            indices=indices,
            gamma=None if self._ct else factor,
            ell=factor if self._ct else None,
        )

    def _first_left_invertible(self) -> tuple[int, float]:
        """Offline: the first ``k`` with ``cond(T[k]) <= max_cond`` (``T[k]`` is data-free)."""
        A = self.sys.A
        stacked = isinstance(A, np.ndarray) and A.ndim == 3
        # T[k] needs A[0..k-1]: a stack of N matrices determines T[0..N]; one step further,
        # LinearSystem's own error says that the stack is too short (not "not observable")
        limit = A.shape[0] + 2 if stacked else 100 + 20 * self._Tseq[0].T.shape[0]
        for k in range(limit):
            tr = self._transform(k)
            if tr.ok:
                return k, tr.cond
        raise DesignError(
            f"T[k] (eq. 15.b) did not become left-invertible within {limit} steps "
            f"(cond(T[k]) > max_cond = {self.max_cond:.0e}): the pair (A[k], C[k]) may not be "
            "uniformly observable; try a smaller gamma or another A_z, B_z (004 Proposition 4)"
        )

    def _transform(self, k: int) -> _Transform:
        """``T[k]`` of (15.b), computed forward once and cached (discrete time)."""
        if self._mode == "dt-lti":
            return self._tr
        seq = self._Tseq
        while len(seq) <= k:
            j = len(seq) - 1
            Aj, Cj = self.sys.A_at(j), self.sys.C_at(j)
            if not np.all(np.isfinite(Aj)) or np.linalg.cond(Aj) > 1e13:
                raise DesignError(
                    f"A[{j}] is singular (cond {np.linalg.cond(Aj):.2e}); the time-varying "
                    "KKL observer (15.b) needs invertible A[k] (004 Assumption 3 (VIII))"
                )
            rhs = self._Az @ seq[j].T + self._Bz @ Cj
            seq.append(_pinv(np.linalg.solve(Aj.T, rhs.T).T, self.max_cond))
        return seq[k]

    # -- shared pieces -------------------------------------------------------------------
    def _recover(self, tr: _Transform, zlo: np.ndarray, zhi: np.ndarray) -> tuple[Any, Any]:
        """(3.c-d)/(15.d): bounds of ``x = T⁺ z`` plus the rounding margin of the recovery."""
        zc, zr = 0.5 * (zlo + zhi), 0.5 * (zhi - zlo)
        aP = np.abs(tr.P)
        xr = aP @ zr + (self._rec * tr.cond) * (aP @ (np.abs(zc) + zr))
        xc = tr.P @ zc
        return xc - xr, xc + xr

    def _usable(
        self,
        state: dict[str, Any],
        y_k: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        C: np.ndarray,
        D: np.ndarray,
        F: np.ndarray,
        u_k: np.ndarray,
        d: Box,
    ) -> np.ndarray:
        """Observed components of ``y[k]``; all dropped when ``y[k]`` contradicts the box."""
        obs = ~np.isnan(y_k)
        if not obs.any() or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return obs
        Co, Fo = C[obs], F[obs]
        yc = Co @ (0.5 * (lo + hi)) + Fo @ (0.5 * (d.lo + d.hi)) + D[obs] @ u_k
        yr = np.abs(Co) @ (0.5 * (hi - lo)) + np.abs(Fo) @ (0.5 * (d.hi - d.lo))
        if np.any(np.abs(y_k[obs] - yc) > yr + 1e-9 * (1.0 + np.abs(yc) + yr)):
            state["_inconsistent"] = True
            return np.zeros_like(obs)
        return obs

    # -- online --------------------------------------------------------------------------
    def _initial_state(self) -> dict[str, Any]:
        nz, nx = self.design.n_z, self.sys.nx
        if self.x0 is not None:
            zlo, zhi = image_bounds(self.design.T, self.x0.lo, self.x0.hi)  # (3.b)/(10.c)/(15.c)
            xlo, xhi = self.x0.lo.copy(), self.x0.hi.copy()
        else:  # T0 = 0: z[0] = 0 exactly
            zlo, zhi = np.zeros(nz), np.zeros(nz)
            xlo, xhi = np.full(nx, -np.inf), np.full(nx, np.inf)
        st: dict[str, Any] = {"zlo": zlo, "zhi": zhi}
        if self._mode == "dt-ltv" or (self._mode == "ct" and not self._tv):
            st.update(xlo=xlo, xhi=xhi)
        if self._mode == "ct":
            st.update(
                T=self.design.T.copy(),
                t_prev=None,
                u_prev=np.zeros(self.sys.nu),
                dlo_prev=np.zeros(self.sys.nd),
                dhi_prev=np.zeros(self.sys.nd),
            )
        if self.coordinates == "x":
            st = {"xh_lo": self._tr.P @ zlo, "xh_hi": self._tr.P @ zhi}  # (6.b-c)
        return st

    def _step(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        if self._mode == "ct":
            assert t_k is not None
            return self._step_ct(state, k, u_k, y_k, t_k)
        return self._step_dt(state, k, u_k, y_k)

    def _first_box(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At ``k = 0`` the prior box itself is known: intersect (sound, never looser)."""
        if self.x0 is None:
            return lo, hi
        return np.maximum(lo, self.x0.lo), np.minimum(hi, self.x0.hi)

    # -- discrete time -------------------------------------------------------------------
    def _step_dt(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        lti = self._mode == "dt-lti"
        A, B, C, D, E, F = self._mats if lti else self.sys.matrices_at(k)
        tk, tn = self._transform(k), self._transform(k + 1)
        if self.coordinates == "x":
            zlo, zhi = self.design.T @ state["xh_lo"], self.design.T @ state["xh_hi"]  # (6.d-e)
        else:
            zlo, zhi = state["zlo"], state["zhi"]
        if tk.ok:
            lo, hi = self._recover(tk, zlo, zhi)
        else:  # time-varying, T[k] not left-invertible: the open-loop box
            lo, hi = state["xlo"].copy(), state["xhi"].copy()
            if k >= self.valid_from and not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
                raise IvobsError(
                    f"kkl: T[{k}] is not left-invertible (cond {tk.cond:.2e}) and no finite "
                    "prior is available; pass x0 so the observer can bridge such steps"
                )
        if k == 0:
            lo, hi = self._first_box(lo, hi)
        d = self.sys.d_at(k, y_k)
        obs = self._usable(state, y_k, lo, hi, C, D, F, u_k, d)
        if lti and obs.all():
            v = self._Bz @ y_k + self._Lu @ u_k
            glo, ghi = (
                self._g_const if self._g_const is not None else image_bounds(self._G, d.lo, d.hi)
            )
            if self.coordinates == "x":
                P = self._tr.P
                state["xh_lo"] = self._Mx @ state["xh_lo"] + P @ (v + glo)  # (6.a)
                state["xh_hi"] = self._Mx @ state["xh_hi"] + P @ (v + ghi)
                return lo, hi
            nlo, nhi = self._Az @ zlo + v + glo, self._Az @ zhi + v + ghi  # (3.a)
        else:
            nlo, nhi = self._update_z(
                k, zlo, zhi, lo, hi, obs, u_k, y_k, d, tk, tn, (B, C, D, E, F)
            )
        if self.coordinates == "x":
            state["xh_lo"], state["xh_hi"] = self._tr.P @ nlo, self._tr.P @ nhi
        else:
            state["zlo"], state["zhi"] = nlo, nhi
        if not lti:  # open-loop box for steps where T[k+1] is not left-invertible
            alo, ahi = image_bounds(A, lo, hi)
            elo, ehi = image_bounds(E, d.lo, d.hi)
            state["xlo"], state["xhi"] = alo + B @ u_k + elo, ahi + B @ u_k + ehi
        return lo, hi

    def _update_z(
        self,
        k: int,
        zlo: np.ndarray,
        zhi: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        obs: np.ndarray,
        u_k: np.ndarray,
        y_k: np.ndarray,
        d: Box,
        tk: _Transform,
        tn: _Transform,
        mats: tuple[np.ndarray, ...],
    ) -> tuple[np.ndarray, np.ndarray]:
        """(3.a)/(15.a) with the observed outputs; missing ones bounded through ``x[k]``."""
        B, C, D, E, F = mats
        Bo, Bm = self._Bz[:, obs], self._Bz[:, ~obs]
        v = Bo @ y_k[obs] + (tn.T @ B - Bo @ D[obs]) @ u_k
        glo, ghi = image_bounds(tn.T @ E - Bo @ F[obs], d.lo, d.hi)
        if obs.all():
            mlo, mhi = self._Az @ zlo, self._Az @ zhi
        elif tk.ok:  # x[k] = T[k]⁺ z[k] exactly: B_m C_m x = B_m C_m T⁺ z
            mlo, mhi = image_bounds(self._Az + Bm @ C[~obs] @ tk.P, zlo, zhi)
        else:
            if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
                raise IvobsError(
                    f"y: measurement missing at step {k}, before T[k] is left-invertible, and no "
                    "prior box on x[0]: pass x0 to predict through missing samples there"
                )
            clo, chi = image_bounds(Bm @ C[~obs], lo, hi)
            mlo, mhi = self._Az @ zlo + clo, self._Az @ zhi + chi
        return mlo + v + glo, mhi + v + ghi

    # -- continuous time -----------------------------------------------------------------
    def _u_between(self, t: float, t0: float, t1: float, u0: np.ndarray, u1: np.ndarray) -> Any:
        if callable(self._hold):
            return as_vector("input_hold(t)", self._hold(t), self.sys.nu)
        if self._hold == "zero":
            return u0
        s = (t - t0) / (t1 - t0)
        return u0 + s * (u1 - u0)

    def _flow(
        self,
        T: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        t0: float,
        t1: float,
        u0: np.ndarray,
        u1: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """From ``t0+`` to ``t1-``: closed form (time-invariant) or SciPy ODE (time-varying)."""
        if self._tv:
            return self._flow_ode(T, zlo, zhi, t0, t1, u0, u1, dlo, dhi)
        return self._flow_lti(T, zlo, zhi, t0, t1, u0, u1, dlo, dhi)

    def _interval_data(self, h: float) -> dict[str, Any]:
        """Matrices of one sampling interval of length ``h`` (time-invariant; cached by ``h``)."""
        from scipy.linalg import expm

        # keyed (and computed) by h rounded to 1e-12, so that a grid such as np.arange(0, 10, .01)
        # (steps differing by 1e-17) reuses one set, the same whatever step comes first
        h = key = round(float(h), 12)
        cache = self.__dict__.setdefault("_ct_cache", {})
        if key in cache:
            return cache[key]
        if len(cache) >= _CACHE_SIZE:  # irregular grids: one entry per distinct period
            cache.clear()
        sys = self.sys
        A, B, E = sys.A_at(0), sys.B_at(0), sys.E_at(0)
        n, m, q = sys.nx, sys.nu, sys.nd
        M = np.zeros((n + 2 * m, n + 2 * m))  # Van Loan: ∫ e^{A(h-s)} B (1, s/h) ds
        M[:n, :n], M[:n, n : n + m], M[n : n + m, n + m :] = A, B, np.eye(m) / h
        eM = expm(M * h)
        Me = np.zeros((n + q, n + q))
        Me[:n, :n], Me[:n, n:] = A, E
        normA = float(np.linalg.norm(A, 2))
        growth = normA * h * np.exp(normA * h)
        N = int(np.clip(np.ceil(400 * growth), 1, 256))  # sub-intervals for the d radius
        mids = (np.arange(N) + 0.5) * h / N
        data = {
            "h": h,
            "Phi_z": expm(self._Az * h),
            "Psi": expm(-A * h),
            "eA": eM[:n, :n],
            "G0": eM[:n, n : n + m],
            "G1": eM[:n, n + m :],
            "GE": expm(Me * h)[:n, n:],
            "nodesE": np.stack([expm(A * (h - s)) @ E for s in mids]),
            "N": N,
            "var": 0.5 * h * h / N * np.exp(normA * h) * np.linalg.norm(A @ E, axis=0),
        }
        if callable(self._hold):  # Gauss-Legendre nodes for a smooth u(t)
            xg, wg = np.polynomial.legendre.leggauss(8)
            sg = 0.5 * h * (xg + 1.0)
            data["gl"] = (sg, 0.5 * h * wg, np.stack([expm(A * (h - s)) @ B for s in sg]))
        cache[key] = data
        return data

    def _input_integral(
        self,
        c: dict[str, Any],
        t0: float,
        t1: float,
        u0: np.ndarray,
        u1: np.ndarray,
        mats: tuple[Any, np.ndarray, np.ndarray] | None = None,
    ) -> np.ndarray:
        """``M ∫ e^{A(h-s)} B u(t0 + s) ds`` over one interval, for the input hold: zero-order
        (``G0 u0``), linear (``G0 u0 + G1 (u1 - u0)``) or a callable (Gauss–Legendre nodes).
        ``mats = (nodes, G0, G1)`` already multiplied by ``M`` (default: those of ``c``,
        ``M = I``)."""
        if mats is None:
            mats = (c["gl"][2] if "gl" in c else None, c["G0"], c["G1"])
        nodes, G0, G1 = mats
        if callable(self._hold):
            sg, wg, _ = c["gl"]
            return sum(
                w * (nb @ self._u_between(t0 + s, t0, t1, u0, u1))
                for s, w, nb in zip(sg, wg, nodes)
            )
        if self._hold == "zero":
            return G0 @ u0
        return G0 @ u0 + G1 @ (u1 - u0)

    def _flow_lti(
        self,
        T: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        t0: float,
        t1: float,
        u0: np.ndarray,
        u1: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Exact flow: ``T(t1-) = e^{A_z h} T e^{-A h}``,
        ``z(t1-) = e^{A_z h} z + T(t1-) ∫ e^{A(h-s)} (B u + E d) ds``; the ``d`` integral bounded by
        midpoint sums of ``|T(t1-) e^{A(h-s)} E|`` plus a bound of their variation on each
        sub-interval (rigorous, not a quadrature)."""
        h = t1 - t0
        c = self._interval_data(h)
        Tn = c["Phi_z"] @ T @ c["Psi"]
        xu = self._input_integral(c, t0, t1, u0, u1)
        dc, dr = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo)
        rad = (h / c["N"]) * np.abs(Tn @ c["nodesE"]).sum(axis=0) @ dr
        rad = rad + np.linalg.norm(Tn, axis=1) * float(c["var"] @ dr)
        mid = Tn @ (xu + c["GE"] @ dc)
        return Tn, c["Phi_z"] @ zlo + mid - rad, c["Phi_z"] @ zhi + mid + rad

    def _anchor(self, c: dict[str, Any], first: bool = False) -> dict[str, Any] | None:
        """The constant ``T`` of a regular grid of period ``h`` (time-invariant; cached).

        With every output observed, one interval maps ``T(t_k+)`` to
        ``e^{A_z h} T e^{-A h} + h B_z C``; its fixed point ``T_h`` solves the Sylvester equation
        (eq. 4 of the sampled system, solved once per period)::

            T_h e^{A h} - e^{A_z h} T_h = h B_z C e^{A h}

        (``T_h → T`` of (4) as ``h → 0``). Started at ``T_h`` (:meth:`_to_anchor`), ``T`` is
        constant at the samples and nothing about it is propagated: ``T(t_k-) = T_h - h B_z C``,
        and the ``d`` radius of an interval is one matrix. ``D = e^{A_z h} T_h - T(t_k-) e^{A h}``
        (the computed residual) enters the radius as ``|D T_h⁻¹| max(|z̲|, |z̄|)``. ``None`` when
        ``T_h`` is singular or ill-conditioned (then ``T`` is propagated by :meth:`_flow_lti`);
        on the first interval (``first``) that is a :class:`DesignError`: the target modes are
        too fast for the sampling period (rows of ``T`` with ``|a_i| h >> 1`` are forgotten
        between samples and become ``h b_i C``).
        """
        if "anchor" not in c:
            c["anchor"] = self._make_anchor(c)
        if c["anchor"] is None and first:
            Th = c.get("T_h")
            cond = _pinv(Th, self.max_cond).cond if Th is not None else float("inf")
            a = float(np.min(np.linalg.eigvals(self._Az).real))
            raise DesignError(
                f"kkl: sampling period h = {c['h']:g}: the transformation at the samples "
                f"(T_h, fixed point of T -> e^(A_z h) T e^(-A h) + h B_z C) has cond {cond:.3e} > "
                f"max_cond = {self.max_cond:.0e}; target modes much faster than 1/h are forgotten "
                f"between samples (fastest eigenvalue of A_z: {a:.4g}, a h = {a * c['h']:.3g}): "
                "pass A_z, B_z with slower eigenvalues (still faster than every mode of A) or "
                "sample faster"
            )
        return c["anchor"]

    def _make_anchor(self, c: dict[str, Any]) -> dict[str, Any] | None:
        """The pieces of :meth:`_anchor` for the interval data ``c`` (None if ``T_h`` is bad)."""
        from scipy.linalg import solve_sylvester

        h, Phi, eA = c["h"], c["Phi_z"], c["eA"]
        Q = h * self._Bz @ self.sys.C_at(0)
        try:
            with np.errstate(all="ignore"):
                Th = solve_sylvester(-Phi, eA, Q @ eA)
        except (np.linalg.LinAlgError, ValueError):
            return None
        for _ in range(4):  # make T_h an exact fixed point of the computed jump
            Tm = Th - Q
            if np.array_equal(Tm + Q, Th):
                break
            Th = Tm + Q
        else:
            return None
        c["T_h"] = Th
        trh = _pinv(Th, self.max_cond)
        if not (trh.ok and np.all(np.isfinite(Tm))):
            return None
        D = Phi @ Th - Tm @ eA
        data = {
            "T": Th,
            "tr": trh,
            "Tm": Tm,
            "trm": _pinv(Tm, self.max_cond),
            "res": np.abs(D @ trh.P),
            "rad": (h / c["N"]) * np.abs(Tm @ c["nodesE"]).sum(axis=0)
            + np.linalg.norm(Tm, axis=1)[:, None] * c["var"][None, :],
            "TG0": Tm @ c["G0"],
            "TG1": Tm @ c["G1"],
            "TGE": Tm @ c["GE"],
        }
        if "gl" in c:
            data["TgB"] = Tm @ c["gl"][2]
        return data

    def _to_anchor(
        self, an: dict[str, Any], k: int, T: np.ndarray, zlo: np.ndarray, zhi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Switch the state ``(T, z̲, z̄)`` at ``t_(k-1)+`` to ``T_h`` when that costs nothing.

        ``T = T_h`` already (bitwise; after a JSON round trip too): nothing to do. First
        interval (``k = 1``, nothing measured yet): ``z`` is re-initialised from ``x0`` by (3.b)
        with ``T_h``. ``T`` within ``1e-9`` (relative) of ``T_h`` (back after missing samples or a
        change of period, the flow being stable): ``T_h x = z + (T_h - T) T⁻¹ z``, bounded by
        Lemma 1. Otherwise the state is returned unchanged.
        """
        Th = an["T"]
        if T is Th:
            return T, zlo, zhi
        if np.array_equal(T, Th):
            return Th, zlo, zhi
        if k == 1 and self.x0 is not None:
            zl, zh = image_bounds(Th, self.x0.lo, self.x0.hi)
            return Th, zl, zh
        if np.max(np.abs(T - Th)) <= _ANCHOR_TOL * np.max(np.abs(Th)):
            tr = _pinv(T, self.max_cond)
            if tr.ok:
                clo, chi = image_bounds((Th - T) @ tr.P, zlo, zhi)
                return Th, zlo + clo, zhi + chi
        return T, zlo, zhi

    def _flow_anchored(
        self,
        c: dict[str, Any],
        an: dict[str, Any],
        zlo: np.ndarray,
        zhi: np.ndarray,
        t0: float,
        t1: float,
        u0: np.ndarray,
        u1: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_flow_lti` from ``T(t0+) = T_h``: the same formulas with the matrices of
        :meth:`_anchor`, plus the residual term of ``T_h``."""
        mid = self._input_integral(c, t0, t1, u0, u1, (an.get("TgB"), an["TG0"], an["TG1"]))
        dc, dr = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo)
        mid = mid + an["TGE"] @ dc
        rad = an["rad"] @ dr + an["res"] @ np.maximum(np.abs(zlo), np.abs(zhi))
        Phi = c["Phi_z"]
        return an["Tm"], Phi @ zlo + mid - rad, Phi @ zhi + mid + rad

    def _flow_ode(
        self,
        T: np.ndarray,
        zlo: np.ndarray,
        zhi: np.ndarray,
        t0: float,
        t1: float,
        u0: np.ndarray,
        u1: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Integrate ``Ṫ = A_z T - T A(t)`` and the bounds (10.a) without ``B_z y`` on [t0, t1]."""
        from scipy.integrate import solve_ivp

        Az = self._Az
        nz, nx = T.shape
        nT = nz * nx
        A_t, B_t, E_t = (_accessor(M) for M in (self.sys.A, self.sys.B, self.sys.E))
        dc, dr = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo)
        hold, du = self._hold, (u1 - u0) / (t1 - t0)

        def rhs(t: float, Y: np.ndarray) -> np.ndarray:
            # centre/radius form of (10.a): (TE)⁺ d̄ - (TE)⁻ d̲ = TE d_c + |TE| d_r
            Tm = Y[:nT].reshape(nz, nx)
            TE = Tm @ E_t(t)
            uu = hold(t) if callable(hold) else (u0 if hold == "zero" else u0 + (t - t0) * du)
            base = Tm @ (B_t(t) @ np.asarray(uu, dtype=float)) + TE @ dc
            rad = np.abs(TE) @ dr
            out = np.empty_like(Y)
            out[:nT] = (Az @ Tm - Tm @ A_t(t)).ravel()
            out[nT : nT + nz] = Az @ Y[nT : nT + nz] + base - rad
            out[nT + nz :] = Az @ Y[nT + nz :] + base + rad
            return out

        Y0 = np.concatenate([T.ravel(), zlo, zhi])
        sol = solve_ivp(
            rhs, (t0, t1), Y0, method="DOP853", rtol=self._rtol, atol=self._atol, first_step=t1 - t0
        )
        if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
            raise IvobsError(f"kkl: integration failed on [{t0}, {t1}]: {sol.message}")
        Y = sol.y[:, -1]
        nlo, nhi = Y[nT : nT + nz], Y[nT + nz :]
        pad = 10 * (self._atol + self._rtol * np.maximum(np.abs(nlo), np.abs(nhi)))
        return Y[:nT].reshape(nz, nx), nlo - pad, nhi + pad

    def _step_ct(
        self, state: dict[str, Any], k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float
    ) -> tuple[np.ndarray, np.ndarray]:
        _, _, C, D, _, F = self.sys.matrices_at(t_k)
        d = self.sys.d_at(k, y_k)
        T, zlo, zhi = state["T"], state["zlo"], state["zhi"]
        h = 0.0
        an = None
        model = None  # time-invariant: the previous box propagated through the model
        if state["t_prev"] is not None:
            t0 = float(state["t_prev"])
            h = t_k - t0
            if not h > 0:
                raise IvobsError(f"t: sample times must increase; got t = {t_k} after {t0}")
            dlo = np.minimum(state["dlo_prev"], d.lo)
            dhi = np.maximum(state["dhi_prev"], d.hi)
            u0 = state["u_prev"]
            if not self._tv:
                c = self._interval_data(h)
                an = self._anchor(c, first=k == 1)
                model = self._predict_box(c, state["xlo"], state["xhi"], t0, t_k, u0, u_k, dlo, dhi)
            if an is not None:
                T, zlo, zhi = self._to_anchor(an, k, T, zlo, zhi)
            if an is not None and T is an["T"]:  # constant T: nothing propagated
                T, zlo, zhi = self._flow_anchored(c, an, zlo, zhi, t0, t_k, u0, u_k, dlo, dhi)
            else:
                an = None
                T, zlo, zhi = self._flow(T, zlo, zhi, t0, t_k, u0, u_k, dlo, dhi)
        obs = ~np.isnan(y_k)
        if h > 0 and obs.any():  # the measurement jump (sampled form of B_z y in (3)/(10))
            tr = an["trm"] if an is not None else _pinv(T, self.max_cond)
            box = self._ct_box(state, tr, zlo, zhi, model)
            if box is not None:
                obs = self._usable(state, y_k, box[0], box[1], C, D, F, u_k, d)
            Bo = h * self._Bz[:, obs]
            if an is not None and obs.all():
                T = an["T"]  # = T(t_k-) + h B_z C exactly (see _anchor)
            else:
                T = T + Bo @ C[obs]
            v = Bo @ (y_k[obs] - D[obs] @ u_k)
            BF = Bo @ F[obs]
            v = v - BF @ (0.5 * (d.lo + d.hi))
            gr = np.abs(BF) @ (0.5 * (d.hi - d.lo))
            zlo, zhi = zlo + v - gr, zhi + v + gr
        tr = an["tr"] if an is not None and T is an["T"] else _pinv(T, self.max_cond)
        box = self._ct_box(state, tr, zlo, zhi, model)
        if box is None:
            raise DesignError(
                f"kkl: T(t) lost left-invertibility at t = {t_k} (cond {tr.cond:.3e} > max_cond "
                f"= {self.max_cond:.0e}); choose faster target dynamics (larger ell) or another "
                "A_z, B_z (004 Propositions 1, 3)"
            )
        lo, hi = box
        if k == 0:
            lo, hi = self._first_box(lo, hi)
        state.update(
            T=T,
            zlo=zlo,
            zhi=zhi,
            t_prev=float(t_k),
            u_prev=u_k.copy(),
            dlo_prev=d.lo.copy(),
            dhi_prev=d.hi.copy(),
        )
        if not self._tv:
            state.update(xlo=lo.copy(), xhi=hi.copy())
        return lo, hi

    def _ct_box(
        self,
        state: dict[str, Any],
        tr: _Transform,
        zlo: np.ndarray,
        zhi: np.ndarray,
        model: tuple[np.ndarray, np.ndarray] | None,
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """The box from ``z`` (3.c-d)/(10.d), intersected with the model prediction ``model`` of
        the previous box (time-invariant; both are sound); the prediction alone while ``T`` is
        not left-invertible (e.g. right after a long gap); None if neither is available.

        An empty intersection beyond rounding means the data contradict the model: reported as
        an inconsistency; each crossed coordinate then keeps the hull of the two crossed ends.
        """
        if not tr.ok:
            return model
        lo, hi = self._recover(tr, zlo, zhi)
        if model is None:
            return lo, hi
        lo, hi = np.maximum(lo, model[0]), np.minimum(hi, model[1])
        cross = lo > hi
        if cross.any():
            if np.any(lo - hi > 1e-9 * (1.0 + np.abs(lo) + np.abs(hi))):
                state["_inconsistent"] = True
            lo, hi = np.where(cross, hi, lo), np.where(cross, lo, hi)
        return lo, hi

    def _predict_box(
        self,
        c: dict[str, Any],
        xlo: np.ndarray,
        xhi: np.ndarray,
        t0: float,
        t1: float,
        u0: np.ndarray,
        u1: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``x(t1) ∈ e^{A h}[x̲, x̄] + ∫ e^{A(h-s)} (B u + E d) ds`` (time-invariant; Lemma 1 and
        the enclosures of :meth:`_flow_lti` with ``T = I``)."""
        if "radI" not in c:
            c["radI"] = c["h"] / c["N"] * np.abs(c["nodesE"]).sum(axis=0) + c["var"][None, :]
            c["abs_eA"] = np.abs(c["eA"])
        xc, xr = 0.5 * (xlo + xhi), 0.5 * (xhi - xlo)
        mid = self._input_integral(c, t0, t1, u0, u1)
        dc, dr = 0.5 * (dlo + dhi), 0.5 * (dhi - dlo)
        mid = mid + c["eA"] @ xc + c["GE"] @ dc
        rad = c["abs_eA"] @ xr + c["radI"] @ dr
        return mid - rad, mid + rad

    # -- vectorised run (discrete-time LTI) ----------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """(3.a) as two linear recursions with matrix ``A_z``, in centre/radius form.

        ``c = (z̄ + z̲)/2`` follows ``c+ = A_z c + B_z y + (TB - B_zD) u + (ḡ + g̲)/2`` and the radius
        ``r+ = A_z r + (ḡ - g̲)/2`` does not depend on the data (one recursion for a whole batch).
        Observer (6) (``coordinates="x"``) runs the same in ``x̂`` with ``A - LC``. The centre
        ``x = T⁺ c``, ``c`` itself (for the recovery margin) and the innovation
        ``y - C T⁺ c - D u - F d_c`` are outputs of one :class:`~ivobs._recursion.SplitFilter`
        pass.
        """
        if self._mode != "dt-lti" or not y.shape[-2] or np.isnan(y).any():
            return None  # (an empty record: the loop)
        if self.sys.d is not None and not isinstance(self.sys.d, Box):
            return None  # bounds computed from y (callable): the loop evaluates them per step
        Tn = y.shape[-2]
        d = self.sys.d
        if isinstance(d, Box) and d.is_time_varying and d.lo.shape[0] < Tn:
            return None  # the loop raises the informative error
        filt, xr0, yr0, gsig, fsig, c0 = self._vector_terms(Tn)
        _, _, C, D, _, F = self._mats
        nx = self.sys.nx
        hi = np.empty((*y.shape[:-1], nx))
        sig = [y, u] if gsig is None else [y, u, gsig, fsig]
        (xc, zc, innov), shared = filt.run(sig, x0=c0, out=[hi, None, None], temp=[1, 2])
        s_x, s_z, s_i = (None, None, None) if shared is None else shared
        # consistency of y[k], k >= 1, with the band of the box at k (row 0: below, from the box
        # intersected with the prior, as in the loop); the data-free band is the narrower one
        band = yr0[1:] + 1e-9 * (1.0 + yr0[1:])  # the test below without |yc| (narrower)
        fail = None
        if not within_band(innov[..., 1:, :], None if s_i is None else s_i[1:], band):
            full = (innov if s_i is None else innov + s_i)[..., 1:, :]
            yc = y[..., 1:, :] - full
            fail = np.abs(full) > yr0[1:] + 1e-9 * (1.0 + np.abs(yc) + yr0[1:])
        del innov
        # radius: data-free part + recovery margin |c| (16 (n_z + n_x) ε cond(T)) |T⁺|
        if s_z is not None:
            zc += s_z
        np.abs(zc, out=zc)
        xr = matrix_product(zc, self._margin.T, out=scratch(self, "xr", hi.shape))
        del zc
        lo = np.empty_like(hi)
        if s_x is None:
            np.subtract(xc, xr0, out=lo)
            xc += xr0
        else:
            np.add(xc, s_x - xr0, out=lo)
            xc += s_x + xr0
        lo -= xr
        xc += xr
        lo[..., 0, :], xc[..., 0, :] = self._first_box(lo[..., 0, :], xc[..., 0, :])
        dc0, dr0 = (0.5 * (self._dlo0 + self._dhi0), 0.5 * (self._dhi0 - self._dlo0))
        c0b, r0b = 0.5 * (lo[..., 0, :] + xc[..., 0, :]), 0.5 * (xc[..., 0, :] - lo[..., 0, :])
        yc0 = c0b @ C.T + u[..., 0, :] @ D.T + F @ dc0
        yr0b = r0b @ np.abs(C).T + np.abs(F) @ dr0
        fail0 = np.abs(y[..., 0, :] - yc0) > yr0b + 1e-9 * (1.0 + np.abs(yc0) + yr0b)
        if not fail0.any() and (fail is None or not fail.any()):
            return lo, xc
        if y.ndim != 3:
            return None  # the loop reports the step and predicts without it
        bad = fail0.any(axis=-1)
        if fail is not None:
            bad |= fail.any(axis=(-2, -1))
        return redo_streams(self, u, y, t, lo, xc, bad)

    def _vector_terms(self, Tn: int) -> tuple[Any, ...]:
        """The filter and the data-free terms of the vectorised path for ``Tn`` steps (cached):
        ``xr0 = |T⁺| r + margin``-part of the radius, ``yr0 = |C| xr0 + |F| d_r`` (the output
        band), the time-varying known inputs ``g_c``, ``F d_c`` (or None) and ``c[0]``."""
        cached = self.__dict__.get("_vec")
        if cached is not None and cached[0] == Tn:
            return cached[1]
        d = self.sys.d
        if isinstance(d, Box) and d.is_time_varying:
            dlo, dhi = d.lo[:Tn], d.hi[:Tn]
        else:
            dd = self.sys.d_at(0)
            dlo, dhi = dd.lo, dd.hi
        tv = dlo.ndim == 2
        self._dlo0, self._dhi0 = (dlo[0], dhi[0]) if tv else (dlo, dhi)
        glo, ghi = image_bounds(self._G, dlo, dhi)
        gc, gr = 0.5 * (glo + ghi), 0.5 * (ghi - glo)
        assert self.x0 is not None
        z0lo, z0hi = image_bounds(self.design.T, self.x0.lo, self.x0.hi)
        c0, r0 = 0.5 * (z0lo + z0hi), 0.5 * (z0hi - z0lo)
        P, Tm = self._tr.P, self.design.T
        _, _, C, D, _, F = self._mats
        ny, nz = self.sys.ny, self.design.n_z
        fc, fr = 0.5 * (dlo + dhi) @ F.T, 0.5 * (dhi - dlo) @ np.abs(F).T
        if self.coordinates == "x":  # observer (6) in x̂, z = T x̂
            M, Win, Hz, x0 = self._Mx, P, Tm, P @ c0
        else:
            M, Win, Hz, x0 = self._Az, np.eye(nz), np.eye(nz), c0
        Hx = P @ Hz
        W = [Win @ self._Bz, Win @ self._Lu] + ([Win, np.zeros((Win.shape[0], ny))] if tv else [])
        nsig = len(W)
        J = [[None] * nsig, [None] * nsig, [np.eye(ny), -D] + ([None, -np.eye(ny)] if tv else [])]
        filt = SplitFilter(
            M,
            W,
            [Hx, Hz, -C @ Hx],
            J,
            g=None if tv else Win @ gc,
            h=[None, None, None if tv else -fc],
        )
        if tv:
            rf = LinearFilter(M, [Win], [Hz])
            zr = rf.run([gr], x0=Win @ r0)[0]
        else:
            zr = LinearFilter(M, [], [Hz], g=Win @ gr).run([], T=Tn, x0=Win @ r0)[0]
        xr0 = zr @ (np.abs(P) + self._margin).T  # data-free part of the x radius
        yr0 = xr0 @ np.abs(C).T + fr  # data-free half-width of the output band
        terms = (filt, xr0, yr0, gc if tv else None, fc if tv else None, x0)
        self.__dict__["_vec"] = (Tn, terms)
        return terms


def _default_ell(A_tilde: np.ndarray, A0: np.ndarray) -> float:
    """The CT factor of (11.a): 2 (Example 2), or more if needed for the flow rule at ``t = 0``:
    ``ell max Re λ(Ã) <= min Re λ(A(0)) - FLOW_MARGIN max(1, ρ(A(0)))``."""
    top = float(np.max(np.linalg.eigvals(A_tilde).real))
    if not top < 0:
        return 2.0  # not Hurwitz: check_target names it
    return max(2.0, flow_cap(A0) / top)


def _accessor(M: Any) -> Callable[[float], np.ndarray]:
    """``t -> M(t)`` without per-call validation (the model validated ``M`` at construction)."""
    if callable(M):
        return lambda t: np.asarray(M(t), dtype=float)
    Mc = np.asarray(M, dtype=float)
    return lambda t: Mc
