"""Fingerprints of what a saved monitor state belongs to: the model's matrices, its disturbance
bounds, the prior box and the monitor's settings, each hashed on its own (SHA-256 of the exact
numbers), so that a state that does not match is refused naming the part that differs.

A leaf module (NumPy and the callables' names only): :mod:`ivobs.monitor` and
:mod:`ivobs.io.statefile` use it.
"""

from __future__ import annotations

import hashlib
import json
from typing import Any

import numpy as np

from .callables import callable_ref

__all__ = ["PARTS", "canonical_json", "digest", "model_fingerprint"]

PARTS = {
    "matrices": "the model's matrices (A, B, C, D, E, F) or its sampling period",
    "bounds": "the disturbance bounds d",
    "prior": "the prior box x0",
    "settings": "the monitor's settings (tight, margin, clear_after)",
}
"""The parts of a model fingerprint and what each covers (the words of the errors)."""


def canonical_json(value: Any) -> str:
    """JSON with sorted keys and no spaces: the same text for the same values, whatever the
    order they were built in (what a checksum hashes)."""
    return json.dumps(value, sort_keys=True, separators=(",", ":"))


def _feed(h: Any, v: Any) -> None:
    """Feed ``v`` to the hash ``h``, with its type, so that different values never collide
    through their spelling (a 1-by-1 matrix and a number, a list and a tuple do not)."""
    if v is None or isinstance(v, (bool, int, float, str)):
        h.update(f"{type(v).__name__}:{v!r};".encode())
    elif isinstance(v, np.generic):
        _feed(h, v.item())
    elif isinstance(v, np.ndarray):
        arr = np.ascontiguousarray(v, dtype="<f8" if v.dtype.kind in "fiub" else None)
        h.update(f"array{arr.dtype.str}{arr.shape};".encode())
        h.update(arr.tobytes() if arr.dtype.kind != "O" else repr(arr.tolist()).encode())
    elif hasattr(v, "lo") and hasattr(v, "hi"):  # a Box
        h.update(b"box;")
        _feed(h, np.asarray(v.lo))
        _feed(h, np.asarray(v.hi))
    elif hasattr(v, "tocsr"):  # a scipy.sparse matrix: its nonzero entries
        csr = v.tocsr()
        csr.sort_indices()
        h.update(f"sparse{csr.shape};".encode())
        for part in (csr.data, csr.indices, csr.indptr):
            _feed(h, np.asarray(part))
    elif isinstance(v, dict):
        h.update(f"dict{len(v)};".encode())
        for key in sorted(v, key=str):
            _feed(h, str(key))
            _feed(h, v[key])
    elif isinstance(v, (list, tuple)):
        h.update(f"seq{len(v)};".encode())
        for x in v:
            _feed(h, x)
    elif callable(v):  # by the name a file gives it (a system file names no other callable)
        ref = callable_ref(v)
        name = f"{getattr(v, '__module__', '')}:{getattr(v, '__qualname__', repr(v))}"
        _feed(h, ["callable", *(ref if ref is not None else (name, {}))])
    else:
        h.update(f"{type(v).__name__}:{v!r};".encode())


def digest(*values: Any) -> str:
    """The SHA-256 (hex, 32 digits) of ``values``, exact to the last bit of every number."""
    h = hashlib.sha256()
    for v in values:
        _feed(h, v)
    return h.hexdigest()[:32]


def model_fingerprint(sys: Any, x0: Any, settings: dict[str, Any]) -> dict[str, str]:
    """The fingerprint of a model ``sys``, its prior box ``x0`` and a monitor's ``settings``:
    one digest per part of :data:`PARTS` (a nonlinear model: its specification for the
    matrices' part, its unknowns' box for the bounds')."""
    if hasattr(sys, "spec") and not hasattr(sys, "interval_matrices"):  # NonlinearSystem
        model = digest(canonical_json(sys.spec()), sys.dt), digest(sys.w_box)
    else:
        matrices = [getattr(sys, m) for m in ("A", "B", "C", "D", "E", "F")]
        model = digest(matrices, sys.dt, sys.interval_matrices()), digest(sys.d)
    return dict(zip(PARTS, (*model, digest(x0), digest(settings)), strict=True))
