"""Generated forward-backward contractors for a constraint ``g(v, u) in [y]`` (HC4-revise,
[Jaulin2001, Ch. 4]).

Forward: the natural extension of ``g`` node by node (the same rounded operations as
:mod:`.forms`). Backward: from the root, intersected with ``[y]``, each node's enclosure is
projected onto its children through the inverse of its operation (``a + b = r`` gives
``a in r - b``; ``a * b = r`` gives ``a in r / b`` where ``b`` excludes 0; ``a**2 = r`` gives
``a in ±sqrt(r)``; ``exp``, ``log``, ``sqrt``, ``tanh``, ``sinh`` through their inverses), every
bound rounded outward. Operations without a cheap inverse (``sin``, ``min``...) contract nothing
below them, which is sound. An intersection that comes out empty proves that no ``v`` in the box
satisfies the constraint: the function returns False (an inconsistent measurement). A node over
constants only is folded into literals when the code is written (:meth:`.codegen.Emitter.fold`)
and is not narrowed (a constant's enclosure stays as it is); the function reads and writes back
only the leaves (and reads only the inputs) the expression uses.

A generated contractor ``c(vl, vh, u, ylo, yhi) -> bool`` narrows the lists ``vl``, ``vh`` in
place (``g in [ylo, yhi]``); for a vector ``g`` (:func:`build_vector_contractor`) ``ylo``,
``yhi`` are lists and the expressions share one DAG.
"""

from __future__ import annotations

import math
from typing import Any

from ._runtime import NAMESPACE, ldn, lup
from .codegen import (
    Emitter,
    compile_source,
    enclose_constant,
    is_literal,
    lower_of,
    product,
    quotient,
    upper_of,
)

__all__ = ["build_contractor", "build_vector_contractor"]


def _proj_sqr(al: float, ah: float, rl: float, rh: float) -> tuple[float, float]:
    """``a`` with ``a**2 in [rl, rh]`` (empty: lo > hi)."""
    if rh < 0.0:
        return 1.0, -1.0
    s = math.nextafter(math.sqrt(rh), math.inf)
    t = max(math.nextafter(math.sqrt(rl), -math.inf), 0.0) if rl > 0.0 else 0.0
    if al > -t:
        return max(al, t), min(ah, s)
    if ah < t:
        return max(al, -s), min(ah, -t)
    return max(al, -s), min(ah, s)


def _proj_sqrt(rl: float, rh: float) -> tuple[float, float]:
    """``a`` with ``sqrt(a) in [rl, rh]``."""
    if rh < 0.0:
        return 1.0, -1.0
    lo = math.nextafter(rl * rl, -math.inf) if rl > 0.0 else -math.inf
    return lo, math.nextafter(rh * rh, math.inf)


def _proj_exp(rl: float, rh: float) -> tuple[float, float]:
    """``a`` with ``exp(a) in [rl, rh]``."""
    if rh <= 0.0:
        return 1.0, -1.0
    lo = ldn(math.log(rl)) if rl > 0.0 else -math.inf
    return lo, lup(math.log(rh)) if rh < math.inf else math.inf


def _proj_tanh(rl: float, rh: float) -> tuple[float, float]:
    if rh <= -1.0 or rl >= 1.0:
        return 1.0, -1.0
    lo = ldn(math.atanh(rl)) if rl > -1.0 else -math.inf
    hi = lup(math.atanh(rh)) if rh < 1.0 else math.inf
    return lo, hi


def _proj_sinh(rl: float, rh: float) -> tuple[float, float]:
    lo = ldn(math.asinh(rl)) if rl > -math.inf else -math.inf
    hi = lup(math.asinh(rh)) if rh < math.inf else math.inf
    return lo, hi


def _excludes0(lo: float, hi: float) -> bool:
    return lo > 0.0 or hi < 0.0


def _value(literal: str) -> float:
    """The double a literal of the generated code stands for (``_PI``, ``_NI``: infinities)."""
    return float(eval(literal, {**NAMESPACE, "__builtins__": {}}))  # our literal


EXTRA = {
    "_proj_sqr": _proj_sqr,
    "_proj_sqrt": _proj_sqrt,
    "_proj_exp": _proj_exp,
    "_proj_tanh": _proj_tanh,
    "_proj_sinh": _proj_sinh,
    "_x0": _excludes0,
}


class _Node:
    __slots__ = ("args", "hi", "kind", "lo", "n")

    def __init__(self, kind: str, lo: str, hi: str, args: list[_Node], n: int = 0):
        self.kind, self.lo, self.hi, self.args, self.n = kind, lo, hi, args, n


class _Builder:
    """Forward code into ``em``, recording the nodes (emission order) for the backward pass."""

    def __init__(self, em: Emitter, leaves: dict[Any, tuple[str, str]], consts: dict[Any, Any]):
        import sympy as sp

        self.sp, self.em = sp, em
        self.leaves, self.consts = leaves, consts
        self.nodes: list[_Node] = []
        self.cache: dict[Any, _Node] = {}

    def node(self, e: Any) -> _Node:
        if e in self.cache:
            return self.cache[e]
        nd = self._node(e)
        self.cache[e] = nd
        return nd

    def _new(self, kind: str, call: str, args: list[_Node], n: int = 0) -> _Node:
        folded = self.em.fold(call)
        if folded is not None:  # over constants only: a constant
            return _Node("const", *folded, [])
        lo, hi = self.em.assign(call)
        nd = _Node(kind, lo, hi, args, n)
        self.nodes.append(nd)
        return nd

    def _binary(self, kind: str, parts: list[_Node]) -> _Node:
        acc = parts[0]
        for p in parts[1:]:
            if kind == "add":
                call = f"_nx({acc.lo} + {p.lo}, _NI), _nx({acc.hi} + {p.hi}, _PI)"
            else:
                call = product((acc.lo, acc.hi), (p.lo, p.hi))
            acc = self._new(kind, call, [acc, p])
        return acc

    def _node(self, e: Any) -> _Node:
        sp, em = self.sp, self.em
        if e.is_Symbol and e in self.leaves:
            lo, hi = self.leaves[e]
            return _Node("leaf", lo, hi, [])
        if e.is_Symbol and e in self.consts:
            lo, hi = self.consts[e]
            return _Node("const", lo, hi, [])
        if not e.free_symbols:
            lo, hi = (repr(v) for v in enclose_constant(e))
            return _Node("const", lo, hi, [])
        if e.is_Add:
            return self._binary("add", [self.node(a) for a in e.args])
        if e.is_Mul:
            args = list(e.args)
            if args[0] == -1:
                a = self.node(sp.Mul(*args[1:]))
                return self._new("neg", f"-{a.hi}, -{a.lo}", [a])
            return self._binary("mul", [self.node(a) for a in args])
        if e.is_Pow and e.exp.is_Integer and int(e.exp) == -1:
            a = self.node(e.base)
            return self._new("recip", f"_recip({a.lo}, {a.hi}, {em.site()})", [a])
        if e.is_Pow and e.exp == 2:
            a = self.node(e.base)
            return self._new("sqr", f"_sqr({a.lo}, {a.hi})", [a])
        if e.is_Pow and e.exp == sp.Rational(1, 2):
            a = self.node(e.base)
            return self._new("sqrt", f"_sqrt({a.lo}, {a.hi}, {em.site()})", [a])
        fn = type(e)
        if fn in (sp.exp, sp.log, sp.tanh, sp.sinh) and len(e.args) == 1:
            a = self.node(e.args[0])
            kind = fn.__name__
            site = f", {em.site()}" if kind == "log" else ""
            return self._new(kind, f"_{kind}({a.lo}, {a.hi}{site})", [a])
        # anything else: its enclosure from the generic emitter, no projection below it
        lo, hi = em.emit(e)
        if is_literal((lo, hi)):
            return _Node("const", lo, hi, [])
        nd = _Node("opaque", lo, hi, [])
        self.nodes.append(nd)
        return nd


def _narrow(em: Emitter, a: _Node, call: str) -> None:
    """``a`` ∩ the pair ``call`` evaluates to; return False when empty."""
    if a.kind == "const":
        return
    em.line(f"pl, ph = {call}")
    em.line(_meet(a))
    em.line(f"if {a.lo} > {a.hi}: return False")


def _meet(a: _Node) -> str:
    """Code of ``a <- a ∩ [pl, ph]``."""
    return f"{a.lo} = {lower_of(a.lo, 'pl')}; {a.hi} = {upper_of(a.hi, 'ph')}"


def _backward(em: Emitter, nd: _Node) -> None:
    r = nd
    k = nd.kind
    if k == "add":
        a, b = nd.args
        _narrow(em, a, f"_nx({r.lo} - {b.hi}, _NI), _nx({r.hi} - {b.lo}, _PI)")
        _narrow(em, b, f"_nx({r.lo} - {a.hi}, _NI), _nx({r.hi} - {a.lo}, _PI)")
    elif k == "mul":
        a, b = nd.args
        for x, o in ((a, b), (b, a)):
            if x.kind == "const":
                continue
            if o.kind == "const":  # its sign is known now
                inline = quotient((r.lo, r.hi), (o.lo, o.hi))
                if inline is not None:
                    _narrow(em, x, inline)
                elif _excludes0(_value(o.lo), _value(o.hi)):
                    _narrow(em, x, f"_div({r.lo}, {r.hi}, {o.lo}, {o.hi}, -1)")
                continue
            em.line(f"if _x0({o.lo}, {o.hi}):")
            em.lines.append("    " + f"    pl, ph = _div({r.lo}, {r.hi}, {o.lo}, {o.hi}, -1)")
            em.lines.append("        " + _meet(x))
            em.lines.append("    " + f"    if {x.lo} > {x.hi}: return False")
    elif k == "neg":
        _narrow(em, nd.args[0], f"-{r.hi}, -{r.lo}")
    elif k == "recip":
        em.line(f"if _x0({r.lo}, {r.hi}):")
        a = nd.args[0]
        if a.kind != "const":
            em.lines.append("    " + f"    pl, ph = _recip({r.lo}, {r.hi}, -1)")
            em.lines.append("        " + _meet(a))
            em.lines.append("    " + f"    if {a.lo} > {a.hi}: return False")
        else:
            em.lines.append("    " + "    pass")
    elif k == "sqr":
        a = nd.args[0]
        _narrow(em, a, f"_proj_sqr({a.lo}, {a.hi}, {r.lo}, {r.hi})")
    elif k in ("sqrt", "exp", "tanh", "sinh"):
        _narrow(em, nd.args[0], f"_proj_{k}({r.lo}, {r.hi})")
    elif k == "log":
        _narrow(em, nd.args[0], f"_exp({r.lo}, {r.hi})")


def build_contractor(
    name: str, expr: Any, label: str, leaves: list[Any], inputs: list[Any], consts: dict[Any, Any]
) -> tuple[Any, list[str]]:
    """Compile ``name(vl, vh, u, ylo, yhi) -> bool`` contracting the boxes of ``leaves`` (the
    lists ``vl``, ``vh``) with ``expr in [ylo, yhi]``; ``inputs`` read from ``u`` (thin)."""
    head = [f"def {name}(vl, vh, u, ylo, yhi):"]
    return _compile(name, [expr], [label], leaves, inputs, consts, head, lambda i: ("ylo", "yhi"))


def build_vector_contractor(
    name: str,
    exprs: list[Any],
    labels: list[str],
    leaves: list[Any],
    inputs: list[Any],
    consts: dict[Any, Any],
) -> tuple[Any, list[str]]:
    """Compile ``name(vl, vh, u, ylo, yhi) -> bool`` contracting the boxes of ``leaves`` with
    ``exprs[i] in [ylo[i], yhi[i]]`` for every ``i`` (lists, read at ``i < len(exprs)``;
    ``labels[i]`` names ``exprs[i]`` in a domain error):
    HC4-revise on the expressions' common DAG [Jaulin2001, Ch. 4], one forward pass over every
    node (a subexpression the components share is evaluated once), every root met with its
    bounds, then one backward pass in the reverse order, so that a shared node is narrowed by
    all its parents before it narrows its children."""
    head = [f"def {name}(vl, vh, u, ylo, yhi):"]
    return _compile(
        name, exprs, labels, leaves, inputs, consts, head, lambda i: (f"ylo[{i}]", f"yhi[{i}]")
    )


def _compile(
    name: str,
    exprs: list[Any],
    labels: list[str],
    leaves: list[Any],
    inputs: list[Any],
    consts: dict[Any, Any],
    head: list[str],
    bounds: Any,
) -> tuple[Any, list[str]]:
    """The code of a contractor: ``head`` (its signature), then HC4-revise on ``exprs`` with
    the root ``i`` met with the pair of code ``bounds(i)``."""
    sites: list[str] = []
    em = Emitter(sites)
    em.lines += head
    free = set().union(*(e.free_symbols for e in exprs))
    env: dict[Any, tuple[str, str]] = dict(consts)
    lv: dict[Any, tuple[str, str]] = {}
    used = [i for i, s in enumerate(leaves) if s in free]
    for i in used:
        em.line(f"v{i}l = vl[{i}]; v{i}h = vh[{i}]")
        env[leaves[i]] = lv[leaves[i]] = (f"v{i}l", f"v{i}h")
    cin: dict[Any, tuple[str, str]] = dict(consts)
    for i, s in enumerate(inputs):
        if s in free:
            em.line(f"u{i} = u[{i}]")
            env[s] = cin[s] = (f"u{i}", f"u{i}")
    em.scope(env)
    b = _Builder(em, lv, cin)
    roots = []
    for expr, label in zip(exprs, labels, strict=True):
        em.label = label
        root = b.node(expr)
        if root.kind in ("leaf", "const"):  # g is one variable: a node to intersect with y
            lo, hi = em.new()  # (a variable even for a constant: it is intersected with y)
            em.line(f"{lo}, {hi} = {root.lo}, {root.hi}")
            nd = _Node("ident", lo, hi, [root])
            b.nodes.append(nd)
            root = nd
        roots.append(root)
    for i, root in enumerate(roots):
        ylo, yhi = bounds(i)
        em.line(f"{root.lo} = {lower_of(root.lo, ylo)}; {root.hi} = {upper_of(root.hi, yhi)}")
        em.line(f"if {root.lo} > {root.hi}: return False")
    for nd in reversed(b.nodes):
        if nd.kind == "ident":
            _narrow(em, nd.args[0], f"{nd.lo}, {nd.hi}")
        else:
            _backward(em, nd)
    for i in used:
        em.line(f"vl[{i}] = v{i}l; vh[{i}] = v{i}h")
    em.line("return True")
    source = "\n".join(em.lines) + "\n"
    return compile_source(source, name, EXTRA), sites
