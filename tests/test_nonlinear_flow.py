"""Guaranteed discretisation of continuous-time nonlinear models (``NonlinearSystem(dt=0)
.discretize(Ts)``, the interval Taylor method of model/nonlinear/flow.py).

Truth: ``scipy.integrate.solve_ivp`` (DOP853, ``rtol = 1e-12``, ``atol = 1e-13``) with the
right-hand sides written here, compared with a margin of ``MARGIN = 1e-8`` (over at most a few
seconds of these smooth, bounded flows the integrator's error is below 1e-10: the pendulum's is
checked against mpmath's Taylor-series ``odefun`` at 25 digits, which the enclosures must contain
with no margin at all).
"""

from __future__ import annotations

import itertools
import math
import pickle

import mpmath as mp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import ivobs
from ivobs.errors import IvobsError

MARGIN = 1e-8
RNG = np.random.default_rng(7)


def pendulum() -> ivobs.NonlinearSystem:
    return ivobs.NonlinearSystem(
        f=["w", "-g/L*sin(th) - 0.2*w + u1 + d1"],
        h=["th + v"],
        states=["th", "w"],
        inputs=["u1"],
        params={"g": 9.81, "L": (0.95, 1.05)},
        d={"d1": (-0.1, 0.1), "v": (-0.01, 0.01)},
        dt=0,
    )


def pendulum_rhs(x, u, w):  # w = (L, d1, v)
    return [x[1], -9.81 / w[0] * math.sin(x[0]) - 0.2 * x[1] + u[0] + w[1]]


def vdp() -> ivobs.NonlinearSystem:
    return ivobs.NonlinearSystem(
        f=["x2", "mu*(1 - x1**2)*x2 - x1 + d1"],
        h=["x1 + v"],
        states=["x1", "x2"],
        params={"mu": 1.0},
        d={"d1": (-0.05, 0.05), "v": (-0.02, 0.02)},
        dt=0,
    )


def vdp_rhs(x, u, w):  # w = (d1, v)
    return [x[1], (1 - x[0] ** 2) * x[1] - x[0] + w[0]]


K = 0.015 * math.sqrt(2 * 9.81)


def tank6() -> ivobs.NonlinearSystem:
    f = ["u1 - k*sqrt(2*g)*sqrt(x1) + w1"]
    f += [f"k*sqrt(2*g)*(sqrt(x{i - 1}) - sqrt(x{i})) + w{i}" for i in range(2, 7)]
    d = {f"w{i}": (-0.001, 0.001) for i in range(1, 7)}
    d.update({f"v{i}": (-0.2, 0.2) for i in range(1, 4)})
    return ivobs.NonlinearSystem(
        f=f,
        h=["x2 + v1", "x4 + v2", "x5 + v3"],
        states=[f"x{i}" for i in range(1, 7)],
        inputs=["u1"],
        params={"k": 0.015, "g": 9.81},
        d=d,
        dt=0,
    )


def tank6_rhs(x, u, w):
    r = [u[0] - K * math.sqrt(x[0]) + w[0]]
    return r + [K * (math.sqrt(x[i - 1]) - math.sqrt(x[i])) + w[i] for i in range(1, 6)]


CASES = {
    # name: (system, rhs, Ts, x box, u)
    "pendulum": (pendulum, pendulum_rhs, 0.1, ([0.4, -0.2], [0.6, 0.2]), [0.3]),
    "vdp": (vdp, vdp_rhs, 0.1, ([1.0, -0.5], [1.3, -0.1]), []),
    "tank6": (
        tank6,
        tank6_rhs,
        0.5,
        ([1.8, 3.8, 3.7, 1.9, 9.5, 3.8], [2.2, 4.2, 4.3, 2.1, 10.5, 4.2]),
        [0.1],
    ),
}


def flow(rhs, x0, u, w, Ts):
    sol = solve_ivp(
        lambda t, x: rhs(x, u, w), (0.0, Ts), x0, method="DOP853", rtol=1e-12, atol=1e-13
    )
    assert sol.success
    return sol.y[:, -1]


def samples(lo, hi, n):
    """Corners of the box (up to 2^6) and uniform points."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    k = len(lo)
    corners = [lo + (hi - lo) * np.array([(c >> i) & 1 for i in range(k)]) for c in range(2**k)]
    return corners[:64] + [lo + (hi - lo) * RNG.random(k) for _ in range(n)]


@pytest.mark.parametrize("name", list(CASES))
def test_box_enclosure_contains_the_flow(name: str) -> None:
    make, rhs, Ts, (xl, xh), u = CASES[name]
    sys = make().discretize(Ts, order=4, disturbances="held")
    wl, wh = sys.w_box.lo, sys.w_box.hi
    lo, hi = sys.f_box(xl, xh, u, wl, wh)
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))
    ws = samples(wl, wh, 0)[:16]  # vertex disturbances and parameters
    for x0 in samples(xl, xh, 30):
        for w in (ws[RNG.integers(len(ws))], ws[0], ws[-1]):
            x1 = flow(rhs, x0, u, w, Ts)
            assert np.all(lo - MARGIN <= x1) and np.all(x1 <= hi + MARGIN), (x0, w, x1, lo, hi)
    # the enclosure is not the trivial one: within 1.6x the spread of the sampled flows
    pts = np.array([flow(rhs, x0, u, w, Ts) for x0 in samples(xl, xh, 0) for w in (ws[0], ws[-1])])
    assert np.all(hi - lo <= 1.6 * (pts.max(0) - pts.min(0)) + 1e-3)


def test_point_enclosures_contain_mpmath_taylor_truth() -> None:
    """No margin: 25-digit ``mpmath.odefun`` (a Taylor-series integrator)."""
    sys = pendulum().discretize(0.1, order=6, disturbances="held")
    mp.mp.dps = 25
    try:
        for x0, L, d1 in (
            ([0.5, 0.1], 1.05, 0.1),
            ([-1.0, 2.0], 0.95, -0.1),
            ([3.0, 0.0], 1.0, 0.0),
        ):
            w = [L, d1, 0.0]
            lo, hi = sys.f_box(x0, x0, [0.3], w, w)
            gL, c = mp.mpf("9.81") / mp.mpf(L), mp.mpf(0.3) + mp.mpf(d1)

            def rhs(t, z, gL=gL, c=c):
                return [z[1], -gL * mp.sin(z[0]) - mp.mpf("0.2") * z[1] + c]

            sol = mp.odefun(rhs, 0, [mp.mpf(x0[0]), mp.mpf(x0[1])])
            x1 = sol(mp.mpf("0.1"))
            for i in range(2):
                assert mp.mpf(lo[i]) <= x1[i] <= mp.mpf(hi[i])
                assert hi[i] - lo[i] < 2e-4  # a point: the remainder (9e-5 at 3.0)
    finally:
        mp.mp.dps = 15


def test_widths_shrink_with_order_and_substeps() -> None:
    cont = vdp()
    x0, w = [1.2, -0.3], [0.01, 0.0]

    def width(order: int, substeps: int) -> float:
        flow = cont.discretize(0.2, order=order, substeps=substeps, disturbances="held")
        lo, hi = flow.f_box(x0, x0, [], w, w)
        return float(np.max(hi - lo))

    by_order = [width(k, 1) for k in (1, 2, 3, 4, 5, 6)]
    by_steps = [width(3, n) for n in (1, 2, 4, 8)]
    assert all(a > 2 * b for a, b in itertools.pairwise(by_order)), by_order
    assert all(a > 4 * b for a, b in itertools.pairwise(by_steps)), by_steps  # ~2^3 per halving
    assert by_order[-1] < 1e-4


@pytest.mark.parametrize("name", ["pendulum", "tank6"])
def test_jacobian_encloses_the_variational_solution(name: str) -> None:
    make, rhs, Ts, (xl, xh), u = CASES[name]
    sys = make().discretize(Ts, order=4, disturbances="held")
    wl, wh = sys.w_box.lo, sys.w_box.hi
    Jxl, Jxh, Jwl, Jwh = sys.f_jac_box(xl, xh, u, wl, wh)
    nx, nw = sys.nx, sys.nw
    eps = 1e-6
    for x0 in samples(xl, xh, 5)[:8]:
        w = wl + (wh - wl) * RNG.random(nw)
        base = flow(rhs, x0, u, w, Ts)
        for j in range(nx + nw):  # central differences: error ~ eps^2 + 1e-12/eps
            dx, dw = np.zeros(nx), np.zeros(nw)
            (dx if j < nx else dw)[j if j < nx else j - nx] = eps
            col = (flow(rhs, x0 + dx, u, w + dw, Ts) - flow(rhs, x0 - dx, u, w - dw, Ts)) / (
                2 * eps
            )
            lo = Jxl[:, j] if j < nx else Jwl[:, j - nx]
            hi = Jxh[:, j] if j < nx else Jwh[:, j - nx]
            assert np.all(lo - 1e-5 <= col) and np.all(col <= hi + 1e-5), (j, lo, col, hi)
        assert base.shape == (nx,)
    assert np.all(Jxh - Jxl < 0.25)  # not trivial


def test_failed_apriori_enclosure_is_a_clear_error() -> None:
    sys = ivobs.NonlinearSystem(f=["x**2"], h=["x"], states=["x"], dt=0)
    flow2 = sys.discretize(2.0)  # x(t) = 1/(1 - t) escapes at t = 1
    with pytest.raises(IvobsError, match="no a priori enclosure of the flow"):
        flow2.f_box([1.0], [1.0], [], [], [])
    lo, hi = sys.discretize(0.5, order=6, substeps=4).f_box([1.0], [1.0], [], [], [])
    assert lo[0] <= 2.0 <= hi[0] and hi[0] - lo[0] < 1e-2  # before the escape: fine
    lo, hi = flow2.f_box([-np.inf], [1.0], [], [], [])
    assert not np.any(np.isnan(lo)) and lo[0] == -np.inf


def test_api_and_refusals() -> None:
    cont = pendulum()
    assert cont.is_continuous and not cont.is_discrete
    with pytest.raises(IvobsError, match="discretize"):
        ivobs.make_estimator("nl-interval", cont, x0=ivobs.Box([0, 0], [1, 1]))
    with pytest.raises(IvobsError, match="solve_ivp"):
        ivobs.simulate_nonlinear(cont, [0.0, 0.0], u=np.zeros((3, 1)))
    fs = cont.discretize(0.1, order=3, substeps=2)
    assert not fs.is_continuous and fs.sampling_period == 0.1
    with pytest.raises(IvobsError, match="already discrete"):
        fs.discretize(0.1)
    with pytest.raises(IvobsError, match="order"):
        cont.discretize(0.1, order=0)
    with pytest.raises(IvobsError, match="substeps"):
        cont.discretize(0.1, substeps=2.5)
    with pytest.raises(IvobsError, match="Ts"):
        cont.discretize(-1.0)
    with pytest.raises(IvobsError, match="dt"):
        ivobs.NonlinearSystem(f=["x"], h=["x"], states=["x"], dt=-1)
    kink = ivobs.NonlinearSystem(f=["-abs(x)"], h=["x"], states=["x"], dt=0)
    with pytest.raises(IvobsError, match="order: 3 needs a smooth f"):
        kink.discretize(0.1, order=3)
    lo, hi = kink.discretize(0.5, order=2).f_box([-0.2], [0.3], [], [], [])
    assert lo[0] <= -0.2 * math.exp(0.5) and hi[0] >= 0.3 * math.exp(-0.5)  # x0 e^(-|t|)
    assert hi[0] - lo[0] < 0.75  # 0.70 (the exact range: 0.51)
    kinked = kink.discretize(0.5, order=2)
    box, y = ivobs.Box([-1.0], [1.0]), 0.1 * np.exp(-0.5 * np.arange(3))[:, None]
    with pytest.raises(IvobsError, match="use nl-interval"):
        ivobs.make_estimator("nl-zonotope", kinked, x0=box).run(None, y)
    res = ivobs.make_estimator("nl-interval", kinked, x0=box).run(None, y)  # y = x = 0.1 e^-t
    assert not np.any(res.inconsistent) and np.all(res.lower <= y) and np.all(y <= res.upper)
    assert "validated flow" in fs._repr_html_()
    back = pickle.loads(pickle.dumps(fs))
    a = fs.f_box([0.5, 0.0], [0.6, 0.1], [0.0], fs.w_box.lo, fs.w_box.hi)
    b = back.f_box([0.5, 0.0], [0.6, 0.1], [0.0], fs.w_box.lo, fs.w_box.hi)
    assert np.array_equal(a[0], b[0]) and back.spec() == fs.spec()
    assert fs.spec()["discretize"] == {
        "Ts": 0.1,
        "order": 3,
        "substeps": 2,
        "disturbances": "varying",
    }


LIMIT = {"nl-interval": 0.2, "nl-zonotope": 0.2, "nl-constrained-zonotope": 0.1}
"""Mean width of the rate after step 10 (measured 0.152, 0.139, 0.072)."""


def simulate(rhs, x0, U, W, V, Ts, out):
    """The test's own simulator: ``u``, ``w`` held over each period (vertex values)."""
    X, Y = [], []
    x = np.asarray(x0, float)
    for k in range(len(U)):
        X.append(x.copy())
        Y.append(out(x) + V[k])
        x = flow(rhs, x, U[k], W[k], Ts)
    return np.array(X), np.array(Y)


def pendulum_record(T: int, Ts: float) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(11)  # the same record for every method
    U = 0.3 * np.sin(0.2 * np.arange(T))[:, None]
    L = rng.choice([0.95, 1.05], T)
    D = rng.choice([-0.1, 0.1], T)
    V = rng.choice([-0.01, 0.01], (T, 1))
    X, Y = simulate(pendulum_rhs, [0.5, 0.0], U, np.c_[L, D, V[:, 0]], V, Ts, lambda x: x[:1])
    return U, X, Y


PEND_X0 = ivobs.Box([0.3, -0.3], [0.7, 0.3])


@pytest.mark.parametrize("method", ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"])
def test_estimators_contain_the_sampled_pendulum(method: str) -> None:
    T, Ts = 50, 0.1
    sys = pendulum().discretize(Ts, order=4, disturbances="held")
    U, X, Y = pendulum_record(T, Ts)
    res = ivobs.make_estimator(method, sys, x0=PEND_X0).run(U, Y)
    assert np.all(res.lower - MARGIN <= X) and np.all(X <= res.upper + MARGIN)
    width = (res.upper - res.lower)[10:].mean(axis=0)
    assert width[0] < 0.021 and width[1] < LIMIT[method], width


def test_the_step_back_through_the_flow_bounds_the_unmeasured_rate() -> None:
    """``h ∘ Φ`` contracted through the flow's mean-value form (model/nonlinear/flowback.py):
    the rate, seen only through the dynamics, is several times tighter than without it
    (measured 0.152 against 1.008 with lag=0)."""
    T, Ts = 50, 0.1
    sys = pendulum().discretize(Ts, order=4, disturbances="held")
    U, X, Y = pendulum_record(T, Ts)
    widths = []
    for lag in (0, 1):  # (without the window-centred form, which bounds the rate too)
        res = ivobs.make_estimator("nl-interval", sys, x0=PEND_X0, lag=lag, window=0).run(U, Y)
        assert np.all(res.lower - MARGIN <= X) and np.all(X <= res.upper + MARGIN)
        widths.append((res.upper - res.lower)[10:, 1].mean())
    assert widths[1] < widths[0] / 4, widths


def test_nl_interval_contains_the_sampled_six_tank() -> None:
    T, Ts = 40, 0.5
    sys = tank6().discretize(Ts, order=3, disturbances="held")
    U = np.full((T, 1), 0.1)
    Wp = RNG.choice([-0.001, 0.001], (T, 6))
    V = RNG.choice([-0.2, 0.2], (T, 3))
    x0 = [2.0, 4.0, 4.0, 2.0, 10.0, 4.0]
    X, Y = simulate(tank6_rhs, x0, U, np.c_[Wp, V], V, Ts, lambda x: x[[1, 3, 4]])
    est = ivobs.make_estimator("nl-interval", sys, x0=ivobs.Box(np.array(x0) - 1, np.array(x0) + 1))
    res = est.run(U, Y)
    assert np.all(res.lower - MARGIN <= X) and np.all(X <= res.upper + MARGIN)
    assert np.all((res.upper - res.lower)[-1] < 2.5)


def test_a_sampled_model_saves_and_loads_with_its_discretisation(tmp_path) -> None:
    """``[system.discretize]``: a saved FlowSystem loads as the same sampled model (Ts, order,
    substeps), with the same enclosure of the flow; bad tables are clear errors."""
    sampled = pendulum().discretize(0.05, order=5, substeps=2)
    path = tmp_path / "pend.toml"
    ivobs.save_system(path, sampled, x0=ivobs.Box([-0.1, -0.1], [0.1, 0.1]))
    text = path.read_text()
    assert "[system.discretize]" in text and "order = 5" in text and "substeps = 2" in text
    back = ivobs.load_system(path).system
    assert (back.dt, back.order, back.substeps) == (0.05, 5, 2)
    x = ivobs.Box([0.1, -0.2], [0.12, -0.18])
    args = (x.lo, x.hi, [0.3], sampled.w_box.lo, sampled.w_box.hi)
    np.testing.assert_array_equal(back.f_box(*args)[0], sampled.f_box(*args)[0])
    bad = {
        "Ts = -1.0": "sampling period > 0",
        "Ts = 0.1\norder = 2.5": "expected an integer",
        "Ts = 0.1\nsteps = 3": "unknown key",
        "order = 4": "missing Ts",
    }
    for table, msg in bad.items():
        path.write_text(
            text.split("[system.discretize]")[0] + "[system.discretize]\n" + table + "\n"
        )
        with pytest.raises(IvobsError, match=msg):
            ivobs.load_system(path)


def test_a_diverging_run_returns_the_steps_before_it() -> None:
    """``x' = x²`` from ``x(0) ∈ [0.5, 0.6]`` escapes before ``t = 2``: the validated flow
    finds no a priori enclosure at the step that reaches it; ``run()`` says so with the step
    and keeps the boxes before it (they contain the exact solution ``1 / (1/x0 − t)``)."""
    sys = ivobs.NonlinearSystem(f=["x**2"], h=["x"], states=["x"], dt=0).discretize(0.1)
    est = ivobs.make_estimator("nl-interval", sys, x0=ivobs.Box([0.5], [0.6]))
    y = np.full((30, 1), np.nan)  # no measurement: the prediction alone
    with pytest.warns(UserWarning, match=r"diverged at step \d+ and stops there"):
        res = est.run(None, y)
    k = res.info["stopped"]["step"]
    assert 5 <= k < 17 and "substeps" in res.info["stopped"]["reason"]
    assert np.all(np.isnan(res.lower[k:])) and np.all(np.isfinite(res.lower[:k]))
    t = 0.1 * np.arange(k)
    for x0 in (0.5, 0.6):
        exact = 1.0 / (1.0 / x0 - t)
        assert np.all(res.lower[:k, 0] <= exact) and np.all(exact <= res.upper[:k, 0])
    with pytest.raises(ivobs.DivergenceError, match="substeps"):  # step(): the error itself
        for _ in range(30):
            est.step()
