"""The sections of a system file about the plant's labels and prior: ``[names]`` and ``[x0]``
(read by :class:`~ivobs.io.systemfile` with the same file/line errors)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model.statespace import SignalNames
from ..sets import Box
from .reader import TomlReader

__all__ = ["PlantSections"]


class PlantSections(TomlReader):
    """``[names]`` and ``[x0]`` of a system file; the reader supplies ``table`` and
    ``check_keys``."""

    def table(self, key: tuple[str, ...], required: bool = False) -> dict[str, Any] | None:
        raise NotImplementedError

    def check_keys(self, table: dict[str, Any], key: tuple[str, ...]) -> None:
        raise NotImplementedError

    def names(self, system: Any) -> SignalNames:
        """``[names]``: labels of the states (and their ``units``), inputs, outputs and
        disturbance components, for plots and tables."""
        tab = self.table(("names",))
        if tab is None:
            return SignalNames()
        self.check_keys(tab, ("names",))
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
