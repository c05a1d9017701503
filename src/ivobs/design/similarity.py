"""Similarity transformations to a nonnegative matrix (interval observers in new coordinates).

Papers: [Tang2019, Theorem 5, Lemma 4 and eq. (48)]; [Efimov2013, Lemma 2 and Theorem 2].

Given a Schur ``M = A − LC`` and a nonnegative ``R`` with the same eigenvalues, eq. (48)

    S = O_R⁻¹ O_M,      O_X = [e; e X; …; e X^(n−1)]   (rows; ``e1`` for ``M``, ``e2`` for ``R``)

gives ``S M S⁻¹ = R`` whenever ``(M, e1)`` and ``(R, e2)`` are observable ([Tang2019, Lemma 4]): by
Cayley–Hamilton ``O_X X = Φ O_X`` with the same companion matrix ``Φ`` for both (same
characteristic polynomial), so ``S M = O_R⁻¹ Φ O_M = R S``. ``z = S x`` as in [Tang2019] and
[Efimov2013, Lemma 2]; [Efimov2013, Theorem 2] uses ``z = S⁻¹ x`` (its ``S`` is this ``S⁻¹``).

**Which spectra have a nonnegative realisation** (the nonnegative inverse eigenvalue problem,
[Efimov2013, §II.B] and its ref. [18] §11.2). Necessary: the spectral radius is itself an
eigenvalue (Perron), every power sum ``s_k = Σ λ_i^k`` is ``>= 0`` (``s_1`` = trace).
:func:`nonnegative_realization` builds ``R`` block-diagonally from blocks that are nonnegative
by construction:

* each real ``λ >= 0``: the ``1×1`` block ``[λ]`` (a repeated one: an upper bidiagonal Jordan chain
  with ones on the superdiagonal — "bidiagonal with the eigenvalues on the diagonal");
* negative real eigenvalues: Suleimanova groups. A group ``{ρ, −μ_1, …, −μ_m}`` with ``ρ >= 0``,
  ``μ_i >= 0``, ``ρ >= Σ μ_i`` is realised by the companion matrix of
  ``(x − ρ) Π (x + μ_i)``, whose non-leading coefficients ``e_{k+1} − ρ e_k`` are ``<= 0``
  (``e_k`` the elementary symmetric functions of the ``μ``: ``e_{k+1} <= e_1 e_k <= ρ e_k``), so
  the companion matrix is nonnegative (Suleimanova 1949; the partition into such groups is
  Perfect's/Kellogg's sufficient condition). Negative eigenvalues (all copies of a value together,
  largest first) go to the nonnegative "leader" with the largest remaining slack;
* a complex pair ``a ± ib`` (``b > 0``) with its own real leader ``ρ``: the ``3×3`` circulant with
  first row ``((ρ + 2a)/3, (ρ − a + √3 b)/3, (ρ − a − √3 b)/3)`` — nonnegative iff
  ``a ± ib`` lies in the triangle with vertices ``ρ, ρω, ρω²`` (``ω = e^{2πi/3}``), i.e.
  ``ρ >= a + √3 b`` and ``ρ >= −2a``. A nonnegative ``2×2`` matrix has real eigenvalues, so a
  complex pair always needs ``n >= 3``.

Not supported (``DesignError`` with the reason): spectra failing the necessary conditions (e.g.
``{0, −0.5}`` of [Efimov2013, §IV.A]: negative trace), complex pairs without a dominating real
eigenvalue in that triangle (realisations mixing several pairs in larger circulants exist,
Fiedler/Soules constructions, but are not implemented), repeated complex pairs, negative
eigenvalues that do not fit the leaders' slack (Borobia's splitting is not implemented). Any
user-given nonnegative ``R`` (``R=`` option) is accepted instead.
"""

from __future__ import annotations

from collections.abc import Callable
from itertools import pairwise

import numpy as np
from scipy.linalg import block_diag

from ..errors import DesignError
from ..linalg import is_observable, observability_matrix, spectral_radius

__all__ = [
    "circulant_block",
    "default_design",
    "default_e1",
    "design_width",
    "modal_width",
    "nonnegative_realization",
    "place_real_poles",
    "similarity_transform",
    "suleimanova_block",
    "transformed_width",
]

_SQ3 = np.sqrt(3.0)


def _fmt(lams: np.ndarray) -> str:
    return (
        "{" + ", ".join(f"{z.real:.4g}" + (f"{z.imag:+.4g}j" if z.imag else "") for z in lams) + "}"
    )


def suleimanova_block(rho: float, negatives: list[float]) -> np.ndarray:
    """Companion matrix (nonnegative) of ``(x − ρ) Π (x − λ_i)``, ``λ_i <= 0``, ``ρ >= Σ|λ_i|``."""
    coeffs = np.poly(np.concatenate([[rho], negatives]))  # monic, highest power first
    m = coeffs.size - 1
    R = np.zeros((m, m))
    R[:-1, 1:] = np.eye(m - 1)
    R[-1, :] = -coeffs[::-1][:-1]  # x^m = −c_0 − c_1 x − …: last row (c_0 … c_{m−1}) negated
    return R


def circulant_block(rho: float, pair: complex) -> np.ndarray:
    """The ``3×3`` real circulant with eigenvalues ``{ρ, a ± ib}``."""
    a, b = pair.real, abs(pair.imag)
    c = np.array([rho + 2 * a, rho - a + _SQ3 * b, rho - a - _SQ3 * b]) / 3.0
    return np.array([[c[0], c[1], c[2]], [c[2], c[0], c[1]], [c[1], c[2], c[0]]])


def _necessary(lams: np.ndarray, tol: float) -> str:
    """The first necessary condition for a nonnegative realisation that fails ('' if none)."""
    n = lams.size
    rho = np.max(np.abs(lams))
    for k in range(1, n + 1):
        s_k = float(np.real(np.sum(lams**k)))
        if s_k < -tol * max(1.0, rho**k) * n:
            what = "trace" if k == 1 else f"power sum s_{k} = trace(R^{k})"
            return f"its {what} is {s_k:.4g} < 0 (the {what} of a nonnegative matrix is >= 0)"
    real_max = max((z.real for z in lams if abs(z.imag) <= tol), default=-np.inf)
    if real_max < rho - tol:
        return (
            f"the spectral radius {rho:.4g} is not an eigenvalue (Perron–Frobenius: a "
            "nonnegative matrix has its spectral radius as an eigenvalue)"
        )
    return ""


def nonnegative_realization(eigs: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """A nonnegative ``R`` with eigenvalues ``eigs`` and a row vector ``e2`` with ``(R, e2)``
    observable (module docstring for the supported spectra). Raises :class:`DesignError`."""
    lams = np.asarray(eigs, dtype=complex).ravel()
    n = lams.size
    scale = max(1.0, float(np.max(np.abs(lams), initial=0.0)))
    tol = tol * scale
    head = f"no nonnegative R with the spectrum {_fmt(lams)}"
    reason = _necessary(lams, tol)
    if reason:
        raise DesignError(f"{head} exists: {reason}")
    reals = np.sort(np.array([z.real for z in lams if abs(z.imag) <= tol]))[::-1]
    pairs = sorted(
        (complex(z.real, abs(z.imag)) for z in lams if z.imag > tol),
        key=lambda z: -(z.real + _SQ3 * z.imag),
    )
    if len(pairs) != sum(1 for z in lams if z.imag < -tol):
        raise DesignError(f"{head}: complex eigenvalues do not come in conjugate pairs")
    if any(abs(a - b) <= tol for a, b in pairwise(pairs)):
        raise DesignError(f"{head} is built by ivobs: repeated complex pairs are not supported")
    leaders = [float(x) for x in reals if x >= -tol]
    negatives = [float(x) for x in reals if x < -tol]
    # Complex pairs: smallest leader that dominates the pair in the circulant triangle.
    blocks: list[np.ndarray] = []
    starts: list[np.ndarray] = []
    for z in pairs:
        need = max(z.real + _SQ3 * z.imag, -2 * z.real)
        fits = [r for r in leaders if r >= need - tol]
        if not fits:
            raise DesignError(
                f"{head} is built by ivobs: the complex pair {z.real:.4g} ± {z.imag:.4g}j needs a "
                f"real eigenvalue ρ >= max(a + √3 b, −2a) = {need:.4g} of its own (3×3 "
                "circulant realisation); choose a gain with real eigenvalues, or pass R="
            )
        r = min(fits)
        leaders.remove(r)
        blocks.append(circulant_block(r, z))
        starts.append(np.array([1.0, 0.0, 0.0]))
    # Negative eigenvalues: Suleimanova groups (copies of one value stay together).
    groups: dict[int, list[float]] = {i: [] for i in range(len(leaders))}
    vals, counts = _merge(negatives, tol)
    order = np.argsort(-np.abs(vals) * counts)
    for idx in order:
        need = abs(vals[idx]) * counts[idx]
        slack = [(leaders[i] - sum(abs(v) for v in groups[i]), i) for i in groups]
        if not slack or max(slack)[0] < need - tol:
            raise DesignError(
                f"{head} is built by ivobs: the negative eigenvalue {vals[idx]:.4g} "
                f"(x{counts[idx]}) does not fit the slack of any nonnegative eigenvalue "
                "(Suleimanova groups need ρ >= Σ|λ_i| in each group); choose a gain with "
                "nonnegative eigenvalues, or pass R="
            )
        groups[max(slack)[1]].extend([float(vals[idx])] * int(counts[idx]))
    for i, r in enumerate(leaders):
        if groups[i]:
            blocks.append(suleimanova_block(r, groups[i]))
            starts.append(np.eye(len(groups[i]) + 1)[0])
    alone = [r for i, r in enumerate(leaders) if not groups[i]]
    lead_vals, lead_counts = _merge(alone, tol)
    for v, c in zip(lead_vals, lead_counts):
        J = np.diag(np.full(int(c), max(float(v), 0.0))) + np.diag(np.ones(int(c) - 1), 1)
        blocks.append(J)
        starts.append(np.eye(int(c))[0])
    R = block_diag(*blocks) if blocks else np.zeros((0, 0))
    R = np.where(np.abs(R) <= 1e-15 * scale, 0.0, R)
    if R.shape != (n, n) or np.any(R < -tol):  # pragma: no cover - construction invariant
        raise DesignError(f"{head}: internal construction failed")
    return np.maximum(R, 0.0), np.concatenate(starts)


def _merge(values: list[float], tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Distinct values (within ``tol``) and their multiplicities."""
    out: list[list[float]] = []
    for v in sorted(values, reverse=True):
        if out and abs(out[-1][0] - v) <= tol:
            out[-1][1] += 1
        else:
            out.append([v, 1])
    return np.array([o[0] for o in out]), np.array([o[1] for o in out], dtype=int)


def similarity_transform(
    M: np.ndarray, R: np.ndarray, e1: np.ndarray, e2: np.ndarray, who: str = "transform"
) -> np.ndarray:
    """``S = O_R⁻¹ O_M`` ([Tang2019, eq. (48)]); raises :class:`DesignError` when a pair is
    not observable ([Tang2019, Lemma 4] / [Efimov2013, Lemma 2] need ``(M, e1)`` and ``(R, e2)``
    observable)."""
    n = M.shape[0]
    O_M = observability_matrix(M, np.reshape(e1, (1, n)))
    O_R = observability_matrix(R, np.reshape(e2, (1, n)))
    for name, O, pair in (("O_R", O_R, "(R, e2)"), ("O_{A−LC}", O_M, "(A − LC, e1)")):
        c = np.linalg.cond(O)
        if not np.isfinite(c) or c > 1e12:
            raise DesignError(
                f"{who}: the pair {pair} is not observable ({name} has condition number "
                f"{c:.3g}); [Tang2019, eq. (48)] needs both pairs observable: choose another "
                f"{'e2' if pair.startswith('(R') else 'e1'} (or A − LC has a repeated "
                "eigenvalue with several eigenvectors: choose another gain)"
            )
    return np.linalg.solve(O_R, O_M)


def place_real_poles(A: np.ndarray, C: np.ndarray, poles: np.ndarray, who: str) -> np.ndarray:
    """``L`` with ``λ(A − LC) = poles`` (SciPy's ``place_poles`` on the dual pair)."""
    from scipy.signal import place_poles

    try:
        res = place_poles(A.T, C.T, np.asarray(poles, dtype=float))
    except (ValueError, np.linalg.LinAlgError) as exc:
        raise DesignError(f"{who}: pole placement at {np.round(poles, 6)} failed: {exc}") from None
    return np.asarray(res.gain_matrix, dtype=float).T


def transformed_width(
    M: np.ndarray, G: np.ndarray, delta: np.ndarray, S: np.ndarray, limit: float = 1.0
) -> np.ndarray:
    """Steady-state width of the bounds of observer (42) for constant bounds:
    ``|S⁻¹| (I − |R|)⁻¹ |S G| Δ`` with ``R = S M S⁻¹`` (``inf`` when ``ρ(|R|) >= limit``: for
    ``limit = 1``, when ``|R|`` is not Schur)."""
    n = M.shape[0]
    Si = np.linalg.inv(S)
    Rabs = np.abs(S @ M @ Si)
    if spectral_radius(Rabs) >= limit:
        return np.full(n, np.inf)
    wz = np.linalg.solve(np.eye(n) - Rabs, np.abs(S @ G) @ delta)
    return np.abs(Si) @ wz


# -- the whole design of observer (42) ------------------------------------------------------------
def _modal_transform(M: np.ndarray) -> np.ndarray | None:
    """``V⁻¹`` with rows of unit norm, eigenvalues in decreasing order (None if not real)."""
    lam, V = np.linalg.eig(M)
    if np.any(np.abs(lam.imag) > 1e-12 * max(1.0, float(np.max(np.abs(lam))))):
        return None
    order = np.argsort(-lam.real, kind="stable")
    V = np.real(V[:, order])
    if np.linalg.cond(V) > 1e12:
        return None
    Vi = np.linalg.inv(V)
    rows: np.ndarray = Vi / np.linalg.norm(Vi, axis=1, keepdims=True)
    return rows


def modal_width(
    A: np.ndarray,
    C: np.ndarray,
    L: np.ndarray,
    G: np.ndarray,
    delta: np.ndarray,
    weights: np.ndarray | None = None,
) -> float:
    """``Σ_i weights_i w_i``, ``w`` the steady-state width of observer (42) with ``R = diag(λ)``,
    ``S = V⁻¹`` (modal coordinates); ``inf`` unless the eigenvalues of ``A − LC`` are real, in
    ``[0, 0.99]`` and ``1e-3`` apart (then ``diag(λ)`` is a nonnegative realisation)."""
    M = A - L @ C
    lam = np.linalg.eigvals(M)
    if np.any(lam.imag != 0) or np.any(lam.real < 0) or np.any(lam.real > 0.99):
        return np.inf
    lam = np.sort(lam.real)
    if lam.size > 1 and np.min(np.diff(lam)) < 1e-3:
        return np.inf
    S = _modal_transform(M)
    if S is None:
        return np.inf
    w = transformed_width(M, G, delta, S)
    if not np.all(np.isfinite(w)):
        return np.inf
    return float(np.sum(w if weights is None else w * weights))


def design_width(
    A: np.ndarray,
    C: np.ndarray,
    L: np.ndarray,
    e1: np.ndarray,
    G: np.ndarray,
    delta: np.ndarray,
    weights: np.ndarray,
) -> float:
    """``Σ_i weights_i w_i`` for the whole default design of observer (42) at ``(L, e1)``:
    ``R`` = :func:`nonnegative_realization` of ``λ(A − LC)`` (with its ``e2``), ``S`` by eq. (48),
    ``w`` = :func:`transformed_width`. ``inf`` where a step fails (spectrum without a supported
    nonnegative realisation, unobservable pair, ``ρ(A − LC) > 0.99``, ``S M S⁻¹`` not >= 0)."""
    M = A - L @ C
    lam = np.linalg.eigvals(M)
    if np.max(np.abs(lam), initial=0.0) > 0.99:
        return np.inf
    try:
        R, e2 = nonnegative_realization(lam)
        S = np.linalg.solve(observability_matrix(R, e2[None]), observability_matrix(M, e1[None]))
        Si = np.linalg.inv(S)
    except (DesignError, np.linalg.LinAlgError):
        return np.inf
    Rs = S @ M @ Si
    if np.any(Rs < -1e-9 * max(1.0, float(np.max(np.abs(Rs))))):
        return np.inf
    w = transformed_width(M, G, delta, S, 0.995)
    return float(w @ weights) if np.all(np.isfinite(w)) else np.inf


def default_design(
    A: np.ndarray,
    C: np.ndarray,
    G_of: Callable[[np.ndarray], np.ndarray],
    delta: np.ndarray,
    who: str,
) -> tuple[np.ndarray, np.ndarray]:
    """Default ``(L, e1)`` of ``interval-transformed`` (a local search for a small steady-state
    width; ``R`` and ``e2`` then come from :func:`nonnegative_realization`).

    1. Four evenly spread sets of distinct poles in ``(0, 1)`` are placed (SciPy
       ``place_poles``); the one with the smallest :func:`modal_width` is kept (``R = diag(λ)``
       is then a nonnegative realisation).
    2. Nelder–Mead over the entries of ``L`` lowers :func:`modal_width` (states weighted by the
       start's widths, so units do not matter; ``100 n p`` evaluations).
    3. Nelder–Mead over ``(L, e1)`` from ``e1 = 1`` minimises :func:`design_width` (``50 (n p +
       n)`` evaluations): the search may leave the positive spectra for any real spectrum
       :func:`nonnegative_realization` supports (e.g. Suleimanova pairs ``{ρ, −μ}``,
       ``ρ >= μ``) and non-diagonal ``R``; it is kept only if it beats step 2. On
       [Efimov2013]'s planar example the steady-state width (sum over the states) drops from
       about 18.6 (step 2) to about 7.

    Without disturbances (``Δ = 0``) the widths of ``G = I`` are used (conditioning only).
    """
    from scipy.optimize import minimize

    n, p = A.shape[0], C.shape[0]
    if not np.any(delta > 0) or G_of(np.zeros((n, p))).size == 0:
        G_of, delta = (lambda L_: np.eye(n)), np.ones(n)
    best_L, best_val = None, np.inf
    last_error = ""
    for a, b in ((0.05, 0.3), (0.2, 0.6), (0.1, 0.9), (0.5, 0.9)):
        poles = np.linspace(a, b, n) if n > 1 else np.array([0.5 * (a + b)])
        try:
            L = place_real_poles(A, C, poles, who)
        except DesignError as exc:
            last_error = str(exc)
            continue
        val = modal_width(A, C, L, G_of(L), delta)
        if val < best_val:
            best_L, best_val = L, val
    if best_L is None:
        why = (
            f"(A, C) is observable; the last attempt said: {last_error}"
            if is_observable(A, C)
            else "(A, C) is not observable"
        )
        raise DesignError(
            f"{who}: could not place distinct real poles in (0, 1) for A − LC: {why}; "
            "pass L= or poles="
        )
    M0 = A - best_L @ C
    S0 = _modal_transform(M0)
    assert S0 is not None
    weights = 1.0 / np.maximum(transformed_width(M0, G_of(best_L), delta, S0), 1e-300)
    opts = {"xatol": 1e-7, "fatol": 1e-7, "adaptive": True}

    def J_modal(x: np.ndarray) -> float:
        L = x.reshape(n, p)
        return modal_width(A, C, L, G_of(L), delta, weights)

    res = minimize(
        J_modal, best_L.ravel(), method="Nelder-Mead", options={"maxfev": 100 * n * p, **opts}
    )
    if np.isfinite(res.fun) and res.fun < J_modal(best_L.ravel()):
        best_L = res.x.reshape(n, p)
    S1 = _modal_transform(A - best_L @ C)
    assert S1 is not None
    e1_modal = S1.sum(axis=0)  # e1ᵀ = e2ᵀ V⁻¹ with e2 = 1 gives S = V⁻¹ for R = diag(λ)

    def J(x: np.ndarray) -> float:
        L = x[: n * p].reshape(n, p)
        return design_width(A, C, L, x[n * p :], G_of(L), delta, weights)

    best_x = np.concatenate([best_L.ravel(), e1_modal])
    best_J = J(best_x)
    res = minimize(
        J,
        np.concatenate([best_L.ravel(), np.ones(n)]),
        method="Nelder-Mead",
        options={"maxfev": 50 * (n * p + n), **opts},
    )
    if np.isfinite(res.fun) and res.fun < best_J:
        best_x = res.x
    return best_x[: n * p].reshape(n, p), best_x[n * p :]


def default_e1(
    M: np.ndarray, R: np.ndarray, e2: np.ndarray, G: np.ndarray, delta: np.ndarray, who: str
) -> np.ndarray:
    """A row ``e1`` for eq. (48): among a few candidates (the one giving ``S = V⁻¹`` for a
    diagonal ``R``, ones, unit vectors) the one with the smallest steady-state width
    (``cond(S)`` when there is no disturbance). For a diagonal ``R`` with distinct eigenvalues
    every observable ``e1`` gives the same boxes (``S`` changes by a diagonal scaling only)."""
    n = M.shape[0]
    cands: list[np.ndarray] = []
    if np.allclose(R, np.diag(np.diag(R))) and np.all(e2 != 0):
        Vi = _modal_transform(M)
        if Vi is not None and np.allclose(np.diag(R), np.sort(np.diag(R))[::-1]):
            cands.append((e2[:, None] * Vi).sum(axis=0))  # then S = O_R⁻¹ O_M = V⁻¹
    cands += [np.ones(n), *np.eye(n)]
    best, best_val = None, np.inf
    for e1 in cands:
        try:
            S = similarity_transform(M, R, e1, e2, who)
        except DesignError:
            continue
        if G.size and np.any(delta > 0):
            val = float(np.sum(transformed_width(M, G, delta, S)))
        else:
            val = float(np.linalg.cond(S))
        if val < best_val * (1 - 1e-9):
            best, best_val = e1, val
    if best is None:
        raise DesignError(
            f"{who}: no candidate e1 makes (A − LC, e1) observable: A − LC has a repeated "
            "eigenvalue with several eigenvectors; choose another gain (or pass S=)"
        )
    return best


def check_transform(
    M: np.ndarray, S: np.ndarray, who: str, R: np.ndarray | None = None, nonnegative: bool = True
) -> np.ndarray:
    """Return ``S M S⁻¹`` after checking that ``S`` is invertible, that it is nonnegative (up to
    round-off, ``1e-9`` relative; not with ``nonnegative=False``: Schur coordinates, where the
    split form needs only the last check) and that its absolute value is Schur. With ``R`` given (a
    user's ``R`` and ``S`` together), also that ``S M S⁻¹ ≈ R`` (``1e-3`` relative: papers print
    four decimals)."""
    cond = np.linalg.cond(S)
    if not np.isfinite(cond) or cond > 1e12:
        raise DesignError(f"{who}: S is singular or nearly so (condition number {cond:.3g})")
    Rs: np.ndarray = S @ M @ np.linalg.inv(S)
    scale = max(1.0, float(np.max(np.abs(Rs))))
    if nonnegative and np.any(Rs < -1e-9 * scale):
        i, j = np.unravel_index(int(np.argmin(Rs)), Rs.shape)
        raise DesignError(
            f"{who}: S (A − LC) S⁻¹ is not nonnegative: entry ({i + 1}, {j + 1}) = "
            f"{Rs[i, j]:.6g} < 0 ([Tang2019, Theorem 5] needs R = S (A − LC) S⁻¹ >= 0)"
        )
    if R is not None and np.max(np.abs(Rs - R)) > 1e-3 * max(1.0, float(np.max(np.abs(R)))):
        raise DesignError(
            f"{who}: S does not transform A − LC into R: max |S (A − LC) S⁻¹ − R| = "
            f"{np.max(np.abs(Rs - R)):.3g}"
        )
    rho = spectral_radius(np.abs(Rs))
    if rho >= 1.0:
        raise DesignError(
            f"{who}: R = S (A − LC) S⁻¹ is not Schur: spectral radius of |R| is {rho:.6g} >= 1"
        )
    return Rs
