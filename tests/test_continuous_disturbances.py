"""Continuous-time plants whose disturbances vary between samples (``discretize(Ts)``'s
default, :mod:`ivobs.model.sampling` and the differential inclusion of
:class:`~ivobs.model.nonlinear.flow.FlowSystem`).

The plants are simulated in the tests (``tests/ctsim.py``), not by ivobs: linear ones with
exact matrix exponentials (SciPy's ``expm``) per constant piece of ``d``, nonlinear ones with
``solve_ivp`` (DOP853, ``rtol = 1e-12``) per piece; ``d`` switches sign many times inside each
sampling period, its sign chosen to push the state outward (the held model's blind spot).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.linalg import expm
from scipy.optimize import linprog

import ivobs
from ctsim import (
    A_OSC,
    SWITCHES,
    T_OSC,
    TS_OSC,
    X0_BOX,
    misses,
    nl_oscillator,
    nl_vdp,
    osc_rhs,
    oscillator,
    simulate_nl,
    simulate_oscillator,
    vdp_rhs,
)
from ivobs.errors import IvobsError

# every linear method but interval (no gain makes this plant's A - LC nonnegative)
LINEAR = [m for m in ivobs.methods() if not m.startswith("nl-") and m != "interval"]


@pytest.mark.parametrize("method", LINEAR)
def test_linear_methods_contain_a_switching_disturbance(method: str) -> None:
    xs, ys = simulate_oscillator()
    sd = oscillator().discretize(TS_OSC)
    res = ivobs.make_estimator(method, sd, x0=X0_BOX).run(y=ys)
    # the simulator's own rounding (expm, 64 products) is far below 1e-12 on states of size 10
    assert misses(res, xs, 1e-12) == 0
    assert not np.any(res.inconsistent)


def test_the_held_model_loses_the_state_and_the_varying_one_is_tight() -> None:
    """The held model is wrong for this plant (``exact`` on it leaves the true state at most
    samples and flags true measurements); the varying model is sound and ``exact`` on it keeps
    the velocity within 1.5 (its disturbance alone moves it by up to ±1 a period)."""
    xs, ys = simulate_oscillator()
    held_sys = oscillator().discretize(TS_OSC, disturbances="held")
    held = ivobs.make_estimator("exact", held_sys, x0=X0_BOX)
    res_held = held.run(y=ys)
    assert misses(res_held, xs) > T_OSC // 2 and np.sum(res_held.inconsistent) > 10
    sd = oscillator().discretize(TS_OSC)
    assert sd.sampling == {"Ts": TS_OSC, "disturbances": "varying", "pieces": 8, "moments": False}
    res = ivobs.make_estimator("exact", sd, x0=X0_BOX).run(y=ys)
    assert misses(res, xs, 1e-12) == 0
    # measured 1.31 (the held model's estimate, having lost the state: about 24)
    width = np.mean(res.width[T_OSC // 2 :, 1])
    assert width < 1.5, width


def test_more_pieces_tighten() -> None:
    xs, ys = simulate_oscillator(2)
    widths = []
    for n in (1, 2, 4, 8):
        sd = oscillator().discretize(TS_OSC, pieces=n)
        assert sd.nd == 2 + (n - 1) + 2  # the sample, the pieces' means, two remainders
        res = ivobs.make_estimator("constrained-zonotope", sd, x0=X0_BOX).run(y=ys)
        assert misses(res, xs, 1e-12) == 0
        widths.append(float(np.mean(res.width[T_OSC // 2 :, 1])))
    assert widths == sorted(widths, reverse=True) and widths[-1] < 0.7 * widths[0], widths


def assert_in_model_set(sd: ivobs.LinearSystem, target: np.ndarray) -> None:
    """``E_d ξ = target`` (within the simulator's rounding) for some ``ξ`` in the sampled
    model's box: a feasibility LP over its disturbances."""
    Ed = np.asarray(sd.E)
    tol = 1e-11 * (1.0 + np.abs(target))
    res = linprog(
        np.zeros(Ed.shape[1]),
        A_ub=np.vstack([Ed, -Ed]),
        b_ub=np.concatenate([target + tol, -target + tol]),
        bounds=list(zip(sd.d.lo, sd.d.hi)),
        method="highs",
    )
    assert res.status == 0, res.message


@pytest.mark.parametrize("seed", range(6))
def test_one_period_lies_in_the_model_zonotope(seed: int) -> None:
    """For random plants and disturbances switching 64 times in a period, ``x(Ts) −
    A_d x0`` is a point of ``E_d [d]`` (a feasibility LP over the model's disturbances)."""
    rng = np.random.default_rng(seed)
    n, m = 3, 2
    A = rng.normal(size=(n, n))
    E = rng.normal(size=(n, m))
    lo = -rng.uniform(0.1, 1.0, m) + rng.uniform(-0.3, 0.3, m)  # asymmetric bounds
    hi = lo + rng.uniform(0.2, 2.0, m)
    Ts = float(rng.uniform(0.05, 0.6))
    sys = ivobs.LinearSystem(A, None, np.eye(1, n), E=E, d=ivobs.Box(lo, hi), dt=0)
    sd = sys.discretize(Ts)
    pieces = 64
    Ph = expm(A * Ts / pieces)
    G = np.linalg.solve(A, Ph - np.eye(n)) @ E
    for _ in range(4):
        x0 = rng.normal(size=n)
        x = x0.copy()
        for _ in range(pieces):
            d = np.where(rng.random(m) < 0.5, lo, hi) if rng.random() < 0.8 else rng.uniform(lo, hi)
            x = Ph @ x + G @ d
        assert_in_model_set(sd, x - sd.A @ x0)


def test_first_moments_lie_in_the_model_zonotope() -> None:
    """An unstable plant sampled slowly: the automatic choice takes the pieces' first moments
    as generators too; one period of a switching ``d`` is a point of the model's set."""
    g, l_ = 9.81, 0.5
    A = np.array([[0.0, 1.0, 0.0, 0.0], [0.0, 0.0, -0.981, 0.0], [0.0, 0.0, 0.0, 1.0],
                  [0.0, 0.0, 1.1 * g / l_, 0.0]])  # fmt: skip
    E = np.array([[0.0], [1.0], [0.0], [-1.0 / l_]])
    sys = ivobs.LinearSystem(A, None, np.eye(2, 4), E=E, d=ivobs.Box([-0.5], [0.5]), dt=0)
    sd = sys.discretize(0.1)
    assert sd.sampling["moments"] and sd.nd == 8 + 8 + 4
    rng = np.random.default_rng(11)
    pieces = 64
    Ph = expm(A * 0.1 / pieces)
    M = np.zeros((5, 5))  # A is singular: ∫ e^{As} ds E from the block exponential
    M[:4, :4], M[:4, 4:] = A, E
    G = expm(M * 0.1 / pieces)[:4, 4:]
    for _ in range(6):
        x0 = rng.normal(size=4)
        x = x0.copy()
        for _ in range(pieces):
            x = Ph @ x + G[:, 0] * rng.choice([-0.5, 0.5])
        assert_in_model_set(sd, x - sd.A @ x0)


def test_options_and_refusals() -> None:
    sys = oscillator()
    sd = sys.discretize(0.1, pieces=1)
    assert sd.nd == 2 + 2 and sd.sampling["pieces"] == 1
    # interval matrices contain the exact exponential; methods that accept them run
    si = sys.discretize(0.1, interval_matrices=True)
    assert si.is_uncertain
    box = si._boxes["A"][0]
    exact = expm(A_OSC * 0.1)
    assert np.all(box.lo <= exact) and np.all(exact <= box.hi)
    assert np.max(box.hi - box.lo) < 1e-13
    ivobs.make_estimator("reachability", si, x0=X0_BOX)
    # time-varying bounds: a remainder per step
    tv = ivobs.Box(np.array([[-1.0, -0.01]] * 5) * [[1], [2], [1], [2], [1]], [[1.0, 0.01]] * 5)
    stv = ivobs.LinearSystem(A_OSC, None, [[1.0, 0.0]], E=sys.E, F=sys.F, d=tv, dt=0).discretize(
        0.1, pieces=2
    )
    assert stv.d.is_time_varying and stv.d.lo.shape == (5, stv.nd)
    assert stv.d.hi[1, -1] > stv.d.hi[0, -1]  # a wider d, a wider remainder
    for kwargs, match in [
        ({"disturbances": "sometimes"}, "disturbances: expected 'varying'"),
        ({"pieces": 3}, "pieces: expected None or a power of two"),
        ({"interval_matrices": 1}, "interval_matrices: expected True or False"),
    ]:
        with pytest.raises(IvobsError, match=match):
            sys.discretize(0.1, **kwargs)
    measured = ivobs.LinearSystem(
        A_OSC, None, [[1.0, 0.0]], E=[[0.0], [1.0]], d=lambda k, y: ivobs.Box([-1.0], [1.0]), dt=0
    )
    with pytest.raises(IvobsError, match="disturbances='held'"):
        measured.discretize(0.1)
    measured.discretize(0.1, disturbances="held")


def test_a_disturbance_in_both_equations_gets_its_own_means() -> None:
    """``d`` in ``E`` and ``F``: the measurement sees the sample, the state its means."""
    sys = ivobs.LinearSystem(
        A_OSC, None, [[1.0, 0.0]], E=[[0.0], [1.0]], F=[[0.1]], d=ivobs.Box([-1.0], [1.0]), dt=0
    )
    sd = sys.discretize(0.2, pieces=2)
    assert sd.nd == 1 + 2 + 2  # the sample, two means, two remainders
    assert np.all(np.asarray(sd.E)[:, 0] == 0.0) and np.asarray(sd.F)[0, 0] == 0.1
    assert np.all(np.asarray(sd.F)[0, 1:] == 0.0)


# -- nonlinear -------------------------------------------------------------------------------


NL = ["nl-interval", "nl-zonotope", "nl-constrained-zonotope"]
MARGIN = 1e-8  # the integrator's error over these short, smooth flows is far below it


@pytest.mark.parametrize("method", NL)
def test_nonlinear_methods_contain_a_switching_disturbance(method: str) -> None:
    xs, ys = simulate_nl(vdp_rhs, [1.0, 0.5], 0.1, 40)
    sd = nl_vdp().discretize(0.1)
    res = ivobs.make_estimator(method, sd, x0=ivobs.Box([0.9, 0.4], [1.1, 0.6])).run(y=ys)
    assert misses(res, xs, MARGIN) == 0 and not np.any(res.inconsistent)


def test_nonlinear_oscillator_held_misses_varying_contains() -> None:
    xs, ys = simulate_nl(osc_rhs, [0.5, -0.3], TS_OSC, 24)
    held = nl_oscillator().discretize(TS_OSC, disturbances="held")
    res = ivobs.make_estimator("nl-constrained-zonotope", held, x0=X0_BOX).run(y=ys)
    assert misses(res, xs, MARGIN) > 0
    sd = nl_oscillator().discretize(TS_OSC)
    for method in NL:
        res = ivobs.make_estimator(method, sd, x0=X0_BOX).run(y=ys)
        assert misses(res, xs, MARGIN) == 0 and not np.any(res.inconsistent), method


def test_flow_box_contains_switching_paths() -> None:
    """``f_box`` of the varying flow contains every path from the box whatever ``d(t)`` does
    (signs switched on 8 pieces, all 2^8 patterns from the corners of the box)."""
    sd = nl_vdp().discretize(0.2, substeps=2)
    xl, xh = [0.9, 0.4], [1.1, 0.6]
    lo, hi = sd.f_box(xl, xh, [], sd.w_box.lo, sd.w_box.hi)
    held = nl_vdp().discretize(0.2, substeps=2, disturbances="held")
    hlo, hhi = held.f_box(xl, xh, [], held.w_box.lo, held.w_box.hi)
    assert np.all(hi - lo <= 1.5 * (hhi - hlo))  # not much wider on this short period
    h = 0.2 / 8
    for corner in [(0.9, 0.4), (0.9, 0.6), (1.1, 0.4), (1.1, 0.6)]:
        for pattern in range(0, 256, 7):
            x = np.array(corner)
            for j in range(8):
                d = 1.0 if (pattern >> j) & 1 else -1.0
                x = solve_ivp(
                    lambda t, z, d=d: vdp_rhs(z, d), (0.0, h), x, method="DOP853",
                    rtol=1e-12, atol=1e-13,
                ).y[:, -1]  # fmt: skip
            assert np.all(lo - MARGIN <= x) and np.all(x <= hi + MARGIN)


def test_nonlinear_options_round_trip(tmp_path) -> None:
    import pickle

    sd = nl_vdp().discretize(0.1, disturbances="held")
    assert sd.spec()["discretize"]["disturbances"] == "held"
    back = pickle.loads(pickle.dumps(sd))
    assert back.disturbances == "held"
    ivobs.save_system(tmp_path / "vdp.toml", sd, x0=ivobs.Box([0.9, 0.4], [1.1, 0.6]))
    text = (tmp_path / "vdp.toml").read_text()
    assert 'disturbances = "held"' in text
    loaded = ivobs.load_system(tmp_path / "vdp.toml").system
    assert loaded.disturbances == "held"
    bad = text.replace('disturbances = "held"', 'disturbances = "often"')
    (tmp_path / "bad.toml").write_text(bad)
    with pytest.raises(IvobsError, match="system.discretize: disturbances: expected 'varying'"):
        ivobs.load_system(tmp_path / "bad.toml")
    with pytest.raises(IvobsError, match="disturbances: expected 'varying'"):
        nl_vdp().discretize(0.1, disturbances="sometimes")


# -- between samples -------------------------------------------------------------------------


def test_kkl_on_the_continuous_plant_contains_a_switching_disturbance() -> None:
    """``kkl`` takes the ``dt=0`` system itself (its flows between samples cover any ``d(t)``)."""
    xs, ys = simulate_oscillator()
    est = ivobs.make_estimator("kkl", oscillator(), x0=X0_BOX)
    res = est.run(y=ys, t=TS_OSC * np.arange(T_OSC))
    assert misses(res, xs, 1e-12) == 0


def fine_oscillator(seed: int = 4, T: int = 30, Ts: float = 0.6, inner: int = 6):
    """Samples every ``Ts`` and, between them, the state at ``inner`` times of each of
    ``SWITCHES`` pieces (exact exponentials), with an input held per period."""
    rng = np.random.default_rng(seed)
    A = A_OSC
    B = np.array([0.0, 1.0])
    h = Ts / SWITCHES
    x = np.array([0.5, -0.3])
    xs, ys, us, paths = [], [], [], []
    for k in range(T):
        xs.append(x.copy())
        ys.append([x[0] + 0.01 * rng.choice([-1.0, 1.0])])
        u = np.sin(0.3 * k)
        us.append([u])
        path = [x.copy()]
        for _ in range(SWITCHES):
            d = 1.0 if x[1] >= 0 else -1.0
            for s in np.linspace(h / inner, h, inner):
                P = expm(A * s)
                path.append(P @ x + np.linalg.solve(A, P - np.eye(2)) @ (B * (u + d)))
            x = path[-1]
        paths.append(np.array(path))
    return np.array(xs), np.array(ys), np.array(us), paths


def test_between_samples_linear() -> None:
    Ts = 0.6
    xs, ys, us, paths = fine_oscillator(Ts=Ts)
    plant = ivobs.LinearSystem(
        A_OSC, [[0.0], [1.0]], [[1.0, 0.0]], E=[[0.0, 0.0], [1.0, 0.0]], F=[[0.0, 1.0]],
        d=ivobs.Box([-1.0, -0.01], [1.0, 0.01]), dt=0,
    )  # fmt: skip
    res = ivobs.make_estimator("exact", plant.discretize(Ts), x0=X0_BOX).run(us, ys)
    assert misses(res, xs, 1e-12) == 0
    tube = ivobs.between_samples(plant, res, us, Ts=Ts)
    assert tube.method == "exact (between samples)" and tube.info["Ts"] == Ts
    for k, path in enumerate(paths):
        assert np.all(tube.lower[k] - 1e-12 <= path) and np.all(path <= tube.upper[k] + 1e-12), k
    # it contains the sample boxes and is not much wider than the state's range in a period
    assert np.all(tube.lower <= res.lower) and np.all(res.upper <= tube.upper)
    span = np.mean([np.ptp(p[:, 1]) for p in paths[10:]])
    assert np.mean(tube.width[10:, 1]) <= 2.5 * span + np.mean(res.width[10:, 1])
    # the estimate of a sampled model carries its times k Ts: the period is read from them
    inferred = ivobs.between_samples(plant, res, us)
    assert inferred.info["Ts"] == pytest.approx(Ts)
    np.testing.assert_allclose(inferred.upper, tube.upper, rtol=1e-9)
    res.t = None
    with pytest.raises(IvobsError, match="Ts: give the sampling period"):
        ivobs.between_samples(plant, res, us)
    with pytest.raises(IvobsError, match="continuous-time plant"):
        ivobs.between_samples(plant.discretize(Ts), res, us, Ts=Ts)
    with pytest.raises(IvobsError, match="u: expected 30 samples"):
        ivobs.between_samples(plant, res, us[:5], Ts=Ts)


def test_between_samples_nonlinear() -> None:
    Ts, T = 0.1, 25
    rng = np.random.default_rng(5)
    x = np.array([1.0, 0.5])
    xs, ys, paths = [], [], []
    for _ in range(T):
        xs.append(x.copy())
        ys.append([x[0] + 0.01 * rng.choice([-1.0, 1.0])])
        path = [x.copy()]
        for _ in range(SWITCHES):
            d = 1.0 if x[1] >= 0 else -1.0
            sol = solve_ivp(
                lambda t, z, d=d: vdp_rhs(z, d), (0.0, Ts / SWITCHES), x, method="DOP853",
                rtol=1e-12, atol=1e-13, t_eval=np.linspace(0.0, Ts / SWITCHES, 5),
            )  # fmt: skip
            path.extend(sol.y.T)
            x = sol.y[:, -1]
        paths.append(np.array(path))
    xs, ys = np.array(xs), np.array(ys)
    sd = nl_vdp().discretize(Ts)
    res = ivobs.make_estimator("nl-zonotope", sd, x0=ivobs.Box([0.9, 0.4], [1.1, 0.6])).run(y=ys)
    assert misses(res, xs, MARGIN) == 0
    for system in (sd, nl_vdp()):
        tube = ivobs.between_samples(system, res, Ts=Ts)
        for k, path in enumerate(paths):
            assert np.all(tube.lower[k] - MARGIN <= path) and np.all(path <= tube.upper[k] + MARGIN)
        assert np.all(tube.lower <= res.lower) and np.all(res.upper <= tube.upper)
