"""
A nonlinear plant: the Hénon map with an uncertain parameter
============================================================

:class:`ivobs.NonlinearSystem` takes the model as expressions (or a Python callable traced
into expressions), with bounded unknown parameters and disturbances; ``nl-interval`` encloses
the state by interval arithmetic with outward rounding, contracted by the measurements
(docs/nonlinear.md). Here the Hénon map of [Efimov2013, Section IV.B] with ``a`` known to
±0.01 and varying at every step, and only ``x2`` measured.
"""

# %%
import numpy as np

import ivobs

sys = ivobs.NonlinearSystem(
    f=["1 - a*x1**2 + x2 + w1", "b*x1"],
    h=["x2 + v1"],
    states=["x1", "x2"],
    inputs=[],
    params={"a": (1.39, 1.41), "b": 0.3},  # a pair: unknown in its bounds; a number: known
    d={"w1": (-0.005, 0.005), "v1": (-0.02, 0.02)},
    dt=True,
)
x0 = ivobs.Box([0.2, 0.0], [0.4, 0.2])

# %%
# A record, simulated here with ``a``, ``w1`` and ``v1`` drawn on the vertices of their bounds.
rng = np.random.default_rng(0)
T = 200
x = np.empty((T, 2))
x[0] = [0.3, 0.1]
a = rng.choice([1.39, 1.41], T)
w = rng.choice([-0.005, 0.005], T)
v = rng.choice([-0.02, 0.02], T)
for k in range(T - 1):
    x[k + 1] = [1 - a[k] * x[k, 0] ** 2 + x[k, 1] + w[k], 0.3 * x[k, 0]]
y = (x[:, 1] + v)[:, None]

# %%
est = ivobs.make_estimator("nl-interval", sys, x0=x0)
res = est.run(None, y)
assert res.contains(x).all()
print("mean width after 20 steps:", np.round(res.mean_width(burn_in=20), 4))

# %%
ax = res.plot(truth=x)
