"""Writing system files (:func:`save_system`, :func:`dumps_system`) and comparing systems
(:func:`equal_systems`: what a written file gives back when read)."""

from __future__ import annotations

import json
import math
import os
import re
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..sets import Box
from .atomic import write_text_atomic
from .callables import callable_ref
from .nlsystemfile import dump_nonlinear
from .systemfile import FORMAT, MATRICES, SystemFile

__all__ = ["dumps_system", "equal_systems", "save_system"]


def _same_value(a: Any, b: Any) -> bool:
    if a is None or b is None:
        return a is None and b is None
    if isinstance(a, str) or isinstance(b, str):  # a callable's parameter
        return bool(a == b)
    if callable(a) or callable(b):
        if not (callable(a) and callable(b)):
            return False
        ra, rb = callable_ref(a), callable_ref(b)
        if ra is None or rb is None:
            return a is b
        return ra[0] == rb[0] and _same_params(ra[1], rb[1])
    if isinstance(a, Box) or isinstance(b, Box):
        return isinstance(a, Box) and isinstance(b, Box) and a == b
    if isinstance(a, dict) or isinstance(b, dict):  # interval matrices, name -> Box
        return isinstance(a, dict) and isinstance(b, dict) and _same_params(a, b)
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


def _same_params(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return set(a) == set(b) and all(_same_value(a[key], b[key]) for key in a)


def equal_systems(a: Any, b: Any) -> bool:
    """Whether two systems are the same model: same ``dt``, the same matrices (arrays equal
    entry for entry, stacks equal, callables the same import path and parameters) and the same
    disturbance bounds; for nonlinear systems, the same names, expressions and bounds."""
    if isinstance(a, NonlinearSystem) or isinstance(b, NonlinearSystem):
        return (
            isinstance(a, NonlinearSystem)
            and isinstance(b, NonlinearSystem)
            and a.spec() == b.spec()
        )
    if not (isinstance(a, LinearSystem) and isinstance(b, LinearSystem)):
        raise IvobsError(
            f"equal_systems: expected two LinearSystems, got {type(a).__name__} and "
            f"{type(b).__name__}"
        )
    if (a.dt is True) != (b.dt is True) or a.dt != b.dt:
        return False
    if (a.nx, a.nu, a.ny, a.nd) != (b.nx, b.nu, b.ny, b.nd):
        return False
    for m in MATRICES:
        sa, sb = _sparse_of(a, m), _sparse_of(b, m)
        if sa is not None and sb is not None:  # compared without building dense views
            if sa.shape != sb.shape or (sa != sb).nnz:
                return False
        elif not _same_value(getattr(a, m), getattr(b, m)):
            return False
    if not _same_value(a.interval_matrices(), b.interval_matrices()):
        return False
    return _same_value(a.d, b.d)


def _sparse_of(system: LinearSystem, m: str) -> Any:
    """The ``scipy.sparse`` matrix ``m`` of ``system`` when it was given sparse, else None."""
    return getattr(getattr(system, f"_{m}", None), "sp", None)


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


def _named(what: str, fn: Any, form: str = "") -> tuple[str, dict[str, Any]]:
    """The import path and parameters of the callable ``fn`` (``what`` in the error when a file
    cannot name it; ``form``: the signature it should have)."""
    ref = callable_ref(fn)
    if ref is None:
        raise IvobsError(
            f"save_system: {what} a callable ivobs cannot name in a file ({fn!r}); use a "
            f"module-level function{form}, or functools.partial of one with keyword parameters"
        )
    return ref


def _matrix_value(name: str, m: Any) -> str:
    if callable(m):
        path, params = _named(f"{name} is", m)
        return _value({"python": path, "params": params})
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
    from ..scenarios import Scenario

    x0_step = int(getattr(system, "x0_step", 0))  # a loaded system file's [x0] step
    if isinstance(system, SystemFile):
        method = system.method if method is None else method
        options = system.options if options is None else options
    if isinstance(system, (SystemFile, Scenario)):
        x0 = system.x0 if x0 is None else x0
        name = name or system.name
        description = description or system.description
        system = system.system
    if not isinstance(system, (LinearSystem, NonlinearSystem)):
        raise IvobsError(
            f"system: expected a LinearSystem, a NonlinearSystem, a SystemFile or a Scenario, got "
            f"{type(system).__name__}"
        )
    options, name, description = dict(options or {}), str(name), str(description)
    nonlinear = isinstance(system, NonlinearSystem)
    model = (
        [
            "#   x[k+1] = f(x, u, p, d),  y[k] = h(x, u, p, d)  (expressions)",
            "#   p in [system.params], d in [system.d],  x[0] in [x0.lower, x0.upper]",
        ]
        if nonlinear
        else [
            "#   x[k+1] = A x[k] + B u[k] + E d[k],  y[k] = C x[k] + D u[k] + F d[k]",
            "#   d[k] in [disturbance.lower, disturbance.upper],  x[0] in [x0.lower, x0.upper]",
        ]
    )
    out = ["# ivobs system file", *model, f"format = {FORMAT}"]
    if name:
        out.append(f"name = {_scalar(name)}")
    if description:
        out.append(f"description = {_scalar(description)}")
    if isinstance(system, NonlinearSystem):
        out += ["", *dump_nonlinear(system, _scalar, _value)]
        if system.names.units:
            out += ["", "[names]", f"units = {_value(list(system.names.units))}"]
        return "\n".join(out + _tail(x0, method, options, x0_step)) + "\n"
    out += ["", "[system]", f"dt = {_scalar(system.dt)}"]
    skip = {"B": system.nu == 0, "D": system.nu == 0, "E": system.nd == 0, "F": system.nd == 0}
    sparse_tables = []
    for m in MATRICES:
        if skip.get(m, False):
            continue
        sp = _sparse_of(system, m)
        box = system.interval_matrices().get(m)
        if box is not None:  # an interval matrix: a sub-table too (docs/uncertain.md)
            sparse_tables += ["", f"[system.{m}]", f"lower = {_value(box.lo)}",
                              f"upper = {_value(box.hi)}"]  # fmt: skip
        elif sp is not None:  # a sub-table, after the other keys of [system]
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
            path, params = _named("the disturbance bounds are", d, " (k, y) -> Box")
            out += [f"python = {_scalar(path)}", f"params = {_value(params)}"]
    names = getattr(system, "names", None)
    labelled = {k: getattr(names, k) for k in ("states", "units", "inputs", "outputs",
                "disturbances") if getattr(names, k, None)}  # fmt: skip
    if labelled:
        out += ["", "[names]"] + [f"{k} = {_value(list(v))}" for k, v in labelled.items()]
    return "\n".join(out + _tail(x0, method, options, x0_step)) + "\n"


def _tail(x0: Any, method: str | None, options: dict[str, Any], x0_step: int = 0) -> list[str]:
    """The ``[x0]`` and ``[method]`` tables."""
    out: list[str] = []
    if x0 is not None:
        if not isinstance(x0, Box) or x0.is_time_varying:
            raise IvobsError(f"save_system: x0 must be a constant ivobs.Box, got {x0!r}")
        out += ["", "[x0]", f"lower = {_value(x0.lo)}", f"upper = {_value(x0.hi)}"]
        out += [f"step = {x0_step}"] if x0_step else []
    if method is not None:
        out += ["", "[method]", f"name = {_scalar(method)}"]
        if options:
            out += ["", "[method.options]"]
            out += [f"{_key(k)} = {_value(v)}" for k, v in options.items()]
    elif options:
        raise IvobsError("save_system: options were given without a method")
    return out


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

    ``system`` is a :class:`~ivobs.LinearSystem`, a :class:`~ivobs.NonlinearSystem` (written as
    its expressions), a :class:`SystemFile` or a
    :class:`~ivobs.scenarios.Scenario` (its prior box, name and description are written too).
    Numbers are written with full precision (``repr``), so :func:`load_system` gives back the
    same system (:func:`equal_systems`). Callable matrices and bounds must be module-level
    functions or ``functools.partial`` of one with keyword parameters.
    """
    text = dumps_system(
        system, x0=x0, method=method, options=options, name=name, description=description
    )
    write_text_atomic(path, text)
