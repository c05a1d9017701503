"""The interval Taylor method for ``x' = f(x, u, w)`` with ``u``, ``w`` constant over the step:
Taylor coefficients by Lie derivatives (SymPy) and their generated interval code.

Taylor coefficients [Nedialkov1999]: ``f^[0] = x``, ``f^[1] = f``,

    f^[i+1] = (1 / (i+1)) (∂f^[i]/∂x) f,

so that for a solution with ``x(ξ) ∈ B`` for ``ξ ∈ [0, h]`` (the a priori enclosure, :mod:`.flow`)

    x(h) = Σ_{i<k} h^i f^[i](x0) + h^k f^[k](x(ξ)),   ξ ∈ [0, h]  (componentwise Lagrange form)
         ∈ Σ_{i<k} h^i f^[i](x0) + h^k f^[k](B).

The polynomial part ``T(z)``, ``z = (x0, w)``, is enclosed twice and the two are intersected:
the natural extension by Horner in ``h``, and the mean-value form ``T(c) + ∂T/∂z([z]) ([z] - c)``
that limits the wrapping effect of one step [Lohner1987], [Nedialkov1999]; the remainder
``h^k f^[k](B)`` is added to both (it does not depend on ``z`` once ``B`` is known).

The step ``h`` is an interval ``[hl, hh]`` (an enclosure of ``Ts / n``): ``h`` occurs several
times and each occurrence is replaced by the interval, which only enlarges the result.

Jacobian of the flow (the variational equation with the same method): the augmented system
``(x, w)' = (f, 0)`` has Taylor coefficients ``(f^[i], 0)``; its sensitivity ``M(t) = ∂(x, w)(t)
/ ∂(x0, w)`` has the Taylor coefficients ``(∂f^[i]/∂z) M`` along the solution, so

    ∂x(h)/∂z ∈ [I 0] + Σ_{1<=i<k} h^i ∂f^[i]/∂z([z]) + h^k ∂f^[k]/∂z(B, [w]) · M_B,

``M_B`` an a priori enclosure of ``M`` over ``[0, h]`` (:mod:`.flow`).
"""

from __future__ import annotations

from typing import Any

from .codegen import Emitter, Pair, compile_source, lower_of, upper_of
from .forms import emit_arguments, emit_centre, emit_meet, emit_rows

__all__ = ["MAX_ORDER", "TaylorCode", "lie_coefficients"]

MAX_ORDER = 12
"""Highest Taylor order accepted (the Lie derivatives grow fast with the order)."""


def lie_coefficients(f: list[Any], x: list[Any], order: int) -> list[list[Any]]:
    """``[f^[1], ..., f^[order]]`` (module docstring), each a list of ``nx`` SymPy expressions;
    ``u`` and ``w`` are constants of the flow (zero derivative)."""
    import sympy as sp

    coefs = [list(f)]
    for i in range(1, order):
        prev = coefs[-1]
        coefs.append(
            [
                sp.Add(*[sp.diff(g, xj) * fj for xj, fj in zip(x, f) if fj != 0])
                * sp.Rational(1, i + 1)
                for g in prev
            ]
        )
    return coefs


class TaylorCode:
    """The generated Taylor step of order ``order`` for ``x' = f`` over the symbol groups
    ``syms`` (``"x"``, ``"u"``, ``"w"``; ``consts``: known parameters' enclosures): the
    compiled ``step(xl, xh, u, wl, wh, bl, bh, hl, hh) -> (lo, hi)`` and, built on first use,
    ``jac(...) -> (Pl, Ph, Ql, Qh)``: ``P = [I 0] + Σ_{1<=i<k} h^i ∂f^[i]/∂z([z])`` and
    ``Q = h^k ∂f^[k]/∂z(B, [w])`` flattened row-major ``(nx, nz)``; ``sites`` labels the
    domain-checked calls."""

    def __init__(
        self, f: list[Any], syms: dict[str, list[Any]], consts: dict[Any, Pair], order: int
    ) -> None:
        coefs = lie_coefficients(f, syms["x"], order)
        self.coefs, self.syms, self.consts = coefs, syms, consts
        self.sites: list[str] = []
        self.step, self.source = _build_step(coefs, syms, consts, self.sites)
        self._jac: Any = None

    @property
    def jac(self) -> Any:
        if self._jac is None:
            self._jac = _build_jac(self.coefs, self.syms, self.consts, self.sites)
        return self._jac


_ARGS = "xl, xh, u, wl, wh, bl, bh, hl, hh"


def _envs(
    em: Emitter, syms: dict[str, list[Any]], consts: dict[Any, Pair]
) -> tuple[dict[Any, Pair], dict[Any, Pair]]:
    """Header lines; the environments over ``([x], [w])`` and over ``(B, [w])``."""
    ex = emit_arguments(em, syms, consts)
    eb = dict(ex)
    for i, s in enumerate(syms["x"]):
        em.line(f"b{i}l = bl[{i}]; b{i}h = bh[{i}]")
        eb[s] = (f"b{i}l", f"b{i}h")
    return ex, eb


def _horner(em: Emitter, first: Pair | None, rows: list[Pair], last: Pair) -> Pair:
    """``first + h (rows[0] + h (rows[1] + ... + h last))`` (``first`` None: omitted)."""
    h = ("hl", "hh")
    acc = last
    for r in reversed(rows):
        acc = em._sum([r, em.mul(h, acc)])
    acc = em.mul(h, acc)
    return acc if first is None else em._sum([first, acc])


def _build_step(
    coefs: list[list[Any]], syms: dict[str, list[Any]], consts: dict[Any, Pair], sites: list[str]
) -> tuple[Any, str]:
    """Code of ``(natural Horner ∩ mean-value ∩ B)`` (module docstring)."""
    k, x, w = len(coefs), syms["x"], syms["w"]
    z = x + w
    em = Emitter(sites)
    em.lines.append(f"def taylor_step({_ARGS}):")
    ex, eb = _envs(em, syms, consts)
    em.scope(eb)
    rem = emit_rows(em, coefs[k - 1], f"f^[{k}] over the a priori enclosure")
    em.scope(ex)
    lower = [emit_rows(em, coefs[i], f"f^[{i + 1}]") for i in range(k - 1)]
    nat = [
        _horner(em, ex[x[j]], [lower[i][j] for i in range(k - 1)], rem[j]) for j in range(len(x))
    ]
    out = nat
    if k > 1:
        out = _mean_value(em, coefs, syms, consts, rem, nat, _jacobian(em, coefs, x, z))
    for j, p in enumerate(out):
        em.line(f"r{j}l = {lower_of(p[0], f'b{j}l')}; r{j}h = {upper_of(p[1], f'b{j}h')}")
    lows, highs = (", ".join(f"r{j}{e}" for j in range(len(x))) for e in "lh")
    em.line(f"return [{lows}], [{highs}]")
    source = "\n".join(em.lines) + "\n"
    return compile_source(source, "taylor_step"), source


def _mean_value(
    em: Emitter,
    coefs: list[list[Any]],
    syms: dict[str, list[Any]],
    consts: dict[Any, Pair],
    rem: list[Pair],
    nat: list[Pair],
    jac: dict[tuple[int, int], Pair],
) -> list[Pair]:
    """``nat ∩ (T(c) + ∂T/∂z([z]) ([z] - c) + h^k R)`` (an infinite bound: ``nat`` only)."""
    k, x, w = len(coefs), syms["x"], syms["w"]
    z = x + w
    zn = [f"x{i}" for i in range(len(x))] + [f"w{i}" for i in range(len(w))]
    cenv = emit_centre(em, syms, consts, nat)
    centre = [emit_rows(em, coefs[i], f"f^[{i + 1}] (at the centre)") for i in range(k - 1)]
    out: list[Pair] = []
    for j, nv in enumerate(nat):
        tc = _horner(em, cenv[x[j]], [centre[i][j] for i in range(k - 1)], rem[j])
        terms = [tc] + [
            em.mul(jac[j, m], (f"d{zn[m]}l", f"d{zn[m]}h")) for m in range(len(z)) if (j, m) in jac
        ]
        out.append(emit_meet(em, nv, terms))
    return out


def _jacobian(
    em: Emitter, coefs: list[list[Any]], x: list[Any], z: list[Any]
) -> dict[tuple[int, int], Pair]:
    """The entries ``(j, m)`` of ``∂(x_j + Σ_i h^i f^[i]_j) / ∂z_m`` (``i < k``) over the
    emitter's scope by Horner's rule, but for the zero ones (the diagonal's are 1)."""
    import sympy as sp

    jac: dict[tuple[int, int], Pair] = {}
    for j in range(len(x)):
        for m, s in enumerate(z):
            ds = [sp.diff(coefs[i][j], s) for i in range(len(coefs) - 1)]
            if any(d != 0 for d in ds):
                em.label = f"d f^[i][{j}] / d {s}"
                one = ("1.0", "1.0") if m == j else ("0.0", "0.0")
                rows = [em.emit(d) for d in ds]
                jac[j, m] = _horner(em, one, rows[:-1], rows[-1])
            elif m == j:
                jac[j, m] = ("1.0", "1.0")
    return jac


def _build_jac(
    coefs: list[list[Any]], syms: dict[str, list[Any]], consts: dict[Any, Pair], sites: list[str]
) -> Any:
    """Code of ``(P, Q)`` of :class:`TaylorCode` (module docstring)."""
    import sympy as sp

    k, x, w = len(coefs), syms["x"], syms["w"]
    z = x + w
    em = Emitter(sites)
    em.lines.append(f"def taylor_jac({_ARGS}):")
    ex, eb = _envs(em, syms, consts)
    h = ("hl", "hh")
    Q: list[Pair] = []
    em.scope(ex)  # all of P over ([x], [w]), then all of Q over (B, [w]): shared subexpressions
    jac = _jacobian(em, coefs, x, z)
    P = [jac.get((j, m), ("0.0", "0.0")) for j in range(len(x)) for m in range(len(z))]
    em.scope(eb)
    for j in range(len(x)):
        for s in z:
            em.label = f"d f^[{k}][{j}] / d {s} over the a priori enclosure"
            q = em.emit(sp.diff(coefs[k - 1][j], s))
            for _ in range(k):
                q = em.mul(h, q)
            Q.append(q)
    lists = [", ".join(p[i] for p in grp) for grp in (P, Q) for i in (0, 1)]
    em.line(f"return [{lists[0]}], [{lists[1]}], [{lists[2]}], [{lists[3]}]")
    return compile_source("\n".join(em.lines) + "\n", "taylor_jac")
