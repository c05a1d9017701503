"""Simulation and disturbance generators."""

import numpy as np
import pytest

import ivobs
from ivobs import Box, IvobsError, LinearSystem, simulate


def _sys():
    A = np.array([[0.9, 0.2], [-0.1, 0.7]])
    return LinearSystem(
        A,
        [[1.0], [0.0]],
        [[1.0, 1.0]],
        D=[[0.5]],
        E=[[0.1, 0], [0, 0.2]],
        F=[[0.0, 1.0]],
        d=Box([-1.0, 0.0], [1.0, 2.0]),
    )


def test_discrete_simulation_follows_the_model():
    s = _sys()
    T = 20
    rng = np.random.default_rng(0)
    u = rng.normal(size=(T, 1))
    d = ivobs.uniform_disturbance(s.d, T, seed=1)
    tr = simulate(s, [1.0, -1.0], u, d)
    assert tr.x.shape == (T, 2) and tr.y.shape == (T, 1) and tr.T == T
    x = np.array([1.0, -1.0])
    for k in range(T):
        np.testing.assert_allclose(tr.x[k], x)
        np.testing.assert_allclose(tr.y[k], s.C @ x + s.D @ u[k] + s.F @ d[k])
        x = s.A @ x + s.B @ u[k] + s.E @ d[k]


def test_generators_stay_in_bounds_and_vertex_hits_vertices():
    box = Box([-1.0, 0.0], [1.0, 2.0])
    for kind in ["sinusoidal", "uniform", "vertex", "zero"]:
        d = ivobs.disturbance(kind, box, 300, seed=3)
        assert d.shape == (300, 2) and box.contains(d).all()
    v = ivobs.vertex_disturbance(box, 300, seed=3)
    assert set(np.unique(v[:, 0])) == {-1.0, 1.0} and set(np.unique(v[:, 1])) == {0.0, 2.0}
    held = ivobs.vertex_disturbance(box, 40, seed=3, hold=10)
    assert np.all(held[:10] == held[0]) and np.all(held[10:20] == held[10])
    np.testing.assert_array_equal(
        ivobs.vertex_disturbance(box, 50, seed=7), ivobs.vertex_disturbance(box, 50, seed=7)
    )
    with pytest.raises(IvobsError, match="unknown disturbance kind"):
        ivobs.disturbance("gaussian", box, 10)


def test_state_dependent_disturbance_and_bound_check():
    s = _sys()
    tr = simulate(s, [0.0, 0.0], np.zeros((10, 1)), lambda k, x: np.array([np.tanh(x[0]), 1.0]))
    assert tr.d.shape == (10, 2) and np.all(tr.d[:, 1] == 1.0)
    with pytest.raises(IvobsError, match="step 3 leaves its bounds in component 1"):
        d = np.ones((10, 2))
        d[3, 1] = 2.5
        simulate(s, [0.0, 0.0], np.zeros((10, 1)), d)
    d = np.ones((10, 2))
    d[3, 1] = 2.5
    simulate(s, [0.0, 0.0], np.zeros((10, 1)), d, check_bounds=False)


def test_bad_signals():
    s = _sys()
    with pytest.raises(IvobsError, match=r"u: expected shape \(T, 1\)"):
        simulate(s, [0, 0], np.zeros((5, 2)), None, T=5)
    with pytest.raises(IvobsError, match="x0: expected a vector of length 2"):
        simulate(s, [0, 0, 0], np.zeros((5, 1)))
    with pytest.raises(IvobsError, match="T: give the number of steps"):
        simulate(LinearSystem(np.eye(1) * 0.5, C=[[1.0]]), [0.0])


def test_continuous_time_zoh_matches_ode_integration():
    Ac = np.array([[0.0, 1.0], [-2.0, -0.5]])
    s = LinearSystem(Ac, [[0.0], [1.0]], [[1.0, 0.0]], E=[[0.0], [1.0]], d=Box([-1], [1]), dt=0)
    t = np.linspace(0, 5, 251)
    u = np.sin(t)[:, None]
    d = ivobs.vertex_disturbance(s.d, t.size, seed=0)
    exact = simulate(s, [1.0, 0.0], u, d, t=t)
    # the same held signals integrated by the ODE solver (callable d forces that path)
    idx = lambda tt: min(int(np.searchsorted(t, tt, side="right")) - 1, t.size - 1)  # noqa: E731
    ode = simulate(s, [1.0, 0.0], lambda tt: u[idx(tt)], lambda tt, x: d[idx(tt)], t=t)
    np.testing.assert_allclose(exact.x, ode.x, atol=1e-6)
    with pytest.raises(IvobsError, match="needs the sample times"):
        simulate(s, [1.0, 0.0], u, d)
