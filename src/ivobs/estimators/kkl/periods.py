"""The matrices of one sampling period of the continuous-time time-invariant KKL observer
(:mod:`.sampled`), enclosed once per period: data-free, so design rather than recursion.

A period is kept for an interval of lengths ``H = [h (1 − 1e-11), h (1 + 1e-11)]`` around a
rounded ``h`` (:func:`period_key`), so that a grid such as ``np.arange(0, 10, 0.01)``, whose
steps differ by rounding, uses one set of matrices: every enclosure holds for every length in
``H``, and the exact length of each interval is checked to lie in it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model import LinearSystem
from ...sets.expm import IntervalMatrix, expm, interval_product, scaled
from ...sets.rounding import down, product_error, up, upper
from .design import Transform, left_inverse
from .flow import Passage, Scalar, lti_kernel, pieces_for, target_exponential

__all__ = ["Anchor", "lti_passage", "make_anchor", "period_key"]

SPREAD = 1e-11
"""Relative spread of the lengths a kept period covers."""


def period_key(h: float) -> tuple[float, Scalar]:
    """The key of the period of length ``h`` (``h`` rounded to 12 digits) and the interval of
    lengths its matrices cover."""
    key = round(float(h), 12)
    return key, (float(down(key * (1.0 - SPREAD))), float(up(key * (1.0 + SPREAD))))


def lti_passage(sys: LinearSystem, A_z: np.ndarray, H: Scalar, callable_input: bool) -> Passage:
    """:class:`~.flow.Passage` of a time-invariant system for every length in ``H``:
    ``e^{A h}``, ``G0 = ∫_0^h e^{A(h−s)} B ds``, ``G1 = ∫_0^h e^{A(h−s)} B (s/h) ds`` and
    ``GE = ∫_0^h e^{A(h−s)} E ds`` as blocks of one validated exponential ([VanLoan1978]):

        exp([[A h, B h, 0, E h], [0, 0, I, 0], [0, 0, 0, 0], [0, 0, 0, 0]])
            = [[e^{A h}, G0, G1, GE], [0, I, I, 0], [0, 0, I, 0], [0, 0, 0, I]],

    the kernel of ``E`` (and of ``B`` for a callable input) and ``e^{A_z h}``."""
    A, B, E = sys.A_at(0), sys.B_at(0), sys.E_at(0)
    n, m, q = sys.nx, sys.nu, sys.nd
    top = np.zeros((n + 2 * m + q, n + 2 * m + q))
    top[:n, :n], top[:n, n : n + m], top[:n, n + 2 * m :] = A, B, E
    Mc, Mr = scaled(top, H)
    Mc[n : n + m, n + m : n + 2 * m] = np.eye(m)  # exact, radius 0
    Ec, Er = expm(Mc, Mr)

    def block(cols: slice) -> IntervalMatrix:
        return Ec[:n, cols], Er[:n, cols]

    alpha = float(upper(np.max(np.abs(A).sum(axis=1)), n + 1)) if n else 0.0
    P = pieces_for(alpha, H[1])
    ell = (float(down(H[0] / P)), float(up(H[1] / P)))
    eA = expm(*scaled(A, ell))
    return Passage(
        h=H,
        Phi=block(slice(0, n)),
        Phiz=target_exponential(A_z, H),
        G0=block(slice(n, n + m)),
        G1=block(slice(n + m, n + 2 * m)),
        GE=block(slice(n + 2 * m, None)),
        kE=lti_kernel(A, E, ell, P, eA),
        kB=lti_kernel(A, B, ell, P, eA) if callable_input else None,
    )


@dataclass(frozen=True)
class Anchor:
    """The constant ``T_h`` of a regular grid (``T``, with its left inverse ``tr``), ``T(t_k-)
    = T_h − h B_z C`` (``Tm``, with ``trm``) and ``Xmag >= |Tm Φ − e^{A_z h} T_h|`` (exact
    ``Φ``, ``e^{A_z h}``), see :meth:`ivobs.estimators.kkl.sampled.ContinuousLTI.anchor`."""

    T: np.ndarray
    tr: Transform
    Tm: np.ndarray
    trm: Transform
    Xmag: np.ndarray


def mismatch(Tp: np.ndarray, ps: Passage, T: np.ndarray) -> np.ndarray:
    """``>= |T' Φ − e^{A_z h} T|`` elementwise for the exact ``Φ``, ``e^{A_z h}`` of ``ps``:
    the coefficient of ``x(t0)`` in ``T' x(t1) = e^{A_z h} T x(t0) + (T' Φ − e^{A_z h} T) x(t0)
    + ...`` (:mod:`.continuous`)."""
    a, ra = interval_product(Tp, None, *ps.Phi)
    b, rb = interval_product(ps.Phiz[0], ps.Phiz[1], T, None)
    d = a - b
    out: np.ndarray = up(up(np.abs(d) + upper(ra + rb, 2)) + product_error(np.abs(d), 1))
    return out


def make_anchor(
    ps: Passage, B_z: np.ndarray, C: np.ndarray, h: float, max_cond: float
) -> tuple[Anchor | None, np.ndarray | None]:
    """The :class:`Anchor` of the period ``ps`` (None if ``T_h`` is singular, ill-conditioned or
    not an exact fixed point of the computed jump) and ``T_h`` itself (None if not computed)."""
    from scipy.linalg import solve_sylvester

    Phi, eA = ps.Phiz[0], ps.Phi[0]
    Q = (h * B_z) @ C
    try:
        with np.errstate(all="ignore"):
            Th = solve_sylvester(-Phi, eA, Q @ eA)
    except (np.linalg.LinAlgError, ValueError):
        return None, None
    for _ in range(4):  # make T_h a fixed point of the computed jump
        Tm = Th - Q
        if np.array_equal(Tm + Q, Th):
            break
        Th = Tm + Q
    else:
        return None, None
    trh = left_inverse(Th, max_cond)
    if not (trh.ok and np.all(np.isfinite(Tm))):
        return None, Th
    anchor = Anchor(T=Th, tr=trh, Tm=Tm, trm=left_inverse(Tm, max_cond), Xmag=mismatch(Tm, ps, Th))
    return anchor, Th
