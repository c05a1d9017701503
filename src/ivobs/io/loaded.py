"""What a loaded system file holds (:class:`SystemFile`), and how its method is built."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..errors import IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..sets import Box
from .options import same_method

__all__ = ["SystemFile"]


@dataclass
class SystemFile:
    """What a system file holds: the model, the prior box, a method and its options."""

    system: LinearSystem | NonlinearSystem
    x0: Box | None = None
    method: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    name: str = ""
    description: str = ""
    source: str = ""
    files: tuple[str, ...] = ()
    """Other files the system file read (its ``[disturbance] csv``)."""
    option_lines: dict[str, int] = field(default_factory=dict)
    """The line of each of ``options`` in the file (for the errors of their values)."""
    x0_step: int = 0
    """The step whose state ``x0`` bounds (``[x0] step``): a log must start there."""

    def make_estimator(
        self, method: str | None = None, *, defaults: dict[str, Any] | None = None, **options: Any
    ) -> Any:
        """The estimator of the file's method (or ``method``) with the file's prior box.

        The file's options apply to the file's method only; ``options`` are added to them, and
        ``defaults`` apply where neither gives the option (a command's own default).
        """
        from ..estimators import make_estimator

        name = method or self.method
        if name is None:
            raise IvobsError(
                f"method: {self.source or 'the system file'} names no method ([method] name = "
                "...); give one (e.g. --method interval-split)"
            )
        opts = dict(defaults or {})
        opts.update(self.options if (self.method and same_method(name, self.method)) else {})
        opts.update(options)
        try:
            return make_estimator(name, self.system, x0=self.x0, **opts)
        except IvobsError as exc:
            raise self._where(exc, set(opts) - set(options)) from None

    def _where(self, exc: IvobsError, from_file: set[str]) -> IvobsError:
        """An error about an option value that came from the file, with its file and line: the
        method's checks name the option first (``order: expected an integer, got 'six'``)."""
        msg = str(exc)
        opt = next((o for o in sorted(from_file) if msg.startswith(f"{o}: ")), None)
        if opt is None:
            return exc
        line = self.option_lines.get(opt)
        where = f"{self.source or '<string>'}" + (f", line {line}" if line else "")
        try:
            out = type(exc)(f"{where}: method.options.{msg}")
        except TypeError:  # pragma: no cover - an error class with other arguments
            out = IvobsError(f"{where}: method.options.{msg}")
        return out
