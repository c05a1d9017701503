"""
Efimov et al. 2013: interval observers without a nonnegative A − LC
===================================================================

[Efimov2013] designs interval observers for systems where no gain makes ``A − LC``
nonnegative: a change of coordinates (Theorem 2, ``interval-transformed``) or a split of the
observer matrix into positive and negative parts (Theorem 3, ``interval-split``). Its Hénon-map
example has an uncertain parameter whose bounds are computed from the measurement (Remark 1).
"""

# %%
import numpy as np

import ivobs

sc = ivobs.scenarios.get("efimov-planar")
print(sc.description)
traj = sc.simulate()
for method in ["interval-transformed", "interval-split"]:
    res = ivobs.make_estimator(method, sc.system, x0=sc.x0).run(traj.u, traj.y)
    assert res.contains(traj.x).all()
    print(f"{method:22s} mean width {np.round(res.mean_width(burn_in=5), 4)}")

# %%
# The planar system, the paper's Fig. 1 redrawn:
from ivobs.report.figures import efimov2013_fig1, efimov2013_fig2

fig = efimov2013_fig1()

# %%
# The Hénon map with the uncertain ``a(t)`` (Fig. 2):
fig = efimov2013_fig2()
