"""A rigorous vertex-switching simulator for soundness tests (written here, not ivobs.simulate).

Every record it returns is an *exact* trajectory of the model, floating-point rounding of the
simulator included, however long the run and however chaotic the map:

* Each step is evaluated in ``mpmath.iv`` interval arithmetic at 200 bits (60 digits), from the
  model's SymPy expressions (``sys.f_exprs``, ``sys.h_exprs``), with the parameters and signals
  on the vertices of their bounds (a decimal bound such as ``0.005`` is the tiny interval around
  the decimal, so the vertex value is the exact decimal).
* A state row ``x_i+ = f0_i(x, u, p) + s`` whose signal ``s`` enters only there, additively,
  is *absorbed*: the new state is the double ``x_i+`` next to ``f0_i + vertex`` for which
  ``x_i+ - f0_i ⊆ [s_lo, s_hi]`` holds for the whole enclosure of ``f0_i``: some admissible
  ``s`` (within about one ulp of the vertex) makes it exact. Such a state is a point, a double.
* Any other row (Hénon's ``x2+ = b x1``) keeps its 60-digit enclosure; the true state is the
  exact value inside it, so a box must contain the whole small interval (``X_lo``, ``X_hi``,
  rounded outwards to doubles). Absorbed rows reset the enclosures at every step, so they do
  not grow along a chaotic orbit.
* Each measurement ``y_j = g_j(x, u, p) + v_j`` is the double next to ``g_j + vertex`` with
  ``y_j - g_j ⊆ [v_lo, v_hi]`` for the whole enclosure of ``g_j``.

A float64 run of a chaotic map is not a trajectory of the model (its rounding grows
exponentially along the orbit); this one is, so the soundness check relies on no margin of the
estimators. Used by tests/test_nl_sound_random.py and benchmarks/bench_nl_sound.py.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp
from mpmath import iv, libmp

import ivobs

PREC = 200
"""Bits of the interval arithmetic (about 60 digits)."""

Fn = Callable[[dict[str, Any]], Any]


def _tanh(x: Any) -> Any:
    """``tanh`` over an interval: increasing, each end ``1 - 2/(exp(2 t) + 1)`` in intervals."""
    lo = 1 - 2 / (iv.exp(2 * iv.mpf(x.a)) + 1)
    hi = 1 - 2 / (iv.exp(2 * iv.mpf(x.b)) + 1)
    return iv.mpf([lo.a, hi.b])


_FUNCS: dict[Any, Callable[[Any], Any]] = {
    sp.sin: iv.sin,
    sp.cos: iv.cos,
    sp.exp: iv.exp,
    sp.log: iv.log,
    sp.tan: iv.tan,
    sp.tanh: _tanh,
    sp.Abs: abs,
}


def _compile(e: sp.Expr) -> Fn:
    """The expression as a closure over ``{name: iv interval}`` (built once, called per step).
    Rationals are divided in intervals, never as doubles."""
    if e.is_Symbol:
        name = e.name
        return lambda env: env[name]
    if e.is_Integer:
        c = iv.mpf(int(e))
        return lambda env: c
    if e.is_Rational:
        c = iv.mpf(int(e.p)) / iv.mpf(int(e.q))
        return lambda env: c
    if e is sp.pi or e is sp.E:
        c = iv.pi if e is sp.pi else iv.e
        return lambda env: c
    if e.is_Add or e.is_Mul:
        parts = [_compile(a) for a in e.args]
        if e.is_Add:
            return lambda env: _fold(parts, env, lambda a, b: a + b)
        return lambda env: _fold(parts, env, lambda a, b: a * b)
    if e.is_Pow:
        base, ex = _compile(e.base), e.exp
        if ex.is_Integer:
            n = int(ex)
            return lambda env: base(env) ** n
        if ex == sp.Rational(1, 2):
            return lambda env: iv.sqrt(base(env))
        power = _compile(ex)
        return lambda env: iv.exp(power(env) * iv.log(base(env)))
    if e.func in (sp.Min, sp.Max):
        parts = [_compile(a) for a in e.args]
        pick = min if e.func is sp.Min else max
        return lambda env: _minmax(pick, [q(env) for q in parts])
    if e.func in _FUNCS:
        fn, arg = _FUNCS[e.func], _compile(e.args[0])
        return lambda env: fn(arg(env))
    raise NotImplementedError(f"exactsim: no interval form for {e.func} in {e}")


def _fold(parts: list[Fn], env: dict[str, Any], op: Callable[[Any, Any], Any]) -> Any:
    acc = parts[0](env)
    for q in parts[1:]:
        acc = op(acc, q(env))
    return acc


def _minmax(pick: Callable[..., Any], vals: list[Any]) -> Any:
    return iv.mpf([pick(v.a for v in vals), pick(v.b for v in vals)])


def _dec(v: float) -> Any:
    """The decimal a bound prints as, enclosed (``0.005`` -> the interval around 5/1000)."""
    return iv.mpf(repr(float(v)))


def down(x: Any) -> float:
    """The largest double <= the interval's lower end."""
    return float(libmp.to_float(x._mpi_[0], rnd="f"))


def up(x: Any) -> float:
    """The smallest double >= the interval's upper end."""
    return float(libmp.to_float(x._mpi_[1], rnd="c"))


def inward(enc: Any, lo: Any, hi: Any, to_hi: bool) -> float:
    """A double ``z`` with ``z - g`` in ``[lo, hi]`` for every ``g`` in ``enc`` (``lo``, ``hi``
    decimal enclosures; the test is on their inner ends), next to ``g + hi`` or ``g + lo``."""
    # rounding towards the inside makes the first candidate the answer unless enc is too wide
    z = down(enc + hi) if to_hi else up(enc + lo)
    for _ in range(64):
        diff = iv.mpf(z) - enc
        if diff.a >= lo.b and diff.b <= hi.a:
            return z
        z = math.nextafter(z, -math.inf if to_hi else math.inf)
    raise AssertionError(f"exactsim: bounds [{lo}, {hi}] too narrow for a double near {enc}")


def absorbed_signal(sys: ivobs.NonlinearSystem, i: int) -> str | None:
    """The signal that enters row ``i`` of ``f`` alone and additively (``f_i = f0 + s``), or
    None. A signal shared with another row or with ``h`` is not absorbed."""
    e = sys.f_exprs[i]
    others = [x for j, x in enumerate(sys.f_exprs) if j != i] + list(sys.h_exprs)
    for s in sorted(e.free_symbols, key=str):
        if s.name in sys.signal_names and not (e - s).has(s):
            if not any(o.has(s) for o in others):
                return str(s.name)
    return None


def noise_signal(sys: ivobs.NonlinearSystem, j: int) -> str:
    """The signal of output ``j``, which must enter it alone and additively."""
    e = sys.h_exprs[j]
    others = list(sys.f_exprs) + [x for k, x in enumerate(sys.h_exprs) if k != j]
    for s in sorted(e.free_symbols, key=str):
        if s.name in sys.signal_names and not (e - s).has(s):
            if not any(o.has(s) for o in others):
                return str(s.name)
    raise NotImplementedError(f"exactsim: output {j} ({e}) has no additive noise of its own")


@dataclass
class Record:
    """An exact trajectory: the true state lies in ``[X_lo, X_hi]`` (equal on absorbed rows),
    ``Y`` the measurements, ``U`` the inputs used."""

    X_lo: np.ndarray
    X_hi: np.ndarray
    Y: np.ndarray
    U: np.ndarray | None

    def misses(self, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """The steps whose box does not contain the whole enclosure of the true state."""
        bad = (lower > self.X_lo) | (self.X_hi > upper) | np.isnan(lower) | np.isnan(upper)
        return np.flatnonzero(bad.any(axis=1))


def simulate(
    sys: ivobs.NonlinearSystem,
    x0: Sequence[float],
    T: int,
    u: np.ndarray | None = None,
    seed: int = 0,
) -> Record:
    """``T`` exact steps from the point ``x0`` (doubles), every unknown parameter and signal on
    a random vertex of its bounds at every step."""
    rng = np.random.default_rng(seed)
    old = iv.prec
    iv.prec = PREC
    try:
        return _run(sys, x0, T, u, rng)
    finally:
        iv.prec = old


def _run(sys: Any, x0: Sequence[float], T: int, u: Any, rng: np.random.Generator) -> Record:
    fs = [(_compile(e), s) for e, s in _rows(sys)]
    outs = [noise_signal(sys, j) for j in range(sys.ny)]
    hs = [_compile(_without(e, v)[0]) for e, v in zip(sys.h_exprs, outs)]
    known = {n: _dec(v) for n, v in sys.known_params.items()}
    vert = {n: (_dec(lo), _dec(hi)) for n, (lo, hi) in sys.param_bounds.items()}
    vert.update({n: (_dec(lo), _dec(hi)) for n, (lo, hi) in sys.signal_bounds.items()})
    names = list(vert)
    x = [iv.mpf(float(v)) for v in x0]
    X_lo, X_hi, Y = np.empty((T, sys.nx)), np.empty((T, sys.nx)), np.empty((T, sys.ny))
    for k in range(T):
        hi_side = rng.integers(0, 2, len(names)).astype(bool)
        env = {**known, **{n: vert[n][int(b)] for n, b in zip(names, hi_side)}}
        env.update(zip(sys.state_names, x))
        if sys.nu:
            env.update(zip(sys.input_names, (iv.mpf(float(c)) for c in u[k])))
        X_lo[k] = [down(c) for c in x]
        X_hi[k] = [up(c) for c in x]
        for j, (g, v) in enumerate(zip(hs, outs)):
            Y[k, j] = inward(g(env), *vert[v], to_hi=bool(env[v] is vert[v][1]))
        x = [
            iv.mpf(inward(f(env), *vert[s], to_hi=bool(env[s] is vert[s][1]))) if s else f(env)
            for f, s in fs
        ]
    return Record(X_lo, X_hi, Y, None if u is None else np.asarray(u[:T], dtype=float))


def _rows(sys: Any) -> list[tuple[sp.Expr, str | None]]:
    """Each row of ``f`` without its absorbed signal, and that signal's name (or None)."""
    return [_without(e, absorbed_signal(sys, i)) for i, e in enumerate(sys.f_exprs)]


def _without(e: sp.Expr, name: str | None) -> tuple[sp.Expr, str | None]:
    if name is None:
        return e, None
    [s] = [q for q in e.free_symbols if q.name == name]
    return e - s, name


# -- linear systems with interval matrices --------------------------------------------------
def vertex_matrix(lo: np.ndarray, hi: np.ndarray, k: int, v: Any, rng: Any) -> np.ndarray:
    """A vertex of the interval matrix ``[lo, hi]`` acting on ``v``: random at even steps; at
    odd steps the one that makes every row of ``M v`` extreme (``ΔM v = ± R |v|``, a random
    sign per row), the hardest case of the interval product."""
    if k % 2 == 0:
        return np.where(rng.integers(0, 2, size=lo.shape).astype(bool), hi, lo)
    s = rng.choice([-1.0, 1.0], size=(lo.shape[0], 1))
    return np.where(s * np.sign(np.asarray(v, dtype=float))[None, :] > 0, hi, lo)


def _private(M: np.ndarray, other: np.ndarray) -> list[int]:
    """For each row of ``M``, a column nonzero in that row only and zero in ``other``."""
    cols = []
    for i in range(M.shape[0]):
        ok = [j for j in range(M.shape[1]) if M[i, j] != 0 and np.count_nonzero(M[:, j]) == 1]
        ok = [j for j in ok if not other[:, j].any()]
        if not ok:
            raise NotImplementedError(f"exactsim: row {i} has no disturbance of its own")
        cols.append(ok[0])
    return cols


def _dot(M: np.ndarray, v: Sequence[Any]) -> list[Any]:
    return [sum((iv.mpf(float(m)) * c for m, c in zip(row, v)), iv.mpf(0)) for row in M]


def simulate_linear(
    sys: ivobs.LinearSystem,
    x0: Sequence[float],
    T: int,
    u: np.ndarray,
    seed: int = 0,
    vertices: np.ndarray | None = None,
) -> Record:
    """``T`` exact steps of a (possibly interval-matrix) discrete-time linear system: ``A``,
    ``B``, ``C``, ``D`` on vertices (:func:`vertex_matrix`), every disturbance on a vertex of
    ``d`` (random, or ``vertices[k]``: True for the upper end); each state and output is
    absorbed into its own disturbance column as in :func:`simulate` (``E``, ``F`` must give
    every row one; the doubles of ``d`` are exact)."""
    rng = np.random.default_rng(seed)
    E, F, dlo, dhi = sys.E, sys.F, sys.d.lo, sys.d.hi
    ecol, fcol = _private(E, F), _private(F, E)
    old, iv.prec = iv.prec, PREC
    try:
        x = [iv.mpf(float(v)) for v in x0]
        X, Y = np.empty((T, sys.nx)), np.empty((T, sys.ny))
        for k in range(T):
            X[k] = [float(c.a) for c in x]  # points: every row is absorbed
            M = _matrices(sys, k, X[k], u[k], rng)
            hi_side = rng.integers(0, 2, size=dlo.shape).astype(bool)
            if vertices is not None:
                hi_side = np.asarray(vertices[k], dtype=bool)
            d = np.where(hi_side, dhi, dlo)
            ys = _plus(_dot(M["C"], x), _dot(M["D"], u[k]), F, d, fcol)
            Y[k] = [_absorb(g, F[j, c], dlo[c], dhi[c], hi_side[c]) for j, (g, c) in
                    enumerate(zip(ys, fcol))]  # fmt: skip
            xs = _plus(_dot(M["A"], x), _dot(M["B"], u[k]), E, d, ecol)
            x = [iv.mpf(_absorb(g, E[i, c], dlo[c], dhi[c], hi_side[c])) for i, (g, c) in
                 enumerate(zip(xs, ecol))]  # fmt: skip
    finally:
        iv.prec = old
    return Record(X, X.copy(), Y, np.asarray(u[:T], dtype=float))


def _matrices(sys: Any, k: int, x: np.ndarray, u: np.ndarray, rng: Any) -> dict[str, Any]:
    """The plant's ``A``, ``B``, ``C``, ``D`` at step ``k``: vertices of the interval ones."""
    boxes = sys.interval_matrices()
    out = {}
    for n, exact in zip("ABCD", (sys.A, sys.B, sys.C, sys.D)):
        bx = boxes.get(n)
        out[n] = exact if bx is None else vertex_matrix(bx.lo, bx.hi, k, x if n in "AC" else u, rng)
    return out


def _plus(a: list[Any], b: list[Any], G: np.ndarray, d: np.ndarray, own: list[int]) -> list[Any]:
    """``a + b + G d`` without each row's own column (absorbed after)."""
    out = []
    for i, (p, q) in enumerate(zip(a, b)):
        rest = [j for j in range(G.shape[1]) if j != own[i] and G[i, j] != 0]
        out.append(p + q + sum((iv.mpf(float(G[i, j])) * iv.mpf(float(d[j])) for j in rest), 0))
    return out


def _absorb(g: Any, gain: float, lo: float, hi: float, to_hi: bool) -> float:
    """The double next to ``g + gain * (hi or lo)`` with ``(z - g) / gain`` in ``[lo, hi]``."""
    ends = [iv.mpf(float(gain)) * iv.mpf(float(b)) for b in (lo, hi)]  # exact products
    a, b = ends if gain > 0 else ends[::-1]
    return inward(g, a, b, to_hi=bool(to_hi) == (gain > 0))
