"""Intersection of several guaranteed estimates (and of the measurement strip).

If every member ``m`` returns a box ``[lo_m, hi_m]`` certain to contain ``x[k]``, so does

::

    lower_k = max_m lo_m,    upper_k = min_m hi_m,

which is never wider than the best member in any component. Members are other ivobs methods run
side by side on the same data; a member ignores nothing and gains nothing from the others (each
keeps its own recursion), so the result is as sound as the weakest assumption among them.

**Measurement strip.** A row ``r`` of ``C`` with a single nonzero entry ``c`` (state ``i``
measured directly, possibly scaled) gives ``c x_i = y_r - D_r u - F_r d`` with ``d`` in its box,
hence by [Efimov2013, Lemma 1] (:func:`ivobs.image_bounds`, applied to ``[1, -D_r, -F_r]`` over
the box of ``(y_r, u, d)``)::

    x_i ∈ (y_r - D_r u - [F_r⁺ d_lo - F_r⁻ d_hi, F_r⁺ d_hi - F_r⁻ d_lo]) / c

(the ends swapped when ``c < 0``). This box is intersected as well (option ``strip``).

**Rounding, proven** (``proven_rounding``; no margin of its own). The intersection and the hull
are comparisons of floats: exact. Each member's box is the member's own, rounded by its own
rules. The strip's numerator is enclosed by :func:`ivobs.image_bounds` (its evaluation bounded
by ``γ_n`` [Higham2002] and rounded outwards) and widened by the rounding of a float64
evaluation of the output row (a record from a float64 simulation: a sample within rounding of
its bound is admissible), and the quotient by ``c`` is rounded outwards (one ``nextafter``).

**Inconsistent data.** An empty intersection means two guaranteed enclosures of the same state
do not meet: the data contradict the model and the bounds (a fault). The step is reported
(``on_inconsistent``), and the box returned is the *hull of the members' boxes* (the strip left
out, as it is what a faulty sample corrupts first): each member handled the fault by its own
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
from ..linalg import gamma
from ..model import LinearSystem
from ..sets import Box, image_bounds
from ..sets.rounding import down, up, upper
from . import get, make_estimator, methods, register
from .base import Design, Estimator
from .persistence import check_version
from .state import STATE_FORMAT, STATE_VERSION, OnlineState, Step, check_counters, evolve

__all__ = ["DEFAULT_METHODS", "Intersect", "IntersectDesign"]

DEFAULT_METHODS = ("reachability", "zonotope", "strip", "fixed-time", "interval-split", "kkl")
"""Members tried when ``methods`` is not given (fast methods with complementary designs); those
not registered, not applicable to the system, or whose design fails are skipped."""


@dataclass(frozen=True)
class IntersectDesign(Design):
    """``methods``: the members' names; ``strip_rows``: rows of ``C`` that pin a state (used when
    ``strip`` is on; time-invariant ``C``); ``skipped``: default members left out, with why."""

    methods: tuple[str, ...]
    strip: bool
    strip_rows: tuple[int, ...]
    skipped: tuple[str, ...] = ()


def _strip_bounds(
    lo: np.ndarray, hi: np.ndarray, y: np.ndarray, u: np.ndarray, D: np.ndarray, F: np.ndarray,
    d: Box, rows: list[tuple[int, int, float]],
) -> None:  # fmt: skip
    """Intersect ``[lo, hi]`` (in place; one step or a record, ``(..., nx)``) with the bounds
    of each pinned state ``x_i = (y_r - D_r u - F_r d) / c`` for ``d`` in its box: the
    numerators of all ``rows`` ``(r, i, c)`` by one :func:`ivobs.image_bounds` of ``[I, -D_R,
    -F_R]`` over the box of ``(y_R, u, d)``, widened by the rounding of a float64 evaluation of
    the output rows (a sample within rounding of its bound is admissible: ``γ_n`` times ``|y| +
    2 (|D_r||u| + |F_r| max(|d_lo|, |d_hi|))``, which bounds ``|c x| + |D_r u| + |F_r d|``),
    the quotients rounded outwards. A NaN sample gives NaN bounds: ignored."""
    r = [row[0] for row in rows]
    c = np.array([row[2] for row in rows])
    yR, DR, FR = y[..., r], D[r], F[r]
    lead, n = yR.shape[:-1], u.shape[-1] + d.lo.shape[0] + 1
    ends = [np.concatenate([yR, np.broadcast_to(u, (*lead, u.shape[-1])),
                            np.broadcast_to(dv, (*lead, dv.shape[0]))], axis=-1)
            for dv in (d.lo, d.hi)]  # fmt: skip
    v_lo, v_hi = image_bounds(np.hstack([np.eye(len(rows)), -DR, -FR]), *ends)
    mag = np.abs(u) @ np.abs(DR).T + np.abs(FR) @ np.maximum(np.abs(d.lo), np.abs(d.hi))
    w = upper(2.0 * gamma(n) * (np.abs(yR) + 2.0 * mag), n + 2)
    v_lo, v_hi = down(v_lo - w), up(v_hi + w)
    neg = c < 0.0
    b_lo = down(np.where(neg, v_hi, v_lo) / c)
    b_hi = up(np.where(neg, v_lo, v_hi) / c)
    for j, (_, state, _) in enumerate(rows):  # a state pinned by several rows: each counts
        lo[..., state] = np.fmax(lo[..., state], b_lo[..., j])
        hi[..., state] = np.fmin(hi[..., state], b_hi[..., j])


def _pinning_rows(C: np.ndarray) -> list[tuple[int, int, float]]:
    """``(row, state, coefficient)`` for the rows of ``C`` with exactly one nonzero entry."""
    out = []
    for r, row in enumerate(C):
        nz = np.flatnonzero(row)
        if nz.size == 1:
            out.append((r, int(nz[0]), float(row[nz[0]])))
    return out


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
    strip : also intersect with the measurement strip of the rows of ``C`` that pin a state
    on_inconsistent : 'warn', 'raise' or 'ignore' (empty intersection, or a member's report)

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
        strip: bool = True,
        on_inconsistent: str = "warn",
    ):
        super().__init__(sys, x0, on_inconsistent=on_inconsistent)
        if not isinstance(strip, (bool, np.bool_)):
            raise IvobsError(f"strip: expected True or False, got {strip!r}")
        if methods is None:
            self.members, skipped = self._default_members()
        else:
            self.members, skipped = self._explicit_members(methods), []
        rows = _pinning_rows(sys.C_at(0)) if not sys.is_time_varying else []
        if sys.uncertainty is not None:  # interval matrices: strips of the exact rows only
            exact = sys.uncertainty.exact_rows()
            rows = [row for row in rows if exact[row[0]]]
        self.design = IntersectDesign(
            methods=tuple(m.name for m in self.members),
            strip=bool(strip),
            strip_rows=tuple(r for r, _, _ in rows),
            skipped=tuple(skipped),
        )
        self._strip_rows = rows
        self.valid_from = min(m.valid_from for m in self.members)

    # -- members --------------------------------------------------------------------------
    def _default_members(self) -> tuple[list[Estimator], list[str]]:
        members: list[Estimator] = []
        skipped: list[str] = []
        for name in DEFAULT_METHODS:
            if name not in methods():
                continue
            cls = get(name)
            reason = self._not_applicable(cls)
            if reason is None:
                try:
                    members.append(make_estimator(name, self.sys, self.x0))
                    continue
                except IvobsError as exc:  # DesignError, or a structural condition not met
                    reason = str(exc)
            skipped.append(f"{name}: {reason}")
        if not members:
            raise DesignError(
                "methods: none of the default members could be designed for this system ("
                + "; ".join(skipped or ["no default method is registered"])
                + "); pass methods=[...] explicitly, e.g. methods=['exact']"
            )
        return members, skipped

    def _not_applicable(self, cls: type[Estimator]) -> str | None:
        if self.sys.is_continuous and not cls.supports_continuous:
            return "discrete-time systems only"
        if self.sys.is_time_varying and not cls.supports_time_varying:
            return "time-invariant systems only"
        if cls.needs_x0 and self.x0 is None:
            return "needs a prior box x0"
        return None

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
                get(spec[0])  # a clear error for an unknown name
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

    # -- the strip ------------------------------------------------------------------------
    def _strip_box(
        self, k: int, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the pinned states from ``y[k]`` alone (±inf elsewhere)."""
        nx = self.sys.nx
        lo, hi = np.full(nx, -np.inf), np.full(nx, np.inf)
        if not self.design.strip:
            return lo, hi
        # matrices are functions of the time in continuous time, of the step otherwise
        _, _, C, D, _, F = self.sys.matrices_at(t_k if self.sys.is_continuous else k)
        rows = self._strip_rows if not self.sys.is_time_varying else _pinning_rows(C)
        rows = [row for row in rows if not np.isnan(y_k[row[0]])]
        if rows:
            _strip_bounds(lo, hi, y_k, u_k, D, F, self.sys.d_at(k, y_k), rows)
        return lo, hi

    def _strip_run(self, u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The strip over a whole record (constant system and bounds), or None."""
        nx = self.sys.nx
        shape = (*y.shape[:-1], nx)
        lo, hi = np.full(shape, -np.inf), np.full(shape, np.inf)
        if not self.design.strip:
            return lo, hi
        if self.sys.is_time_varying:
            return None  # the pinning rows depend on the step: the loop (as step() does)
        if not self._strip_rows:
            return lo, hi
        if not self.sys.has_constant_bounds:
            return None
        _, _, _, D, _, F = self.sys.matrices_at(0)
        with np.errstate(invalid="ignore"):  # NaN (missing) stays NaN: no information
            _strip_bounds(lo, hi, y, u, D, F, self.sys.d_at(0, None), self._strip_rows)
        return lo, hi

    # -- combining ------------------------------------------------------------------------
    @staticmethod
    def _combine(
        los: np.ndarray, his: np.ndarray, s_lo: np.ndarray, s_hi: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Intersect the members' boxes (NaN rows = not yet valid: ignored) and the strip.

        Returns ``(lo, hi, empty)`` over the leading axes; where ``empty`` (two bounds cross),
        the hull of the members' boxes instead (see the module docstring).
        """
        lo = np.fmax(np.fmax.reduce(los, axis=0), s_lo)
        hi = np.fmin(np.fmin.reduce(his, axis=0), s_hi)
        with np.errstate(invalid="ignore"):
            empty = np.any(lo > hi, axis=-1)
        if np.any(empty):
            hull_lo = np.fmin.reduce(los, axis=0)
            hull_hi = np.fmax.reduce(his, axis=0)
            lo = np.where(empty[..., None], hull_lo, lo)
            hi = np.where(empty[..., None], hull_hi, hi)
        return lo, hi, empty

    # -- online ---------------------------------------------------------------------------
    def _initial_state(self) -> IntersectState:
        return IntersectState(members=tuple(m.initial_state() for m in self.members))

    def _step(
        self, state: IntersectState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[IntersectState]:
        nx, k = self.sys.nx, state.k
        los, his, members = [], [], []
        flagged = False
        for m, ms in zip(self.members, state.members, strict=True):
            # each member's box is proven by the member (its own rounding model)
            ms, box = m.advance(ms, u_k, y_k, t_k, finite=False, keep=not self._branching)
            members.append(ms)
            flagged |= ms.inconsistent
            los.append(box.lo)
            his.append(box.hi)
        if k < self.valid_from:
            lo_s = hi_s = np.full(nx, np.nan)
        else:
            lo_s, hi_s = self._strip_box(k, u_k, y_k, t_k)
        lo, hi, empty = self._combine(np.array(los), np.array(his), lo_s, hi_s)
        new = evolve(state, members=tuple(members))
        return Step(new, lo, hi, flagged or bool(empty))

    # -- offline --------------------------------------------------------------------------
    def _run(
        self, u: np.ndarray, y: np.ndarray, t: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """Members' own (vectorised where they have it) runs, intersected. Falls back to the
        loop (returns None) when anything needs reporting: a member's inconsistency, an empty
        intersection, or a strip that depends on the step."""
        strip = self._strip_run(u, y)
        if strip is None:
            return None
        los, his = [], []
        for m in self.members:
            out = _member_run(m, u, y, t)
            if out is None:
                return None
            los.append(out[0])
            his.append(out[1])
        lo, hi, empty = self._combine(np.array(los), np.array(his), *strip)
        if np.any(empty):
            return None
        return lo, hi

    # -- persistence ----------------------------------------------------------------------
    def fingerprint(self) -> str:
        parts = [self.name, str(self.design.strip)] + [m.fingerprint() for m in self.members]
        return hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]

    def save_state(self, st: Any) -> dict[str, Any]:
        """The online state (JSON-serialisable): the members' saved states, each in its own
        envelope (method, design fingerprint), nested in the intersection's."""
        return {
            "format": STATE_FORMAT,
            "version": STATE_VERSION,
            "method": self.name,
            "fingerprint": self.fingerprint(),
            "state": {
                "k": st.k,
                "inconsistent": st.inconsistent,
                "members": [
                    m.save_state(ms) for m, ms in zip(self.members, st.members, strict=True)
                ],
            },
        }

    def check_state(self, state: Any) -> IntersectState:
        """The state saved by :meth:`state`, checked: the same members with the same designs,
        the counters, and each member's state by the member."""
        if not isinstance(state, dict) or not isinstance(state.get("state"), dict):
            raise IvobsError("state: expected the dict returned by Estimator.state()")
        if state.get("method") != self.name or state.get("fingerprint") != self.fingerprint():
            raise IvobsError(
                f"state: saved by method {state.get('method')!r} with other members or "
                f"designs; it can only be restored into the same {self.name!r} estimator"
            )
        check_version(state)
        saved = state["state"]
        counters = {"k": saved.get("k")}
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
    """A member's own run (its vectorised path where it has one), rounded by its own margin, NaN
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
