"""Nonlinear models in system files: ``[system]`` with ``f``, ``h`` (expression strings, the
language of :class:`~ivobs.NonlinearSystem`), ``states``, ``inputs``, ``outputs``, ``dt`` and the
tables ``[system.params]`` (a number: known; ``[lo, hi]``: unknown) and ``[system.d]``
(``name = [lo, hi]``). Expressions are read by a whitelist, never executed: loading a
nonlinear system file runs no code.

A continuous-time model (``dt = 0``) may carry its guaranteed discretisation in
``[system.discretize]`` (``Ts``, ``order``, ``substeps``, ``disturbances``: the arguments of
:meth:`~ivobs.NonlinearSystem.discretize`), so that a saved sampled model loads as it was saved.
Examples of both: docs/nonlinear.md, "System files".
"""

from __future__ import annotations

import dataclasses
import re
from typing import Any

from ..errors import IvobsError
from ..model import NonlinearSystem
from .reader import TomlReader

__all__ = ["NONLINEAR_KEYS", "dump_nonlinear", "read_nonlinear"]

NONLINEAR_KEYS = ("dt", "states", "inputs", "outputs", "f", "h", "params", "d", "discretize")
DISCRETIZE_KEYS = ("Ts", "order", "substeps", "disturbances")


def _strings(reader: TomlReader, key: tuple[str, ...], value: Any, what: str) -> list[str]:
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise reader.fail(key, f"expected a list of {what} (strings), got {value!r}")
    return list(value)


def _table(reader: TomlReader, key: tuple[str, ...], value: Any) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise reader.fail(key, f"expected a table of name = value, got {value!r}")
    return dict(value)


def read_nonlinear(reader: Any, sysd: dict[str, Any], dt: bool | float) -> NonlinearSystem:
    """The :class:`~ivobs.NonlinearSystem` of a ``[system]`` table with ``f`` and ``h``;
    errors name the file, the line and the key."""
    other = sorted(set(sysd) - set(NONLINEAR_KEYS))
    if other:
        raise reader.fail(
            ("system", other[0]),
            f"a nonlinear system (f, h) takes no matrix {other[0]}; allowed keys: "
            f"{', '.join(NONLINEAR_KEYS)}",
        )
    if "disturbance" in reader.doc:
        raise reader.fail(
            ("disturbance",),
            "a nonlinear system gives its signal bounds in [system.d] (name = [lo, hi])",
        )
    for k in ("f", "h", "states"):
        if k not in sysd:
            raise reader.fail(("system",), f"missing {k} = [...] (a nonlinear system)")
    args: dict[str, Any] = {
        "f": _strings(reader, ("system", "f"), sysd["f"], "expressions"),
        "h": _strings(reader, ("system", "h"), sysd["h"], "expressions"),
        "states": _strings(reader, ("system", "states"), sysd["states"], "names"),
        "inputs": _strings(reader, ("system", "inputs"), sysd.get("inputs", []), "names"),
        "params": _table(reader, ("system", "params"), sysd.get("params", {})),
        "d": _table(reader, ("system", "d"), sysd.get("d", {})),
        "dt": dt,
    }
    if "outputs" in sysd:
        args["outputs"] = _strings(reader, ("system", "outputs"), sysd["outputs"], "names")
    try:
        model = NonlinearSystem(**args)
    except IvobsError as exc:
        raise reader.fail(_key_of(str(exc)), str(exc)) from None
    if "names" in reader.doc:  # units (and other labels) beside the model's own names
        given = {k: v for k, v in vars(reader.names(model)).items() if v is not None}
        model.names = dataclasses.replace(model.names, **given)
    if "discretize" in sysd:
        return _discretized(reader, model, sysd["discretize"])
    return model


def _discretized(reader: Any, model: NonlinearSystem, table: Any) -> NonlinearSystem:
    """``model`` (continuous-time) sampled as ``[system.discretize]`` says (the values are
    checked by :meth:`NonlinearSystem.discretize <ivobs.NonlinearSystem.discretize>`)."""
    key = ("system", "discretize")
    spec = _table(reader, key, table)
    other = sorted(set(spec) - set(DISCRETIZE_KEYS))
    if other:
        raise reader.fail(
            (*key, other[0]), f"unknown key; allowed keys: {', '.join(DISCRETIZE_KEYS)}"
        )
    if "Ts" not in spec:
        raise reader.fail(key, "missing Ts = <sampling period > 0>")
    if model.dt != 0:
        raise reader.fail(
            key, f"only a continuous-time model (dt = 0) is discretised; dt = {model.dt}"
        )
    try:
        return model.discretize(
            spec["Ts"],
            order=spec.get("order", 4),
            substeps=spec.get("substeps", 1),
            disturbances=spec.get("disturbances", "varying"),
        )
    except IvobsError as exc:
        raise reader.fail(key, str(exc)) from None


def _key_of(msg: str) -> tuple[str, ...]:
    """The file key an error of :class:`~ivobs.NonlinearSystem` is about."""
    m = re.match(r"^(params|d)\['([^']+)'\]", msg)
    if m:
        return ("system", m.group(1), m.group(2))
    m = re.match(r"^(f|h|states|inputs|outputs|params|d|dt)\b", msg)
    return ("system", m.group(1)) if m else ("system",)


def dump_nonlinear(system: NonlinearSystem, scalar: Any, value: Any) -> list[str]:
    """The ``[system]`` lines of a nonlinear system (``scalar``, ``value``: the writer's TOML
    formatters)."""
    spec = system.spec()
    out = ["[system]", f"dt = {scalar(spec['dt'])}"]
    for k in ("states", "inputs", "outputs", "f", "h"):
        out.append(f"{k} = {value(spec[k])}")
    if spec["params"]:
        out += ["", "[system.params]"]
        out += [
            f"{n} = {value(list(v) if isinstance(v, tuple) else v)}"
            for n, v in spec["params"].items()
        ]
    if spec["d"]:
        out += ["", "[system.d]"]
        out += [f"{n} = {value(list(v))}" for n, v in spec["d"].items()]
    if "discretize" in spec:  # a sampled continuous-time model (FlowSystem)
        out += ["", "[system.discretize]"]
        out += [f"{k} = {scalar(v)}" for k, v in spec["discretize"].items()]
    return out
