"""Guaranteed discretisation of a continuous-time :class:`~ivobs.NonlinearSystem`: the
validated flow over one sampling period as a discrete-time model (docs/nonlinear.md,
"Continuous-time plants").

``x' = f(x, u, p, d)`` sampled every ``Ts``; ``u`` is held constant over each period
(zero-order hold) and so are the unknown parameters and signals ``w = (p, d)``: any value of
their box, one per period (the discrete model's ``w[k]``, as ``LinearSystem.discretize`` assumes
for its disturbances). A ``w`` that varies *inside* a period is not covered. Then

    x[k+1] = Φ_Ts(x[k], u[k], w[k])

and :class:`FlowSystem` encloses ``Φ_Ts`` over boxes with the interval Taylor method of order
``k`` ([Lohner1987], [Nedialkov1999]), ``n`` substeps of ``h = Ts / n``:

1. **a priori enclosure** ``B`` with ``[x0] + [0, h] f(B, u, [w]) ⊆ B``: then the solution from
   every ``x0 ∈ [x0]`` exists on ``[0, h]`` and stays in ``B`` (Picard–Lindelöf; the Picard
   operator maps the continuous functions into ``B`` to themselves, Schauder's fixed point and
   uniqueness for a locally Lipschitz ``f``). Found by inflating ``[x0] + [0, h] f([x0])`` and
   retrying; when it fails the substep is halved (up to :data:`MAX_HALVINGS` times), then an
   :class:`~ivobs.IvobsError` says so (the solution may blow up within the period);
2. **the Taylor step** (:mod:`.taylor`): natural ∩ mean-value enclosure of the polynomial, plus
   the remainder ``h^k f^[k](B)``, intersected with ``B``.

Every operation is rounded outward (the generated code of :mod:`.codegen`; the a priori tests
below with ``nextafter``); ``h`` is the interval enclosing ``Ts / n``, halved exactly.

The Jacobian of ``Φ`` (for ``nl-zonotope`` and ``nl-constrained-zonotope``) comes from the
variational equation with the same method (:mod:`.taylor`), its a priori enclosure
``M_B ⊇ [I 0] + [0, h] ∂f/∂z(B, [w]) M_B`` found likewise, and the substeps chained by interval
matrix products.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import Any

import numpy as np

from ...errors import IvobsError
from ._runtime import DomainError
from .codegen import _enclose_fraction
from .flowback import FlowBackContractor
from .system import NonlinearSystem
from .taylor import MAX_ORDER, build_taylor

__all__ = ["MAX_HALVINGS", "FlowSystem"]

Pair = tuple[np.ndarray, np.ndarray] | None

MAX_HALVINGS = 10
"""Halvings of a substep whose a priori enclosure fails before giving up."""
TRIES = 8
"""Inflate-and-retry rounds of one a priori enclosure."""
INFLATE_REL, INFLATE_ABS = 0.1, 1e-9

Vec = list[float]


def _dn(v: float) -> float:
    return math.nextafter(v, -math.inf)


def _up(v: float) -> float:
    return math.nextafter(v, math.inf)


_ND, _NU = np.float64(-np.inf), np.float64(np.inf)


def _count(what: str, v: Any, lo: int, hi: int) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= v <= hi:
        raise IvobsError(f"{what}: expected an integer in [{lo}, {hi}], got {v!r}")
    return int(v)


class _FlowForms:
    """Stands for the ``Forms`` of ``f`` (``natural``, ``tight``, ``jacobian``, ``sites``) so
    the nonlinear methods call the flow as they call a discrete map. Domain errors are turned
    into :class:`~ivobs.IvobsError` inside, hence no sites."""

    def __init__(self, flow: FlowSystem) -> None:
        self.natural = self.tight = flow._enclose
        self.jacobian = flow._enclose_jacobian
        self.natjac = flow._enclose_natjac
        self.sites: list[str] = []
        self.source = flow._taylor.source


class FlowSystem(NonlinearSystem):
    """The discrete-time model ``x[k+1] = Φ_Ts(x[k], u[k], w[k])`` of a continuous-time
    :class:`~ivobs.NonlinearSystem` (module docstring); made by
    :meth:`NonlinearSystem.discretize`. ``h`` and its members are those of the continuous
    system; ``f_box``, ``f_tight_box`` and ``f_jac_box`` enclose the flow and its Jacobian;
    ``f_exprs`` stay the vector field. ``hf_contractors()`` step back through the flow
    (:mod:`.flowback`)."""

    def __init__(self, continuous: NonlinearSystem, Ts: Any, order: Any = 4, substeps: Any = 1):
        if not continuous.is_continuous:
            raise IvobsError("discretize: the system is already discrete-time")
        if isinstance(Ts, bool) or not isinstance(Ts, (int, float)) or not 0 < Ts < math.inf:
            raise IvobsError(f"Ts: expected a sampling period > 0, got {Ts!r}")
        self.__dict__.update(continuous.__dict__)
        self.continuous = continuous
        self.dt = float(Ts)
        self.order = _count("order", order, 1, MAX_ORDER)
        self.substeps = _count("substeps", substeps, 1, 1 << 16)
        self.smooth: bool = _check_smooth(self.f_exprs, self.order)
        self._taylor = build_taylor(self.f_exprs, self._groups(), self._consts, self.order)
        # no symbolic h∘Φ: one step back through the flow's mean-value form, per output (it
        # needs the flow's Jacobian: a non-smooth f has none here, its contractors do nothing)
        self._hf = [
            (FlowBackContractor(self, i) if self.smooth else _no_contraction, [])
            for i in range(self.ny)
        ]
        self._h_step = _enclose_fraction(Fraction(self.dt) / self.substeps)
        self._back_cache: Any = None  # the step back's last linearisation (.flowback)
        self._f = _FlowForms(self)  # type: ignore[assignment]

    # -- the flow over a box ------------------------------------------------------------------
    def _enclose(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Vec, Vec]:
        """``(lo, hi)`` lists enclosing ``Φ_Ts(x, u, w)`` for every ``x ∈ [xl, xh]``,
        ``w ∈ [wl, wh]``."""
        lo, hi, _ = self._run(xl, xh, u, wl, wh, False)
        return lo, hi

    def _enclose_jacobian(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Any, Any]:
        """``∂Φ_Ts/∂(x, w)`` enclosed over the box, flattened ``(nx, nx + nw)``."""
        if not self.smooth:
            raise IvobsError(
                "sys: the Jacobian of a validated flow needs a smooth f (this one uses abs, min "
                "or max), so nl-zonotope and nl-constrained-zonotope cannot take it; use "
                "nl-interval"
            )
        _, _, A = self._run(xl, xh, u, wl, wh, True)
        assert A is not None
        return A[0][: self.nx].ravel(), A[1][: self.nx].ravel()

    def _enclose_natjac(self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec) -> tuple[Any, ...]:
        """The flow's box and its Jacobian over the same box in one pass (the ``natjac`` form
        of :class:`.forms.Forms` that the set methods call): ``(lo, hi, jac_lo, jac_hi)``,
        lists, the Jacobian row-major over ``(x, w)``."""
        if not self.smooth:
            self._enclose_jacobian(xl, xh, u, wl, wh)  # the refusal, with its message
        lo, hi, A = self._run(xl, xh, u, wl, wh, True)
        assert A is not None
        return lo, hi, A[0][: self.nx].ravel().tolist(), A[1][: self.nx].ravel().tolist()

    def _run(self, xl: Any, xh: Any, u: Any, wl: Any, wh: Any, jac: bool) -> tuple[Vec, Vec, Pair]:
        """The substeps from ``[xl, xh]``: the box at ``Ts`` and (``jac``) the augmented
        Jacobian ``∂(x, w)(Ts)/∂(x0, w)`` ``(lo, hi)``, or None."""
        xl, xh = [float(v) for v in xl], [float(v) for v in xh]
        wl, wh, u = [float(v) for v in wl], [float(v) for v in wh], [float(v) for v in u]
        nz = self.nx + self.nw
        A: Pair = (np.eye(nz), np.eye(nz)) if jac else None
        if not all(map(math.isfinite, xl + xh + wl + wh)):  # the whole space (sound)
            full = np.full((nz, nz), np.inf)
            return [-math.inf] * self.nx, [math.inf] * self.nx, (-full, full) if jac else None
        for _ in range(self.substeps):
            xl, xh, A = self._advance(xl, xh, u, wl, wh, self._h_step, A, 0)
        return xl, xh, A

    def _advance(
        self,
        xl: Vec,
        xh: Vec,
        u: Vec,
        wl: Vec,
        wh: Vec,
        h: tuple[float, float],
        A: Pair,
        depth: int,
    ) -> tuple[Vec, Vec, Pair]:
        """One substep of length in ``h = (hl, hh)``, halved while an a priori enclosure
        fails; ``A``: the augmented Jacobian so far (or None)."""
        B = self._apriori(xl, xh, u, wl, wh, h[1])
        M = None if B is None or A is None else self._apriori_jac(B[0], B[1], u, wl, wh, h[1])
        if B is None or (A is not None and M is None):
            if depth >= MAX_HALVINGS or h[0] * 0.5 == 0.0:
                what = "the flow" if B is None else "the flow's Jacobian"
                raise IvobsError(
                    f"discretize: no a priori enclosure of {what} over {h[1]:.6g} (Ts = "
                    f"{self.dt:g} halved {depth} times) from x in [{xl}, {xh}]: the solution "
                    "may leave every bounded set within the period (finite escape), or f is "
                    "unbounded near the box; use a smaller Ts or check the model"
                )
            half = (h[0] * 0.5, h[1] * 0.5)  # exact: a power of two
            xl, xh, A = self._advance(xl, xh, u, wl, wh, half, A, depth + 1)
            return self._advance(xl, xh, u, wl, wh, half, A, depth + 1)
        args = (xl, xh, u, wl, wh, B[0], B[1], h[0], h[1])
        if A is not None:
            assert M is not None
            A = _imatmul(*self._substep_jac(args, M), *A)
        lo, hi = self._generated(self._taylor.step, args)
        return lo, hi, A

    def _generated(self, fn: Any, args: tuple[Any, ...]) -> Any:
        try:
            return fn(*args)
        except DomainError as exc:
            sites = self._taylor.sites
            where = sites[exc.site] if 0 <= exc.site < len(sites) else "expression"
            raise IvobsError(
                f"discretize: {where}: {exc.what} (the range [{exc.lo:.17g}, {exc.hi:.17g}] "
                "reached it); the Taylor coefficients are undefined over the box"
            ) from None

    def _fnat(self, bl: Vec, bh: Vec, u: Vec, wl: Vec, wh: Vec) -> Any:
        f = self.continuous._f
        return self.continuous._call(f.natural, f.sites, bl, bh, u, wl, wh)

    def _picard(
        self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec, bl: Vec, bh: Vec, hh: float
    ) -> tuple[Vec, Vec]:
        """``[x0] + [0, hh] f(B)``, outward rounded."""
        fl, fh = self._fnat(bl, bh, u, wl, wh)
        lo = [_dn(a + min(0.0, _dn(hh * f))) for a, f in zip(xl, fl)]
        hi = [_up(a + max(0.0, _up(hh * f))) for a, f in zip(xh, fh)]
        return lo, hi

    def _apriori(
        self, xl: Vec, xh: Vec, u: Vec, wl: Vec, wh: Vec, hh: float
    ) -> tuple[Vec, Vec] | None:
        """A box ``B`` with ``[x0] + [0, hh] f(B) ⊆ B`` (module docstring), or None."""
        bl, bh = self._picard(xl, xh, u, wl, wh, xl, xh, hh)
        for _ in range(TRIES):
            if not all(map(math.isfinite, bl + bh)):
                return None
            tl, th = _inflate(bl, bh)
            nl, nh = self._picard(xl, xh, u, wl, wh, tl, th, hh)
            if all(a >= c for a, c in zip(nl, tl)) and all(b <= d for b, d in zip(nh, th)):
                # T is verified, so x(t) ∈ x0 + [0, t] f(T) ⊆ N for t in [0, hh]: N holds it
                return nl, nh
            bl = [min(a, c) for a, c in zip(nl, tl)]
            bh = [max(b, d) for b, d in zip(nh, th)]
        return None

    # -- the Jacobian of one substep ------------------------------------------------------------
    def _substep_jac(
        self, args: tuple[Any, ...], M: tuple[np.ndarray, np.ndarray]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Augmented ``∂(x, w)(h)/∂(x0, w)`` over the substep (module docstring of
        :mod:`.taylor`): ``P + Q M_B`` on top of ``[0 I]``."""
        nx, nz = self.nx, self.nx + self.nw
        Pl, Ph, Ql, Qh = self._generated(self._taylor.jac, args)
        Ml, Mh = M
        Rl, Rh = _imatmul(_arr(Ql, nx, nz), _arr(Qh, nx, nz), Ml, Mh)
        Jl = _aug(np.nextafter(_arr(Pl, nx, nz) + Rl, _ND), nz)
        Jh = _aug(np.nextafter(_arr(Ph, nx, nz) + Rh, _NU), nz)
        return Jl, Jh

    def _apriori_jac(
        self, bl: Vec, bh: Vec, u: Vec, wl: Vec, wh: Vec, hh: float
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """An enclosure ``M_B`` (augmented, ``(nz, nz)``) of the sensitivity over ``[0, hh]``:
        ``[I 0] + [0, hh] ∂f/∂z(B, [w]) M_B ⊆ M_B``, or None."""
        nx, nz = self.nx, self.nx + self.nw
        f = self.continuous._f
        jl, jh = self.continuous._call(f.jacobian, f.sites, bl, bh, u, wl, wh)
        with np.errstate(invalid="ignore", over="ignore"):
            El = np.minimum(0.0, np.nextafter(hh * _arr(jl, nx, nz), _ND))
            Eh = np.maximum(0.0, np.nextafter(hh * _arr(jh, nx, nz), _NU))
        I0 = np.eye(nz)[:nx]
        # candidate radius around I (not itself rigorous, the test below is): the image of
        # I ± R is within I ± |E| (I + R), strictly inside I ± R when R - |E| R = |E| + D, D > 0
        # (R = (I - |E|)^-1 (|E| + D)); the rows of the constant w stay exactly [0 I]
        mag = np.zeros((nz, nz))
        mag[:nx] = np.maximum(np.abs(El), np.abs(Eh))
        if not np.all(np.isfinite(mag)) or np.max(np.abs(np.linalg.eigvals(mag))) >= 0.5:
            return None  # ρ(|E|) too large: a shorter substep
        D = np.zeros((nz, nz))
        D[:nx] = 1e-12 + 1e-9 * mag[:nx]
        R = np.maximum(np.linalg.solve(np.eye(nz) - mag, mag + D), 0.0) * (1.0 + 1e-9)
        for _ in range(TRIES):
            Tl, Th = np.eye(nz) - R, np.eye(nz) + R
            Sl, Sh = _imatmul(El, Eh, Tl, Th)
            Nl = _aug(np.nextafter(I0 + Sl, _ND), nz)
            Nh = _aug(np.nextafter(I0 + Sh, _NU), nz)
            if np.all(Nl >= Tl) and np.all(Nh <= Th):
                return Nl, Nh  # T verified, so M(t) ∈ I0 + [0, t] [J] T ⊆ N
            R = 2.0 * R + D
        return None

    # -- identity ------------------------------------------------------------------------------
    @property
    def is_continuous(self) -> bool:
        return False

    def spec(self) -> dict[str, Any]:
        """The continuous system's keyword arguments and the discretisation."""
        out = self.continuous.spec()
        out["discretize"] = {"Ts": self.dt, "order": self.order, "substeps": self.substeps}
        return out

    def __reduce__(self) -> Any:
        return (_rebuild_flow, (self.continuous.spec(), self.dt, self.order, self.substeps))

    def _repr_html_(self) -> str:
        from ..._html import summary_html

        rows = [(f"{x}' =", str(e)) for x, e in zip(self.state_names, self.f_text)]
        rows += [(f"{n} =", str(e)) for n, e in zip(self.output_names, self.h_text)]
        rows += [
            ("sampled", f"Ts = {self.dt:g}, Taylor order {self.order}, {self.substeps} substep(s)")
        ]
        return summary_html("ivobs NonlinearSystem (validated flow)", rows)

    def __repr__(self) -> str:
        return (
            f"FlowSystem(nx={self.nx}, nu={self.nu}, ny={self.ny}, Ts={self.dt:g}, "
            f"order={self.order}, substeps={self.substeps})"
        )


def _no_contraction(*args: Any) -> bool:
    return True


def _check_smooth(f: list[Any], order: int) -> bool:
    """Refuse ``abs``, ``min``, ``max`` in ``f`` above order 2. Up to order 2 the step holds
    with their generalised derivatives: ``x(h) - x0 - h f(x0) = ∫_0^h (f(x(s)) - f(x0)) ds``
    with ``f_i(x(s)) - f_i(x0) ∈ ∂f_i(B) s f(B)`` (Lebourg [Clarke1983, Theorem 2.3.7]), i.e.
    ``h² f^[2](B)``; beyond, Taylor's remainder needs derivatives that do not exist at the
    kinks. Returns whether ``f`` is smooth (the flow's Jacobian is only offered then)."""
    import sympy as sp

    kinks = (sp.Abs, sp.Min, sp.Max, sp.sign, sp.Heaviside)
    smooth = not any(e.has(*kinks) for e in f)
    if order > 2 and not smooth:
        raise IvobsError(
            f"order: {order} needs a smooth f (the Taylor remainder of order k uses k "
            "derivatives); f uses abs, min or max: use order=1 or 2 (and more substeps)"
        )
    return smooth


def _rebuild_flow(spec: dict[str, Any], Ts: float, order: int, substeps: int) -> FlowSystem:
    return FlowSystem(NonlinearSystem(**spec), Ts, order, substeps)


def _arr(v: Any, n: int, m: int) -> np.ndarray:
    return np.asarray(v, dtype=float).reshape(n, m)


def _aug(top: np.ndarray, nz: int) -> np.ndarray:
    """``[[top], [0 I]]``: the rows of the constant ``w`` below the state rows."""
    nx = top.shape[0]
    return np.vstack([top, np.eye(nz)[nx:]])


def _inflate(lo: list[float], hi: list[float]) -> tuple[list[float], list[float]]:
    e = [INFLATE_REL * (b - a) + INFLATE_ABS * (1.0 + max(abs(a), abs(b))) for a, b in zip(lo, hi)]
    return [_dn(a - d) for a, d in zip(lo, e)], [_up(b + d) for b, d in zip(hi, e)]


def _imatmul(
    Al: np.ndarray, Ah: np.ndarray, Bl: np.ndarray, Bh: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Interval matrix product, outward rounded: each product within one ulp (``nextafter``),
    a ``0 × ∞`` corner counted as 0 (IEEE 1788); the sum's error bounded by ``γ_n Σ|terms|``
    [Higham2002, Section 3.1] plus ``n`` times the smallest subnormal, then one more ulp."""
    from ...linalg import gamma

    with np.errstate(invalid="ignore", over="ignore"):
        a = (Al[:, :, None], Ah[:, :, None])
        b = (Bl[None, :, :], Bh[None, :, :])
        P = np.stack([a[i] * b[j] for i in (0, 1) for j in (0, 1)])
        P = np.where(np.isnan(P), 0.0, P)
        lo = np.nextafter(P.min(axis=0), _ND)
        hi = np.nextafter(P.max(axis=0), _NU)
        n = Al.shape[1]
        g, eta = gamma(n + 1), n * 5e-324
        sl = lo.sum(axis=1) - (g * np.abs(lo).sum(axis=1) + eta)
        sh = hi.sum(axis=1) + (g * np.abs(hi).sum(axis=1) + eta)
        sl = np.where(np.isnan(sl), -np.inf, sl)
        sh = np.where(np.isnan(sh), np.inf, sh)
    return np.nextafter(sl, _ND), np.nextafter(sh, _NU)
