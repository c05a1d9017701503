"""python-control ``StateSpace`` objects as ivobs systems.

A ``control.StateSpace`` has one input vector; ivobs splits it into known inputs ``u`` and
bounded unknown disturbances ``d``: ``x+ = A x + B_u u + B_d d``, ``y = C x + D_u u + D_d d``.
Signal names (``ss.state_labels``, ``input_labels``, ``output_labels``) are kept on the system
(``sys.names``) for plots and tables.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..sets import Box

__all__ = ["SignalNames", "from_statespace", "is_statespace"]


@dataclass(frozen=True)
class SignalNames:
    """Names of a system's states, inputs, outputs and disturbances (``None``: unnamed)."""

    states: tuple[str, ...] | None = None
    inputs: tuple[str, ...] | None = None
    outputs: tuple[str, ...] | None = None
    disturbances: tuple[str, ...] | None = None
    units: tuple[str, ...] | None = None
    """Units of the states (``"rad"``, ``"m/s"``)."""

    def state_labels(self) -> tuple[str, ...] | None:
        """``"name (unit)"`` per state (plots, tables), or None when the states are unnamed."""
        if self.states is None:
            return None
        units = self.units or ("",) * len(self.states)
        return tuple(f"{n} ({u})" if u else n for n, u in zip(self.states, units))


def is_statespace(obj: Any) -> bool:
    """Whether ``obj`` is a python-control ``StateSpace`` (without importing python-control:
    a ``StateSpace`` is callable, so it must not be taken for a time-varying matrix)."""
    return type(obj).__module__.startswith("control.") and all(
        hasattr(obj, k) for k in ("A", "B", "C", "D", "dt")
    )


def _input_index(spec: Any, labels: Sequence[str], m: int) -> list[int]:
    """Indices of the disturbance inputs, given by index or by label."""
    items = [spec] if isinstance(spec, (int, str, np.integer)) else list(spec)
    out: list[int] = []
    for item in items:
        if isinstance(item, str):
            if item not in labels:
                raise IvobsError(
                    f"disturbances: no input named {item!r}; the inputs are {list(labels)}"
                )
            out.append(list(labels).index(item))
        elif isinstance(item, (int, np.integer)) and 0 <= int(item) < m:
            out.append(int(item))
        else:
            raise IvobsError(
                f"disturbances: expected input indices in 0..{m - 1} or input names, got {item!r}"
            )
    if len(set(out)) != len(out):
        raise IvobsError(f"disturbances: an input is listed twice: {items!r}")
    return out


def from_statespace(
    cls: Any,
    ss: Any,
    *,
    disturbances: Any = (),
    d: Any = None,
    E: Any = None,
    F: Any = None,
) -> Any:
    """:meth:`ivobs.LinearSystem.from_statespace`, building a ``cls``."""
    if not is_statespace(ss) and not all(hasattr(ss, k) for k in "ABCD"):
        raise IvobsError(
            f"ss: expected a control.StateSpace (with A, B, C, D), got {type(ss).__name__}"
        )
    A, B, C, D = (np.asarray(getattr(ss, k), dtype=float) for k in "ABCD")
    dt = getattr(ss, "dt", True)
    if dt is None:
        raise IvobsError(
            "ss.dt: python-control's unspecified timebase (None); set dt=0 (continuous) or "
            "dt=True / a period (discrete)"
        )
    m = B.shape[1]
    labels = list(getattr(ss, "input_labels", [f"u[{i}]" for i in range(m)]))
    idx = _input_index(disturbances, labels, m) if disturbances is not None else []
    if idx:
        if E is not None or F is not None:
            raise IvobsError("disturbances: give either disturbance inputs of ss or E/F, not both")
        if not isinstance(d, Box) or d.dim != len(idx):
            raise IvobsError(
                f"d: expected a Box of {len(idx)} components (the bounds of the disturbance "
                f"inputs {[labels[i] for i in idx]}), got {d!r}"
            )
        known = [i for i in range(m) if i not in idx]
        E, F = B[:, idx], D[:, idx]
        B, D = B[:, known], D[:, known]
    else:
        known = list(range(m))
    sys = cls(A, B, C, D=D, E=E, F=F, d=d, dt=dt)
    sys.names = SignalNames(
        states=_labels(ss, "state_labels", A.shape[0]),
        inputs=tuple(labels[i] for i in known),
        outputs=_labels(ss, "output_labels", C.shape[0]),
        disturbances=tuple(labels[i] for i in idx) or None,
    )
    return sys


def _labels(ss: Any, attr: str, n: int) -> tuple[str, ...] | None:
    labels = getattr(ss, attr, None)
    if labels is None or len(labels) != n:
        return None
    return tuple(str(v) for v in labels)
