"""nl-constrained-zonotope's hull LPs as one block program (issue 16, option ``hull_lp``).

* ``hull_lp="block"`` (the default) solves the ``2 nx`` hull programs of a step as one HiGHS
  program (:func:`ivobs.sets.czonotope._highs.block_duals`), ``"chain"`` warm-started one after
  the other (the linear ``constrained-zonotope`` method's way, whose boxes stay bit for bit:
  tests/test_czonotope_hull_speed.py). Both certify every bound by its multipliers, so both
  must contain the exact state of tests/exactsim.py (60-digit intervals, the unknowns on their
  vertices) on the chaotic Hénon map and a random system of tests/randsys.py; they differ only
  where a degenerate program has several optimal multipliers, so their mean widths agree closely.
* The option reaches the solver: the block program is called in block mode only.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import numpy as np
import pytest

import ivobs
from exactsim import Record, simulate
from ivobs.errors import IvobsError
from ivobs.sets.czonotope import _highs
from randsys import random_nonlinear

T = 400


@cache
def _henon() -> tuple[ivobs.NonlinearSystem, ivobs.Box, Record]:
    sc = ivobs.scenarios.get("henon-nl")
    return sc.system, sc.x0, simulate(sc.system, sc.x_true0, T, seed=11)


@cache
def _random() -> tuple[ivobs.NonlinearSystem, ivobs.Box, Record, np.ndarray | None]:
    case = random_nonlinear(1, T)
    rec = simulate(case.system, case.x_true0, T, case.u, seed=1)
    return case.system, case.x0, rec, None if case.u is None else case.u[:T]


def _widths(sys_: ivobs.NonlinearSystem, x0: ivobs.Box, rec: Record, u: object, lp: str) -> Any:
    est = ivobs.make_estimator("nl-constrained-zonotope", sys_, x0=x0, hull_lp=lp)
    res = est.run(u, rec.Y)
    assert rec.misses(res.lower, res.upper).tolist() == []  # every box holds the exact state
    assert not res.inconsistent.any()
    return res.upper - res.lower


@pytest.mark.parametrize("case", ["henon", "random"])
def test_block_and_chain_contain_the_exact_state_with_the_same_widths(case: str) -> None:
    if case == "henon":
        sys_, x0, rec = _henon()
        u = None
    else:
        sys_, x0, rec, u = _random()
    block = _widths(sys_, x0, rec, u, "block")
    chain = _widths(sys_, x0, rec, u, "chain")
    assert np.isfinite(block).all() and block[50:].max() < 1.0
    ratio = block[50:].mean() / chain[50:].mean()
    assert abs(ratio - 1.0) <= 0.005, ratio
    # per step the multipliers may differ, but neither way is far looser
    per_step = block[50:].mean(axis=1) / chain[50:].mean(axis=1)
    assert 0.95 < per_step.min() and per_step.max() < 1.05, (per_step.min(), per_step.max())


@pytest.mark.parametrize("lp", ["block", "chain"])
def test_the_option_chooses_the_solver(monkeypatch: pytest.MonkeyPatch, lp: str) -> None:
    calls = {"block": 0, "chain": 0}
    real_block, real_chain = _highs.block_duals, _highs.chain_duals

    def block(*args: Any) -> Any:
        calls["block"] += 1
        return real_block(*args)

    def chain(*args: Any) -> Any:
        calls["chain"] += 1
        return real_chain(*args)

    monkeypatch.setattr(_highs, "block_duals", block)
    monkeypatch.setattr(_highs, "chain_duals", chain)
    sys_, x0, rec = _henon()
    est = ivobs.make_estimator("nl-constrained-zonotope", sys_, x0=x0, hull_lp=lp)
    assert est.design.block_max == (_highs.BLOCK_SIZE if lp == "block" else 0)
    est.run(None, rec.Y[:20])
    assert calls[lp] == 20 and calls["chain" if lp == "block" else "block"] == 0


def test_the_linear_method_keeps_its_chains(monkeypatch: pytest.MonkeyPatch) -> None:
    used = {"block": 0}

    def block(*args: Any) -> Any:  # pragma: no cover - must not be called
        used["block"] += 1
        raise AssertionError("block program used by the linear method")

    monkeypatch.setattr(_highs, "block_duals", block)
    sc = ivobs.scenarios.get("servo-motor", horizon=30)
    tr = sc.simulate("vertex", seed=0)
    ivobs.make_estimator("constrained-zonotope", sc.system, x0=sc.x0).run(tr.u, tr.y)
    assert used["block"] == 0


def test_a_bad_hull_lp_is_refused() -> None:
    sys_, x0, _ = _henon()
    with pytest.raises(IvobsError, match=r"hull_lp: expected 'block' or 'chain', got 'simplex'"):
        ivobs.make_estimator("nl-constrained-zonotope", sys_, x0=x0, hull_lp="simplex")
