"""
Comparing methods: bounds relative to the truth, and widths over time
=====================================================================

Overlaying every method's band on a state that grows (the servo's angle θ goes from 0 to about
37 rad) collapses all bands into one line. The comparison figure plots instead each method's
bounds **minus the true state** (left; minus the tightest method's centre when there is no
truth) and the widths on a log scale (right), so every band stays visible on every state. The
same figure and an interactive HTML page come from ``ivobs compare servo-motor --plot F --html
P``.
"""

# %%
import ivobs
from ivobs.report import compare, markdown_table
from ivobs.report.compare_figure import comparison_figure

sc = ivobs.scenarios.get("servo-motor")
traj, results = compare(
    sc, ["exact", "reachability", "zonotope", "interval-split"], disturbance="vertex", seed=0
)
print(markdown_table(results, ["θ", "n", "i"], reference="exact"))

# %%
# ``exact`` is the linear-programming reference: the tightest box any method could give from
# the same data. Every method contains it, and the ratios above say how far each is from it.
estimates = {r.method: r.estimate for r in results}
fig = comparison_figure(
    estimates, truth=traj.x, state_names=["θ", "n", "i"], title="servo motor, vertex disturbances"
)
