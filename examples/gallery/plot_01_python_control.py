"""
A python-control plant, from model to DataFrame, figure and HTML report
=======================================================================

The notebook path: build a plant with python-control, mark one input as a bounded unknown
disturbance, estimate its state with a guaranteed method, look at the result as a
``pandas.DataFrame`` and as a figure, and write an interactive HTML comparison.
"""

# %%
# The plant: a DC servo motor (angle, speed, current) in continuous time, with a known voltage
# input ``V`` and an unknown load torque ``tau`` bounded by 0.05. python-control names the
# states and inputs; ivobs keeps the names.
import control
import numpy as np

import ivobs

A = np.array([[0.0, 1.0, 0.0], [0.0, -1.6, 5.0], [0.0, -0.4, -0.05]])
B = np.array([[0.0, 0.0], [0.0, -1.0], [0.75, 0.0]])
C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
ss = control.ss(
    A, B, C, 0, states=["theta", "omega", "i"], inputs=["V", "tau"], outputs=["theta_m", "omega_m"]
)
sys = ivobs.LinearSystem.from_statespace(
    ss, disturbances=["tau"], d=ivobs.Box([-0.05], [0.05])
).discretize(0.1)
sys

# %%
# A record: 150 steps with the disturbance on the vertices of its bounds (the hardest case for
# a guaranteed method), from a prior box on ``x[0]``.
x0 = ivobs.Box([-0.2] * 3, [0.2] * 3)
U = np.full((150, 1), 2.0)
traj = ivobs.simulate(
    sys, x0=[0.05, -0.1, 0.0], u=U, d=ivobs.vertex_disturbance(sys.d, 150, seed=0)
)

# %%
# Estimate. ``reachability`` designs an H∞ gain once, then runs the recursion; every box
# contains the true state.
est = ivobs.make_estimator("reachability", sys, x0=x0)
res = est.run(traj.u, traj.y)
assert res.contains(traj.x).all()
res

# %%
# A tidy DataFrame: one row per step and state, with the truth when given.
df = res.to_pandas(truth=traj)
df.head()

# %%
df.groupby("state")["width"].describe()

# %%
# The figure: bounds and true state.
ax = res.plot(truth=traj.x)

# %%
# An interactive comparison with a second method, as a self-contained HTML page (plotly; open
# it in a browser, zoom into the bands).
import tempfile
from pathlib import Path

from ivobs.report.html import html_report

other = ivobs.make_estimator("interval-split", sys, x0=x0).run(traj.u, traj.y)
page = html_report(
    Path(tempfile.mkdtemp()) / "comparison.html",
    {"reachability": res, "interval-split": other},
    title="servo: two methods",
    truth=traj.x,
)
print(page.name, page.stat().st_size // 1024, "kB")
