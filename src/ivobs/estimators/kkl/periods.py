"""The matrices of one sampling period of the continuous-time time-invariant KKL observer
(:mod:`.sampled`), computed once per period: data-free, so design rather than recursion."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...model import LinearSystem
from .design import Transform, left_inverse

__all__ = ["Anchor", "PeriodData", "make_anchor", "period_data"]


@dataclass(frozen=True)
class Anchor:
    """The constant ``T_h`` of a regular grid (``T``, with its left inverse ``tr``), ``T(t_k-)
    = T_h - h B_z C`` (``Tm``, with ``trm``), the residual term ``res = |D T_h⁻¹|``, the ``d``
    radius matrix ``rad`` of one interval and the input matrices multiplied by ``Tm`` (see
    :meth:`ivobs.estimators.kkl.sampled.ContinuousLTI.anchor`)."""

    T: np.ndarray
    tr: Transform
    Tm: np.ndarray
    trm: Transform
    res: np.ndarray
    rad: np.ndarray
    TG0: np.ndarray
    TG1: np.ndarray
    TGE: np.ndarray
    TgB: np.ndarray | None


@dataclass
class PeriodData:
    """One sampling interval of length ``h``: ``Phi_z = e^{A_z h}``, ``Psi = e^{-A h}``,
    ``eA = e^{A h}``, ``∫ e^{A(h-s)} B (1, s/h) ds`` (``G0``, ``G1``, Van Loan), ``GE = ∫ e^{A(h-s)}
    E ds``, ``e^{A(h-s)} E`` at the ``N`` midpoints (``nodesE``) with the bound ``var`` of their
    variation, and Gauss–Legendre nodes ``gl = (s, w, e^{A(h-s)} B)`` for a callable input.
    The anchor of the period and the radius matrices of the model prediction are added when
    first needed."""

    h: float
    Phi_z: np.ndarray
    Psi: np.ndarray
    eA: np.ndarray
    G0: np.ndarray
    G1: np.ndarray
    GE: np.ndarray
    nodesE: np.ndarray
    N: int
    var: np.ndarray
    gl: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
    anchor: Anchor | None = None
    anchor_done: bool = False
    T_h: np.ndarray | None = None
    _identity: tuple[np.ndarray, np.ndarray] | None = None

    def identity_radius(self) -> tuple[np.ndarray, np.ndarray]:
        """The ``d`` radius matrix of one interval with ``T = I`` and ``|e^{A h}|`` (the model
        prediction of the previous box)."""
        if self._identity is None:
            radI = self.h / self.N * np.abs(self.nodesE).sum(axis=0) + self.var[None, :]
            self._identity = (radI, np.abs(self.eA))
        return self._identity


def period_data(sys: LinearSystem, A_z: np.ndarray, h: float, gauss: bool) -> PeriodData:
    """:class:`PeriodData` of a time-invariant system for the period ``h`` (``gauss``: with the
    Gauss–Legendre nodes of a callable input)."""
    from scipy.linalg import expm

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
    gl = None
    if gauss:  # Gauss-Legendre nodes for a smooth u(t)
        xg, wg = np.polynomial.legendre.leggauss(8)
        sg = 0.5 * h * (xg + 1.0)
        gl = (sg, 0.5 * h * wg, np.stack([expm(A * (h - s)) @ B for s in sg]))
    return PeriodData(
        h=h,
        Phi_z=expm(A_z * h),
        Psi=expm(-A * h),
        eA=eM[:n, :n],
        G0=eM[:n, n : n + m],
        G1=eM[:n, n + m :],
        GE=expm(Me * h)[:n, n:],
        nodesE=np.stack([expm(A * (h - s)) @ E for s in mids]),
        N=N,
        var=0.5 * h * h / N * np.exp(normA * h) * np.linalg.norm(A @ E, axis=0),
        gl=gl,
    )


def make_anchor(
    c: PeriodData, B_z: np.ndarray, C: np.ndarray, max_cond: float
) -> tuple[Anchor | None, np.ndarray | None]:
    """The :class:`Anchor` of the period ``c`` (None if ``T_h`` is singular, ill-conditioned or
    not an exact fixed point of the computed jump) and ``T_h`` itself (None if not computed)."""
    from scipy.linalg import solve_sylvester

    h, Phi, eA = c.h, c.Phi_z, c.eA
    Q = h * B_z @ C
    try:
        with np.errstate(all="ignore"):
            Th = solve_sylvester(-Phi, eA, Q @ eA)
    except (np.linalg.LinAlgError, ValueError):
        return None, None
    for _ in range(4):  # make T_h an exact fixed point of the computed jump
        Tm = Th - Q
        if np.array_equal(Tm + Q, Th):
            break
        Th = Tm + Q
    else:
        return None, None
    trh = left_inverse(Th, max_cond)
    if not (trh.ok and np.all(np.isfinite(Tm))):
        return None, Th
    D = Phi @ Th - Tm @ eA
    anchor = Anchor(
        T=Th,
        tr=trh,
        Tm=Tm,
        trm=left_inverse(Tm, max_cond),
        res=np.abs(D @ trh.P),
        rad=(h / c.N) * np.abs(Tm @ c.nodesE).sum(axis=0)
        + np.linalg.norm(Tm, axis=1)[:, None] * c.var[None, :],
        TG0=Tm @ c.G0,
        TG1=Tm @ c.G1,
        TGE=Tm @ c.GE,
        TgB=Tm @ c.gl[2] if c.gl is not None else None,
    )
    return anchor, Th
