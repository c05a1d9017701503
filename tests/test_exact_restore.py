"""``exact`` after ``state()``/``restore()`` continues with the same solves as the run that saved
it (identically, full horizon and moving window, badly scaled time-varying systems), and an
unstable system whose programs HiGHS's own scaling made fail gets tight boxes, no program
stopped."""

import json
import warnings

import numpy as np
import pytest

import ivobs
from ivobs.testing import adversarial_run, assert_contains, random_system

T = 30


def _scaled_time_varying(seed: int, nx: int, ny: int, nu: int, nd: int | None, spread: float):
    """``random_system`` in coordinates with magnitudes spread over ``10^±spread`` and ``A``
    modulated at every step (stacked matrices); ``x0`` of the same scales."""
    rng = np.random.default_rng(5000 + seed)
    base = random_system(seed, nx=nx, ny=ny, nu=nu, nd=nd)
    s = 10.0 ** rng.uniform(-spread, spread, nx)
    S, Si = np.diag(s), np.diag(1 / s)
    A = np.array([S @ base.A @ Si * m for m in 1 + 0.2 * rng.uniform(-1, 1, T + 5)])
    sys = ivobs.LinearSystem(A, S @ base.B, base.C @ Si, E=S @ base.E, F=base.F, d=base.d)
    return sys, ivobs.Box(-s, s)


def _steps(est, u, y, ks):
    return np.array([np.r_[b.lo, b.hi] for b in (est.step(u[k], y[k]) for k in ks)])


@pytest.mark.parametrize("window", [None, 5])
@pytest.mark.parametrize("cut", [5, 12, 20])
def test_restored_state_continues_identically_on_a_badly_scaled_time_varying_system(window, cut):
    """Magnitudes over 1e±3, A time-varying: before, the restored continuation differed from the
    run by up to 7e-7 absolute (47 times the box width here), as the program rebuilt from the
    saved state was scaled by HiGHS differently and solved from a cold start."""
    sys, x0 = _scaled_time_varying(12, nx=2, ny=2, nu=1, nd=3, spread=3.0)
    tr = adversarial_run(sys, x0, T, seed=13)
    opts = {"progress": False, "window": window}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = _steps(ivobs.make_estimator("exact", sys, x0=x0, **opts), tr.u, tr.y, range(T))
        first = ivobs.make_estimator("exact", sys, x0=x0, **opts)
        _steps(first, tr.u, tr.y, range(cut))
        saved = json.loads(json.dumps(first.state()))
        second = ivobs.make_estimator("exact", sys, x0=x0, **opts)
        second.restore(saved)
        rest = _steps(second, tr.u, tr.y, range(cut, T))
    np.testing.assert_array_equal(rest, ref[cut:])
    assert_contains(ivobs.Estimate(rest[:, :2], rest[:, 2:]), tr.x[cut:])


def test_a_state_with_empty_bases_restores_from_a_cold_start():
    """Empty bases (a state built without a solver) restore from a cold start (equal to the
    solver's tolerance), and a basis that is not HiGHS status codes is refused by name."""
    sys, x0 = _scaled_time_varying(4, nx=2, ny=1, nu=1, nd=None, spread=0.0)
    tr = adversarial_run(sys, x0, 12, seed=5)
    est = ivobs.make_estimator("exact", sys, x0=x0, progress=False)
    ref = _steps(est, tr.u, tr.y, range(12))
    first = ivobs.make_estimator("exact", sys, x0=x0, progress=False)
    _steps(first, tr.u, tr.y, range(6))
    saved = first.state()
    assert len(saved["state"]["basis_min"]["array"]) > 0
    old = json.loads(json.dumps(saved))
    for key in ("basis_min", "basis_max"):
        old["state"][key].update(shape=[0], array=[])
    second = ivobs.make_estimator("exact", sys, x0=x0, progress=False)
    second.restore(old)
    np.testing.assert_allclose(_steps(second, tr.u, tr.y, range(6, 12)), ref[6:], atol=1e-8)
    bad = json.loads(json.dumps(saved))
    bad["state"]["basis_min"]["array"][0] = 9
    with pytest.raises(ivobs.IvobsError, match="basis_min"):
        ivobs.make_estimator("exact", sys, x0=x0, progress=False).restore(bad)


def test_an_unstable_system_gets_tight_boxes_with_no_program_stopped():
    """An unstable 6-state system (|x| up to 8e7 in 30 steps): HiGHS's equilibration, computed
    once and extended row by row, made 40 of its programs end 'unknown' (loose safe bounds,
    summed width 525, 13 s on a quiet machine); now every program is solved (width 93). The
    iteration budget bounds the time of every program whatever happens: a budget hit is
    reported (RuntimeWarning) and its box is still guaranteed."""
    base = random_system(11, nx=6, ny=5, nu=0, rho=None)
    rng = np.random.default_rng(5011)
    rng.uniform(size=6)
    stacked = np.array([base.A * m for m in 1 + 0.2 * rng.uniform(-1, 1, T + 5)])
    sys = ivobs.LinearSystem(lambda k: stacked[k], None, base.C, E=base.E, F=base.F, d=base.d)
    c = rng.uniform(-3, 3, 6)
    x0 = ivobs.Box(c - 1, c + 1)
    tr = adversarial_run(sys, x0, T, seed=12)
    est = ivobs.make_estimator("exact", sys, x0=x0, progress=False, on_inconsistent="raise")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)  # no program stopped by the budget
        res = est.run(tr.u, tr.y)
    assert_contains(res, tr.x)
    assert float(res.width.sum()) < 150.0  # was 525 (programs ended 'unknown')
