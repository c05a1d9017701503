"""
Tang et al. 2019: the DC servo motor
====================================

The first example of [Tang2019] (Section VII): a DC servo motor with 3 states and 2 outputs,
process and measurement disturbances. Four guaranteed methods run on one record; the table
gives their mean widths, the figure redraws the paper's Fig. 2 (Algorithm 1 against the
zonotope observer with the gain ``L1``, and against the interval observer with ``L2``).
"""

# %%
import numpy as np

import ivobs
from ivobs.report import compare, markdown_table

sc = ivobs.scenarios.get("servo-motor")
print(sc.description)
traj, results = compare(sc, ["reachability", "zonotope", "interval", "interval-split"])
print(markdown_table(results, ["θ", "n", "i"]))

# %%
# Every method's box contains the true state at every step:
assert all(r.estimate.contains(traj.x).all() for r in results)
print({r.method: np.round(r.estimate.mean_width(burn_in=10), 4) for r in results})

# %%
# The paper's Fig. 2, with ivobs' methods (what differs from the paper: the figures page).
from ivobs.report.figures import tang2019_fig2

fig = tang2019_fig2()
