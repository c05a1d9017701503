"""simulate_batch: many records at once, equal to simulate record by record."""

from __future__ import annotations

import numpy as np
import pytest

import ivobs
from ivobs import IvobsError


def test_batch_equals_simulate_record_by_record():
    sc = ivobs.scenarios.get("servo-motor")
    sys, B, T = sc.system, 7, 60
    rng = np.random.default_rng(0)
    x0 = sc.x0.lo + (sc.x0.hi - sc.x0.lo) * rng.random((B, 3))
    d = np.stack([ivobs.vertex_disturbance(sys.d, T, seed=s) for s in range(B)])
    u = rng.normal(size=(T, 1))  # shared by every record
    tr = ivobs.simulate_batch(sys, x0, u, d)
    assert tr.x.shape == (B, T, 3) and tr.y.shape == (B, T, 2) and tr.T == T
    for b in range(B):
        one = ivobs.simulate(sys, x0[b], u, d[b])
        np.testing.assert_allclose(tr.x[b], one.x, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(tr.y[b], one.y, rtol=1e-13, atol=1e-13)
    # a batch goes straight into run(), and every box contains its record's state
    est = ivobs.make_estimator("interval-split", sys, x0=sc.x0).run(tr.u, tr.y)
    assert est.lower.shape == (B, T, 3) and np.all(est.contains(tr.x))


def test_time_varying_and_errors():
    A = np.stack([[[0.5 + 0.01 * k]] for k in range(5)])
    sys = ivobs.LinearSystem(A, None, [[1.0]], E=[[1.0]], d=ivobs.Box([-1.0], [1.0]))
    tr = ivobs.simulate_batch(sys, [[1.0], [2.0]], d=np.zeros((5, 1)))
    np.testing.assert_allclose(tr.x[1, :, 0], 2 * np.cumprod([1, 0.5, 0.51, 0.52, 0.53]))
    with pytest.raises(IvobsError, match="leaves its bounds"):
        ivobs.simulate_batch(sys, [1.0], d=np.full((5, 1), 2.0))
    with pytest.raises(IvobsError, match="disagree on the number of records"):
        ivobs.simulate_batch(sys, np.zeros((3, 1)), d=np.zeros((2, 5, 1)))
    with pytest.raises(IvobsError, match="give the number of steps"):
        ivobs.simulate_batch(sys, [1.0])
    with pytest.raises(IvobsError, match=r"x0: expected finite \(B, 1\)"):
        ivobs.simulate_batch(sys, [[np.nan]], T=3)
