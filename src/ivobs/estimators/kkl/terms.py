"""The matrices of one step of the discrete-time KKL observer for one pattern of observed
outputs, with the proven bound of every floating-point error the step makes
([Higham2002, Lemma 3.1]; :mod:`ivobs.sets.rounding`).

**The identity the step rests on.** With ``T`` the transformation at ``k`` and ``T'`` the one at
``k + 1`` (time-invariant: ``T' = T``), ``o`` the observed outputs and ``m`` the missing ones,
for every trajectory of the model ``x+ = A x + B u + E d``, ``y = C x + D u + F d``::

    T' x+ = A_z (T x) + B_o y_o + L_o u + G_o d + X_o x                              (eq. 5)

    L_o = T' B - B_o D_o,   G_o = T' E - B_o F_o,   X_o = T' A - A_z T - B_o C_o

exactly, in real arithmetic, whatever ``T`` and ``T'`` are. For the paper's ``T`` (eq. (4):
``T A = A_z T + B_z C``; eq. (15.b): ``T' A = A_z T + B_z C``) ``X_o = B_m C_m``: the missing
outputs, bounded on the box of ``x`` ([Dinh2024, Lemma 1]); with every output observed it is
the residual of (4), zero in exact arithmetic. ivobs uses the float ``T`` of the design as the
*exact* transformation of the observer (time-invariant): ``X`` is then the tiny residual of the
float solution, bounded on the box of ``x`` like a missing output. The time-varying sequence
(15.b) is instead the exact real sequence, of which the float ``T̂[k]`` is within ``τ[k]``
(:class:`~.design.TransformSequence`): there ``X_o = B_m C_m`` and ``τ`` enters ``L_o`` and
``G_o``.

**Coefficients.** ``L_o``, ``G_o``, ``X_o`` are computed once (per pattern, time-invariant) in
floats: ``fl(Σ P_i Q_i)`` differs from the exact sum by at most ``γ_n Σ |P_i| |Q_i|`` (``n`` the
number of products in an entry): :func:`combination` keeps that bound with the matrix.

**The step** (:meth:`Terms.advance`) evaluates ``z̲+ = A_z z̲ + B_o y_o + L̂ u + g̲`` and ``z̄+``
(``g̲, ḡ``: the proven Lemma-1 image of ``Ĝ`` on the bounds of ``d``, widened by ``|G - Ĝ| |d|``)
as one sum of at most ``n = n_z + n_o + n_u + 2`` terms per entry: in any order of evaluation
its error is at most ``γ_n`` times the sum of the magnitudes of the terms (``A_z |z|``,
``|B_o| |y_o|``, ``|L̂| |u|``, ``|g|``) plus ``n`` underflows. To that ``ε`` adds ``|L - L̂| |u|``
and ``|X| |x|`` on the box of ``x`` (missing outputs: the image ``X̂ [x̲, x̄]`` is one more term
of the sum and only ``|X - X̂| |x|`` is added). ``ε`` is itself one product ``K [|z|; |y_o|;
|u|; |x|; 1]`` whose coefficients carry a factor ``2 γ_{n+2} (1 + 2 γ_{m+3})``: the 2 covers the
rounding of the magnitudes, the second factor that of ``ε``'s own evaluation (``m`` terms). The
bounds are then rounded outward by one ulp: the exact ``T' x+`` lies in ``[z̲+, z̄+]``, which
never crosses.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import inf, nextafter

import numpy as np

from ...sets import image_bounds
from ...sets.rounding import ETA, down, gamma, product_error, up, upper

__all__ = ["Consistency", "Terms", "combination", "consistency", "factor", "make_terms"]

_ONE = np.ones(1)


def combination(*pairs: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``M̂ = fl(Σ_i P_i Q_i)`` and ``e >= |M - M̂|`` (``M`` the exact sum, every ``P_i``,
    ``Q_i`` a float matrix): the product bound of [Higham2002, Lemma 3.1] over the ``n = Σ``
    inner dimensions of the terms (:func:`~ivobs.sets.rounding.product_error`)."""
    M = np.asarray(sum(P @ Q for P, Q in pairs), dtype=float)
    n = sum(P.shape[1] for P, _ in pairs)
    if n == 0:  # an empty sum: exactly zero
        return M, np.zeros_like(M)
    s = sum(np.abs(P) @ np.abs(Q) for P, Q in pairs)
    return M, product_error(np.asarray(s, dtype=float), n)


def factor(n: int, m: int) -> float:
    """``2 γ_{n+2} (1 + 2 γ_{m+3})``, rounded up: the factor of the magnitudes of a sum of ``n``
    products (any order of evaluation) in a bound evaluated as a sum of ``m`` products."""
    return float(up(2.0 * gamma(n + 2) * (1.0 + 2.0 * gamma(m + 3))))


def g_image(
    G: np.ndarray, Gerr: np.ndarray, dlo: np.ndarray, dhi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of ``G d`` (exact ``G``, within ``Gerr`` of the float ``Ĝ``) for ``d ∈ [d̲, d̄]``:
    the proven Lemma-1 image of ``Ĝ`` widened by ``Gerr |d|``."""
    glo, ghi = image_bounds(G, dlo, dhi)
    if G.shape[1] == 0:
        return glo, ghi
    e = upper(np.maximum(np.abs(dlo), np.abs(dhi)) @ Gerr.T, G.shape[1])
    return down(glo - e), up(ghi + e)


@dataclass(frozen=True)
class Consistency:
    """The consistency test of the observed outputs ``y_o = C_o x + D_o u + F_o d``.

    ``M [x̲; x̄; u; |x|; |u|; 1]`` gives the Lemma-1 bounds ``C_o⁺ x̲ - C_o⁻ x̄ + D_o u + f̲`` and
    ``C_o⁺ x̄ - C_o⁻ x̲ + D_o u + f̄`` (``f``: the bounds of ``F_o d``, a constant column for
    constant bounds of ``d``) and their error bound ``c (|C_o| |x| + |D_o| |u| + |f|)``
    (``c = 2 γ_{n+2} (1 + 2 γ_{m+3})``, ``n = 2 n_x + n_u + 1``): an admissible sample lies
    between the bounds less/plus the error; a sample outside them, rounded outward, certainly
    contradicts the model. Time-varying bounds of ``d``: ``f`` is computed per step."""

    M: np.ndarray
    C: np.ndarray
    D: np.ndarray
    F: np.ndarray
    const: bool
    c: float
    eta: float

    def contradicts(
        self,
        y_o: np.ndarray,
        u: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        xabs: np.ndarray,
        uabs: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
        slack: np.ndarray | None = None,
    ) -> bool:
        """Whether ``y_o`` is certainly outside ``C_o [x̲, x̄] + D_o u + F_o [d̲, d̄]`` (an
        admissible sample, also one within rounding of the set's boundary, never is);
        ``slack``: the exact output is known to lie within ``y_o ± slack``."""
        no = y_o.shape[0]
        if self.const:
            r = self.M.dot(np.concatenate((lo, hi, u, xabs, uabs, _ONE)))
        else:
            r = self.M.dot(np.concatenate((lo, hi, u, xabs, uabs)))
            flo, fhi = image_bounds(self.F, dlo, dhi)
            r[:no] += flo
            r[no : 2 * no] += fhi
            r[2 * no :] += self.c * np.maximum(np.abs(flo), np.abs(fhi)) + self.eta
        # each bound less/plus its error (and the slack), rounded outward: a few outputs, in
        # Python floats (the same IEEE operations as on arrays, a fraction of their cost)
        rl, yl = r.tolist(), y_o.tolist()
        sl = None if slack is None else slack.tolist()
        for i in range(no):
            err = rl[2 * no + i]
            below, above = rl[i] - err, rl[no + i] + err
            if sl is not None:
                below, above = nextafter(below - sl[i], -inf), nextafter(above + sl[i], inf)
            if yl[i] < nextafter(below, -inf) or yl[i] > nextafter(above, inf):
                return True
        return False


def consistency(
    C: np.ndarray, D: np.ndarray, F: np.ndarray, d: tuple[np.ndarray, np.ndarray] | None
) -> Consistency:
    """:class:`Consistency` of the observed rows ``C_o, D_o, F_o`` (``d``: constant bounds of
    ``d``, or None)."""
    no, nx = C.shape
    nu = D.shape[1]
    Cp, Cn = np.maximum(C, 0.0), np.maximum(-C, 0.0)
    c = factor(2 * nx + nu + 1, nx + nu + 1)
    eta = (2 * (nx + nu) + 8) * ETA
    M = np.zeros((3 * no, 3 * nx + 2 * nu + (d is not None)))
    M[:no, :nx], M[:no, nx : 2 * nx], M[:no, 2 * nx : 2 * nx + nu] = Cp, -Cn, D
    M[no : 2 * no, :nx], M[no : 2 * no, nx : 2 * nx], M[no : 2 * no, 2 * nx : 2 * nx + nu] = (
        -Cn,
        Cp,
        D,
    )
    M[2 * no :, 2 * nx + nu : 3 * nx + nu] = up(c * np.abs(C))
    M[2 * no :, 3 * nx + nu : 3 * nx + 2 * nu] = up(c * np.abs(D))
    if d is not None:
        flo, fhi = image_bounds(F, *d)
        fcol = np.concatenate((flo, fhi, up(c * np.maximum(np.abs(flo), np.abs(fhi)) + eta)))
        M[:, -1] = fcol
    return Consistency(M=M, C=C, D=D, F=F, const=d is not None, c=c, eta=eta)


@dataclass(frozen=True)
class Terms:
    """One pattern ``obs`` of observed outputs at one step (module docstring).

    ``M [z̲; z̄; y_o; u; |z|; |y_o|; |u|; |x|; 1]`` gives ``[z̲+; z̄+]`` before the error and the
    error bound ``ε`` (the ``|x|`` column only when ``X`` is not zero; the constant column only
    for constant bounds of ``d``, which carries ``g`` and its part of ``ε``). Missing outputs
    (``x_sym`` False): ``X̂ [x̲, x̄]`` is added at the step, its magnitude times ``c`` to ``ε``.
    ``G``, ``Gerr``: for bounds of ``d`` that vary; ``L``, ``Lerr``, ``xmag`` (``>= |X|`` or
    ``|X - X̂|``): for the vectorised run. ``check``: the consistency test of ``y_o``.
    """

    obs: np.ndarray
    full: bool
    nz: int
    M: np.ndarray
    const: bool
    x_sym: bool
    x_used: bool
    X: np.ndarray
    xmag: np.ndarray
    L: np.ndarray
    Lerr: np.ndarray
    G: np.ndarray
    Gerr: np.ndarray
    c: float
    eta: float
    check: Consistency
    outward: np.ndarray

    def advance(
        self,
        zlo: np.ndarray,
        zhi: np.ndarray,
        zabs: np.ndarray,
        y_o: np.ndarray,
        u: np.ndarray,
        uabs: np.ndarray,
        lo: np.ndarray,
        hi: np.ndarray,
        xabs: np.ndarray,
        dlo: np.ndarray,
        dhi: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """``[z̲+, z̄+]`` of (3.a)/(15.a) with the observed outputs (module docstring);
        ``zabs = max(|z̲|, |z̄|)``, ``xabs`` likewise for the box ``[x̲, x̄]`` of ``x``."""
        nz = self.nz
        parts = [zlo, zhi, y_o, u, zabs, np.abs(y_o), uabs]
        if self.x_used:
            parts.append(xabs)
        if self.const:
            parts.append(_ONE)
        r = self.M.dot(np.concatenate(parts))
        out, eps = r[: 2 * nz], r[2 * nz :]
        if not self.const:  # bounds of d that vary: G [d̲, d̄] at this step
            glo, ghi = g_image(self.G, self.Gerr, dlo, dhi)
            out[:nz] += glo
            out[nz:] += ghi
            eps += self.c * np.maximum(np.abs(glo), np.abs(ghi)) + self.eta
        if not self.x_sym and self.x_used:  # missing outputs: X̂ [x̲, x̄] is one more term
            rlo, rhi = image_bounds(self.X, lo, hi)
            out[:nz] += rlo
            out[nz:] += rhi
            eps += self.c * np.maximum(np.abs(rlo), np.abs(rhi))
        out[:nz] -= eps
        out[nz:] += eps
        np.nextafter(out, self.outward, out=out)
        return out[:nz], out[nz:]


def make_terms(
    obs: np.ndarray,
    A_z: np.ndarray,
    B_z: np.ndarray,
    L: tuple[np.ndarray, np.ndarray],
    G: tuple[np.ndarray, np.ndarray],
    X: tuple[np.ndarray, np.ndarray],
    CDF: tuple[np.ndarray, np.ndarray, np.ndarray],
    d: tuple[np.ndarray, np.ndarray] | None,
    through: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    check: Consistency | None = None,
) -> Terms:
    """:class:`Terms` of the pattern ``obs`` from ``(L̂, |L - L̂|)``, ``(Ĝ, |G - Ĝ|)``,
    ``(X̂, |X - X̂|)`` (:func:`combination`, plus ``τ`` terms for a time-varying ``T``) and
    the rows of ``(C, D, F)``; ``d``: constant bounds of ``d`` (or None); ``check``: the
    consistency test of these rows, if already built.

    ``through = (P, |I - P T| row sums, ...)``: the missing outputs bounded through ``z``
    instead of the box: ``X x = X P z + X (I - P T) x``, so ``z+`` has the matrix ``Q = A_z +
    X P`` (mixed signs: its Lemma-1 image, [Dinh2024, Lemma 1]) and ``|X| |I - P T| |x|`` is
    added to ``ε`` with the error of ``Q̂``."""
    nz = A_z.shape[0]
    full = bool(np.all(obs))
    Bo = B_z[:, obs]
    Lh, Le = L
    Xh, Xe = X
    Gh, Ge = G
    nu, no, nx = Lh.shape[1], Bo.shape[1], Xh.shape[1]
    x_sym = full  # every output observed: X is a residual, bounded by |X| |x|
    x_used = bool(np.any(Xh) or np.any(Xe))
    n = nz + no + nu + 3  # terms of each entry of (3.a): A_z z, B_o y_o, L̂ u, g, X̂ x
    m = nz + no + nu + nx + 2  # terms of each entry of ε
    c = factor(n, m)
    eta = (n + m + 8) * ETA
    if through is None:
        Zp, Zn, z_mag = A_z, np.zeros((nz, nz)), up(c * A_z)
        x_mag = up(np.abs(Xh) + Xe) if x_sym else Xe
    else:
        P, resid, _ = through
        Q, eQ = combination((A_z, np.eye(nz)), (Xh, P))
        eQ = up(eQ + upper(Xe @ np.abs(P), nz))
        Zp, Zn, z_mag = np.maximum(Q, 0.0), np.maximum(-Q, 0.0), up(c * np.abs(Q) + eQ)
        x_sym = True  # X (I - P T) x: a residual, bounded by |X| r ‖x‖∞ <= (|X| r) 1ᵀ |x|
        x_mag = np.repeat(upper((np.abs(Xh) + Xe) @ resid, nx + 1)[:, None], nx, axis=1)
        x_used = bool(np.any(x_mag))
    # columns [z̲, z̄, y_o, u | |z|, |y_o|, |u|, |x| | 1]
    w = 2 * nz + no + nu
    M = np.zeros((3 * nz, w + nz + no + nu + (nx if x_used else 0) + (d is not None)))
    for rows, first, second in ((slice(0, nz), Zp, -Zn), (slice(nz, 2 * nz), -Zn, Zp)):
        M[rows, :nz], M[rows, nz : 2 * nz] = first, second
        M[rows, 2 * nz : 2 * nz + no], M[rows, 2 * nz + no : w] = Bo, Lh
    K = M[2 * nz :]
    K[:, w : w + nz] = z_mag
    K[:, w + nz : w + nz + no] = up(c * np.abs(Bo))
    K[:, w + nz + no : w + nz + no + nu] = up(c * np.abs(Lh) + Le)
    if x_used:
        K[:, w + nz + no + nu : w + nz + no + nu + nx] = up(x_mag * (1.0 + 2.0 * gamma(m + 3)))
    if d is not None:  # constant bounds of d: g = G d and its part of ε in one column
        glo, ghi = g_image(Gh, Ge, *d)
        M[:, -1] = np.concatenate((glo, ghi, up(c * np.maximum(np.abs(glo), np.abs(ghi)) + eta)))
    if check is None:
        C, D, F = (A[obs] for A in CDF)
        check = consistency(C, D, F, d)
    return Terms(
        obs=obs,
        full=full,
        nz=nz,
        M=M,
        const=d is not None,
        x_sym=x_sym,
        x_used=x_used,
        X=Xh,
        xmag=x_mag,
        L=Lh,
        Lerr=Le,
        G=Gh,
        Gerr=Ge,
        c=c,
        eta=eta,
        check=check,
        outward=np.repeat([-np.inf, np.inf], nz),  # the directions of [lower; upper]
    )
