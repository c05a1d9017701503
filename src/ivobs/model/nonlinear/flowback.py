"""One step back through a validated flow: contract ``(x', w', w)`` with
``h_i(Φ(x', u', w'), u, w) ∈ [ylo, yhi]`` (the ``hf_contractors`` of a
:class:`~ivobs.model.nonlinear.flow.FlowSystem`, where ``h ∘ Φ`` has no symbolic form).

1. **forward**: ``[x] = Φ([x'], u', [w'])`` (the validated flow);
2. **measurement**: contract ``([x], [w])`` with ``h_i(x, u, w) ∈ [ylo, yhi]`` (the system's
   forward-backward contractor of ``h_i``);
3. **backward** through the mean-value form of the flow [Moore2009, Ch. 6]: with ``z' = (x',
   w')``, ``c`` the centre of its box and ``[J]`` the flow's Jacobian enclosure over the box,
   ``Φ_j(z') ∈ Φ_j(c) + Σ_l [J]_jl (z'_l - c_l)`` for every ``z'`` of the box, so for each ``m``
   with ``0 ∉ [J]_jm`` (one Gauss–Seidel sweep, [Jaulin2001, Ch. 4])

       z'_m ∈ c_m + ([x]_j - Φ_j(c) - Σ_{l≠m} [J]_jl (z'_l - c_l)) / [J]_jm,

   the already narrowed ``z'_l`` used in the sum (they stay inside the box over which ``[J]``
   holds, and ``c`` need not be in them). Every operation is outward rounded (:mod:`._runtime`).
   When the flow's signals vary between samples, ``Φ(z') ⊆ Φ_c(z') ± s`` over the box (its
   spread, :mod:`.flow`): ``Φ_c(c)`` is widened by the box's ``s``.

An empty intersection proves the measurement inconsistent (``False``).
"""

from __future__ import annotations

import math
from typing import Any

from ._runtime import div, mul

__all__ = ["FlowBackContractor"]

_NI, _PI = -math.inf, math.inf


def _sub(al: float, ah: float, bl: float, bh: float) -> tuple[float, float]:
    return math.nextafter(al - bh, _NI), math.nextafter(ah - bl, _PI)


class FlowBackContractor:
    """``fn(vl, vh, u, ylo, yhi) -> bool`` for output ``i`` of ``flow``: leaves ``vl``,
    ``vh`` = ``x' + w' + w`` (narrowed in place), inputs ``u = u' + u`` (module docstring)."""

    def __init__(self, flow: Any, i: int) -> None:
        self.flow, self.i = flow, i

    def __call__(
        self, vl: list[float], vh: list[float], u: list[float], ylo: float, yhi: float
    ) -> bool:
        fs = self.flow
        nx, nw, nu = fs.nx, fs.nw, fs.nu
        nz = nx + nw
        up, uk = u[:nu], u[nu:]
        zl, zh = vl[:nz], vh[:nz]
        if not all(map(math.isfinite, zl + zh)):
            return True  # nothing to linearise over: no contraction (sound)
        x1l, x1h = fs._enclose(zl[:nx], zh[:nx], up, zl[nx:], zh[nx:])
        al, ah = list(x1l) + vl[nz:], list(x1h) + vh[nz:]
        fn, sites = fs._hc[self.i]
        if not fs._call(fn, sites, al, ah, uk, ylo, yhi):
            return False
        vl[nz:], vh[nz:] = al[nx:], ah[nx:]
        if not self._backward(zl, zh, up, al[:nx], ah[:nx], list(x1l), list(x1h)):
            return False
        vl[:nz], vh[:nz] = zl, zh
        return True

    def _linearise(self, zl: list[float], zh: list[float], up: list[float]) -> tuple[Any, ...]:
        """``(c, Φ(c) lo, hi, [J] lo, hi)`` over the box, or those of a box that contains it
        with the same ``u'`` (the other outputs' contractors of the same step: the form holds
        over any sub-box, ``c`` need not be inside it), shared through the flow."""
        fs = self.flow
        nx = fs.nx
        last = fs._back_cache
        if last is not None and last[0] == up:
            bl, bh = last[1], last[2]
            if all(a >= b for a, b in zip(zl, bl)) and all(a <= b for a, b in zip(zh, bh)):
                hit: tuple[Any, ...] = last[3]
                return hit
        c = [min(max(0.5 * a + 0.5 * b, a), b) for a, b in zip(zl, zh)]
        if fs._varying:  # Φ(z') ⊆ Φ_c(z') ± s over the box: Φ_c(c) widened by the box's s
            pl, ph, _, _ = fs._run(c[:nx], c[:nx], up, c[nx:], c[nx:], False, False)
            s = fs._spread_of(zl[:nx], zh[:nx], up, zl[nx:], zh[nx:]) or [0.0] * nx
            pl = [math.nextafter(a - e, _NI) for a, e in zip(pl, s)]
            ph = [math.nextafter(b + e, _PI) for b, e in zip(ph, s)]
        else:
            pl, ph = fs._enclose(c[:nx], c[:nx], up, c[nx:], c[nx:])
        Jl, Jh = fs._enclose_jacobian(zl[:nx], zh[:nx], up, zl[nx:], zh[nx:])
        out = (c, pl, ph, Jl, Jh)
        fs._back_cache = (list(up), list(zl), list(zh), out)
        return out

    def _backward(
        self,
        zl: list[float],
        zh: list[float],
        up: list[float],
        tl: list[float],
        th: list[float],
        x1l: list[float],
        x1h: list[float],
    ) -> bool:
        """Step 3 on ``[zl, zh]`` (narrowed in place) for the rows ``j`` that step 2
        narrowed (``[tl, th]`` inside the forward ``[x1l, x1h]``)."""
        fs = self.flow
        nx, nz = fs.nx, fs.nx + fs.nw
        rows = [j for j in range(nx) if tl[j] > x1l[j] or th[j] < x1h[j]]
        if not rows:
            return True
        c, pl, ph, Jl, Jh = self._linearise(zl, zh, up)
        for j in rows:
            row = [float(v) for v in Jl[j * nz : (j + 1) * nz]]
            row += [float(v) for v in Jh[j * nz : (j + 1) * nz]]
            if not all(map(math.isfinite, row)):
                continue  # an unbounded derivative (a domain edge): no contraction from row j
            for m in range(nz):
                jl, jh = float(Jl[j * nz + m]), float(Jh[j * nz + m])
                if not (jl > 0.0 or jh < 0.0):
                    continue
                rl, rh = _sub(tl[j], th[j], pl[j], ph[j])
                for k in range(nz):
                    if k != m:
                        dl, dh = _sub(zl[k], zh[k], c[k], c[k])
                        ql, qh = mul(float(Jl[j * nz + k]), float(Jh[j * nz + k]), dl, dh)
                        rl, rh = _sub(rl, rh, ql, qh)
                ql, qh = div(rl, rh, jl, jh, -1)
                lo = math.nextafter(c[m] + ql, _NI)
                hi = math.nextafter(c[m] + qh, _PI)
                zl[m], zh[m] = max(zl[m], lo), min(zh[m], hi)
                if zl[m] > zh[m]:
                    return False
        return True
