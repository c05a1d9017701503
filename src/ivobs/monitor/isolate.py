"""Fault isolation: which outputs are at fault, decided by the consistency of output subsets.

The band test of :mod:`ivobs.monitor` says *that* the data contradict the model, and names the
outputs outside the band at that step. That names the wrong output when the estimate had
already taken a faulty sample in: a bias on the servo's speed sensor that stays inside the
loose band of ``interval-split`` for a few steps pulls its estimate, and the band then rejects
the healthy angle. Isolation asks instead, over a window of the recent data, which outputs must
be *removed* for the rest to fit the model:

* the window: the steps ``s..k`` (``k`` the step being decided, ``s`` an anchor step, so that
  it holds between ``window`` and ``1.5 window`` steps; fewer at the start of a record); the
  prior is ``P_s``, the monitor's prediction of ``x[s]`` from the data *before* ``s``;
* the test of an output set ``S``: is there a trajectory of the model from ``x[s] ∈ P_s`` whose
  outputs other than ``S`` match the measurements of ``s..k`` within the noise bounds? For an
  exactly known linear model this is one trajectory program of the ``exact`` method over the
  window (:mod:`ivobs.estimators.exact`: its rows with their rounding ranges, its HiGHS chains;
  infeasible only with a Farkas certificate), solved once for the window rather than at every
  step; with interval matrices a ``constrained-zonotope`` run over the window, for a nonlinear
  model ``nl-constrained-zonotope``. Each reports an inconsistency only when there is one, so
  "inconsistent" is proven; "consistent" means that none was found;
* the candidates: the single outputs whose removal makes the window consistent, tested first;
  if none does, the pairs (when there are at most :data:`MAX_PAIRS` of them). A set that
  contains a candidate is not tested: the smallest explanations are the ones reported.

The verdicts (:attr:`Isolation.verdict`): ``"isolated"``, one candidate; ``"ambiguous"``,
several (``y1 or y2``: the data of the window cannot tell them apart, for instance two sensors of
one state; all of them are then held out, since one is faulty and which one is unknown);
``"consistent"``, the whole window fits the model from ``P_s`` (the contradiction needed
memory from before ``s``: the band's blame is kept); ``"unexplained"``, no output set of the
sizes tested explains the data (an actuator fault or a wrong model; the band's blame is kept).

Under the model's assumptions and a fault that began at or after ``s`` on the outputs of a
candidate, the true trajectory fits the data without them, so the faulty set is always among
the candidates (or a superset of one, when it is not the smallest explanation). A fault that
started before ``s`` (seen late) may be isolated wrongly: its samples are in ``P_s``.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations
from typing import Any

import numpy as np

from ..errors import IvobsError
from ..model import LinearSystem, NonlinearSystem
from ..sets import Box
from ._codec import _decode, _encode, saved_entry
from .records import output_names

__all__ = ["DEFAULT_WINDOW", "MAX_PAIRS", "History", "Isolation", "WindowTest", "isolate"]

DEFAULT_WINDOW = 20
"""Steps of data an isolation looks at (at least; up to half as many more)."""

MAX_PAIRS = 15
"""Pairs of outputs are tested only when there are at most this many (six outputs): the number
of window runs grows with the square of the outputs."""

VERDICTS = ("isolated", "ambiguous", "consistent", "unexplained")


@dataclass(frozen=True)
class Isolation:
    """The outcome of one isolation over the window ``start..end`` (module docstring).

    ``candidates``: the output sets (0-based indices, sorted) whose removal makes the data of
    the window consistent with the model, smallest first; ``verdict``: one of
    ``"isolated"``, ``"ambiguous"``, ``"consistent"``, ``"unexplained"``.
    """

    candidates: tuple[tuple[int, ...], ...]
    start: int
    end: int
    verdict: str

    @property
    def conclusive(self) -> bool:
        """The window names the faulty outputs (one candidate or several)."""
        return self.verdict in ("isolated", "ambiguous")

    @property
    def outputs(self) -> tuple[int, ...]:
        """Every output of a candidate: what is held out of the estimate."""
        return tuple(sorted({i for c in self.candidates for i in c}))

    @property
    def text(self) -> str:
        """Readable: ``y2``; ``y1 or y2 (cannot be told apart)``; ``not isolated: ...``."""
        names = " or ".join(output_names(c) for c in self.candidates)
        if self.verdict == "isolated":
            return names
        if self.verdict == "ambiguous":
            return f"{names} (cannot be told apart)"
        if self.verdict == "consistent":
            return f"not isolated: steps {self.start}..{self.end} fit the model"
        return f"not isolated: no output set explains steps {self.start}..{self.end}"

    def describe(self) -> str:
        """The sentence of a step's reason."""
        window = f"steps {self.start}..{self.end}"
        if self.verdict == "isolated":
            return f"isolated to {self.text}: {window} fit the model without it"
        if self.verdict == "ambiguous":
            names = " or ".join(output_names(c) for c in self.candidates)
            return f"isolated to {names}: {window} fit the model without either, cannot tell which"
        return self.text

    def save(self) -> dict[str, Any]:
        return {
            "candidates": [list(c) for c in self.candidates],
            "start": self.start,
            "end": self.end,
            "verdict": self.verdict,
        }

    @classmethod
    def restore(cls, saved: Any, ny: int, k: int) -> Isolation | None:
        """From :meth:`save`, checked (``ny`` outputs, the monitor at step ``k``)."""
        if saved is None:
            return None
        try:
            cands = tuple(tuple(c) for c in saved["candidates"])
            start, end, verdict = saved["start"], saved["end"], saved["verdict"]
            ok = (
                verdict in VERDICTS
                and all(type(i) is int and 0 <= i < ny for c in cands for i in c)
                and all(type(v) is int for v in (start, end))
                and 0 <= start <= end < max(k, 1)
            )
        except (KeyError, TypeError):
            ok = False
        if not ok:
            raise IvobsError("state: isolation: expected the isolation saved by the monitor")
        return cls(cands, start, end, verdict)


class WindowTest:
    """The consistency test of a window's data with some outputs removed, for one model
    (module docstring): :meth:`consistent`. ``method`` is None where the model cannot be
    tested this way (time-varying matrices or bounds over time, bounds computed from ``y``:
    a window run starts at the estimator's step 0)."""

    def __init__(self, sys: LinearSystem | NonlinearSystem):
        self.sys = sys
        self.method: str | None
        if isinstance(sys, NonlinearSystem):
            self.method = "nl-constrained-zonotope"
        elif (
            sys.is_continuous
            or sys.is_time_varying
            or not sys.has_constant_bounds
            or sys.bounds_depend_on_y
        ):
            self.method = None
        else:
            # the window LP where the matrices are known; interval matrices need the
            # constrained zonotope's realisations
            self.method = "constrained-zonotope" if sys.is_uncertain else "exact"

    def consistent(
        self,
        prior: Box,
        u: np.ndarray,
        y: np.ndarray,
        t: np.ndarray | None,
        removed: tuple[int, ...],
    ) -> bool:
        """Whether ``y`` (``(n, ny)``, the outputs of ``removed`` ignored) and ``u`` fit a
        trajectory of the model from ``x[s] ∈ prior``. Stops at the first inconsistent step."""
        from ..estimators import make_estimator

        assert self.method is not None
        yy = y.copy()
        yy[:, list(removed)] = np.nan
        if self.method == "exact":
            verdict = self._program(prior, u, yy)
            if verdict is not None:
                return verdict
        est = make_estimator(self.method, self.sys, x0=prior)
        est.on_inconsistent = "ignore"
        state = est.initial_state()
        for j in range(yy.shape[0]):
            u_j = u[j] if self.sys.nu else None
            state, _ = est.advance(state, u_j, yy[j], None if t is None else float(t[j]))
            if state.inconsistent:
                return False
        return True

    def _program(self, prior: Box, u: np.ndarray, y: np.ndarray) -> bool | None:
        """The window's trajectory program (an exactly known, time-invariant linear model),
        built as the ``exact`` method builds its own, each block's variable bounds the
        interval prediction of the block before: consistent (True), inconsistent (False, with a
        certificate), or None when the solver could not tell (the window is then run step by
        step, each step's bounds from the program, as the ``exact`` method does)."""
        from ..estimators.exact.highs import INFEASIBLE, OK, WarmStartedLP
        from ..estimators.exact.program import TrajectoryLP
        from ..estimators.exact.rows import dynamics, measurement, outside_prediction, prediction

        sys = self.sys
        assert isinstance(sys, LinearSystem)
        d = sys.d_at(0)
        lp = TrajectoryLP(sys.nx, sys.nd, sys.ny)
        p_lo, p_hi = prior.lo.copy(), prior.hi.copy()
        for j in range(y.shape[0]):
            dyn = None
            if j > 0:
                prev = (p_lo, p_hi, d.lo, d.hi)
                dyn = dynamics(sys, 0, u[j - 1], *prev)
                p_lo, p_hi = prediction(sys, 0, u[j - 1], prev, dyn.tau)
                if not (np.all(np.isfinite(p_lo)) and np.all(np.isfinite(p_hi))):
                    return None
            meas = measurement(sys, 0, u[j], y[j], True, p_lo, p_hi, d.lo, d.hi)
            if outside_prediction(meas, p_lo, p_hi, d.lo, d.hi):
                return False  # certain by interval arithmetic already
            lp.push(dyn, meas, (p_lo, p_hi), (d.lo, d.hi), 0.5 * (p_lo + p_hi))
        verdict = WarmStartedLP(lp, parallel=False).last_x_box()[2]
        return True if verdict == OK else False if verdict == INFEASIBLE else None


def isolate(
    test: WindowTest,
    prior: Box,
    start: int,
    u: np.ndarray,
    y: np.ndarray,
    t: np.ndarray | None,
) -> Isolation:
    """The isolation of the window ``start..start + len(y) - 1`` from ``x[start] ∈ prior``
    (module docstring). Outputs never measured in the window are not candidates: removing them
    changes nothing."""
    end = start + y.shape[0] - 1
    if test.consistent(prior, u, y, t, ()):
        return Isolation((), start, end, "consistent")
    measured = [i for i in range(y.shape[1]) if not np.isnan(y[:, i]).all()]
    sets: list[tuple[int, ...]] = [(i,) for i in measured]
    if len(measured) * (len(measured) - 1) // 2 <= MAX_PAIRS:
        sets += list(combinations(measured, 2))
    found: list[tuple[int, ...]] = []
    for size in (1, 2):
        for s in (c for c in sets if len(c) == size):
            if test.consistent(prior, u, y, t, s):
                found.append(s)
        if found:
            break
    if not found:
        return Isolation((), start, end, "unexplained")
    return Isolation(tuple(found), start, end, "isolated" if len(found) == 1 else "ambiguous")


@dataclass
class Anchor:
    """The monitor before step ``k``: the estimator's state, the box of ``x[k-1]`` (``prev``)
    and the prediction ``P_k`` of ``x[k]`` from the data before ``k``."""

    k: int
    state: Any
    prev: dict[str, Any] | None
    pred: tuple[np.ndarray, np.ndarray] | None


class History:
    """The data of the recent steps and the monitor's state at a few anchor steps (every
    ``window // 2`` steps): what an isolation's window starts from, and what the estimate is
    recomputed from when the isolation finds that a faulty output had entered it. Anchors
    rather than every step's state: a saved monitor holds at most three estimator states."""

    def __init__(self, window: int):
        self.window = window
        self.every = max(1, window // 2)
        self.anchors: list[Anchor] = []
        self.rows: list[tuple[int, np.ndarray, np.ndarray, float | None]] = []

    def anchor(self, k: int, state: Any, prev: Any, pred: Any) -> None:
        """The monitor before step ``k`` (kept when ``k`` is an anchor step)."""
        if k % self.every == 0:
            self.anchors.append(Anchor(k, state, prev, pred))

    def push(self, k: int, u: np.ndarray, y: np.ndarray, t: float | None) -> None:
        """The data of step ``k``; anchors that no window starting ``window`` steps back from
        the next step needs are dropped, with their rows."""
        self.rows.append((k, u, y, t))
        first = self.first(k + 1)
        self.anchors = [a for a in self.anchors if a.k >= first]
        self.rows = [r for r in self.rows if r[0] >= first]

    def first(self, k: int) -> int:
        """The window start for step ``k``: the latest anchor step at least ``window`` steps
        back (step 0 at the start of a record)."""
        return max(0, (k - self.window + 1) // self.every * self.every)

    def start(self, k: int) -> Anchor | None:
        """The anchor the window of step ``k`` starts from (None when it was not kept: the
        monitor was restored from a state without one)."""
        first = self.first(k)
        return next((a for a in self.anchors if a.k == first), None)

    def reset(self) -> None:
        self.anchors, self.rows = [], []

    # -- persistence ------------------------------------------------------------------------
    def save(self, save_state: Any) -> dict[str, Any]:
        def box(b: tuple[np.ndarray, np.ndarray] | None) -> Any:
            return None if b is None else [_encode(b[0]), _encode(b[1])]

        return {
            "anchors": [
                {
                    "k": a.k,
                    "estimator": save_state(a.state),
                    "prev": None if a.prev is None else {n: _encode(v) for n, v in a.prev.items()},
                    "pred": box(a.pred),
                }
                for a in self.anchors
            ],
            "rows": [[k, _encode(u), _encode(y), t] for k, u, y, t in self.rows],
        }

    def restore(self, saved: Any, check_state: Any, check_prev: Any, sys: Any, k: int) -> None:
        """From :meth:`save` (None: a state without history; isolations then start with the
        next anchor), every entry checked."""
        self.reset()
        if saved is None:
            return
        with saved_entry("history: expected the window history saved by the monitor"):
            anchors = []
            for a in saved["anchors"]:
                ak = a["k"]
                if type(ak) is not int or not 0 <= ak <= k:
                    raise ValueError
                pred = a["pred"]
                if pred is not None:
                    pred = (_decode(pred[0]), _decode(pred[1]))
                    if pred[0].shape != (sys.nx,) or pred[1].shape != (sys.nx,):
                        raise ValueError
                prev = check_prev(a["prev"])
                state = check_state(a["estimator"])
                if state.k != ak:  # the monitor before step ak: its estimator at step ak
                    raise ValueError
                anchors.append(Anchor(ak, state, prev, pred))
            rows = []
            for rk, u, y, t in saved["rows"]:
                uu, yy = _decode(u), _decode(y)
                if (
                    type(rk) is not int
                    or not 0 <= rk < k
                    or uu.shape != (sys.nu,)
                    or yy.shape != (sys.ny,)
                    or not (t is None or isinstance(t, (int, float)))
                ):
                    raise ValueError
                rows.append((rk, uu, yy, None if t is None else float(t)))
        self.anchors, self.rows = anchors, rows
