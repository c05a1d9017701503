"""
Wang et al. 2020: the fixed-time estimator
==========================================

[Wang2020] builds an interval estimator from a window of ``s + 1`` past measurements (parity
space), with a matrix ``T`` chosen optimally (Theorem 1). It needs no prior box on ``x[0]``:
the bounds are valid from step ``s`` on, whatever the initial state.
"""

# %%
import numpy as np

import ivobs

sc = ivobs.scenarios.get("dinh2019")
est = ivobs.make_estimator("fixed-time", sc.system, s=sc.reference["s"])
np.set_printoptions(precision=4, suppress=True)
print("T of Theorem 1:\n", est.design.T)
print("the paper's T:\n", np.asarray(sc.reference["T"]))

# %%
traj = sc.simulate()
res = est.run(traj.u, traj.y)
print("bounds valid from step", res.valid_from)
assert res.contains(traj.x).all()

# %%
# The paper's Fig. 1 (the bounds of ``x1``), redrawn:
from ivobs.report.figures import wang2020_fig1

fig = wang2020_fig1()
