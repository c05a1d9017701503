"""Adding a method to ivobs: a measured-state predictor in about 80 lines.

The method: predict the box by interval arithmetic on the model,
``x[k+1] ∈ A [x[k]] + B u[k] + E [d[k]]`` ([Efimov2013, Lemma 1]), and, for every output that
measures one state directly (a row of ``C`` with a single nonzero entry ``c``), intersect that
state's interval with what the measurement allows, ``x_i ∈ (y_j − D_j u − F_j [d]) / c``. It is
sound for any plant, needs no design, and is tight on the measured states only: a baseline, and a
template. docs/architecture.md walks through it.

Run: ``python examples/custom_method.py`` (prints the mean widths of the new method beside
``interval-split`` on the servo motor of [Tang2019]).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

import ivobs
from ivobs.estimators import Design, Estimator, register
from ivobs.estimators.state import OnlineState, Step
from ivobs.sets import image_bounds
from ivobs.sets.rounding import UNIT_ROUNDOFF, down, up
from ivobs.testing import check_estimator


@dataclass(frozen=True)
class PredictorDesign(Design):
    """``rows``: for each state measured directly, ``(state i, output j, coefficient c)``."""

    rows: tuple[tuple[int, int, float], ...]


@dataclass(frozen=True)
class PredictorState(OnlineState):
    """The box of ``x[k]`` before ``y[k]`` is used."""

    lo: np.ndarray
    hi: np.ndarray
    bounds: ClassVar[tuple[tuple[str, str], ...]] = (("lo", "hi"),)


@register
class MeasuredStatePredictor(Estimator):
    """Interval prediction intersected with the directly measured states (see module doc).

    **Data used:** the box of ``x[k]`` uses ``u[0..k]``, ``y[0..k]`` (a filter)."""

    name = "measured-state-predictor"
    order = 500
    summary = "interval prediction intersected with directly measured states (an example)"
    reference = "[Efimov2013, Lemma 1]"
    data_used = "filter"
    needs_x0 = True
    proven_rounding = True  # every operation below contains its exact result (sets.rounding)

    def __init__(self, sys: ivobs.LinearSystem, x0: ivobs.Box | None = None, **options: Any):
        super().__init__(sys, x0, **options)
        C = sys.matrices_at(0)[2]
        rows = []
        for j in range(sys.ny):
            nonzero = np.flatnonzero(C[j])
            if nonzero.size == 1:  # output j measures state i directly
                rows.append((int(nonzero[0]), j, float(C[j, nonzero[0]])))
        self.design = PredictorDesign(rows=tuple(rows))

    def _initial_state(self) -> PredictorState:
        assert self.x0 is not None
        return PredictorState(lo=self.x0.lo.copy(), hi=self.x0.hi.copy())

    def _step(
        self, state: PredictorState, u_k: np.ndarray, y_k: np.ndarray, t_k: float | None
    ) -> Step[PredictorState]:
        A, B, _, D, E, F = self.sys.matrices_at(state.k)
        d = self.sys.d_at(state.k, y_k)
        lo, hi = state.lo.copy(), state.hi.copy()
        inconsistent = False
        for i, j, c in self.design.rows:  # correction by the measurement strip
            if np.isnan(y_k[j]):
                continue  # a missing sample: predict without it
            # c x_i = y_j − D_j u − F_j d, with y_j known to half an ulp (a logger's rounding);
            # image_bounds contains the exact interval, and each further operation rounds out
            v_lo, v_hi = image_bounds(np.hstack([D[j], F[j]])[None], [*u_k, *d.lo], [*u_k, *d.hi])
            slack = up(abs(y_k[j]) * UNIT_ROUNDOFF)
            r_lo, r_hi = down(down(y_k[j] - v_hi[0]) - slack), up(up(y_k[j] - v_lo[0]) + slack)
            a, b = (down(r_lo / c), up(r_hi / c)) if c > 0 else (down(r_hi / c), up(r_lo / c))
            if b < lo[i] or a > hi[i]:
                inconsistent = True  # y contradicts the model: not used
                continue
            lo[i], hi[i] = max(lo[i], a), min(hi[i], b)
        # prediction of x[k+1] = A x + B u + E d over the box: one rigorous interval image
        n_lo, n_hi = image_bounds(np.hstack([A, B, E]), [*lo, *u_k, *d.lo], [*hi, *u_k, *d.hi])
        return Step(replace(state, lo=n_lo, hi=n_hi), lo, hi, inconsistent)


def main() -> None:
    report = check_estimator(MeasuredStatePredictor)  # the checks every ivobs method passes
    print(f"conformance: {report.steps} steps on {report.checked}, skipped {list(report.skipped)}")
    sc = ivobs.scenarios.get("servo-motor", horizon=200)
    tr = sc.simulate("vertex", seed=0)
    for method in ("measured-state-predictor", "interval-split"):
        res = ivobs.make_estimator(method, sc.system, x0=sc.x0).run(tr.u, tr.y)
        assert res.contains(tr.x).all()
        print(f"{method:26s} mean widths {np.round(res.mean_width(burn_in=20), 4)}")


if __name__ == "__main__":
    main()
