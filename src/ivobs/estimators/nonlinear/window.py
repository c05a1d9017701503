"""The window-centred form of :mod:`~ivobs.estimators.nonlinear.interval`: the box of ``x[k]``
as the hull of affine enclosures composed over the last steps, in the coordinates of an
observer, so that boxes do not wrap on maps that rotate or couple their states.

**The form.** For each kept step ``j``, ``ζ_j = (x[j], w[j])`` lies in the corrected box
``B_j``; over it ``f`` and ``h`` have mean-value forms (:func:`affine`, the bounds of
:func:`~ivobs.estimators.nonlinear.meanvalue.linearise`: ``|f(ζ) - g0 - J (ζ - c)| <= ρ`` for
*every* ``ζ ∈ B_j``, so at the true ``ζ_j`` with no mean-value segment to follow). As the true
output is ``y_j = h(ζ_j)`` (``y_j`` within its measurement interval), for *any* matrix ``L_j``

    x[j+1] = f(ζ_j) + L_j (y_j - h(ζ_j))
           ∈ b_j + F_j x[j] + Fw_j (w[j] - cw_j) ± n_j,      F = Jx - L Hx,  Fw = Jw - L Hw  (T)

(:func:`transition`). The current step's measurement gives the filter form
``x[k] = x[k] + K (y_k - h(ζ_k)) ∈ a + G x[k] ± r`` with ``G = I - K Hx`` (:func:`filter_start`,
(S)). Substituting (T) backwards, newest first, ``x[k] ∈ m_j + Φ_j x[j] ± R_j`` with
``Φ_j = G F_{k-1} ⋯ F_j``, ``m_j = a + Σ Φ_{i+1} b_i`` and ``R_j = r + Σ (|Φ_{i+1}| n_i +
|Φ_{i+1} Fw_i| |B_i^w - cw_i|)`` over ``i = j..k-1``, so over the box ``[c_j ± r_j]`` of ``x[j]``

    x[k] ∈ m_j + Φ_j c_j ± (R_j + |Φ_j| r_j)                                              (H)

for every kept ``j`` and for ``j = k`` (``Φ_k = G``): :func:`hull`. The products ``Φ_j`` are
carried as matrices, never as boxes: the form's dependence on the box ``j`` steps back decays
like ``F^(k-j)``, where a box form grows like ``|F|^(k-j)`` (wrapping), and intersecting over
``j`` keeps what each past box knew. This is the centred form [Moore2009, Ch. 6] composed
along the trajectory, in the coordinates of a Luenberger observer of gain ``L``: the interval
observer of [Jaulin2001, Ch. 6] with an output injection. Any gains keep it sound; these are a
Kalman filter's on the same linearisations [Kalman1960], with the squared radii of the boxes as
variances (:func:`filter_gain`, :func:`predictor`): on random stable linear plants the box is
then within 1.07-1.68 times the exact hull (BENCHMARKS.md).

**Rounding (proof).** The model of :mod:`ivobs.sets.rounding` ([Higham2002, Lemma 3.1 and
Section 3.1]): a floating-point expression that is a sum of products, each of whose exact terms
passes through at most ``N`` roundings, differs from the exact one by at most ``γ_N`` times the
same expression on absolute values, in any order of evaluation, plus at most ``η = ETA/2`` per
product that underflows; a bound computed in floating point carries ``2 γ_N`` (which absorbs
its own rounding), and a sum of nonnegative bounds is made an upper bound by
:func:`~ivobs.sets.rounding.upper` with the number of its roundings. The mean-value forms prove
their own bounds (:func:`affine`); the measurement ``y ± r`` covers the reals the double
stands for (:func:`measured`). Then:

(T) ``F`` is the double ``fl(J - fl(L H))``; the exact ``J - L H`` differs from it by at most
``γ (|J| + |L| |H|)``, which acts on ``ζ - c`` (``|ζ - c| <= Δ``, one rounded subtraction,
up). ``b`` is the double ``fl(g0 + L fl(y - fl(h0 + H t)) - F cx)`` with ``t = fl(c - ch)``;
the exact ``g0 + L (y - h0 - H (c - ch)) - F cx`` is within ``γ_N`` (``N = n + ny + 6``) of
``|g0| + |L| (|y| + |h0| + |H| |t|) + |F| |cx|``. So ``n = ρ + |L| (r + ρ_h) + 2 γ_N`` times
those magnitudes, plus ``N η (1 + Σ|L|) (1 + Σ|t|) (1 + ΣΔ)`` for the underflows, rounded up.

(S) Alike: ``G = fl(I - fl(K Hx))`` is within ``γ (I + |K| |Hx|)`` of ``I - K Hx`` and acts on
``|x[k]| <= max(|xlo|, |xhi|)``; ``a = fl(K fl(fl(y - h0) + fl(Hx chx)))`` is within ``γ_N |K|
(|y| + |h0| + |Hx| |chx|)`` of the exact; ``fl(K Hw)`` within ``γ |K| |Hw|``.

(H) ``Φ`` is the double computed at each substitution, ``fl(Φ F)``: the exact ``Φ F`` differs
by at most ``γ_n |Φ| |F|`` and acts on ``|x[j]| <= |c| + Δ`` of the step's linearisation box
(which holds every later box of ``x[j]``); the products ``fl(Φ b)``, ``fl(Φ Fw)`` and the centre
``fl(Φ fl(F c_j))`` (for ``Φ_j c_j``) err alike. All of these are at most ``4 γ_{n+2} fl(|Φ|
e)`` with ``e = |b| + 4 |F| (|c| + Δ) + |Fw| Δw + 1e-300`` (``fl(|Φ| e)`` is within ``γ_n`` of
the exact product of nonnegative numbers; the last term covers the underflow of ``fl(F c_j)``
times ``|Φ|``); the other underflows add ``(n + 2) η`` per product times the magnitudes they act
on (``eta``). The running sums add ``2u|s| + ETA`` per rounded addition of a result ``s``.
The hull of (H) is ``[down(m - ρ), up(m + ρ)]`` with ``ρ`` all these terms rounded up: it
contains the exact hull of the exact enclosures at every magnitude, and so the true ``x[k]``.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

from ...linalg import UNIT_ROUNDOFF, gamma
from ...sets.rounding import ETA, down, mid_rad, up, upper
from .meanvalue import Linearisation

__all__ = [
    "Gains",
    "Measured",
    "Rows",
    "Start",
    "Transition",
    "affine",
    "centred",
    "filter_gain",
    "filter_start",
    "hull",
    "measured",
    "predictor",
    "radius",
    "transition",
]

_TWO_U = 2.0 * UNIT_ROUNDOFF


def _err(s: np.ndarray) -> np.ndarray:
    """A bound of ``|exact - s|`` for ``s``, one rounded addition or subtraction."""
    out: np.ndarray = _TWO_U * np.abs(s) + ETA
    return out


def _g(n: int) -> float:
    """``2 γ_n``: the relative error of an expression whose every term passes through at most
    ``n`` roundings, doubled to absorb the rounding of the bound's own evaluation."""
    return 2.0 * gamma(n)


def radius(lo: np.ndarray, hi: np.ndarray, c: np.ndarray) -> np.ndarray:
    """``Δ >= |ζ - c|`` for every ``ζ`` of ``[lo, hi]`` (one rounded subtraction, up)."""
    return up(np.maximum(hi - c, c - lo))  # type: ignore[no-any-return]


class Measured(NamedTuple):
    """The measurement of a step as ``y ± r`` (the recorded doubles; 0 where missing) and the
    components present."""

    y: np.ndarray
    r: np.ndarray
    seen: np.ndarray


def measured(y: np.ndarray, ylo: list[float], yhi: list[float]) -> Measured:
    """``y ± r`` covering the measurement interval ``[ylo, yhi]`` of each present
    component (the two neighbouring doubles: each difference is exact, and rounded up)."""
    seen = ~np.isnan(y)
    ym = np.where(seen, y, 0.0)
    r = np.where(seen, up(np.maximum(np.array(yhi) - ym, ym - np.array(ylo))), 0.0)
    return Measured(ym, r, seen)


def affine(
    evals: tuple[Any, ...], lo: np.ndarray, hi: np.ndarray, u: np.ndarray, nx: int
) -> Linearisation:
    """The mean-value form (MV) of :mod:`~ivobs.estimators.nonlinear.meanvalue` over the finite
    box ``[lo, hi]`` at its centre, as :func:`~ivobs.estimators.nonlinear.meanvalue.linearise`
    with ``natural=False`` (the same bounds, the same proof of their rounding) but on arrays,
    for the larger joint vectors of this form: ``g0 = gl``, ``J̃ = mid [J]``,
    ``ρ = upper(up(gh - gl) + D Δ, n + 1)``; a row whose bounds are not finite takes the
    natural inclusion (``J̃_i = 0``); a set-valued map widens ``ρ`` and the natural inclusion
    by its spread. Floating-point exceptions are the caller's to silence (an infinite bound is
    expected here)."""
    value, natjac = evals[0], evals[1]
    c = np.minimum(np.maximum(0.5 * lo + 0.5 * hi, lo), hi)
    cl, bl, bh, ul = c.tolist(), lo.tolist(), hi.tolist(), u.tolist()
    gl, gh = value(cl[:nx], cl[:nx], ul, cl[nx:], cl[nx:])  # g(c), outward rounded
    nl, nh, jl, jh = natjac(bl[:nx], bh[:nx], ul, bl[nx:], bh[nx:])  # g(B) and [J] over B
    n = len(cl)
    m = len(gl)
    g0, ghi, nat_lo, nat_hi = np.array((gl, gh, nl, nh), dtype=float).reshape(4, m)
    Jl, Jh = np.array((jl, jh), dtype=float).reshape(2, m, n)
    J = 0.5 * Jl + 0.5 * Jh  # J̃ = mid [J] (halves: no overflow)
    D = up(np.maximum(Jh - J, J - Jl))
    rho = upper(up(ghi - g0) + D @ radius(lo, hi, c), n + 1)
    edges = ~np.isfinite(rho + g0 + J.sum(axis=1))
    if edges.any():  # a domain edge: the natural inclusion
        J[edges] = 0.0
        g0[edges], rho[edges] = mid_rad(nat_lo[edges], nat_hi[edges])
    if len(evals) > 2:  # a set-valued map: widened by its spread over the box
        spread = np.array(evals[2](bl[:nx], bh[:nx], ul, bl[nx:], bh[nx:]), dtype=float)
        if spread.size:
            rho = up(rho + spread)
            nat_lo, nat_hi = down(nat_lo - spread), up(nat_hi + spread)
    return Linearisation(g0, J, rho, c, nat_lo, nat_hi)


def centred(lin: Linearisation, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The natural inclusion met with the centred form ``g0 + J̃ ([lo, hi] - c) ± ρ`` of the
    mean-value form ``lin`` over the box ``[lo, hi]`` it was made on [Moore2009, Ch. 6], with
    ``delta = radius(lo, hi, lin.c)``: ``|J̃ (ζ - c)| <= |J̃| Δ``, the sum ``|J̃| Δ + ρ``
    rounded up (``n + 2`` roundings on a path) and the two bounds outward (an infinite bound
    gives NaN, which fmax/fmin ignore)."""
    s = upper(np.abs(lin.J) @ delta + lin.rho, lin.c.shape[0] + 2)
    return np.fmax(lin.nat_lo, down(lin.g0 - s)), np.fmin(lin.nat_hi, up(lin.g0 + s))


class Transition(NamedTuple):
    """``x[j+1] ∈ b + F x[j] + Fw (w[j] - cw) ± n`` for the true ``(x[j], w[j])``, with
    ``|w[j] - cw| <= dw``; ``e`` bounds the magnitudes whose products are rounded in the
    backward substitution, ``eta`` their underflow."""

    b: np.ndarray
    F: np.ndarray
    Fw: np.ndarray
    n: np.ndarray
    e: np.ndarray
    dw: np.ndarray
    eta: Any


def transition(
    lf: Linearisation,
    lh: Linearisation | None,
    L: np.ndarray,
    delta: np.ndarray,
    meas: Measured,
    nx: int,
) -> Transition:
    """The transition of the step whose joint box ``[lo, hi]`` has the radius ``delta =
    radius(lo, hi, lf.c)``: ``f`` linearised over it as ``lf``, ``h`` over a box containing it
    as ``lh`` (None, or ``L`` zero: no output injection); ``L`` has zero columns where the
    measurement is missing or not used. Rounding: module docstring, (T)."""
    c = lf.c
    n = c.shape[0]
    J, cx = lf.J, c[:nx]
    absJ = np.abs(J)
    ny = L.shape[1]
    N = n + ny + 6
    if lh is None or not L.any():
        F = J
        b = lf.g0 - J[:, :nx] @ cx
        noise = lf.rho + _g(N) * (np.abs(lf.g0) + absJ[:, :nx] @ np.abs(cx))
        under = N * ETA
    else:
        H = lh.J
        t = c - lh.c  # h(ζ) ∈ h0 + H (c - ch) + H (ζ - c) ± ρh
        F = J - L @ H
        z = meas.y - (lh.g0 + H @ t)
        b = (lf.g0 + L @ z) - F[:, :nx] @ cx
        absL = np.abs(L)
        abst = np.abs(t)
        inner = np.abs(meas.y) + np.abs(lh.g0) + np.abs(H) @ (abst + delta)
        noise = (
            lf.rho
            + absL @ (meas.r + lh.rho + _g(N) * inner)
            + _g(N) * (np.abs(lf.g0) + np.abs(F[:, :nx]) @ np.abs(cx) + absJ @ delta)
        )
        under = N * ETA * (1.0 + float(absL.sum())) * (1.0 + float(abst.sum()))
    under *= 1.0 + float(delta.sum())
    noise = upper(noise + under, n + ny + 16)
    Fx, Fw = F[:, :nx], F[:, nx:]
    dx, dw = delta[:nx], delta[nx:]
    v = np.abs(cx) + dx  # >= |x[j]|
    e = np.abs(b) + 4.0 * (np.abs(Fx) @ v) + np.abs(Fw) @ dw + 1e-300  # (1e-300: underflow)
    eta = (nx + 2) * ETA * (3.0 + 4.0 * float(v.sum()) + float(dw.sum())) * 2.0
    return Transition(b, Fx.copy(), Fw.copy(), noise, e, dw, eta)


class Start(NamedTuple):
    """The filter form of the current step: ``x[k] ∈ m + Φ x[k] ± R`` (``Φ`` a double)."""

    phi: np.ndarray
    m: np.ndarray
    R: np.ndarray
    eta: float


def filter_start(
    lh: Linearisation | None,
    K: np.ndarray,
    dw: np.ndarray | None,
    xlo: np.ndarray,
    xhi: np.ndarray,
    meas: Measured,
    nx: int,
) -> Start:
    """``x[k] = x[k] + K (y_k - h(ζ_k))`` as ``m + Φ x[k] ± R``: ``h`` linearised as ``lh`` over
    a joint box whose ``w`` part has the radius ``dw`` about ``lh.c`` (:func:`radius`),
    ``[xlo, xhi]`` the current box of ``x[k]`` (inside it); ``Φ = I`` and ``m = R = 0``
    without a measurement. Rounding: module docstring, (S)."""
    if lh is None or dw is None or not K.any():
        return Start(np.eye(nx), np.zeros(nx), np.zeros(nx), 0.0)
    ch = lh.c
    n, ny = ch.shape[0], K.shape[1]
    H = lh.J
    Hx, chx = H[:, :nx], ch[:nx]
    a = K @ ((meas.y - lh.g0) + Hx @ chx)
    KH = K @ H
    G = np.eye(nx) - KH[:, :nx]
    v = np.maximum(np.abs(xlo), np.abs(xhi))  # >= |x[k]|
    N = n + ny + 4
    mag = np.concatenate([np.abs(chx) + v, dw])  # (|ch| + v, Δw): what |H| acts on
    inner = np.abs(meas.y) + np.abs(lh.g0) + np.abs(H) @ mag
    absK = np.abs(K)
    R = absK @ (meas.r + lh.rho + _g(N) * inner) + _g(N) * v + np.abs(KH[:, nx:]) @ dw
    under = N * ETA * (1.0 + float(absK.sum())) * (1.0 + float(mag.sum()))
    return Start(G, a, upper(R + under, N + 12), 0.0)


class Rows(NamedTuple):
    """The kept steps, oldest first: the boxes ``[lo, hi]`` of ``x[j]`` and the transitions
    ``j -> j + 1`` (a :class:`Transition` whose fields are stacked along a first axis over the
    steps, ``eta`` an array)."""

    lo: np.ndarray
    hi: np.ndarray
    steps: Transition

    def empty(self) -> Rows:
        """No kept step (the same shapes otherwise)."""
        return Rows(self.lo[:0], self.hi[:0], Transition(*(a[:0] for a in self.steps)))


def hull(start: Start, xlo: np.ndarray, xhi: np.ndarray, rows: Rows) -> tuple[np.ndarray, ...]:
    """``(lo, hi)``, one row per box (the current box ``[xlo, xhi]`` first, then the kept boxes
    newest first): the hulls of the module docstring, each outward rounded (NaN or infinite
    where a bound is not finite). Rounding: module docstring, (H). The products ``Φ`` are
    formed one after the other; all the rest is done on the stack of them, the products of
    ``|Φ|`` in one batch."""
    nx = len(xlo)
    M = rows.lo.shape[0]
    steps = rows.steps
    nw = steps.dw.shape[1]
    F = steps.F[::-1]  # newest first
    phis = np.empty((M + 1, nx, nx))  # Φ after substituting each kept step, newest first
    phis[0] = start.phi
    for i in range(M):
        np.matmul(phis[i], F[i], out=phis[i + 1])
    lo = np.concatenate([xlo[None], rows.lo[::-1]])
    hi = np.concatenate([xhi[None], rows.hi[::-1]])
    c = 0.5 * lo + 0.5 * hi
    g = 4.0 * gamma(nx + 2)
    # |Φ_i| times: n and e of the step substituted next, the radius of box i, |c_0| (row 0)
    Y = np.zeros((M + 1, nx, 4))
    Y[:M, :, 0] = steps.n[::-1]
    Y[:M, :, 1] = steps.e[::-1]
    Y[:, :, 2] = radius(lo, hi, c)
    Y[0, :, 3] = np.abs(c[0])
    Z = np.abs(phis) @ Y
    centres = np.empty((M + 1, nx))
    radii = np.empty((M + 1, nx))
    centres[0] = start.m + phis[0] @ c[0]
    radii[0] = start.R + Z[0, :, 2] + g * Z[0, :, 3]
    if M:
        cols = np.empty((M, nx, 2 + nw))  # b, F c, Fw of each kept step, newest first
        cols[:, :, 0] = steps.b[::-1]
        cols[:, :, 1] = (F @ c[1:, :, None])[:, :, 0]
        cols[:, :, 2:] = steps.Fw[::-1]
        P = phis[:-1] @ cols  # Φ b, Φ F c, Φ Fw before each substitution
        cs = np.cumsum(P[:, :, 0], axis=0)  # in order: each partial sum one rounding
        wsum = (np.abs(P[:, :, 2:]) @ steps.dw[::-1, :, None])[:, :, 0]
        R = start.R + np.cumsum(Z[:-1, :, 0] + g * Z[:-1, :, 1] + wsum + _err(cs), axis=0)
        m = start.m + cs
        centres[1:] = m + P[:, :, 1]
        radii[1:] = R + Z[1:, :, 2] + _err(m)
    eta = start.eta + float(np.sum(steps.eta)) + (M + 1) * (nx + 2) * ETA
    rad = upper(radii + _err(centres) + eta, 8 * (M + 2) + 2 * (nx + nw) + 8)
    return down(centres - rad), up(centres + rad)


class Gains(NamedTuple):
    """The filter gain ``K`` of a step and what its transition's gain reuses: the output
    components used, their ``Hx``, ``Hw``, ``P Hxᵀ``, covariance ``S`` and its inverse, and
    the variances of ``w``."""

    K: np.ndarray
    seen: np.ndarray
    Hx: np.ndarray
    Hw: np.ndarray
    PHt: np.ndarray
    S: np.ndarray
    Si: np.ndarray
    sw: np.ndarray


def filter_gain(
    P: np.ndarray, lh: Linearisation, seen: np.ndarray, dw: np.ndarray, nx: int
) -> Gains:
    """The gain of a Kalman filter on ``h`` linearised as ``lh`` (components ``seen``) with the
    prior ``P`` and the squares of the radii as variances (``dw`` of ``w``, ``ρ_h`` of the
    remainders): any gain keeps the form sound, this one makes it tight. Zero where ``S`` is
    singular or not finite (floating-point exceptions are the caller's to silence)."""
    K = np.zeros((nx, lh.J.shape[0]))
    H = lh.J[seen]
    Hx, Hw = H[:, :nx], H[:, nx:]
    sw = dw * dw
    PHt = P @ Hx.T
    S = Hx @ PHt + (Hw * sw) @ Hw.T + np.diag(lh.rho[seen] ** 2)
    if S.shape[0] == 1:
        Si = 1.0 / S if S[0, 0] > 0.0 else np.full_like(S, np.nan)
    else:
        try:
            Si = np.linalg.inv(S)
        except np.linalg.LinAlgError:
            Si = np.full_like(S, np.nan)
    Ks = PHt @ Si
    if np.isfinite(Ks).all():
        K[:, seen] = Ks
    return Gains(K, seen, Hx, Hw, PHt, S, Si, sw)


def predictor(
    P: np.ndarray, g: Gains | None, J: np.ndarray, rho: np.ndarray, dw: np.ndarray, nx: int, ny: int
) -> tuple[np.ndarray, np.ndarray]:
    """``(L, P+)``: the gain of the transition (the predictor form of the same Kalman filter,
    ``w`` shared by ``f`` and ``h``) and the next prior covariance, from ``f`` linearised as
    ``J``, ``ρ`` over a box whose ``w`` part has the radii ``dw``; ``L`` zero without a
    measurement. ``P+`` not finite when the recursion is not (floating-point exceptions are
    the caller's to silence)."""
    Jx, Jw = J[:, :nx], J[:, nx:]
    L = np.zeros((nx, ny))
    sw = dw * dw
    Pn = Jx @ P @ Jx.T + (Jw * sw) @ Jw.T + np.diag(rho * rho)
    if g is not None and g.K.any():
        Ls = (Jx @ g.PHt + (Jw * g.sw) @ g.Hw.T) @ g.Si
        if np.isfinite(Ls).all():
            L[:, g.seen] = Ls
            Pn = Pn - Ls @ g.S @ Ls.T
    Pn = 0.5 * Pn + 0.5 * Pn.T
    return L, Pn
