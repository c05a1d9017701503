"""
Data interop: pandas and xarray in, pandas and xarray out
=========================================================

A log can come from a ``pandas.DataFrame`` (columns ``k`` or ``t``, ``u1..``, ``y1..``; NaN is a
missing sample), and an :class:`~ivobs.Estimate` exports to a tidy DataFrame (one row per step
and state) or to an ``xarray.Dataset``. The bounds CSV written by ``Estimate.to_csv`` reads
back with ``Estimate.from_csv``.
"""

# %%
import numpy as np
import pandas as pd

import ivobs
from ivobs.io import log_from_frame

sc = ivobs.scenarios.get("dinh2019")
traj = sc.simulate(seed=3)
frame = pd.DataFrame({"k": np.arange(len(traj.y))})
for j in range(sc.system.nu):
    frame[f"u{j + 1}"] = traj.u[:, j]
frame["y1"] = traj.y[:, 0]
frame.loc[10:12, "y1"] = np.nan  # three missing samples
log = log_from_frame(frame, sc.system)
res = ivobs.make_estimator("fixed-time", sc.system).run(log.u, log.y)
print(int(res.missing.sum()), "missing samples; bounds valid from step", res.valid_from)

# %%
# Tidy: one row per step and state. Filter, group, pivot as usual.
df = res.to_pandas(truth=traj, names=["position", "speed"])
df[df.k.between(8, 14) & (df.state == "position")]

# %%
df[df.k >= res.valid_from].groupby("state")[["width"]].agg(["mean", "max"])

# %%
# xarray: ``lower``, ``upper`` and ``truth`` over ``(k, state)``.
ds = res.to_xarray(truth=traj, names=["position", "speed"])
ds

# %%
(ds.upper - ds.lower).sel(state="speed").plot()
