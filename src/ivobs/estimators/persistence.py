"""``state()`` / ``restore()`` of every estimator: the typed online state (``state.py``) in a
versioned envelope with the method's name and a fingerprint of its design."""

from __future__ import annotations

import hashlib
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from ..errors import IvobsError
from .state import STATE_FORMAT, STATE_VERSION, OnlineState, dump_state, load_state

if TYPE_CHECKING:
    from .base import Design

__all__ = ["Persistence"]


class Persistence:
    """Saving and restoring the online state (a mix-in of :class:`~ivobs.estimators.Estimator`,
    which provides the attributes declared here)."""

    name: ClassVar[str]
    sys: Any
    design: Design
    _state: OnlineState | None

    def initial_state(self) -> OnlineState:
        raise NotImplementedError

    def fingerprint(self) -> str:
        """A hash of the method, the dimensions and the numbers of the design: a state restores
        only into the estimator that produced it."""
        parts = [self.name, str(self.sys.nx), str(self.sys.nu), str(self.sys.ny)]
        for key, val in self.design.as_dict().items():
            # numbers only: provenance strings (how a gain was obtained) do not change the state
            if isinstance(val, np.ndarray) and val.dtype.kind in "fiub":
                parts.append(key + np.array2string(val, precision=12))
            elif isinstance(val, (int, float)):
                parts.append(f"{key}={val}")
        return hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]

    def state(self) -> dict[str, Any]:
        """The online state as a JSON-serialisable dict (see :meth:`restore`): the method, the
        fingerprint of its design, the format version and the state's fields."""
        return self.save_state(self._state if self._state is not None else self.initial_state())

    def save_state(self, st: OnlineState) -> dict[str, Any]:
        """A given online state of this estimator as the JSON-serialisable dict of
        :meth:`state`."""
        return {
            "format": STATE_FORMAT,
            "version": STATE_VERSION,
            "method": self.name,
            "fingerprint": self.fingerprint(),
            "state": self._dump(st),
        }

    def _dump(self, st: Any) -> Any:
        """The ``"state"`` entry of :meth:`save_state` (the state's fields)."""
        return dump_state(st)

    def _load(self, saved: Any) -> OnlineState:
        """The online state from the ``"state"`` entry, checked against a fresh one."""
        return load_state(saved, self.initial_state())

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a state saved by :meth:`state` (same method and design); the saved
        values are checked against a fresh state of this estimator."""
        self._state = self.check_state(state)

    def check_state(self, state: Any) -> OnlineState:
        """The online state held by ``state`` (a dict from :meth:`state`), checked against this
        estimator (method, design fingerprint, format version, every entry); raises
        :class:`~ivobs.IvobsError` naming what is wrong. Does not change the estimator."""
        if not isinstance(state, dict) or "state" not in state:
            raise IvobsError("state: expected the dict returned by Estimator.state()")
        if state.get("method") != self.name or state.get("fingerprint") != self.fingerprint():
            raise IvobsError(
                f"state: saved by method {state.get('method')!r} with another design (or other "
                f"members); it can only be restored into the same method ({self.name!r}) with "
                "the same design"
            )
        version = state.get("version", 1)  # a state saved before typed states has none
        if version != STATE_VERSION:
            raise IvobsError(
                f"state: saved in state format version {version!r}; this ivobs reads version "
                f"{STATE_VERSION} (typed states). Re-run from the start of the record, or load "
                "it with the ivobs version that saved it"
            )
        return self._load(state["state"])
