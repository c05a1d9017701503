"""System files (TOML) and measurement logs (CSV): operating ivobs on real data.

A **system file** holds everything an estimator needs besides the data: the matrices of

::

    x[k+1] = A x[k] + B u[k] + E d[k]          d[k] ∈ [lower, upper]
    y[k]   = C x[k] + D u[k] + F d[k]          x[0] ∈ [x0.lower, x0.upper]

the sampling period ``dt``, the disturbance bounds (constant, per step inline or from columns of a
CSV file, or a Python callable), the prior box on ``x[0]``, and a method with its options::

    name = "servo-motor"

    [system]
    dt = 0.1
    A = [[1.0, 0.1, 0.0], [0.0, 0.8495, 0.4977], [0.0, -0.0357, 0.9995]]
    B = [[0.0], [0.0], [0.0729]]
    C = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]

    [x0]
    lower = [-0.2, -0.2, -0.2]
    upper = [0.2, 0.2, 0.2]

    [method]
    name = "interval-split"

A sparse matrix (``scipy.sparse``, large systems) is written as a table of its nonzero entries
(0-based indices, in row-major order)::

    [system.A]
    shape = [2000, 2000]
    rows = [0, 0, 1, 1, 1, ...]
    cols = [0, 1, 0, 1, 2, ...]
    values = [0.19, 0.4, 0.4, 0.19, 0.4, ...]

and read back as a ``scipy.sparse`` CSR matrix (``docs/scale.md``).

Every rejected file raises :class:`~ivobs.IvobsError` naming the file, the line and the key.
The full format is documented in ``docs/operating.md``.

**Security**: a matrix or a bound may name a Python callable by import path
(``A = { python = "ivobs.scenarios:pendulum_A", params = { L0 = 1.0, L1 = 0.5, omega = 1.0 } }``).
Loading such a file imports that module, which runs its code: load system files from trusted
sources only.

A **log** is a CSV file with a header: an optional step (``k`` / ``step``) or time (``t`` /
``time``) column, the inputs ``u1, u2, ...`` and the measurements ``y1, y2, ...`` in header order.
An empty cell or ``NaN`` in a ``y`` column is a missing sample. :func:`read_log` reads one,
:class:`LogParser` parses rows one at a time (the streaming monitor).

Every file ivobs writes is written to a temporary file in the same folder and then renamed, so
that a crash or an error never leaves a half-written file behind (:func:`atomic_path`).
"""

from __future__ import annotations

import contextlib
import csv
import functools
import importlib
import json
import math
import os
import re
import stat
import tempfile
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import IvobsError
from .model import LinearSystem
from .sets import Box

__all__ = [
    "Log",
    "LogParser",
    "LogRow",
    "SystemFile",
    "atomic_path",
    "callable_ref",
    "check_output_path",
    "dumps_system",
    "equal_systems",
    "load_system",
    "loads_system",
    "read_log",
    "save_system",
    "write_log",
]

FORMAT = 1
_MATRICES = ("A", "B", "C", "D", "E", "F")
_KEYS: dict[tuple[str, ...], tuple[str, ...]] = {
    (): ("format", "name", "description", "system", "disturbance", "x0", "method"),
    ("system",): ("dt", *_MATRICES),
    ("disturbance",): ("lower", "upper", "csv", "python", "params"),
    ("x0",): ("lower", "upper"),
    ("method",): ("name", "options"),
}


# ============================================================================================
# atomic writes
# ============================================================================================
def _file_mode(path: Path) -> int:
    """The mode a plain ``open(path, "w")`` gives: the existing file's, else ``0o666`` less the
    umask (``tempfile.mkstemp`` creates ``0o600`` files)."""
    with contextlib.suppress(OSError):
        return stat.S_IMODE(path.stat().st_mode)
    return 0o666 & ~_umask()


def _umask() -> int:
    """The process umask: from ``/proc/self/status`` where it exists (reading it with
    ``os.umask`` sets it for a moment, which other threads creating files could see)."""
    with contextlib.suppress(OSError, ValueError):
        with open("/proc/self/status", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    mask = os.umask(0)
    os.umask(mask)
    return mask


def check_output_path(path: str | os.PathLike[str], what: str | None = None) -> Path:
    """Check that ``path`` can be written as a file (its folder exists, it is no folder itself),
    before any work is done. ``what`` names the argument in the error (e.g. ``"--csv"``)."""
    path = Path(path)
    prefix = f"{what}: " if what else ""
    folder = path.parent if str(path.parent) else Path(".")
    if str(path) in ("", "."):
        raise IvobsError(f"{prefix}expected a file name, got {str(path)!r}")
    if path.is_dir():
        raise IvobsError(f"{prefix}{str(path)!r} is a directory; expected a file name")
    if not folder.is_dir():
        why = "is not a directory" if folder.exists() else "does not exist"
        raise IvobsError(f"{prefix}cannot write {str(path)!r}: the folder {str(folder)!r} {why}")
    if not os.access(folder, os.W_OK):
        raise IvobsError(f"{prefix}cannot write {str(path)!r}: the folder is not writable")
    return path


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path next to ``path`` (same suffix); rename it to ``path`` on success,
    delete it on any error. Readers never see a half-written file. The file gets the mode a
    plain ``open(path, "w")`` would give (the umask's, or the replaced file's)."""
    path = check_output_path(path)
    folder = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(
            dir=folder, prefix=f".{path.name}.", suffix=path.suffix or ".tmp"
        )
    except OSError as exc:
        raise IvobsError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    os.close(fd)
    try:
        os.chmod(tmp, _file_mode(path))
        yield Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file, then rename)."""
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)


# ============================================================================================
# callables by import path
# ============================================================================================
def callable_ref(fn: Any) -> tuple[str, dict[str, Any]] | None:
    """``("module:qualname", params)`` for a module-level function or a ``functools.partial`` of
    one with keyword parameters; ``None`` for anything a file cannot name (lambdas, closures,
    positional partials, callable objects)."""
    params: dict[str, Any] = {}
    if isinstance(fn, functools.partial):
        if fn.args:
            return None
        params = {k: _plain(v) for k, v in fn.keywords.items()}
        fn = fn.func
    module = getattr(fn, "__module__", None)
    qualname = getattr(fn, "__qualname__", None)
    if not module or not qualname or "<" in qualname:
        return None
    path = f"{module}:{qualname}"
    try:
        if _resolve(path) is not fn:
            return None
    except IvobsError:
        return None
    return path, params


def _plain(value: Any) -> Any:
    """Parameters as plain Python values (what a TOML file can hold and give back)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.generic,)):
        return value.item()
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def _resolve(path: str) -> Any:
    if not isinstance(path, str) or path.count(":") != 1:
        raise IvobsError(f"expected 'package.module:function', got {path!r}")
    mod_name, qualname = path.split(":")
    try:
        obj: Any = importlib.import_module(mod_name)
    except Exception as exc:
        raise IvobsError(f"cannot import module {mod_name!r}: {exc!r}") from None
    for part in qualname.split("."):
        if not hasattr(obj, part):
            raise IvobsError(f"module {mod_name!r} has no attribute {qualname!r}")
        obj = getattr(obj, part)
    if not callable(obj):
        raise IvobsError(f"{path!r} is not callable")
    return obj


def _make_callable(path: str, params: dict[str, Any]) -> Any:
    fn = _resolve(path)
    return functools.partial(fn, **params) if params else fn


def _same_value(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if callable(a) or callable(b):
        if not (callable(a) and callable(b)):
            return False
        ra, rb = callable_ref(a), callable_ref(b)
        if ra is None or rb is None:
            return a is b
        return ra[0] == rb[0] and _same_params(ra[1], rb[1])
    if isinstance(a, Box) or isinstance(b, Box):
        return isinstance(a, Box) and isinstance(b, Box) and a == b
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def _same_params(a: dict[str, Any], b: dict[str, Any]) -> bool:
    if set(a) != set(b):
        return False
    for key in a:
        va, vb = a[key], b[key]
        if isinstance(va, str) or isinstance(vb, str):
            if va != vb:
                return False
        elif not _same_value(va, vb):
            return False
    return True


def equal_systems(a: LinearSystem, b: LinearSystem) -> bool:
    """Whether two systems are the same model: same ``dt``, the same matrices (arrays equal
    entry for entry, stacks equal, callables the same import path and parameters) and the same
    disturbance bounds."""
    if not (isinstance(a, LinearSystem) and isinstance(b, LinearSystem)):
        raise IvobsError(
            f"equal_systems: expected two LinearSystems, got {type(a).__name__} and "
            f"{type(b).__name__}"
        )
    if (a.dt is True) != (b.dt is True) or a.dt != b.dt:
        return False
    if (a.nx, a.nu, a.ny, a.nd) != (b.nx, b.nu, b.ny, b.nd):
        return False
    for m in _MATRICES:
        sa, sb = _sparse_of(a, m), _sparse_of(b, m)
        if sa is not None and sb is not None:  # compared without building dense views
            if sa.shape != sb.shape or (sa != sb).nnz:
                return False
        elif not _same_value(getattr(a, m), getattr(b, m)):
            return False
    return _same_value(a.d, b.d)


def _sparse_of(system: LinearSystem, m: str) -> Any:
    """The ``scipy.sparse`` matrix ``m`` of ``system`` when it was given sparse, else None."""
    return getattr(getattr(system, f"_{m}", None), "sp", None)


# ============================================================================================
# writing system files
# ============================================================================================
_BARE = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE.match(k) else json.dumps(k, ensure_ascii=False)


def _scalar(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        f = float(v)
        if math.isnan(f):
            return "nan"
        if math.isinf(f):
            return "inf" if f > 0 else "-inf"
        return repr(f)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    raise IvobsError(
        f"save_system: cannot write a value of type {type(v).__name__} ({v!r}); system files "
        "hold numbers, strings, booleans, arrays and tables"
    )


def _value(v: Any, indent: str = "") -> str:
    """A TOML value: arrays of two or more dimensions are written one row per line."""
    if isinstance(v, Box):
        return _value({"lower": v.lo, "upper": v.hi}, indent)
    if isinstance(v, dict):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    if isinstance(v, (list, tuple, np.ndarray)):
        arr = v if isinstance(v, np.ndarray) else None
        if arr is not None and arr.dtype.kind in "biuf":
            if arr.ndim == 0:
                return _scalar(arr.item())
            if arr.ndim == 1 or arr.size == 0:
                return "[" + ", ".join(_scalar(float(x)) for x in arr.ravel()) + "]"
            inner = indent + "    "
            rows = ",\n".join(inner + _value(r, inner) for r in arr)
            return "[\n" + rows + ",\n" + indent + "]"
        return "[" + ", ".join(_value(x, indent) for x in v) + "]"
    return _scalar(v)


def _matrix_value(name: str, m: Any) -> str:
    if callable(m):
        ref = callable_ref(m)
        if ref is None:
            raise IvobsError(
                f"save_system: {name} is a callable ivobs cannot name in a file ({m!r}); use a "
                "module-level function, or functools.partial of one with keyword parameters"
            )
        return _value({"python": ref[0], "params": ref[1]})
    return _value(np.asarray(m, dtype=float))


def _sparse_lines(sp: Any) -> list[str]:
    """``shape``, ``rows``, ``cols``, ``values`` of a sparse matrix (row-major, 0-based)."""
    csr = sp.tocsr()
    csr.sum_duplicates()
    csr.sort_indices()
    rows = np.repeat(np.arange(csr.shape[0]), np.diff(csr.indptr))

    def listing(values: list[str]) -> str:
        if len(values) <= 12:
            return "[" + ", ".join(values) + "]"
        lines = [", ".join(values[i : i + 12]) for i in range(0, len(values), 12)]
        return "[\n" + ",\n".join("    " + ln for ln in lines) + ",\n]"

    return [
        f"shape = [{csr.shape[0]}, {csr.shape[1]}]",
        "rows = " + listing([str(int(i)) for i in rows]),
        "cols = " + listing([str(int(j)) for j in csr.indices]),
        "values = " + listing([_scalar(float(v)) for v in csr.data]),
    ]


def dumps_system(
    system: Any,
    *,
    x0: Box | None = None,
    method: str | None = None,
    options: dict[str, Any] | None = None,
    name: str = "",
    description: str = "",
) -> str:
    """The TOML text of a system file (see :func:`save_system`)."""
    system, x0, method, options, name, description = _unpack(
        system, x0, method, options, name, description
    )
    out = [
        "# ivobs system file",
        "#   x[k+1] = A x[k] + B u[k] + E d[k],  y[k] = C x[k] + D u[k] + F d[k]",
        "#   d[k] in [disturbance.lower, disturbance.upper],  x[0] in [x0.lower, x0.upper]",
        f"format = {FORMAT}",
    ]
    if name:
        out.append(f"name = {_scalar(name)}")
    if description:
        out.append(f"description = {_scalar(description)}")
    out += ["", "[system]", f"dt = {_scalar(system.dt)}"]
    skip = {"B": system.nu == 0, "D": system.nu == 0, "E": system.nd == 0, "F": system.nd == 0}
    sparse_tables = []
    for m in _MATRICES:
        if skip.get(m, False):
            continue
        sp = _sparse_of(system, m)
        if sp is not None:  # a sub-table, after the other keys of [system]
            sparse_tables += ["", f"[system.{m}]", *_sparse_lines(sp)]
        else:
            out.append(f"{m} = {_matrix_value(m, getattr(system, m))}")
    out += sparse_tables
    if system.nd:
        out += ["", "[disturbance]"]
        d = system.d
        if isinstance(d, Box):
            out += [f"lower = {_value(d.lo)}", f"upper = {_value(d.hi)}"]
        else:
            ref = callable_ref(d)
            if ref is None:
                raise IvobsError(
                    f"save_system: the disturbance bounds are a callable ivobs cannot name in a "
                    f"file ({d!r}); use a module-level function (k, y) -> Box, or "
                    "functools.partial of one with keyword parameters"
                )
            out += [f"python = {_scalar(ref[0])}", f"params = {_value(ref[1])}"]
    if x0 is not None:
        if not isinstance(x0, Box) or x0.is_time_varying:
            raise IvobsError(f"save_system: x0 must be a constant ivobs.Box, got {x0!r}")
        out += ["", "[x0]", f"lower = {_value(x0.lo)}", f"upper = {_value(x0.hi)}"]
    if method is not None:
        out += ["", "[method]", f"name = {_scalar(method)}"]
        if options:
            out += ["", "[method.options]"]
            out += [f"{_key(k)} = {_value(_plain_option(v))}" for k, v in options.items()]
    elif options:
        raise IvobsError("save_system: options were given without a method")
    return "\n".join(out) + "\n"


def _plain_option(v: Any) -> Any:
    if isinstance(v, Box) or isinstance(v, np.ndarray):
        return v
    if isinstance(v, np.generic):
        return v.item()
    return v


def _unpack(
    system: Any, x0: Any, method: Any, options: Any, name: str, description: str
) -> tuple[LinearSystem, Box | None, str | None, dict[str, Any], str, str]:
    from .scenarios import Scenario

    if isinstance(system, SystemFile):
        x0 = system.x0 if x0 is None else x0
        method = system.method if method is None else method
        options = system.options if options is None else options
        name = name or system.name
        description = description or system.description
        system = system.system
    elif isinstance(system, Scenario):
        x0 = system.x0 if x0 is None else x0
        name = name or system.name
        description = description or system.description
        system = system.system
    if not isinstance(system, LinearSystem):
        raise IvobsError(
            f"system: expected a LinearSystem, a SystemFile or a Scenario, got "
            f"{type(system).__name__}"
        )
    return system, x0, method, dict(options or {}), str(name), str(description)


def save_system(
    path: str | os.PathLike[str],
    system: Any,
    *,
    x0: Box | None = None,
    method: str | None = None,
    options: dict[str, Any] | None = None,
    name: str = "",
    description: str = "",
) -> None:
    """Write a system file (TOML) atomically.

    ``system`` is a :class:`~ivobs.LinearSystem`, a :class:`SystemFile` or a
    :class:`~ivobs.scenarios.Scenario` (its prior box, name and description are written too).
    Numbers are written with full precision (``repr``), so :func:`load_system` gives back the
    same system (:func:`equal_systems`). Callable matrices and bounds must be module-level
    functions or ``functools.partial`` of one with keyword parameters.
    """
    text = dumps_system(
        system, x0=x0, method=method, options=options, name=name, description=description
    )
    write_text_atomic(path, text)


# ============================================================================================
# reading system files
# ============================================================================================
@dataclass
class SystemFile:
    """What a system file holds: the model, the prior box, a method and its options."""

    system: LinearSystem
    x0: Box | None = None
    method: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    name: str = ""
    description: str = ""
    source: str = ""

    def make_estimator(self, method: str | None = None, **options: Any) -> Any:
        """The estimator of the file's method (or ``method``) with the file's prior box.

        The file's options apply to the file's method only; ``options`` are added to them.
        """
        from .estimators import make_estimator

        name = method or self.method
        if name is None:
            raise IvobsError(
                f"method: {self.source or 'the system file'} names no method ([method] name = "
                "...); give one (e.g. --method interval-split)"
            )
        opts = dict(self.options) if (self.method and _same_method(name, self.method)) else {}
        opts.update(options)
        return make_estimator(name, self.system, x0=self.x0, **opts)


def _same_method(a: str, b: str) -> bool:
    return a.strip().lower().replace("_", "-") == b.strip().lower().replace("_", "-")


class KeyLines:
    """Line numbers of the keys of a TOML text (for semantic errors: tomllib has no positions)."""

    _HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(#.*)?$")
    _PART = r'(?:[A-Za-z0-9_-]+|"[^"]*"|\'[^\']*\')'
    _KEY = re.compile(rf"^\s*({_PART}(?:\s*\.\s*{_PART})*)\s*=")
    _INLINE = re.compile(rf"({_PART})\s*=")

    def __init__(self, text: str):
        self.lines = text.splitlines()
        self.where: dict[tuple[str, ...], int] = {}
        table: tuple[str, ...] = ()
        for i, line in enumerate(self.lines, start=1):
            m = self._HEADER.match(line)
            if m:
                table = self._split(m.group(1))
                self.where.setdefault(table, i)
                continue
            m = self._KEY.match(line)
            if m:
                key = table + self._split(m.group(1))
                self.where.setdefault(key, i)
                brace = line.find("{", m.end())
                if brace >= 0:  # keys of an inline table on the same line
                    for sub in self._INLINE.finditer(line, brace):
                        self.where.setdefault(key + self._split(sub.group(1)), i)

    @staticmethod
    def _split(dotted: str) -> tuple[str, ...]:
        parts = re.findall(r'"[^"]*"|\'[^\']*\'|[^.\s]+', dotted)
        return tuple(p[1:-1] if p[:1] in "\"'" else p for p in parts)

    def line(self, key: tuple[str, ...]) -> int | None:
        for n in range(len(key), -1, -1):
            if key[:n] in self.where:
                return self.where[key[:n]]
        return None


class _Reader:
    """Validate a parsed system file, raising errors that name the file, the line and the key."""

    def __init__(self, text: str, source: str, base_dir: Path):
        self.source, self.base_dir = source, base_dir
        self.lines = KeyLines(text)
        try:
            self.doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            m = re.search(r"line (\d+)", str(exc))
            shown = ""
            if m and 1 <= int(m.group(1)) <= len(self.lines.lines):
                shown = f": {self.lines.lines[int(m.group(1)) - 1].strip()!r}"
            where = f", line {m.group(1)}" if m else ""
            raise IvobsError(f"{source}{where}: not valid TOML ({exc}){shown}") from None

    def fail(self, key: tuple[str, ...], msg: str) -> IvobsError:
        line = self.lines.line(key)
        where = f", line {line}" if line else ""
        label = ".".join(key) if key else "(top level)"
        return IvobsError(f"{self.source}{where}: {label}: {msg}")

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

    # -- values ---------------------------------------------------------------------------
    def numbers(self, key: tuple[str, ...], value: Any, ndims: tuple[int, ...]) -> np.ndarray:
        """A rectangular array of numbers whose dimension is one of ``ndims``."""
        shape = self._shape(key, value, ())
        if len(shape) not in ndims:
            what = {1: "a list of numbers", 2: "an array of rows (e.g. [[1.0, 0.0]])"}
            exp = " or ".join(what.get(n, f"a {n}-D array") for n in ndims)
            raise self.fail(key, f"expected {exp}, got a {len(shape)}-D value of shape {shape}")
        return np.array(value, dtype=float).reshape(shape)

    def _shape(self, key: tuple[str, ...], value: Any, index: tuple[int, ...]) -> tuple[int, ...]:
        at = "".join(f"[{i}]" for i in index)
        if isinstance(value, bool) or isinstance(value, (str, dict)) or value is None:
            raise self.fail(key, f"entry {at or '(value)'}: expected a number, got {value!r}")
        if isinstance(value, (int, float)):
            return ()
        if not isinstance(value, list):  # pragma: no cover - tomllib gives no other types
            raise self.fail(key, f"entry {at}: unexpected {type(value).__name__}")
        if not value:
            return (0,)
        shapes = [self._shape(key, v, (*index, i)) for i, v in enumerate(value)]
        for i, s in enumerate(shapes):
            if s != shapes[0]:
                raise self.fail(
                    key,
                    f"ragged array: row {at}[{i}] has shape {s}, row {at}[0] has {shapes[0]}",
                )
        return (len(value), *shapes[0])

    def matrix(self, key: tuple[str, ...], value: Any) -> Any:
        if isinstance(value, dict):
            if "python" not in value and ("shape" in value or "values" in value):
                return self.sparse(key, value)
            return self.python(key, value)
        arr = self.numbers(key, value, (2, 3))
        bad = ~np.isfinite(arr)
        if np.any(bad):
            idx = "".join(f"[{int(i)}]" for i in np.argwhere(bad)[0])
            raise self.fail(key, f"entry {idx} is {arr[bad][0]}; matrices must be finite")
        return arr

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
            return _make_callable(path, params)
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
            system = LinearSystem(
                mats["A"],
                mats.get("B"),
                mats["C"],
                D=mats.get("D"),
                E=mats.get("E"),
                F=mats.get("F"),
                d=d,
                dt=dt,
            )
        except IvobsError as exc:
            arg = re.match(r"^([A-F]|d|dt)\b", str(exc))
            key = (
                ("system", arg.group(1))
                if arg and arg.group(1) in (*_MATRICES, "dt")
                else (("disturbance",) if arg else ("system",))
            )
            raise self.fail(key, str(exc)) from None
        x0 = self.x0(system.nx)
        method, options = self.method()
        return SystemFile(system, x0, method, options, name, desc, self.source)

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
        mats = {m: self.matrix(("system", m), sysd[m]) for m in _MATRICES if m in sysd}
        arrays = {m: v for m, v in mats.items() if not callable(v)}  # dense or sparse

        def dims(m: str) -> tuple[int, ...] | None:
            return tuple(arrays[m].shape[-2:]) if m in arrays else None

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
                            f"entry [{i}]: no column {v!r} in the bounds file "
                            f"(columns: {', '.join(table)})",
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
        with open(path, newline="", encoding="utf-8") as fh:
            rows = [
                (i, r)
                for i, r in enumerate(csv.reader(fh), start=1)
                if r and not r[0].lstrip().startswith("#")
            ]
        if len(rows) < 2:
            raise self.fail(key, f"bounds file {str(path)!r} needs a header and one row per step")
        header = [h.strip() for h in rows[0][1]]
        data = np.empty((len(rows) - 1, len(header)))
        for j, (line, r) in enumerate(rows[1:]):
            if len(r) != len(header):
                raise self.fail(
                    key, f"{path}, line {line}: expected {len(header)} fields, got {len(r)}"
                )
            for c, cell in enumerate(r):
                try:
                    if "_" in cell:  # float() accepts 1_000; a CSV number does not
                        raise ValueError(cell)
                    data[j, c] = float(cell)
                except ValueError:
                    raise self.fail(
                        key,
                        f"{path}, line {line}, column {header[c]!r}: expected a "
                        f"number, got {cell!r}",
                    ) from None
                if not math.isfinite(data[j, c]):
                    raise self.fail(
                        key,
                        f"{path}, line {line}, column {header[c]!r}: bounds "
                        f"must be finite, got {cell!r}",
                    )
        return {h: data[:, c] for c, h in enumerate(header)}

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

    def method(self) -> tuple[str | None, dict[str, Any]]:
        tab = self.table(("method",))
        if tab is None:
            return None, {}
        from .estimators import get

        name = tab.get("name")
        if not isinstance(name, str):
            raise self.fail(("method", "name"), f"expected a method name, got {name!r}")
        try:
            cls = get(name)
        except IvobsError as exc:
            raise self.fail(("method", "name"), str(exc)) from None
        opts = tab.get("options", {})
        if not isinstance(opts, dict):
            raise self.fail(("method", "options"), f"expected a table, got {opts!r}")
        allowed = cls.options()
        out: dict[str, Any] = {}
        for k, v in opts.items():
            if k not in allowed:
                raise self.fail(
                    ("method", "options", k),
                    f"{cls.name} has no option {k!r}; accepted: {', '.join(allowed)}",
                )
            out[k] = self.option(("method", "options", k), v)
        return name, out

    def option(self, key: tuple[str, ...], v: Any) -> Any:
        if isinstance(v, dict):
            if set(v) == {"lower", "upper"}:
                try:
                    return Box(
                        self.numbers((*key, "lower"), v["lower"], (1,)),
                        self.numbers((*key, "upper"), v["upper"], (1,)),
                    )
                except IvobsError as exc:
                    raise self.fail(key, str(exc)) from None
            return {k: self.option((*key, k), x) for k, x in v.items()}
        if (
            isinstance(v, list)
            and v
            and all(isinstance(x, (int, float, list)) and not isinstance(x, bool) for x in v)
        ):
            return self.numbers(key, v, (1, 2, 3))
        return v


def loads_system(text: str, *, source: str = "<string>", base_dir: Any = ".") -> SystemFile:
    """Read a system file from its text (``base_dir``: where relative CSV paths point)."""
    return _Reader(text, source, Path(base_dir)).read()


def load_system(path: str | os.PathLike[str]) -> SystemFile:
    """Read a system file (TOML). Returns a :class:`SystemFile` (``.system``, ``.x0``,
    ``.method``, ``.options``). Raises :class:`~ivobs.IvobsError` naming the line and the key of
    anything malformed. Loading a file that names a Python callable imports its module: load
    trusted files only."""
    path = Path(path)
    if path.is_dir():
        raise IvobsError(f"system file {str(path)!r} is a directory; expected a TOML file")
    if not path.is_file():
        raise IvobsError(f"system file {str(path)!r} not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise IvobsError(f"{path}: not a UTF-8 text file ({exc})") from None
    return loads_system(text, source=str(path), base_dir=path.parent)


# ============================================================================================
# logs
# ============================================================================================
_STEP_COLS = ("k", "step")
_TIME_COLS = ("t", "time")
_SIGNAL = re.compile(r"^(?P<kind>[uy])(?:\d+|[_\[(.].*)?$", re.IGNORECASE)
_NUMBERED = re.compile(r"^[uy](?:(\d+)|_(\d+)|\[(\d+)\]|\((\d+)\)|\.(\d+))$", re.IGNORECASE)


def _signal_number(column: str) -> int | None:
    """The number of a signal column (``y2``, ``y_2``, ``y[2]``, ``y(2)``), else None."""
    m = _NUMBERED.match(column)
    return None if m is None else int(next(g for g in m.groups() if g is not None))


@dataclass
class LogRow:
    """One parsed row: the step and/or time value when the log has them, ``u`` and ``y``."""

    line: int
    u: np.ndarray
    y: np.ndarray
    step: int | None = None
    t: float | None = None


class LogParser:
    """Parse a log row by row (used by :func:`read_log` and the streaming monitor).

    Call :meth:`header` with the first non-comment line, then :meth:`row` with each further
    line. Errors name the source, the line and the column.
    """

    def __init__(self, nu: int, ny: int, source: str = "<log>"):
        self.nu, self.ny, self.source = nu, ny, source
        self.columns: list[str] = []
        self._step: int | None = None
        self._time: int | None = None
        self._u: list[int] = []
        self._y: list[int] = []
        self._last: LogRow | None = None

    @property
    def has_step(self) -> bool:
        return self._step is not None

    @property
    def has_time(self) -> bool:
        return self._time is not None

    def fail(self, line: int, msg: str) -> IvobsError:
        return IvobsError(f"{self.source}, line {line}: {msg}")

    @staticmethod
    def _cells(text: str) -> list[str]:
        return next(csv.reader([text]))

    def header(self, text: str, line: int = 1) -> None:
        """Read the header: signal columns numbered ``u1, u2, ...`` (also ``y[2]``, ``y_2``)
        are mapped by their number, whatever their order; unnumbered ones (``u_speed``) are
        taken in header order. A UTF-8 byte-order mark (Excel) is ignored."""
        cols = [c.strip() for c in self._cells(text.lstrip("\ufeff"))]
        self.columns = cols
        seen: set[str] = set()
        for i, c in enumerate(cols):
            low = c.lower()
            if low in seen:
                raise self.fail(line, f"duplicate column {c!r}")
            seen.add(low)
            m = _SIGNAL.match(c)
            if low in _STEP_COLS:
                if self._step is not None:
                    raise self.fail(line, "two step columns (k, step): keep one")
                self._step = i
            elif low in _TIME_COLS:
                if self._time is not None:
                    raise self.fail(line, "two time columns (t, time): keep one")
                self._time = i
            elif m:
                (self._u if m.group("kind").lower() == "u" else self._y).append(i)
            else:
                raise self.fail(
                    line,
                    f"unexpected column {c!r}: a log has an optional step "
                    "(k or step) or time (t or time) column, input columns u1, u2, "
                    "... and measurement columns y1, y2, ...",
                )
        for kind, idx, n in (("u", self._u, self.nu), ("y", self._y, self.ny)):
            if len(idx) != n:
                names = [cols[i] for i in idx]
                what = "inputs" if kind == "u" else "measurements"
                raise self.fail(
                    line,
                    f"the system has {n} {what}, so the log needs {n} "
                    f"{kind}-columns ({kind}1, ...); found {len(idx)}: {names}",
                )
            self._by_number(kind, idx, line)

    def _by_number(self, kind: str, idx: list[int], line: int) -> None:
        """Order the ``kind`` columns ``idx`` (in place) by their number when all have one."""
        nums = [_signal_number(self.columns[i]) for i in idx]
        if not idx or any(n is None for n in nums):
            return
        n = len(idx)
        for base in (1, 0):
            if sorted(nums) == list(range(base, base + n)):  # type: ignore[type-var]
                idx[:] = [i for _, i in sorted(zip(nums, idx))]  # type: ignore[type-var]
                return
        names = ", ".join(self.columns[i] for i in idx)
        raise self.fail(
            line,
            f"{kind}-columns {names}: expected the numbers {kind}1..{kind}{n} (each once; "
            "columns are matched by their number)",
        )

    def row(self, text: str, line: int) -> LogRow:
        if not self.columns:
            raise self.fail(line, "no header line before the data")
        cells = self._cells(text)
        if len(cells) != len(self.columns):
            raise self.fail(
                line,
                f"expected {len(self.columns)} fields ({','.join(self.columns)}), got {len(cells)}",
            )
        vals = np.empty(len(cells))
        for i, cell in enumerate(cells):
            s = cell.strip()
            if s == "" or s.lower() == "nan":
                vals[i] = np.nan
                continue
            try:
                if "_" in s:  # float() accepts 1_000; a CSV number does not
                    raise ValueError(s)
                vals[i] = float(s)
            except ValueError:
                raise self.fail(
                    line, f"column {self.columns[i]!r}: expected a number, got {s!r}"
                ) from None
            if not math.isfinite(vals[i]):
                raise self.fail(
                    line,
                    f"column {self.columns[i]!r}: infinite value {s!r} (use "
                    "an empty cell or NaN for a missing measurement)",
                )
        for i in [
            *self._u,
            *([self._step] if self.has_step else []),
            *([self._time] if self.has_time else []),
        ]:
            if np.isnan(vals[i]):
                what = "inputs must be known at every step" if i in self._u else "required"
                raise self.fail(line, f"column {self.columns[i]!r} is missing ({what})")
        out = LogRow(line=line, u=vals[self._u], y=vals[self._y])
        if self._step is not None:
            v = vals[self._step]
            if v != int(v):
                raise self.fail(
                    line, f"column {self.columns[self._step]!r}: expected an integer step, got {v}"
                )
            out.step = int(v)
            if (
                self._last is not None
                and self._last.step is not None
                and out.step <= self._last.step
            ):
                raise self.fail(
                    line,
                    f"step {out.step} does not increase (previous "
                    f"{self._last.step}, line {self._last.line})",
                )
        if self._time is not None:
            out.t = float(vals[self._time])
            if self._last is not None and self._last.t is not None and out.t <= self._last.t:
                raise self.fail(
                    line,
                    f"time {out.t} does not increase (previous "
                    f"{self._last.t}, line {self._last.line})",
                )
        self._last = out
        return out


def not_utf8(source: str, exc: UnicodeDecodeError) -> IvobsError:
    """The error for a log that is not UTF-8 text."""
    return IvobsError(
        f"{source}: not valid UTF-8 ({exc.reason}, byte "
        f"{exc.object[exc.start : exc.start + 1]!r}); a log must be UTF-8 text (CSV)"
    )


def _is_skipped(text: str) -> bool:
    s = text.strip()
    return not s or s.startswith("#")


@dataclass
class Log:
    """A measurement record: ``u`` ``(T, nu)``, ``y`` ``(T, ny)`` (NaN = missing), the step and
    time columns when present."""

    u: np.ndarray
    y: np.ndarray
    t: np.ndarray | None = None
    steps: np.ndarray | None = None
    columns: list[str] = field(default_factory=list)

    @property
    def T(self) -> int:
        return int(self.y.shape[0])

    @property
    def missing(self) -> np.ndarray:
        """``(T,)`` bool: rows with at least one missing measurement."""
        return np.any(np.isnan(self.y), axis=1)


def read_log(path: str | os.PathLike[str], system: LinearSystem) -> Log:
    """Read a CSV log for ``system`` (its ``nu`` inputs and ``ny`` measurements).

    Lines starting with ``#`` and blank lines are skipped. Errors name the line and the column:
    a wrong number of fields, text where a number belongs, a missing input, a step or time that
    does not increase.
    """
    path = Path(path)
    if path.is_dir():
        raise IvobsError(f"log file {str(path)!r} is a directory; expected a CSV file")
    if not path.is_file():
        raise IvobsError(f"log file {str(path)!r} not found")
    parser = LogParser(system.nu, system.ny, str(path))
    rows: list[LogRow] = []
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            for i, text in enumerate(fh, start=1):
                if _is_skipped(text):
                    continue
                if not parser.columns:
                    parser.header(text, i)
                else:
                    rows.append(parser.row(text, i))
    except UnicodeDecodeError as exc:
        raise not_utf8(str(path), exc) from None
    if not parser.columns:
        raise IvobsError(f"{path}: empty log (expected a header line such as k,u1,y1,y2)")
    if not rows:
        raise IvobsError(f"{path}: the log has a header but no data rows")
    return Log(
        u=np.array([r.u for r in rows]).reshape(len(rows), system.nu),
        y=np.array([r.y for r in rows]).reshape(len(rows), system.ny),
        t=np.array([r.t for r in rows]) if parser.has_time else None,
        steps=np.array([r.step for r in rows]) if parser.has_step else None,
        columns=parser.columns,
    )


def write_log(
    path: str | os.PathLike[str], u: Any, y: Any, *, t: Any = None, steps: bool = True
) -> None:
    """Write a log (``k[,t],u1..,y1..``) atomically; NaN measurements become empty cells."""
    y = np.atleast_2d(np.asarray(y, dtype=float))
    T = y.shape[0]
    u = np.zeros((T, 0)) if u is None else np.asarray(u, dtype=float).reshape(T, -1)
    cols = (["k"] if steps else []) + (["t"] if t is not None else [])
    cols += [f"u{i + 1}" for i in range(u.shape[1])] + [f"y{i + 1}" for i in range(y.shape[1])]
    tt = None if t is None else np.asarray(t, dtype=float).ravel()

    def cell(v: float) -> str:
        return "" if np.isnan(v) else repr(float(v))

    lines = [",".join(cols)]
    for k in range(T):
        parts = ([str(k)] if steps else []) + ([repr(float(tt[k]))] if tt is not None else [])
        parts += [cell(v) for v in u[k]] + [cell(v) for v in y[k]]
        lines.append(",".join(parts))
    write_text_atomic(path, "\n".join(lines) + "\n")
