"""``NonlinearSystem``: ``x[k+1] = f(x, u, p, d)``, ``y[k] = h(x, u, p, d)`` with named states,
inputs, parameters (known numbers, or unknown within bounds and free to change at every step)
and bounded unknown signals ``d``.

The per-step unknown vector is ``w = (unknown parameters, d signals)`` with constant bounds
``w_box``. ``f`` and ``h`` are expressions (strings, :mod:`.parse`) or Python callables traced
with SymPy symbols (:mod:`ivobs.nlmath`); both become SymPy expressions, from which guaranteed
interval functions are generated once (:mod:`.forms`, :mod:`.contract`). docs/nonlinear.md.
"""

from __future__ import annotations

import functools
import importlib
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from ...errors import IvobsError
from ...sets import Box
from ..linear import TimeBase, check_dt
from ..statespace import SignalNames
from ._runtime import DomainError
from .codegen import enclose_float
from .contract import build_contractor, build_vector_contractor
from .forms import Forms, build_forms
from .parse import RESERVED, folded_name, parse_expression
from .trace import expression_text, trace_callable

__all__ = ["NonlinearSystem"]

Pair = tuple[float, float]


def _names(what: str, value: Any) -> list[str]:
    if value is None:
        return []
    if isinstance(value, str):
        value = [value]
    try:
        names = list(value)
    except TypeError:
        raise IvobsError(f"{what}: expected a list of names, got {type(value).__name__}") from None
    for n in names:
        if not isinstance(n, str) or not n.isidentifier() or n.startswith("_"):
            raise IvobsError(
                f"{what}: expected names (Python identifiers not starting with '_'), got {n!r}"
            )
        if n in RESERVED:
            raise IvobsError(f"{what}: {n!r} is a reserved name (a function or constant)")
        if folded_name(n) != n:
            raise IvobsError(f"{what}: {n!r} is read as {folded_name(n)!r} in expressions "
                             f"(Unicode NFKC folding); name it {folded_name(n)!r}")  # fmt: skip
    return names


def _number(what: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)):
        raise IvobsError(f"{what}: expected a number, got {v!r}")
    f = float(v)
    if not math.isfinite(f):
        raise IvobsError(f"{what}: expected a finite number, got {v!r}")
    return f


def _bounds(what: str, v: Any) -> Pair:
    if (
        isinstance(v, (str, bytes))
        or not isinstance(v, (Sequence, np.ndarray))
        or np.ndim(v) != 1
        or len(v) != 2
    ):
        raise IvobsError(f"{what}: expected a pair (lo, hi), got {v!r}")
    lo, hi = _number(f"{what}[0]", v[0]), _number(f"{what}[1]", v[1])
    if lo > hi:
        raise IvobsError(f"{what}: lower bound {lo} > upper bound {hi}")
    return lo, hi


class NonlinearSystem(TimeBase):
    """A discrete-time nonlinear model with bounded unknowns (see the module docstring).

    Parameters
    ----------
    f : list of ``nx`` expressions, or a callable ``f(x, u, p, d)`` returning ``nx`` values
        (``x``, ``u``: tuples; ``p``, ``d``: dicts by name), written with :mod:`ivobs.nlmath`.
    h : list of ``ny`` expressions or a callable, likewise.
    states, inputs : the names used for ``x`` and ``u``.
    params : ``{name: number}`` (known) or ``{name: (lo, hi)}`` (unknown, any value in the
        bounds at every step).
    d : ``{name: (lo, hi)}``: bounded unknown signals (disturbances, noise).
    dt : ``True`` or a sampling period ``> 0``; ``0``: ``f`` is the vector field of
        ``x' = f(x, u, p, d)`` (continuous time), for :meth:`discretize` (the methods take its
        result, a validated flow; docs/nonlinear.md).
    outputs : names of the outputs (default ``y1..y<ny>``).
    """

    is_time_varying = False
    has_constant_bounds = True

    def __init__(
        self,
        f: Any,
        h: Any,
        *,
        states: Any,
        inputs: Any = (),
        params: dict[str, Any] | None = None,
        d: dict[str, Any] | None = None,
        dt: Any = True,
        outputs: Any = None,
    ) -> None:
        import sympy as sp

        self.dt = check_dt(dt)
        self.state_names = _names("states", states)
        if not self.state_names:
            raise IvobsError("states: expected at least one state name")
        self.input_names = _names("inputs", inputs)
        params = {} if params is None else params
        d = {} if d is None else d
        for what, dct in (("params", params), ("d", d)):
            if not isinstance(dct, dict):
                raise IvobsError(f"{what}: expected a dict {{name: bounds}}, got {dct!r}")
        _names("params", list(params))
        _names("d", list(d))
        self.known_params: dict[str, float] = {}
        self.param_bounds: dict[str, Pair] = {}
        for name, v in params.items():
            if isinstance(v, (Sequence, np.ndarray)) and not isinstance(v, str) and np.ndim(v):
                self.param_bounds[name] = _bounds(f"params[{name!r}]", v)
            else:
                self.known_params[name] = _number(f"params[{name!r}]", v)
        self.signal_bounds = {n: _bounds(f"d[{n!r}]", v) for n, v in d.items()}
        every = self.state_names + self.input_names + list(params) + list(d)
        dup = sorted({n for n in every if every.count(n) > 1})
        if dup:
            raise IvobsError(
                f"names: {', '.join(map(repr, dup))} used twice among states, inputs, params, d"
            )
        self.param_names = list(self.param_bounds)
        self.signal_names = list(self.signal_bounds)
        self._sym = {n: sp.Symbol(n, real=True) for n in every}
        self.f_exprs = self._read("f", f, len(self.state_names))
        self.h_exprs = self._read("h", h, None)
        self.f_text = [expression_text(e) for e in self.f_exprs]
        self.h_text = [expression_text(e) for e in self.h_exprs]
        self.output_names = _names("outputs", outputs) or [f"y{i + 1}" for i in range(self.ny)]
        if len(self.output_names) != self.ny:
            raise IvobsError(f"outputs: expected {self.ny} names, got {len(self.output_names)}")
        self.names = SignalNames(
            states=tuple(self.state_names),
            inputs=tuple(self.input_names) or None,
            outputs=tuple(self.output_names),
            disturbances=tuple(self.signal_names) or None,
        )
        """Labels for plots and tables (as ``LinearSystem.names``; a system file may add
        ``units``)."""
        self._build()

    # -- construction -----------------------------------------------------------------------
    def _read(self, what: str, given: Any, n: int | None) -> list[Any]:
        if callable(given):
            exprs = trace_callable(what, given, self)
        else:
            if isinstance(given, str) or not isinstance(given, (Sequence, np.ndarray)):
                raise IvobsError(
                    f"{what}: expected a list of expressions (one per "
                    f"{'state' if what == 'f' else 'output'}) or a callable, got {given!r}"
                )
            exprs = [parse_expression(t, self._sym, f"{what}[{i}]") for i, t in enumerate(given)]
        if n is not None and len(exprs) != n:
            raise IvobsError(f"{what}: expected {n} expressions (one per state), got {len(exprs)}")
        return exprs

    def _build(self) -> None:
        syms = self._groups()
        self._consts: dict[Any, tuple[str, str]] = {}
        for n, v in self.known_params.items():
            lo, hi = enclose_float(v)
            self._consts[self._sym[n]] = (repr(lo), repr(hi))
        self._f = build_forms("f", self.f_exprs, self._labels("f"), syms, self._consts)
        self._h = build_forms("h", self.h_exprs, self._labels("h"), syms, self._consts)
        leaves = syms["x"] + syms["w"]
        self._hc = [
            build_contractor(f"hc{i}", e, self._labels("h")[i], leaves, syms["u"], self._consts)
            for i, e in enumerate(self.h_exprs)
        ]
        # outputs that share a state or unknown pass what one narrows on to the others
        seen: set[Any] = set()
        self._hc_coupled = False
        for e in self.h_exprs:
            mine = e.free_symbols & set(leaves)
            self._hc_coupled = self._hc_coupled or bool(mine & seen)
            seen |= mine
        self._hf: list[Any] | None = None
        self._fc: tuple[Any, list[str]] | None = None
        pairs = [self.param_bounds[n] for n in self.param_names]
        pairs += [self.signal_bounds[n] for n in self.signal_names]
        wl = [enclose_float(p[0])[0] for p in pairs]
        wh = [enclose_float(p[1])[1] for p in pairs]
        self.w_box = Box(np.array(wl, dtype=float), np.array(wh, dtype=float))
        dl, dh = wl[len(self.param_names) :], wh[len(self.param_names) :]
        self._d_box = Box(np.array(dl, dtype=float), np.array(dh, dtype=float))

    def _groups(self) -> dict[str, list[Any]]:
        s = self._sym
        return {
            "x": [s[n] for n in self.state_names],
            "u": [s[n] for n in self.input_names],
            "w": [s[n] for n in self.param_names + self.signal_names],
        }

    def _labels(self, what: str) -> list[str]:
        texts = self.f_text if what == "f" else self.h_text
        return [f"{what}[{i}] = {t!r}" for i, t in enumerate(texts)]

    # -- the SystemModel protocol -----------------------------------------------------------
    @property
    def nx(self) -> int:
        return len(self.state_names)

    @property
    def nu(self) -> int:
        return len(self.input_names)

    @property
    def ny(self) -> int:
        return len(self.h_exprs)

    @property
    def nd(self) -> int:
        return len(self.signal_names)

    @property
    def nw(self) -> int:
        """Length of the per-step unknown vector ``w = (unknown params, d signals)``."""
        return len(self.param_names) + len(self.signal_names)

    def discretize(
        self, Ts: float, *, order: int = 4, substeps: int = 1, disturbances: str = "varying"
    ) -> NonlinearSystem:
        """The guaranteed discretisation of this continuous-time system (``dt=0``) with
        sampling period ``Ts``: a discrete-time model whose ``f`` encloses the exact flow over
        one period, by the interval Taylor method of order ``order`` with ``substeps`` substeps
        (halved further where the a priori enclosure fails) [Nedialkov1999], [Lohner1987].
        ``u`` and the unknown parameters ``p`` are constant over each period; the signals ``d``
        vary in their box at every instant (``disturbances="varying"``, a differential
        inclusion [Kapela2009]) or are held (``"held"``: any value of their box per period).
        :class:`~ivobs.model.nonlinear.flow.FlowSystem`, docs/continuous.md."""
        # FlowSystem derives from this class (flow -> system): it is looked up when called,
        # as the method registry loads its modules, so the dependency stays one-way and the
        # Taylor machinery loads only for continuous-time models
        flow = importlib.import_module(f"{__package__}.flow")
        result: NonlinearSystem = flow.FlowSystem(
            self, Ts, order=order, substeps=substeps, disturbances=disturbances
        )
        return result

    @property
    def d(self) -> Box:
        """Bounds of the signals ``d`` (in ``signal_names`` order)."""
        return self._d_box

    def d_at(self, k: Any, y: Any = None) -> Box:
        return self._d_box

    # -- guaranteed evaluations (numpy in, numpy out) -----------------------------------------
    def _call(self, fn: Any, sites: list[str], *args: Any) -> Any:
        try:
            return fn(*args)
        except DomainError as exc:
            raise IvobsError(
                f"{sites[exc.site] if 0 <= exc.site < len(sites) else 'expression'}: "
                f"{exc.what} (the range [{exc.lo:.17g}, {exc.hi:.17g}] reached it); the model "
                "is undefined for every point of the box"
            ) from None

    def _args(self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any) -> tuple[list[float], ...]:
        def vec(name: str, v: Any, n: int) -> list[float]:
            a = np.asarray(v, dtype=float).reshape(-1)
            if a.shape[0] != n:
                raise IvobsError(f"{name}: expected {n} values, got {a.shape[0]}")
            return list(a.tolist())

        nx, nw = self.nx, self.nw
        u = np.zeros(0) if u is None else u
        return (
            vec("xlo", xlo, nx),
            vec("xhi", xhi, nx),
            vec("u", u, self.nu),
            vec("wlo", wlo, nw),
            vec("whi", whi, nw),
        )

    def _box(self, forms: Forms, tight: bool, *args: Any) -> tuple[np.ndarray, np.ndarray]:
        fn = forms.tight if tight else forms.natural
        lo, hi = self._call(fn, forms.sites, *self._args(*args))
        return np.array(lo, dtype=float), np.array(hi, dtype=float)

    def f_box(self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any) -> tuple[np.ndarray, ...]:
        """Natural inclusion ``(lo, hi)`` of ``f`` over the box (shape ``(nx,)``)."""
        return self._box(self._f, False, xlo, xhi, u, wlo, whi)

    def f_tight_box(self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any) -> tuple[np.ndarray, ...]:
        """Natural inclusion ∩ mean-value form of ``f`` (:mod:`.forms`)."""
        return self._box(self._f, True, xlo, xhi, u, wlo, whi)

    def h_box(self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any) -> tuple[np.ndarray, ...]:
        """Natural inclusion ``(lo, hi)`` of ``h`` (shape ``(ny,)``)."""
        return self._box(self._h, False, xlo, xhi, u, wlo, whi)

    def h_tight_box(self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any) -> tuple[np.ndarray, ...]:
        """Natural inclusion ∩ mean-value form of ``h``."""
        return self._box(self._h, True, xlo, xhi, u, wlo, whi)

    def _jac(self, forms: Forms, n: int, *args: Any) -> tuple[np.ndarray, ...]:
        lo, hi = self._call(forms.jacobian, forms.sites, *self._args(*args))
        m = self.nx + self.nw
        L = np.array(lo, dtype=float).reshape(n, m)
        H = np.array(hi, dtype=float).reshape(n, m)
        nx = self.nx
        return L[:, :nx].copy(), H[:, :nx].copy(), L[:, nx:].copy(), H[:, nx:].copy()

    def f_jac_box(self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any) -> tuple[np.ndarray, ...]:
        """Enclosures ``(Jx_lo, Jx_hi, Jw_lo, Jw_hi)`` of ``df/dx`` ``(nx, nx)`` and ``df/dw``
        ``(nx, nw)`` over the box."""
        return self._jac(self._f, self.nx, xlo, xhi, u, wlo, whi)

    def h_jac_box(self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any) -> tuple[np.ndarray, ...]:
        """Enclosures of ``dh/dx`` ``(ny, nx)`` and ``dh/dw`` ``(ny, nw)`` over the box."""
        return self._jac(self._h, self.ny, xlo, xhi, u, wlo, whi)

    def evaluators(self, which: str) -> tuple[Callable[..., Any], Callable[..., Any]]:
        """``(natural, natjac)`` of ``f`` (``which="f"``) or ``h``: list-in, list-out forms of
        :meth:`f_box` and of :meth:`f_box` with :meth:`f_jac_box` over the same box (one call,
        the Jacobian row-major over ``(x, w)``, :class:`.forms.Forms`) for the per-step code of
        the set methods: the arguments ``(xl, xh, u, wl, wh)`` are lists of floats of the right
        lengths and are not checked; a domain error raises IvobsError as elsewhere."""
        forms = self._f if which == "f" else self._h
        call, sites, nat, nj = self._call, forms.sites, forms.natural, forms.natjac
        return (lambda *a: call(nat, sites, *a)), (lambda *a: call(nj, sites, *a))

    def h_contract(
        self, xlo: Any, xhi: Any, u: Any, wlo: Any, whi: Any, y: Any, y_hi: Any = None
    ) -> tuple[np.ndarray, ...] | None:
        """Forward-backward contraction of the box ``(x, w)`` with ``h(x, u, w) = y`` (or
        ``h in [y, y_hi]``; NaN components of ``y`` are skipped): ``(xlo, xhi, wlo, whi)``, or
        None when no point of the box is consistent with ``y`` (:mod:`.contract`)."""
        xl, xh, uu, wl, wh = self._args(xlo, xhi, u, wlo, whi)
        yv = np.asarray(y, dtype=float).reshape(-1)
        yh = yv if y_hi is None else np.asarray(y_hi, dtype=float).reshape(-1)
        if yv.shape[0] != self.ny or yh.shape[0] != self.ny:
            raise IvobsError(f"y: expected {self.ny} values, got {yv.shape[0]}")
        vl, vh = xl + wl, xh + wh
        if not self.contract_lists(vl, vh, uu, yv.tolist(), yh.tolist()):
            return None
        nx = self.nx
        a = np.array
        return a(vl[:nx]), a(vh[:nx]), a(vl[nx:], dtype=float), a(vh[nx:], dtype=float)

    def contract_lists(
        self, vl: list[float], vh: list[float], u: list[float], ylo: list[float], yhi: list[float]
    ) -> bool:
        """:meth:`h_contract` on the lists ``vl = xl + wl``, ``vh`` (narrowed in place) with
        ``h in [ylo, yhi]``; two sweeps over the outputs when some of them share a state or
        unknown (the second carries what one output narrowed to the others; outputs over
        disjoint variables have nothing to pass on, and each is contracted once, as a single
        output is)."""
        for _ in range(2 if self._hc_coupled else 1):
            for (fn, sites), a, b in zip(self._hc, ylo, yhi):
                if a == a and not self._call(fn, sites, vl, vh, u, a, b):
                    return False
        return True

    def hf_contractors(self) -> list[tuple[Any, list[str]]]:
        """Contractors of ``h(f(x', u', w'), u, w) in [ylo, yhi]`` over the leaves
        ``(x', w', w)`` with inputs ``(u', u)``: one step back through the model (built on
        first use)."""
        if self._hf is None:
            import sympy as sp

            g = self._groups()
            prev = {s: sp.Symbol(f"{s.name}__prev", real=True) for s in g["x"] + g["u"] + g["w"]}
            fp = [e.xreplace(prev) for e in self.f_exprs]
            sub = dict(zip(g["x"], fp))
            leaves = [prev[s] for s in g["x"] + g["w"]] + g["w"]
            inputs = [prev[s] for s in g["u"]] + g["u"]
            self._hf = [
                build_contractor(
                    f"hf{i}", e.xreplace(sub), f"h[{i}](f(x[k-1]))", leaves, inputs, self._consts
                )
                for i, e in enumerate(self.h_exprs)
            ]
        return self._hf

    def f_contractor(self) -> tuple[Any, list[str]]:
        """The contractor of ``f(x, u, w) in [lo, hi]`` over the leaves ``(x, w)`` with the
        inputs ``u``, every state at once (:func:`.contract.build_vector_contractor`, called
        ``(vl, vh, u, lo, hi)`` with the box of the next state in ``lo``, ``hi``): the box of a
        step narrowed by the box of the next state (a window of steps back; built on first
        use)."""
        if self._fc is None:
            g = self._groups()
            self._fc = build_vector_contractor(
                "fc", self.f_exprs, self._labels("f"), g["x"] + g["w"], g["u"], self._consts
            )
        return self._fc

    def f_repeated_rows(self) -> list[int]:
        """The rows of ``f`` in whose expression some state or unknown occurs more than once
        (``x1 - k sqrt(x1)``). Elsewhere the forward-backward contractor of a row is already
        its tightest: HC4-revise on an expression where every variable occurs once gives the
        hull of the constraint's projection [Jaulin2001, Ch. 4]."""
        import sympy as sp

        g = self._groups()
        leaves = set(g["x"] + g["w"])
        rows = []
        for i, e in enumerate(self.f_exprs):
            seen = [t for t in sp.preorder_traversal(e) if t in leaves]
            if len(seen) > len(set(seen)):
                rows.append(i)
        return rows

    # -- conversions ---------------------------------------------------------------------
    @classmethod
    def from_linear(cls, lin: Any, who: str = "NonlinearSystem.from_linear") -> NonlinearSystem:
        """The same model as a time-invariant discrete-time :class:`~ivobs.LinearSystem` with
        constant bounds (states ``x1..``, inputs ``u1..``, signals ``d1..``; the matrices'
        entries taken exactly as the doubles they are)."""
        from .convert import linear_spec

        return cls(**linear_spec(lin, who))

    def _repr_html_(self) -> str:
        """Jupyter: the equations, the unknown parameters and signals with their bounds."""
        from ..._html import summary_html

        spec = self.spec()
        rows = [(f"{x}⁺ =", str(e)) for x, e in zip(self.state_names, spec["f"])]
        rows += [(f"y{i + 1} =", str(e)) for i, e in enumerate(spec["h"])]
        rows += [("unknown", ", ".join(self.param_names + self.signal_names) or "none")]
        return summary_html("ivobs NonlinearSystem", rows)

    def __repr__(self) -> str:
        return (
            f"NonlinearSystem(nx={self.nx}, nu={self.nu}, ny={self.ny}, "
            f"params={self.param_names}, d={self.signal_names})"
        )

    def __reduce__(self) -> tuple[Callable[..., NonlinearSystem], tuple[Any, ...]]:
        return (functools.partial(NonlinearSystem, **self.spec()), ())

    def spec(self) -> dict[str, Any]:
        """The keyword arguments that rebuild this system (expressions as text)."""
        params: dict[str, Any] = dict(self.known_params)
        params.update(self.param_bounds)
        return {
            "f": list(self.f_text),
            "h": list(self.h_text),
            "states": list(self.state_names),
            "inputs": list(self.input_names),
            "params": params,
            "d": dict(self.signal_bounds),
            "dt": self.dt,
            "outputs": list(self.output_names),
        }
