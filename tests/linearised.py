"""The reference of nonlinear tightness: the time-varying linear model linearised along the TRUE
trajectory (``A_k = ∂f/∂x``, ``E_k = ∂f/∂w`` at ``(x_k, w_k)``, the affine parts as inputs with
``B = I``; the same for ``h``; the same bounds of ``w``), whose exact hull is what a method that
knew the linearisation points would give from the same data. Shared by the tests and
``benchmarks/bench_nl_horizon.py``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

import ivobs


def truth_w(sys: ivobs.NonlinearSystem, tr: ivobs.Trajectory) -> np.ndarray:
    """The per-step ``w = (params, signals)`` of a simulated trajectory."""
    p = np.zeros((tr.T, 0)) if tr.p is None else np.broadcast_to(tr.p, (tr.T, tr.p.shape[-1]))
    return np.hstack([p, tr.d])


def linearised_along(sys: ivobs.NonlinearSystem, tr: ivobs.Trajectory) -> tuple[Any, np.ndarray]:
    """The LTV model linearised along the true trajectory, and its inputs (the affine parts)."""
    w = truth_w(sys, tr)
    nx, ny, T = sys.nx, sys.ny, tr.T
    A, E, C, F, uf, uh = [], [], [], [], [], []
    for k in range(T):
        x, u, wk = tr.x[k], tr.u[k], w[k]
        ax, bx, aw, bw = sys.f_jac_box(x, x, u, wk, wk)
        Jx, Jw = 0.5 * (ax + bx), 0.5 * (aw + bw)
        flo, fhi = sys.f_box(x, x, u, wk, wk)
        hx_lo, hx_hi, hw_lo, hw_hi = sys.h_jac_box(x, x, u, wk, wk)
        Hx, Hw = 0.5 * (hx_lo + hx_hi), 0.5 * (hw_lo + hw_hi)
        hlo, hhi = sys.h_box(x, x, u, wk, wk)
        A.append(Jx), E.append(Jw), C.append(Hx), F.append(Hw)
        uf.append(0.5 * (flo + fhi) - Jx @ x - Jw @ wk)
        uh.append(0.5 * (hlo + hhi) - Hx @ x - Hw @ wk)
    lin = ivobs.LinearSystem(
        A=lambda k: A[min(k, T - 1)],
        B=np.hstack([np.eye(nx), np.zeros((nx, ny))]),
        C=lambda k: C[min(k, T - 1)],
        D=np.hstack([np.zeros((ny, nx)), np.eye(ny)]),
        E=lambda k: E[min(k, T - 1)],
        F=lambda k: F[min(k, T - 1)],
        d=sys.w_box,
    )
    return lin, np.hstack([np.array(uf), np.array(uh)])
