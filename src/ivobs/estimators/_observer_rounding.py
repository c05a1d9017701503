"""The proven bounds of the rounding of the Luenberger observer behind ``reachability`` and
``zonotope`` (the proof: :mod:`ivobs.estimators._luenberger`).

* :func:`difference`: a float matrix ``M = fl(A - L C)`` and the bound of its difference to the
  exact ``A - L C``;
* :func:`rounding_matrix`: ``W``, the rounding of one observer step as a linear function of the
  magnitudes it involves ([Higham2002, eq. (3.5)]);
* :func:`envelope`: proven bounds ``|M^i X| 1 <= a λ^i`` of the powers of the float ``M``
  (``‖M^i‖∞ <= c λ^i``: :func:`ivobs.sets.rounding.certified_norms`), computed from float
  powers and the bounds of their own rounding;
* :func:`scaling`: a diagonal scaling ``s`` of powers of two that balances ``M``, in whose
  norm ``‖v‖_s = ‖S⁻¹ v‖∞`` the rounding of a badly scaled state is measured;
* :class:`Channels`: where the observer's rounding goes while ``M`` is the same at every step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import DesignError
from ..linalg import UNIT_ROUNDOFF, gamma
from ..sets.rounding import (
    ETA,
    DecayBound,
    certified_norms,
    decay_of,
    exactly_scaled,
    product_error,
    up,
    upper,
)
from ._recursion import abs_max

__all__ = ["Channels", "difference", "envelope", "rounding_matrix"]

THETAS = (0.5, 0.25, 0.1)
"""Decay targets ``θ`` tried for the rate ``λ`` of the envelopes (:func:`decay_of`): the one
with the smallest sum ``(a_L + a_x) / (1 - λ)`` is kept."""

TAIL = 2.0**-20
"""An envelope (:func:`envelope`) stops at the power whose tail is below this fraction of it."""

MAX_POWERS = 2000
"""Most powers of ``M`` an envelope is computed over: beyond, the tail bound of the last one
holds (wider for a slowly converging gain: about ``c`` times the first powers)."""


def difference(A: np.ndarray, L: np.ndarray, C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(M, ΔM)``: ``M = fl(A - fl(L C))`` and ``ΔM >= |A - L C - M|`` exactly: the product's
    error (``product_error(|L| |C|)``) plus the subtraction's (``u |M|``, doubled to cover the
    rounding of this sum), rounded up."""
    M = A - L @ C
    dM = up(product_error(np.abs(L) @ np.abs(C), L.shape[1]) + 2.0 * UNIT_ROUNDOFF * np.abs(M))
    return M, dM


def envelope(M: np.ndarray, X: np.ndarray, decay: DecayBound) -> np.ndarray:
    """``a`` with ``|M^i X| 1 <= a λ^i`` for every ``i >= 0`` (exact powers of the float ``M``,
    ``λ = decay.lam``).

    ``P_{i+1} = fl(M P_i)``, ``P_0 = X``, differs from ``M^i X`` by ``Σ_{j<i} M^{i-1-j} E_j``
    (``|E_j| 1 <= product_error(|M| |P_j| 1)``), at most ``c S_i`` with ``S_{i+1} = λ S_i +
    ‖|E_i| 1‖∞`` (``‖M^m‖∞ <= c λ^m``, :func:`decay_of`). So ``κ_i = |P_i| 1 + c S_i`` bounds
    ``|M^i X| 1``, ``a = max_i κ_i / λ^i``; beyond the last power ``K`` computed,
    ``|M^j X| 1 <= c λ^{j-K} ‖κ_K‖∞``, which the maximum includes; ``K`` is the first power
    whose own part of that tail is below :data:`TAIL` of ``a`` (at most :data:`MAX_POWERS`).
    Everything rounded up."""
    n, m = X.shape
    lam, c = decay.lam, decay.c
    absM = np.abs(M)
    inv = math.nextafter(1.0 / lam, math.inf) if lam > 0 else math.inf
    P, S, scale = X.astype(float), 0.0, 1.0  # scale >= λ^{-i}
    a = np.zeros(n)
    for _ in range(MAX_POWERS):
        rows = upper(np.abs(P).sum(axis=1), m)
        kappa = upper(rows + c * S, 2)
        a = np.maximum(a, up(kappa * scale))
        tail = float(up(c * float(kappa.max()) * scale))
        # stop once the powers themselves are negligible (the rounding part of the tail, c S_i
        # λ^{-i}, no longer decreases: it is kept, at about γ c² of a)
        if c * float(rows.max()) * scale <= TAIL * float(a.max()) or not scale < 1e300:
            break
        S = (lam * S + float(product_error(absM @ rows, n).max())) * (1.0 + 4.0 * UNIT_ROUNDOFF)
        P = M @ P
        scale = math.nextafter(scale * inv, math.inf)
    out: np.ndarray = np.maximum(a, tail)
    return out


MAX_EXPONENT = 500
"""The scaling ``s`` of :class:`Channels` is ``2^e`` with ``|e| <=`` this: ``s``, ``1 / s`` and
``s_j / s_i`` are exact floats."""


def scaling(M: np.ndarray) -> np.ndarray:
    """``s``: powers of two, ``2^e`` with ``|e| <=`` :data:`MAX_EXPONENT`, that balance ``M``
    (:func:`ivobs.design.balance.state_scaling`: LAPACK ``gebal`` of ``|M|``, ``S⁻¹ M S`` with
    rows and columns of similar norms, ``S = diag(s)``); ones when ``M`` is already balanced."""
    n = M.shape[0]
    if not n:
        return np.ones(0)
    from ..design.balance import state_scaling

    _, e = np.frexp(state_scaling(M, np.zeros((0, n))))  # gebal's s: 2^(e - 1)
    out: np.ndarray = np.ldexp(1.0, np.clip(e - 1, -MAX_EXPONENT, MAX_EXPONENT))
    return out


def _times(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """``>= v f`` for ``v >= 0`` and ``f`` powers of two: exact, but where ``f < 1`` it may
    underflow, so rounded up there."""
    out = v * f
    rounded: np.ndarray = np.where(f < 1.0, up(out), out)
    return rounded


def _norm(v: np.ndarray, inv: np.ndarray) -> float:
    """``>= max_i v_i inv_i`` (``v >= 0``, ``inv`` powers of two)."""
    return float(max(_times(v, inv).tolist(), default=0.0))


@dataclass(frozen=True)
class Channels:
    """Where the observer's rounding goes while ``M`` is the same at every step (the proof: the
    module docstring of :mod:`ivobs.estimators._luenberger`), measured in the scaled norm
    ``‖v‖_s = ‖S⁻¹ v‖∞`` (``S = diag(s)``, :func:`scaling`; ``inv = 1 / s``).

    With ``M̃ = S⁻¹ M S`` and ``L̃ = S⁻¹ L`` (exact: powers of two), ``|M̃^i L̃| 1 <= ã_L λ^i``
    and ``|M̃^i| 1 <= ã_x λ^i`` (:func:`envelope`), so ``|M^i L| 1 = S |M̃^i L̃| 1 <= a_L λ^i``
    and ``|M^i| s = S |M̃^i| 1 <= a_x λ^i`` with ``a_L = s ⊙ ã_L``, ``a_x = s ⊙ ã_x``. The
    rounding of all steps so far is within ``a_L q_L + a_x q_x``; ``L``, ``x``: the scalar
    recursions of ``q_L`` (rate ``λ``, input ``‖e_ν‖∞``) and ``q_x`` (input ``‖ξ‖_s``; rate
    ``λ + β_x``: ``ΔM`` acting on that part, ``β_x = ‖ΔM a_x‖_s``; ``β_L = ‖ΔM a_L‖_s``
    multiplies ``q_L`` into ``q_x``'s input); ``cL``, ``cx``: ``|C| a_L``, ``|C| a_x``, their
    image in ``y``; ``K = [[a_L, a_x], [c_L, c_x]]``. ``down``: some ``s_i > 1`` (a product
    by ``1 / s_i`` may underflow, so it is rounded up). ``s = 1`` (a balanced ``M``): the
    ∞-norm, the envelopes of ``M`` itself."""

    aL: np.ndarray
    ax: np.ndarray
    cL: np.ndarray
    cx: np.ndarray
    K: np.ndarray
    betaL: float
    L: DecayBound
    x: DecayBound
    inv: np.ndarray
    down: bool

    @classmethod
    def of(cls, M: np.ndarray, dM: np.ndarray, L: np.ndarray, C: np.ndarray) -> Channels:
        """The envelopes for ``M`` (its rate chosen among :data:`THETAS`), in the scaling of
        :func:`scaling` (ones if ``M̃`` or ``L̃`` would not be exact)."""
        n = M.shape[0]
        s = scaling(M)
        inv = 1.0 / s  # exact: powers of two
        Ms = exactly_scaled(M, s[None, :] * inv[:, None])  # M̃ = S⁻¹ M S
        Ls = exactly_scaled(L, inv[:, None])  # L̃ = S⁻¹ L
        if Ms is None or Ls is None:
            s, inv, Ms, Ls = np.ones(n), np.ones(n), M, L
        best: tuple[float, np.ndarray, np.ndarray, float] | None = None
        norms = certified_norms(Ms, min(THETAS)) if n else np.ones(1)
        for theta in THETAS:
            decay = decay_of(norms, theta)
            if decay is None:
                continue
            aL, ax = envelope(Ms, Ls, decay), envelope(Ms, np.eye(n), decay)
            score = float(aL.max() + ax.max()) / (1.0 - decay.lam)
            if best is None or score < best[0]:
                best = (score, aL, ax, decay.lam)
        assert best is not None
        _, aL, ax, lam = best
        aL, ax = _times(aL, s), _times(ax, s)  # a = s ⊙ ã
        betaL = _norm(upper(dM @ aL, n), inv)
        lam_x = float(up(lam + _norm(upper(dM @ ax, n), inv)))
        if not lam_x < 1.0:
            raise DesignError(
                "the rounding of the observer cannot be bounded: the decay rate of A - LC with "
                f"its rounding is {lam_x:.17g} >= 1"
            )
        cL, cx = upper(np.abs(C) @ aL, n), upper(np.abs(C) @ ax, n)
        K = np.vstack([np.column_stack([aL, ax]), np.column_stack([cL, cx])])
        rates = DecayBound(1.0, lam), DecayBound(1.0, lam_x)
        return cls(aL, ax, cL, cx, K, betaL, *rates, inv, bool((inv < 1.0).any()))

    def norm(self, v: np.ndarray) -> float:
        """``>= ‖v‖_s = max_i v_i / s_i`` for ``v >= 0`` (``nx,``): the input of ``q_x``. The
        products by ``1 / s_i`` are exact unless they underflow (error below ``2^-1075``), so
        the largest computed one, one ulp up where some ``s_i > 1``, bounds the exact maximum."""
        m: float = max((v * self.inv).tolist(), default=0.0)
        return math.nextafter(m, math.inf) if self.down else m

    def norms(self, v: np.ndarray) -> np.ndarray:
        """``>= ‖v‖_s`` over the last axis of ``v >= 0`` (as :meth:`norm`)."""
        out: np.ndarray = abs_max(v * self.inv)
        return up(out) if self.down else out

    def widen(self, s: np.ndarray, qL: float, qx: float) -> np.ndarray:
        """``>= s + K [q_L; q_x]`` for ``s = [ρ; ȳ]`` (or its first rows, ``ρ``)."""
        out: np.ndarray = upper(s + self.K[: s.shape[0]] @ np.array((qL, qx)), 4)
        return out


def rounding_matrix(mats: tuple[np.ndarray, ...], L: np.ndarray, c_used: np.ndarray) -> np.ndarray:
    """``W`` with ``[ε; e_ν] <= fl(W z)``, ``z = [|x̂|; |u|; |c|; |y|; |ν|; 1]``, for one step
    of the observer with gain ``L`` (module docstring: ``ε`` bounds the rounding of ``x̂+`` given
    ``fl(ν)``, ``e_ν`` that of ``ν``, which enters ``x̂+`` through ``L``).

    Row ``i`` of ``ν = y - fl([C D F] [x̂; u; c])`` sums ``n_i`` products and ``y_i``, row ``i``
    of ``x̂+ = fl([A B E] [x̂; u; c]) + fl(L fl(ν))`` the products of both: ``γ_{n_i}`` of the sum
    of their magnitudes bounds the error ([Higham2002, eq. (3.5)], any order of evaluation),
    ``n_i`` counting the nonzero coefficients only (a zero product adds no error; ``c_used``:
    the components of ``c`` that may be nonzero), plus ``n_i η`` of underflow. ``W``'s entries
    are rounded up and enlarged by the rounding of the product ``W z`` itself."""
    A, B, C, D, E, F = mats
    nx, ny = A.shape[0], C.shape[0]
    aL = np.abs(L)
    C_nu = np.hstack([np.abs(C), np.abs(D), np.abs(F) * c_used, np.eye(ny)])  # |y| last
    n_nu = np.count_nonzero(C_nu, axis=1)
    W_nu = np.hstack([C_nu, np.zeros((ny, ny))]) * gamma_rows(n_nu)
    W_nu = np.hstack([W_nu, (n_nu + 1)[:, None] * ETA])
    C_x = np.hstack([np.abs(A), np.abs(B), np.abs(E) * c_used, np.zeros((nx, ny)), aL])
    n_x = np.count_nonzero(C_x, axis=1) + 1
    W_x = np.hstack([C_x * gamma_rows(n_x), (n_x + 1)[:, None] * ETA])
    W = upper(np.vstack([W_x, W_nu]), 4)
    m = W.shape[1]  # fl(W z) >= (1 - γ_m) W z - m η
    W *= 1.0 + 2.0 * gamma(m + 2)
    W[:, -1] += (m + 2) * ETA
    out: np.ndarray = up(W)
    return out


def gamma_rows(n: np.ndarray) -> np.ndarray:
    """``γ_{n_i}`` ([Higham2002, Lemma 3.1]) as a column, one per row count ``n_i``."""
    return np.array([gamma(int(k)) for k in n])[:, None]
