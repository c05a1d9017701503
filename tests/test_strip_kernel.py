"""The strip method's compiled step (issue 17, ``estimators/_strip_kernel_nb.py``) against its
NumPy reference (``strip.py``): the same bounds up to the rounding of a different order of
operations, the true state of a simulator held (tests/test_strip_fast.py runs its simulator with
both paths), the NumPy fallback without numba, no FMA contraction in the machine code.

Tolerance of the comparison: the two paths evaluate the same formulas with the same margins, but
the sums in another order (loops instead of NumPy's pairwise sums and BLAS; a hand-written
pivoted QR instead of LAPACK's), so each bound differs in its last bits at each step; the filter
contracts, so the differences do not accumulate: measured at most 11 units in the last place of
the bound's magnitude over the records below. The test allows ``64 ε max(|bound|, width)``."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from types import SimpleNamespace

import numpy as np
import pytest

import ivobs
from ivobs.estimators import _strip_kernel
from ivobs.testing import random_system

pytest.importorskip("numba")

TOL = 64 * np.finfo(float).eps


def _numpy_path(sc_sys, x0, **opts):
    """A strip estimator built with the kernel disabled (the module flag)."""
    before = _strip_kernel.ENABLED
    _strip_kernel.ENABLED = False
    try:
        return ivobs.make_estimator("strip", sc_sys, x0=x0, **opts)
    finally:
        _strip_kernel.ENABLED = before


def _simulate(sys_, rng, T):
    """x+ = A x + B u + E d, y = C x + D u + F d, x[0] and d[k] at vertices of their boxes."""
    A, B, C, D, E, F = sys_.matrices_at(0)
    db = sys_.d_at(0, None)
    u = rng.normal(size=(T, B.shape[1]))
    x, y = np.empty((T, A.shape[0])), np.empty((T, C.shape[0]))
    xk = rng.choice([-1.0, 1.0], A.shape[0])
    for k in range(T):
        d = np.where(rng.random(db.lo.shape[0]) < 0.5, db.lo, db.hi)
        x[k], y[k] = xk, C @ xk + D @ u[k] + F @ d
        xk = A @ xk + B @ u[k] + E @ d
    return SimpleNamespace(u=u, y=y, x=x)


def _cases():
    sc = ivobs.scenarios.get("servo-motor", horizon=2000)
    yield "servo", sc.system, sc.x0, sc.simulate("vertex", seed=0), {}
    tank = ivobs.scenarios.get("cora-tank30")
    yield "tank30", tank.system, tank.x0, tank.recorded, {}
    for seed, (nx, ny) in enumerate([(5, 2), (8, 4)]):
        rng = np.random.default_rng(40 + seed)
        sys_ = random_system(rng, nx=nx, ny=ny, nu=1, feedthrough=True)
        x0 = ivobs.Box(-np.ones(nx), np.ones(nx))
        tr = _simulate(sys_, rng, 400)
        yield f"random{nx}", sys_, x0, tr, {"reduction": "girard"} if seed else {}


@pytest.mark.parametrize("case", list(_cases()), ids=lambda c: c[0])
def test_kernel_gives_the_numpy_bounds_to_a_few_ulps(case) -> None:
    _, sys_, x0, tr, opts = case
    fast = ivobs.make_estimator("strip", sys_, x0=x0, **opts)
    ref = _numpy_path(sys_, x0, **opts)
    assert fast._kernel is not None and ref._kernel is None
    a, b = fast.run(tr.u, tr.y), ref.run(tr.u, tr.y)
    width = b.upper - b.lower
    scale = np.maximum(np.maximum(np.abs(b.lower), np.abs(b.upper)), width)
    assert np.all(np.abs(a.lower - b.lower) <= TOL * scale)
    assert np.all(np.abs(a.upper - b.upper) <= TOL * scale)
    assert np.array_equal(a.inconsistent, b.inconsistent)
    # both hold the simulated (or recorded) state
    for r in (a, b):
        assert np.all(r.lower <= tr.x) and np.all(tr.x <= r.upper)


def test_kernel_online_steps_equal_its_run_and_the_state_round_trips() -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=300)
    tr = sc.simulate("vertex", seed=3)
    est = ivobs.make_estimator("strip", sc.system, x0=sc.x0)
    res = est.run(tr.u, tr.y)
    est.reset()
    for k in range(150):
        est.step(tr.u[k], tr.y[k])
    saved = est.state()
    est2 = ivobs.make_estimator("strip", sc.system, x0=sc.x0)
    est2.restore(saved)
    for k in range(150, 300):
        box = est2.step(tr.u[k], tr.y[k])
        assert np.array_equal(box.lo, res.lower[k]) and np.array_equal(box.hi, res.upper[k])


def test_fallback_when_disabled_by_the_environment(monkeypatch) -> None:
    monkeypatch.setenv(_strip_kernel.ENV, "0")
    sc = ivobs.scenarios.get("servo-motor", horizon=200)
    est = ivobs.make_estimator("strip", sc.system, x0=sc.x0)
    assert est._kernel is None
    tr = sc.simulate("vertex", seed=1)
    res = est.run(tr.u, tr.y)
    assert np.all(res.lower <= tr.x) and np.all(tr.x <= res.upper)
    monkeypatch.delenv(_strip_kernel.ENV)
    assert ivobs.make_estimator("strip", sc.system, x0=sc.x0)._kernel is not None


def test_fallback_without_numba_and_import_ivobs_does_not_import_it() -> None:
    """A fresh interpreter where ``import numba`` fails: the NumPy path, the same numbers as
    with the kernel disabled here; and ``import ivobs`` alone never imports numba."""
    code = (
        "import sys, json; sys.modules['numba'] = None\n"
        "import ivobs\n"
        "sc = ivobs.scenarios.get('servo-motor', horizon=100)\n"
        "est = ivobs.make_estimator('strip', sc.system, x0=sc.x0)\n"
        "r = est.run(*(lambda t: (t.u, t.y))(sc.simulate('vertex', seed=2)))\n"
        "print(json.dumps([est._kernel is None, r.upper[-1].tolist()]))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300,
        env={**os.environ},
    )  # fmt: skip
    none, upper = json.loads(out.stdout.strip().splitlines()[-1])
    assert none is True
    sc = ivobs.scenarios.get("servo-motor", horizon=100)
    tr = sc.simulate("vertex", seed=2)
    ref = _numpy_path(sc.system, sc.x0).run(tr.u, tr.y)
    assert upper == ref.upper[-1].tolist()
    mods = subprocess.run(
        [sys.executable, "-c", "import ivobs, sys; print('numba' in sys.modules)"],
        capture_output=True, text=True, check=True, timeout=120,
    )  # fmt: skip
    assert mods.stdout.strip() == "False"


def test_kernel_is_not_used_where_it_does_not_apply() -> None:
    sc = ivobs.scenarios.get("servo-motor", horizon=50)
    assert ivobs.make_estimator("strip", sc.system, x0=sc.x0, reduction="box")._kernel is None


def test_no_fastmath_and_no_fma_in_the_compiled_step() -> None:
    """The kernel's functions are compiled without ``fastmath``; and numba's code for a
    multiply-add loop under the kernel's options (freshly compiled: the machine code of cached
    functions cannot be inspected) has no fused multiply-add, so ``a * b + c`` is rounded twice
    as the margins assume. (The whole kernel was checked the same way with the cache off: no
    ``vfmadd``; BENCHMARKS.md.)"""
    import numba

    from ivobs.estimators import _strip_kernel_nb as nb
    from ivobs.sets.zonotope import MAX_BASIS_CONDITION

    assert nb.MAX_COND == MAX_BASIS_CONDITION
    from ivobs.estimators import _strip_kernel_linalg as la

    kernel = [
        f
        for mod in (nb, la)
        for f in vars(mod).values()
        if isinstance(f, numba.core.dispatcher.Dispatcher)
    ]
    assert len(kernel) >= 10
    for fn in kernel:
        assert type(fn._cache).__name__ == "FunctionCache"  # cache=True
        assert not fn.targetoptions.get("fastmath", False)

    def axpy_dot(x, y, z):
        a = 0.0
        for k in range(x.shape[0]):
            z[k] = z[k] + x[k] * y[k]
            a += x[k] * y[k]
        return a

    probe = numba.njit(axpy_dot)
    x = np.arange(1.0, 65.0)
    probe(x, x, x.copy())
    sig = probe.signatures[0]
    assert " fast " not in probe.inspect_llvm(sig) and " contract " not in probe.inspect_llvm(sig)
    asm = probe.inspect_asm(sig)
    assert "vmulpd" in asm or "vmulsd" in asm or "mulsd" in asm  # the code is there
    assert "vfmadd" not in asm and "vfmsub" not in asm and "vfnmadd" not in asm
    # with fastmath the same loop does get contracted: the check above can fail
    fast = numba.njit(fastmath=True)(axpy_dot)
    fast(x, x, x.copy())
    assert "vfmadd" in fast.inspect_asm(fast.signatures[0]) or not _has_fma()


def _has_fma() -> bool:
    try:
        with open("/proc/cpuinfo") as fh:
            return " fma " in fh.read()
    except OSError:
        return False
