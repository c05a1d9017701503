"""System files (TOML): the model, the disturbance bounds, the prior box and a method.

A system file holds everything an estimator needs besides the data: the matrices of

::

    x[k+1] = A x[k] + B u[k] + E d[k]          d[k] ∈ [lower, upper]
    y[k]   = C x[k] + D u[k] + F d[k]          x[0] ∈ [x0.lower, x0.upper]

the sampling period ``dt``, the disturbance bounds (constant, per step inline or from columns of
a CSV file, or a Python callable), the prior box on ``x[0]``, and a method with its options. A
sparse matrix (``scipy.sparse``) is a table of its nonzero entries (``shape``, ``rows``,
``cols``, ``values``; 0-based, row-major) and is read back as a CSR matrix. The format is
documented in ``docs/operating.md``; :func:`~ivobs.io.save_system` writes it. A nonlinear model
(``f``, ``h`` expressions) is read by :mod:`.nlsystemfile`.

Every rejected file raises :class:`~ivobs.IvobsError` naming the file, the line and the key.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from .._validate import as_bool
from ..errors import IvobsError
from ..model import LinearSystem
from ..model.statespace import SignalNames
from ..sets import Box
from .boundsfile import read_bounds_csv
from .callables import make_callable
from .loaded import SystemFile
from .nlsystemfile import read_nonlinear
from .options import read_method
from .reader import TomlReader

__all__ = ["FORMAT", "MATRICES", "SystemFile", "load_system", "loads_system"]

FORMAT = 1
MATRICES = ("A", "B", "C", "D", "E", "F")
_NONLINEAR = ("states", "inputs", "outputs", "f", "h", "params", "d", "discretize")
_KEYS: dict[tuple[str, ...], tuple[str, ...]] = {
    (): ("format", "name", "description", "system", "disturbance", "x0", "method", "names"),
    ("system",): ("dt", *MATRICES, *_NONLINEAR),
    ("disturbance",): ("lower", "upper", "csv", "python", "params"),
    ("x0",): ("lower", "upper", "step"),
    ("method",): ("name", "options"),
    ("names",): ("states", "units", "inputs", "outputs", "disturbances"),
}


class _SystemReader(TomlReader):
    """Validate a parsed system file, raising errors that name the file, the line and the key."""

    def __init__(self, text: str, source: str, base_dir: Path, allow_code: bool):
        super().__init__(text, source)
        self.base_dir = base_dir
        self.allow_code = allow_code
        self.files: list[str] = []

    def check_keys(self, table: dict[str, Any], key: tuple[str, ...]) -> None:
        allowed = _KEYS[key]
        for k in table:
            if k not in allowed:
                where = f"[{'.'.join(key)}]" if key else "the top level"
                raise self.fail(
                    (*key, k),
                    f"unknown key {k!r} in {where}; allowed keys: {', '.join(allowed)}",
                )

    def table(self, key: tuple[str, ...], required: bool = False) -> dict[str, Any] | None:
        val = self.doc.get(key[0]) if key else self.doc
        if val is None:
            if required:
                raise self.fail(key, f"missing table [{key[0]}]")
            return None
        if not isinstance(val, dict):
            raise self.fail(key, f"expected a table [{key[0]}], got {type(val).__name__}")
        self.check_keys(val, key)
        return val

    def names(self, system: Any) -> SignalNames:
        """``[names]``: labels of the states (and their ``units``), inputs, outputs and
        disturbance components, for plots and tables."""
        tab = self.table(("names",))
        if tab is None:
            return SignalNames()
        sizes = {"states": system.nx, "units": system.nx, "inputs": system.nu,
                 "outputs": system.ny, "disturbances": system.nd}  # fmt: skip
        out: dict[str, tuple[str, ...]] = {}
        for k, n in sizes.items():
            if k not in tab:
                continue
            v = tab[k]
            if not isinstance(v, list) or not all(isinstance(e, str) for e in v):
                raise self.fail(("names", k), f"expected a list of strings, got {v!r}")
            if len(v) != n:
                raise self.fail(("names", k), f"expected {n} names (the system's), got {len(v)}")
            out[k] = tuple(v)
        return SignalNames(**out)

    def x0_step(self) -> int:
        """``[x0] step``: the step whose state the prior box bounds (default 0); a log must
        start there (:mod:`ivobs.io.steps`)."""
        tab = self.table(("x0",)) or {}
        step = tab.get("step", 0)
        if isinstance(step, bool) or not isinstance(step, int) or not 0 <= step <= 2**53:
            raise self.fail(("x0", "step"), f"expected a step in 0..2**53, got {step!r}")
        return step

    def x0(self, nx: int) -> Box | None:
        tab = self.table(("x0",))
        if tab is None:
            return None
        vec = {}
        for k in ("lower", "upper"):
            if k not in tab:
                raise self.fail(("x0",), f"missing {k} (the prior box is [lower, upper])")
            v = self.numbers(("x0", k), tab[k], (1,))
            if v.shape[0] != nx:
                raise self.fail(
                    ("x0", k), f"expected {nx} values (one per state), got {v.shape[0]}"
                )
            if not np.all(np.isfinite(v)):
                raise self.fail(("x0", k), "the prior box must be finite")
            vec[k] = v
        bad = vec["lower"] > vec["upper"]
        if np.any(bad):
            i = int(np.argmax(bad))
            raise self.fail(
                ("x0", "lower"),
                f"lower > upper in component {i}: {vec['lower'][i]} > {vec['upper'][i]}",
            )
        return Box(vec["lower"], vec["upper"])

    # -- values ---------------------------------------------------------------------------

    def matrix(self, key: tuple[str, ...], value: Any) -> Any:
        if isinstance(value, dict):
            if "python" not in value and ("shape" in value or "values" in value):
                return self.sparse(key, value)
            if "python" not in value and ("lower" in value or "upper" in value):
                return self.interval(key, value)
            return self.python(key, value)
        arr = self.numbers(key, value, (2, 3))
        bad = ~np.isfinite(arr)
        if np.any(bad):
            idx = "".join(f"[{int(i)}]" for i in np.argwhere(bad)[0])
            raise self.fail(key, f"entry {idx} is {arr[bad][0]}; matrices must be finite")
        return arr

    def interval(self, key: tuple[str, ...], spec: dict[str, Any]) -> Box:
        """An interval matrix ``{ lower = [[...]], upper = [[...]] }`` (A, B, C, D only): the
        plant may use any matrix between the two at every step (docs/uncertain.md; one given
        for ``E`` or ``F`` is refused by :class:`~ivobs.LinearSystem`)."""
        unknown = sorted(set(spec) - {"lower", "upper"})
        if unknown:
            raise self.fail(
                (*key, unknown[0]),
                "unknown key; an interval matrix is given as lower = [[...]], upper = [[...]]",
            )
        bounds = []
        for part in ("lower", "upper"):
            if part not in spec:
                raise self.fail(key, f"interval matrix: missing {part} = [[...]]")
            arr = self.numbers((*key, part), spec[part], (2,))
            if not np.all(np.isfinite(arr)):
                raise self.fail((*key, part), "an interval matrix needs finite bounds")
            bounds.append(arr)
        lo, hi = bounds
        if lo.shape != hi.shape:
            raise self.fail((*key, "upper"), f"lower has shape {lo.shape}, upper {hi.shape}")
        bad = lo > hi
        if np.any(bad):
            i, j = (int(v) for v in np.argwhere(bad)[0])
            raise self.fail(
                (*key, "lower"), f"lower > upper at entry [{i}][{j}]: {lo[i, j]} > {hi[i, j]}"
            )
        return Box(lo, hi)

    def sparse(self, key: tuple[str, ...], spec: dict[str, Any]) -> Any:
        """A sparse matrix from ``shape``, ``rows``, ``cols``, ``values`` (0-based indices)."""
        from scipy.sparse import coo_matrix

        unknown = sorted(set(spec) - {"shape", "rows", "cols", "values"})
        if unknown:
            raise self.fail(
                (*key, unknown[0]),
                "unknown key; a sparse matrix is given as shape = [rows, cols] and the lists "
                "rows, cols, values of its nonzero entries (0-based indices)",
            )
        for part in ("shape", "rows", "cols", "values"):
            if part not in spec:
                raise self.fail(key, f"sparse matrix: missing {part} = [...]")
        shape = spec["shape"]
        if (
            not isinstance(shape, list)
            or len(shape) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in shape)
        ):
            raise self.fail(
                (*key, "shape"), f"expected [rows, cols] (integers >= 0), got {shape!r}"
            )
        idx = {}
        for part, limit in (("rows", shape[0]), ("cols", shape[1])):
            vals = spec[part]
            if not isinstance(vals, list) or not all(
                isinstance(v, int) and not isinstance(v, bool) for v in vals
            ):
                raise self.fail((*key, part), "expected a list of integer indices")
            arr = np.array(vals, dtype=np.int64)
            bad = (arr < 0) | (arr >= limit)
            if np.any(bad):
                raise self.fail(
                    (*key, part),
                    f"index {int(arr[bad][0])} is outside 0..{limit - 1} (0-based indices)",
                )
            idx[part] = arr
        values = self.numbers((*key, "values"), spec["values"], (1,))
        if not np.all(np.isfinite(values)):
            raise self.fail((*key, "values"), "matrices must be finite")
        if not (len(idx["rows"]) == len(idx["cols"]) == len(values)):
            raise self.fail(
                key,
                f"sparse matrix: rows, cols and values have different lengths "
                f"({len(idx['rows'])}, {len(idx['cols'])}, {len(values)})",
            )
        flat = idx["rows"] * max(shape[1], 1) + idx["cols"]
        if np.unique(flat).size != flat.size:
            raise self.fail(key, "sparse matrix: an entry (row, col) is given twice")
        m = coo_matrix((values, (idx["rows"], idx["cols"])), shape=tuple(shape)).tocsr()
        m.sort_indices()
        return m

    def python(self, key: tuple[str, ...], spec: dict[str, Any]) -> Any:
        unknown = sorted(set(spec) - {"python", "params"})
        if unknown:
            raise self.fail(
                (*key, unknown[0]),
                "unknown key; a callable is given as "
                '{ python = "module:function", params = { ... } }',
            )
        path = spec.get("python")
        if not isinstance(path, str):
            raise self.fail(key, 'expected python = "package.module:function"')
        params = spec.get("params", {})
        if not isinstance(params, dict):
            raise self.fail((*key, "params"), f"expected a table, got {params!r}")
        try:
            return make_callable(path, params, allow_code=self.allow_code)
        except IvobsError as exc:
            raise self.fail((*key, "python"), str(exc)) from None

    # -- sections -------------------------------------------------------------------------
    def read(self) -> SystemFile:
        self.check_keys(self.doc, ())
        fmt = self.doc.get("format", FORMAT)
        if fmt != FORMAT or isinstance(fmt, bool):
            raise self.fail(("format",), f"unsupported format {fmt!r}; this ivobs reads {FORMAT}")
        name = self.string(("name",), self.doc.get("name", ""))
        desc = self.string(("description",), self.doc.get("description", ""))
        sysd = self.table(("system",), required=True)
        assert sysd is not None
        if "f" in sysd or "h" in sysd:  # a nonlinear model (expressions, no matrices)
            return self.finish(read_nonlinear(self, sysd, self.dt(sysd)), name, desc)
        extra = sorted(set(sysd) - {"dt", *MATRICES})
        if extra:
            raise self.fail(
                ("system", extra[0]),
                f"{extra[0]} belongs to a nonlinear system, which needs f and h (expressions)",
            )
        mats = self.system_matrices(sysd)
        dist = self.table(("disturbance",))
        d = self.disturbance(dist, mats) if dist is not None else None
        if d is None:
            for m in ("E", "F"):
                if m in sysd:
                    raise self.fail(
                        ("system", m),
                        f"{m} is given but there is no [disturbance] table with the bounds of d",
                    )
        dt = self.dt(sysd)
        try:
            system = LinearSystem(**mats, d=d, dt=dt)  # mats: A and C, and B, D, E, F if given
        except IvobsError as exc:
            arg = re.match(r"^([A-F]|d|dt)\b", str(exc))
            key = (
                ("system", arg.group(1))
                if arg and arg.group(1) in (*MATRICES, "dt")
                else (("disturbance",) if arg else ("system",))
            )
            raise self.fail(key, str(exc)) from None
        system.names = self.names(system)
        return self.finish(system, name, desc)

    def finish(self, system: Any, name: str, desc: str) -> SystemFile:
        """The prior box and the method, around the model."""
        x0 = self.x0(system.nx)
        method, options = self.method()
        lines = {o: self.lines.line(("method", "options", o)) for o in options}
        return SystemFile(
            system, x0, method, options, name, desc, self.source, tuple(self.files),
            {o: n for o, n in lines.items() if n is not None}, self.x0_step(),
        )  # fmt: skip

    def string(self, key: tuple[str, ...], value: Any) -> str:
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, got {value!r}")
        return value

    def dt(self, sysd: dict[str, Any]) -> bool | float:
        dt = sysd.get("dt", True)
        if (
            dt is False
            or not isinstance(dt, (bool, int, float))
            or (not isinstance(dt, bool) and not (math.isfinite(dt) and dt >= 0))
        ):
            raise self.fail(
                ("system", "dt"),
                f"expected true or a period > 0 (discrete time) or 0 (continuous time), got {dt!r}",
            )
        return True if dt is True else float(dt)

    def system_matrices(self, sysd: dict[str, Any]) -> dict[str, Any]:
        for m in ("A", "C"):
            if m not in sysd:
                what = "state matrix" if m == "A" else "output matrix"
                raise self.fail(("system",), f"missing matrix {m} (the {what})")
        mats = {m: self.matrix(("system", m), sysd[m]) for m in MATRICES if m in sysd}
        arrays = {m: v for m, v in mats.items() if not callable(v)}  # dense or sparse

        def dims(m: str) -> tuple[int, ...] | None:
            v = arrays.get(m)
            return None if v is None else tuple((v.lo if isinstance(v, Box) else v).shape[-2:])

        A = dims("A")
        if A is not None and A[0] != A[1]:
            raise self.fail(("system", "A"), f"expected a square matrix, got shape {A}")
        nx = A[0] if A else None
        C = dims("C")
        ny = C[0] if C else None
        B = dims("B")
        nu = B[1] if B else 0
        expected = {
            "B": (nx, None),
            "C": (None, nx),
            "D": (ny, nu),
            "E": (nx, None),
            "F": (ny, None),
        }
        for m, (rows, cols) in expected.items():
            s = dims(m)
            if s is None:
                continue
            if (rows is not None and s[0] != rows) or (cols is not None and s[1] != cols):
                r_s, c_s = ("any" if v is None else v for v in (rows, cols))
                exp = f"({r_s}, {c_s})"
                raise self.fail(
                    ("system", m),
                    f"expected shape {exp} to match the other "
                    f"matrices (nx = {nx}, nu = {nu}, ny = {ny}), got {s}",
                )
        e, f = dims("E"), dims("F")
        if e is not None and f is not None and e[1] != f[1]:
            raise self.fail(
                ("system", "F"),
                f"E has {e[1]} columns, F has {f[1]}: both act on the same disturbance d",
            )
        return mats

    def disturbance(self, dist: dict[str, Any], mats: dict[str, Any]) -> Any:
        key = ("disturbance",)
        if "python" in dist:
            extra = sorted(set(dist) & {"lower", "upper", "csv"})
            if extra:
                raise self.fail(
                    (*key, extra[0]),
                    "give either python = ... (a callable) or lower/upper bounds, not both",
                )
            return self.python(key, dist)
        if "params" in dist:
            raise self.fail((*key, "params"), "params belong to a callable (python = ...)")
        for k in ("lower", "upper"):
            if k not in dist:
                raise self.fail(key, f"missing {k} (the bounds of d are [lower, upper])")
        nd = next(
            (v.shape[-1] for m, v in mats.items() if m in ("E", "F") and isinstance(v, np.ndarray)),
            None,
        )
        table = self.bounds_csv(dist) if "csv" in dist else None
        lo = self.bound((*key, "lower"), dist["lower"], table)
        hi = self.bound((*key, "upper"), dist["upper"], table)
        for k, v in (("lower", lo), ("upper", hi)):
            if nd is not None and v.shape[-1] != nd:
                raise self.fail(
                    (*key, k), f"expected {nd} bounds (the columns of E and F), got {v.shape[-1]}"
                )
        if lo.ndim == 2 and hi.ndim == 1:
            hi = np.broadcast_to(hi, lo.shape).copy()
        if hi.ndim == 2 and lo.ndim == 1:
            lo = np.broadcast_to(lo, hi.shape).copy()
        if lo.shape != hi.shape:
            raise self.fail((*key, "upper"), f"lower has shape {lo.shape}, upper {hi.shape}")
        bad = lo > hi
        if np.any(bad):
            idx = tuple(int(i) for i in np.argwhere(bad)[0])
            at = f"step {idx[0]}, component {idx[1]}" if lo.ndim == 2 else f"component {idx[0]}"
            raise self.fail((*key, "lower"), f"lower > upper at {at}: {lo[idx]} > {hi[idx]}")
        return Box(lo, hi)

    def bound(self, key: tuple[str, ...], value: Any, table: dict[str, np.ndarray] | None) -> Any:
        """A vector of bounds (entries may name CSV columns) or an inline (T, nd) array."""
        if isinstance(value, list) and any(isinstance(v, str) for v in value):
            if table is None:
                raise self.fail(
                    key, 'entries naming CSV columns need csv = "file.csv" in [disturbance]'
                )
            T = len(next(iter(table.values())))
            cols = []
            for i, v in enumerate(value):
                if isinstance(v, str):
                    if v not in table:
                        raise self.fail(
                            key,
                            f"entry [{i}]: no column {v!r} in the bounds file (its header "
                            f"names {len(table)} columns)",
                        )
                    cols.append(table[v])
                else:
                    cols.append(np.full(T, self.numbers(key, v, (0,)).item()))
            out = np.column_stack(cols)
        else:
            out = self.numbers(key, value, (1, 2))
        bad = np.isnan(out) | np.isinf(out)
        if np.any(bad):
            raise self.fail(key, f"bounds must be finite numbers, got {out[bad][0]}")
        return out

    def bounds_csv(self, dist: dict[str, Any]) -> dict[str, np.ndarray]:
        key = ("disturbance", "csv")
        name = dist["csv"]
        if not isinstance(name, str):
            raise self.fail(key, f"expected a file name, got {name!r}")
        path = Path(name) if Path(name).is_absolute() else self.base_dir / name
        if not path.is_file():
            raise self.fail(key, f"bounds file {str(path)!r} not found")
        self.files.append(str(path))
        try:
            return read_bounds_csv(path)
        except IvobsError as exc:
            raise self.fail(key, str(exc)) from None

    def method(self) -> tuple[str | None, dict[str, Any]]:
        tab = self.table(("method",))
        if tab is None:
            return None, {}
        return read_method(self, tab)


def loads_system(
    text: str, *, source: str = "<string>", base_dir: Any = ".", allow_code: bool = False
) -> SystemFile:
    """Read a system file from its text (``base_dir``: where relative CSV paths point;
    ``allow_code``: as in :func:`load_system`)."""
    return _SystemReader(text, source, Path(base_dir), as_bool("allow_code", allow_code)).read()


def load_system(path: str | os.PathLike[str], *, allow_code: bool = False) -> SystemFile:
    """Read a system file (TOML). Returns a :class:`SystemFile` (``.system``, ``.x0``,
    ``.method``, ``.options``). Raises :class:`~ivobs.IvobsError` naming the line and the key of
    anything malformed.

    Loading runs no code by default: a callable ``{ python = "module:function" }`` is resolved
    only when it is one of ivobs' scenario functions (``ivobs.scenarios``); any other is
    refused unless ``allow_code=True`` (resolving it imports its module and the estimator
    calls it: pass it for files you trust only)."""
    allow_code = as_bool("allow_code", allow_code)
    path = Path(path)
    if path.is_dir():
        raise IvobsError(f"system file {str(path)!r} is a directory; expected a TOML file")
    if not path.is_file():
        raise IvobsError(f"system file {str(path)!r} not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise IvobsError(f"{path}: not a UTF-8 text file ({exc})") from None
    except OSError as exc:
        raise IvobsError(f"system file {str(path)!r}: cannot read it ({exc.strerror})") from None
    return loads_system(text, source=str(path), base_dir=path.parent, allow_code=allow_code)
