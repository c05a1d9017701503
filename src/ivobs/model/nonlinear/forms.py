"""Generated inclusion functions of a vector of expressions ``g(x, u, w)``: the natural
extension, its Jacobian, and the natural extension intersected with the mean-value form.

Mean-value (centred) form [Moore2009, Ch. 6]: for ``z = (x, w)`` in the box ``[z]`` and a
centre ``c`` in it,

    g(z) in g(c) + J([z]) ([z] - c),          J = dg/dz over the box,

with ``g(c)`` enclosed by the natural extension at the point. It is tighter than the natural
extension on wide boxes with repeated variables and looser when each variable occurs once (the
Hénon map), so the two are always intersected. Non-smooth functions differentiate to their
generalised (Clarke) derivatives (``abs -> sign`` with ``[-1, 1]`` at 0), for which the
mean-value inclusion still holds ([Clarke1983, Theorem 2.3.7], Lebourg).

All generated functions take Python lists ``(xl, xh, u, wl, wh)`` and return lists.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from .codegen import Emitter, Pair, compile_source, lower_of, upper_of

__all__ = ["Forms", "build_forms", "emit_centre", "emit_meet"]


class Forms:
    """The compiled functions of one vector ``g`` (``natural``, ``tight``, ``jacobian``, and
    ``natjac``: the natural extension and the Jacobian over the same box in one call, sharing
    their subexpressions, ``(nat_lo, nat_hi, jac_lo, jac_hi)`` with the Jacobian row-major) and
    the labels of their domain-checked calls (``sites``)."""

    def __init__(
        self, natural: Any, tight: Any, jacobian: Any, natjac: Any, sites: list[str], source: str
    ):
        self.natural, self.tight, self.jacobian = natural, tight, jacobian
        self.natjac = natjac
        self.sites, self.source = sites, source


def _repeats(e: Any, z: list[Any]) -> bool:
    """Whether a variable of ``z`` occurs more than once in ``e``. If none does, the natural
    extension is the exact range up to rounding [Moore2009, Ch. 6] (single-use expressions, as
    in the Hénon map) and the mean-value form cannot tighten it: it is skipped."""
    import sympy as sp

    counts = Counter(node for node in sp.preorder_traversal(e) if node in z)
    return any(c > 1 for c in counts.values())


def emit_arguments(
    em: Emitter, syms: dict[str, list[Any]], consts: dict[Any, Pair]
) -> dict[Any, Pair]:
    """Code reading the arguments ``u``, ``wl``, ``wh``, ``xl``, ``xh`` into variables; the
    environment of the symbols (and of the known parameters ``consts``)."""
    env: dict[Any, Pair] = dict(consts)
    for i, s in enumerate(syms["u"]):
        em.line(f"u{i} = u[{i}]")
        env[s] = (f"u{i}", f"u{i}")
    for g in ("w", "x"):
        for i, s in enumerate(syms[g]):
            em.line(f"{g}{i}l = {g}l[{i}]; {g}{i}h = {g}h[{i}]")
            env[s] = (f"{g}{i}l", f"{g}{i}h")
    return env


def _header(name: str, em: Emitter, syms: dict[str, list[Any]], consts: dict[Any, Pair]) -> None:
    em.lines.append(f"def {name}(xl, xh, u, wl, wh):")
    em.scope(emit_arguments(em, syms, consts))


def emit_rows(em: Emitter, exprs: list[Any], labels: list[str] | str) -> list[Pair]:
    """The code of each of ``exprs``, labelled ``labels[j]`` (a string: ``labels[j]``)."""
    out = []
    for j, e in enumerate(exprs):
        em.label = labels[j] if isinstance(labels, list) else f"{labels}[{j}]"
        out.append(em.emit(e))
    return out


def _ret(em: Emitter, pairs: list[Pair]) -> None:
    em.line(f"return [{', '.join(p[0] for p in pairs)}], [{', '.join(p[1] for p in pairs)}]")


def emit_centre(
    em: Emitter,
    syms: dict[str, list[Any]],
    consts: dict[Any, Pair],
    nat: list[Pair],
    used: set[Any] | None = None,
) -> dict[Any, Pair]:
    """Code of the centred forms' common start: return ``nat`` when a bound of the box
    ``z = (x, w)`` is infinite, else the centre ``c`` (midpoint clipped into the box) and the
    outward-rounded offsets ``[z] - c`` (``d{name}l``, ``d{name}h``); the emitter's scope is
    set to the centre (and the inputs), which is returned. ``used``: the only variables of
    ``z`` the forms read (None: all), the others neither checked nor centred."""
    pairs = [(s, f"x{i}") for i, s in enumerate(syms["x"])]
    pairs += [(s, f"w{i}") for i, s in enumerate(syms["w"])]
    if used is not None:
        pairs = [(s, n) for s, n in pairs if s in used]
    z, zname = [s for s, _ in pairs], [n for _, n in pairs]
    box = [f"{n}l" for n in zname] + [f"{n}h" for n in zname]
    em.line(f"s = {' + '.join(box) if box else '0.0'}")
    lows, highs = ", ".join(p[0] for p in nat), ", ".join(p[1] for p in nat)
    em.line(f"if s - s != 0.0: return [{lows}], [{highs}]")  # an infinite bound: natural only
    cenv: dict[Any, Pair] = dict(consts)
    for s, n in zip(z, zname):
        em.line(f"c{n} = 0.5 * {n}l + 0.5 * {n}h")  # the midpoint, clipped into the box
        em.line(f"c{n} = {lower_of(f'c{n}', f'{n}l')}; c{n} = {upper_of(f'c{n}', f'{n}h')}")
        em.line(f"d{n}l = _nx({n}l - c{n}, _NI) if {n}l != c{n} else 0.0")
        em.line(f"d{n}h = _nx({n}h - c{n}, _PI) if {n}h != c{n} else 0.0")
        cenv[s] = (f"c{n}", f"c{n}")
    for i, s in enumerate(syms["u"]):
        cenv[s] = (f"u{i}", f"u{i}")
    em.scope(cenv)
    return cenv


def _mean_value(
    em: Emitter,
    exprs: list[Any],
    nat: list[Pair],
    jac: list[list[Any]],
    repeated: list[bool],
    syms: dict[str, list[Any]],
    consts: dict[Any, Pair],
    labels: list[str],
) -> list[Pair]:
    """Code of ``natural ∩ (g(c) + J([z]) ([z] - c))`` for the rows with a repeated variable
    (the natural rows ``nat`` already emitted over the box)."""
    z = syms["x"] + syms["w"]
    zname = [f"x{i}" for i in range(len(syms["x"]))] + [f"w{i}" for i in range(len(syms["w"]))]
    entries = {}
    for i, row in enumerate(jac):
        for j, d in enumerate(row):
            if d != 0 and repeated[i]:
                em.label = f"d {labels[i]} / d {z[j]}"
                entries[i, j] = em.emit(d)
    rows = [e for e, r in zip(exprs, repeated) if r]
    emit_centre(em, syms, consts, nat, set().union(*(e.free_symbols for e in rows)))
    out: list[Pair] = []
    for i, nv in enumerate(nat):
        if not repeated[i]:  # single-use: the natural extension is already the exact range
            out.append(nv)
            continue
        em.label = f"{labels[i]} (at the centre)"
        terms = [em.emit(exprs[i])] + [
            em.mul(entries[i, j], (f"d{zname[j]}l", f"d{zname[j]}h"))
            for j in range(len(z))
            if (i, j) in entries
        ]
        out.append(emit_meet(em, nv, terms))
    return out


def emit_meet(em: Emitter, nat: Pair, terms: list[Pair]) -> Pair:
    """Code of ``nat ∩ (terms[0] + terms[1] + ...)``: a centred form met with the natural
    inclusion ``nat`` of the same row (each encloses the range, so their meet does)."""
    m = em._sum(terms)
    r = em.new()
    em.line(f"{r[0]} = {lower_of(nat[0], m[0])}; {r[1]} = {upper_of(nat[1], m[1])}")
    return r


def build_forms(
    name: str,
    exprs: list[Any],
    labels: list[str],
    syms: dict[str, list[Any]],
    consts: dict[Any, Pair],
) -> Forms:
    """Compile the natural, tight (natural ∩ mean-value) and Jacobian functions of ``exprs``
    over the symbols ``syms`` (``"x"``, ``"u"``, ``"w"`` lists); ``consts``: symbols with
    constant enclosures (known parameters)."""
    import sympy as sp

    sites: list[str] = []
    z = syms["x"] + syms["w"]
    jac = [[sp.diff(e, s) for s in z] for e in exprs]
    chunks = []

    em = Emitter(sites)
    _header(f"{name}_natural", em, syms, consts)
    _ret(em, emit_rows(em, exprs, labels))
    chunks.append("\n".join(em.lines))

    em = Emitter(sites)
    _header(f"{name}_jacobian", em, syms, consts)
    flat: list[Pair] = []
    for i, row in enumerate(jac):
        flat += emit_rows(em, row, [f"d {labels[i]} / d {s}" for s in z])
    _ret(em, flat)
    chunks.append("\n".join(em.lines))

    em = Emitter(sites)
    _header(f"{name}_natjac", em, syms, consts)
    both = emit_rows(em, exprs, labels)
    flat = []
    for i, row in enumerate(jac):
        flat += emit_rows(em, row, [f"d {labels[i]} / d {s}" for s in z])
    em.line(f"return [{', '.join(p[0] for p in both)}], [{', '.join(p[1] for p in both)}], ")
    em.lines[-1] += f"[{', '.join(p[0] for p in flat)}], [{', '.join(p[1] for p in flat)}]"
    chunks.append("\n".join(em.lines))

    em = Emitter(sites)
    _header(f"{name}_tight", em, syms, consts)
    nat = emit_rows(em, exprs, labels)
    repeated = [_repeats(e, z) for e in exprs]
    out = _mean_value(em, exprs, nat, jac, repeated, syms, consts, labels) if any(repeated) else nat
    _ret(em, out)
    chunks.append("\n".join(em.lines))

    source = "\n\n".join(chunks) + "\n"
    ns = compile_source(source, f"{name}_natural").__globals__  # compiled once: one namespace
    nat, tight, jac, both = (ns[f"{name}_{k}"] for k in ("natural", "tight", "jacobian", "natjac"))
    return Forms(nat, tight, jac, both, sites, source)
