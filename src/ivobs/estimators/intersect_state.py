"""``state()`` / ``restore()`` of ``intersect``: its members' saved states, each in its own
envelope (method, design fingerprint), inside the intersection's."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import IvobsError
from .persistence import check_version
from .state import STATE_FORMAT, STATE_VERSION, check_counters

if TYPE_CHECKING:
    from .intersect import Intersect

__all__ = ["check_members", "save_members"]


def save_members(est: Intersect, st: Any) -> dict[str, Any]:
    """The envelope of the intersection's state, with the members' states nested."""
    return {
        "format": STATE_FORMAT,
        "version": STATE_VERSION,
        "method": est.name,
        "fingerprint": est.fingerprint(),
        "state": {
            "k": st.k,
            "scale": st.scale,
            "inconsistent": st.inconsistent,
            "members": [m.save_state(ms) for m, ms in zip(est.members, st.members, strict=True)],
        },
    }


def check_members(est: Intersect, state: Any) -> dict[str, Any]:
    """The fields of the intersection's state saved by :func:`save_members`, checked: the same
    members with the same designs, the counters, and each member's state by the member."""
    if not isinstance(state, dict) or not isinstance(state.get("state"), dict):
        raise IvobsError("state: expected the dict returned by Estimator.state()")
    if state.get("method") != est.name or state.get("fingerprint") != est.fingerprint():
        raise IvobsError(
            f"state: saved by method {state.get('method')!r} with other members or designs; "
            f"it can only be restored into the same {est.name!r} estimator"
        )
    check_version(state)
    saved = state["state"]
    counters = {"k": saved.get("k"), "scale": saved.get("scale", 0.0)}
    check_counters(counters)
    members = saved.get("members")
    if not isinstance(members, list) or len(members) != len(est.members):
        raise IvobsError(f"state: expected the states of {len(est.members)} members")
    return {
        "members": tuple(m.check_state(s) for m, s in zip(est.members, members, strict=True)),
        "k": counters["k"],
        "scale": counters["scale"],
        "inconsistent": bool(saved.get("inconsistent", False)),
    }
