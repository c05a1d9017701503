"""Intersection of several guaranteed estimates (and of the measurement strip).

If every member ``m`` returns a box ``[lo_m, hi_m]`` certain to contain ``x[k]``, so does

::

    lower_k = max_m lo_m,    upper_k = min_m hi_m,

which is never wider than the best member in any component. Members are other ivobs methods run
side by side on the same data; a member ignores nothing and gains nothing from the others (each
keeps its own recursion), so the result is as sound as the weakest assumption among them.

**Measurement strips.** Every output row gives ``C_r x ∈ y_r - D_r u - F_r [d]``; the
intersection is met with these strips (option ``strips``, on by default:
:mod:`ivobs.estimators.measured`, with its rounding proof), so a state measured directly is
never wider than its sensor's band.

**Rounding, proven** (``proven_rounding``; no margin of its own). The intersection and the hull
are comparisons of floats: exact. Each member's box is the member's own, rounded by its own
rules; the strips are rounded outwards (:mod:`ivobs.estimators.measured`).

**Inconsistent data.** An empty intersection means two guaranteed enclosures of the same state
do not meet: the data contradict the model and the bounds (a fault). The step is reported
(``on_inconsistent``), and the box returned is the *hull of the members' boxes*: each member
handled the fault by its own
rules (e.g. ``exact`` predicts without the sample), so the hull contains the state as long as one
member's enclosure does, and it is never empty or inverted. Every enclosure contains the state
of an admissible record, so a crossing of two bounds, by however little, is a contradiction:
no tolerance. Steps a member itself reports as inconsistent are reported too.

Data used: the union of what the members use (``u[0..k]``, ``y[0..k]`` at most, each member
its own prior ``x0``); the strip uses ``u[k]``, ``y[k]``.
"""

from __future__ import annotations

import hashlib
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import DesignError, IvobsError
from ..model import LinearSystem
from ..sets import Box
from . import make_estimator, methods, register
from .base import Design, Estimator
from .state import OnlineState, Step, check_counters, evolve

__all__ = ["DEFAULT_METHODS", "Intersect", "IntersectDesign"]

DEFAULT_METHODS = ("reachability", "zonotope", "strip", "fixed-time", "interval-split", "kkl")
"""Members tried when ``methods`` is not given (fast methods with complementary designs); those
not registered, not applicable to the system, or whose design fails are skipped."""


@dataclass(frozen=True)
class IntersectDesign(Design):
    """``methods``: the members' names; ``strip_rows``: the output rows whose strips meet the
    box (the exactly known ones; used when ``strip`` is on); ``skipped``: default members left
    out, with why."""

    methods: tuple[str, ...]
    strip: bool
    strip_rows: tuple[int, ...]
    skipped: tuple[str, ...] = ()


@dataclass(frozen=True)
class IntersectState(OnlineState):
    """The members' online states, in the order of ``design.members``."""

    members: tuple[Any, ...] = field(default=())


@register
class Intersect(Estimator):
    """Intersection of the boxes of several guaranteed estimators, step by step.

    Parameters
    ----------
    sys : LinearSystem
    x0 : Box, prior on ``x[0]`` passed to the members built by name (optional if none needs it)
    methods : list of method names, ``(name, options)`` pairs, or :class:`Estimator` instances
        (built for the same system). Default: :data:`DEFAULT_METHODS` that can be designed for
        ``sys`` (skipped ones are listed in ``design.skipped``).
    on_inconsistent : 'warn', 'raise' or 'ignore' (empty intersection, or a member's report)
    strips : also meet the box with the measurement strips of ``y[k]`` (every exact output row;
        :mod:`ivobs.estimators.measured`; on by default)

    Notes
    -----
    ``valid_from`` is the earliest member's; before a member's own ``valid_from`` it is ignored.

    **Interval matrices** (docs/uncertain.md): sound as its members are; the default members
    are those that accept them (the others are skipped with the reason), and the measurement
    strip uses only the rows whose ``C`` and ``D`` rows are exact.
    See the module docstring for what is returned when the data are inconsistent.
    """

    name = "intersect"
    design: IntersectDesign
    order = 110
    summary = "intersection of several guaranteed estimates (and the measurement strip)"
    reference = "intersection of guaranteed enclosures; output strips by [Efimov2013, Lemma 1]"
    supports_continuous = True
    supports_time_varying = True
    needs_x0 = False
    proven_rounding = True  # comparisons of the members' boxes, a strip rounded outwards
    supports_uncertain = True  # members that accept interval matrices; exact rows' strips

    def __init__(
        self,
        sys: LinearSystem,
        x0: Box | None = None,
        *,
        methods: Any = None,
        on_inconsistent: str = "warn",
        strips: bool | None = None,
    ):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent, strips=strips)
        if methods is None:
            self.members, skipped = self._default_members()
        else:
            self.members, skipped = self._explicit_members(methods), []
        rows = () if self._strips is None else tuple(int(r) for r in self._strips.rows)
        self.design = IntersectDesign(
            methods=tuple(m.name for m in self.members),
            strip=self.strips,
            strip_rows=rows,
            skipped=tuple(skipped),
        )
        self.valid_from = min(m.valid_from for m in self.members)

    # -- members --------------------------------------------------------------------------
    def _default_members(self) -> tuple[list[Estimator], list[str]]:
        members: list[Estimator] = []
        skipped: list[str] = []
        for name in DEFAULT_METHODS:
            if name not in methods():
                continue
            try:  # the method refuses a system or prior it cannot take, with the reason
                members.append(make_estimator(name, self.sys, self.x0))
            except IvobsError as exc:  # DesignError, or a structural condition not met
                skipped.append(f"{name}: {exc}")
        if not members:
            raise DesignError(
                "methods: none of the default members could be designed for this system ("
                + "; ".join(skipped or ["no default method is registered"])
                + "); pass methods=[...] explicitly, e.g. methods=['exact']"
            )
        return members, skipped

    def _explicit_members(self, methods: Any) -> list[Estimator]:
        if isinstance(methods, (str, Estimator)) or not isinstance(methods, (list, tuple)):
            raise IvobsError(
                "methods: expected a list of method names, (name, options) pairs or Estimator "
                f"instances, got {methods!r}"
            )
        if not methods:
            raise IvobsError("methods: expected at least one member, got an empty list")
        members = []
        for i, spec in enumerate(methods):
            if isinstance(spec, Estimator):
                self._check_instance(i, spec)
                members.append(spec)
            elif isinstance(spec, str):
                members.append(make_estimator(spec, self.sys, self.x0))
            elif (
                isinstance(spec, (list, tuple))
                and len(spec) == 2
                and isinstance(spec[0], str)
                and isinstance(spec[1], dict)
            ):
                options = dict(spec[1])
                x0 = options.pop("x0", self.x0)
                members.append(make_estimator(spec[0], self.sys, x0, **options))
            else:
                raise IvobsError(
                    f"methods[{i}]: expected a method name, a (name, options dict) pair or an "
                    f"Estimator instance, got {spec!r}"
                )
        return members

    def _check_instance(self, i: int, est: Estimator) -> None:
        s, o = self.sys, est.sys
        if (o.nx, o.nu, o.ny) != (s.nx, s.nu, s.ny) or o.is_continuous != s.is_continuous:
            raise IvobsError(
                f"methods[{i}]: the {est.name!r} estimator was built for a system with "
                f"(nx, nu, ny) = ({o.nx}, {o.nu}, {o.ny}); this one has ({s.nx}, {s.nu}, {s.ny}). "
                "Members must estimate the same plant"
            )

    # -- combining ------------------------------------------------------------------------
    @staticmethod
    def _combine(los: np.ndarray, his: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Intersect the members' boxes (NaN rows = not yet valid: ignored).

        Returns ``(lo, hi, empty)`` over the leading axes; where ``empty`` (two bounds cross),
        the hull of the members' boxes instead (see the module docstring).
        """
        lo = np.fmax.reduce(los, axis=0)
        hi = np.fmin.reduce(his, axis=0)
        with np.errstate(invalid="ignore"):
            empty = np.any(lo > hi, axis=-1)
        if np.any(empty):
            lo = np.where(empty[..., None], np.fmin.reduce(los, axis=0), lo)
            hi = np.where(empty[..., None], np.fmax.reduce(his, axis=0), hi)
        return lo, hi, empty

    # -- online ---------------------------------------------------------------------------
    def _initial_state(self) -> IntersectState:
        return IntersectState(members=tuple(m.initial_state() for m in self.members))

    def _step(
        self, state: IntersectState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[IntersectState]:
        los, his, members = [], [], []
        flagged = False
        for m, ms in zip(self.members, state.members, strict=True):
            # each member's box is proven by the member (its own rounding model)
            ms, box = m.advance(ms, u_k, y_k, t_k, finite=False, keep=not self._branching)
            members.append(ms)
            flagged |= ms.inconsistent
            los.append(box.lo)
            his.append(box.hi)
        lo, hi, empty = self._combine(np.array(los), np.array(his))
        new = evolve(state, members=tuple(members))
        return Step(new, lo, hi, flagged or bool(empty))

    # -- offline --------------------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Members' own (vectorised where they have it) runs, intersected. Falls back to the
        loop (returns None) when anything needs reporting: a member's inconsistency or an empty
        intersection.

        Given the same members' boxes, the loop's boxes bit for bit: :meth:`_combine` compares
        floats (exact, step by step on either path), and the strips are met step by step by the
        one kernel (:func:`ivobs.sets.strip.meet_strips`; :mod:`ivobs.estimators.record` here,
        :meth:`~ivobs.estimators.base.Estimator.advance` in the loop). So this path is as sound
        as the members' vectorised paths, and where it is wider than the loop, a member's
        vectorised path is wider than its loop."""
        outs = []
        for m in self.members:
            out = _member_run(m, u, y, t)
            if out is None:
                return None
            outs.append(out)
        los, his = zip(*outs, strict=True)
        lo, hi, empty = self._combine(np.array(los), np.array(his))
        return None if np.any(empty) else (lo, hi)

    # -- persistence ----------------------------------------------------------------------
    def fingerprint(self) -> str:
        parts = [self.name, str(self.design.strip)] + [m.fingerprint() for m in self.members]
        return hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]

    def _dump(self, st: Any) -> dict[str, Any]:
        """The members' saved states, each in its own envelope (method, design fingerprint)."""
        members = [m.save_state(ms) for m, ms in zip(self.members, st.members, strict=True)]
        return {"k": st.k, "inconsistent": st.inconsistent, "members": members}

    def _load(self, saved: Any) -> IntersectState:
        """The counters, and each member's state checked by the member."""
        if not isinstance(saved, dict):
            raise IvobsError("state: expected the dict returned by Estimator.state()")
        counters: dict[str, Any] = {"k": saved.get("k")}
        check_counters(counters)
        members = saved.get("members")
        if not isinstance(members, list) or len(members) != len(self.members):
            raise IvobsError(f"state: expected the states of {len(self.members)} members")
        return IntersectState(
            members=tuple(m.check_state(s) for m, s in zip(self.members, members, strict=True)),
            k=counters["k"],
            inconsistent=bool(saved.get("inconsistent", False)),
        )


def _member_run(
    m: Estimator, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """A member's own run (its vectorised path where it has one), rounded by its own rules, NaN
    before its ``valid_from``; None when anything needs the loop: a sample the member flags (the
    loop reports it once, as the intersection's) or bounds that left the float range (the other
    members may still bound the state)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = m.run(u, y, t=t, vectorize=True)
    except IvobsError:  # overflow, or a member told to raise on inconsistent data
        return None
    if np.any(res.inconsistent):
        return None
    return res.lower, res.upper
