"""
Dinh & Tran 2024: KKL interval observers for time-varying systems
=================================================================

[Dinh2024] transforms the state into coordinates where the observer is a stable linear filter
(a Sylvester / KKL transformation), bounds the error there, and maps the bounds back. Its third
example is a discrete-time linear time-varying system whose matrix has cosine and sine entries.
"""

# %%
import numpy as np

import ivobs

sc = ivobs.scenarios.get("kkl-ltv-dt")
print(sc.description)
traj = sc.simulate()
res = ivobs.make_estimator("kkl", sc.system, x0=sc.x0).run(traj.u, traj.y)
assert res.contains(traj.x).all()
print("valid from step", res.valid_from, "; mean width", np.round(res.mean_width(burn_in=3), 4))

# %%
# The paper's Fig. 5 (state ``x2``, without and with disturbances), redrawn:
from ivobs.report.figures import dinh2024_fig5

fig = dinh2024_fig5()
