"""
A small campaign: scenarios × methods × seeds
=============================================

A campaign runs a grid of jobs (one scenario, method, option set and seed each), appends each
finished job to a CSV table at once (an interrupted campaign resumes where it stopped), and
writes a Markdown summary. Here a small grid runs in this process (``workers=0``); the same
spec runs on local processes (the default) or a Dask cluster (``scheduler=``). From the command
line: ``ivobs campaign grid.toml``.
"""

# %%
import tempfile
from pathlib import Path

from ivobs import campaign

folder = Path(tempfile.mkdtemp())
(folder / "grid.toml").write_text("""
name = "two fast methods, vertex disturbances"
scenarios = ["servo-motor", "dinh2019"]
methods = ["interval-split", "zonotope"]
seeds = [0, 1, 2]
disturbance = "vertex"
horizon = 60
burn_in = 6
output = "results.csv"
""")
spec = campaign.load_spec(folder / "grid.toml")
print(len(spec.jobs()), "jobs; the first id:", spec.jobs()[0].id)

# %%
res = campaign.run_campaign(spec, workers=0, progress=False)
print(
    "ran",
    res.ran,
    "skipped",
    res.skipped,
    "failed",
    res.count("failed"),
    "violations",
    res.violations,
)
assert not res.violations  # no box missed the true state

# %%
# Run again: every job is already in the table, nothing is recomputed.
again = campaign.run_campaign(spec, workers=0, progress=False)
print("ran", again.ran, "skipped", again.skipped)

# %%
# The summary, in Markdown (mean widths over the seeds, containment, times):
print(res.summary())
