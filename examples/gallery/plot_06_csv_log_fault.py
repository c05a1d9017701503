"""
Your plant from files: a system file, a CSV log with a sensor fault, the monitor's alarm
========================================================================================

Operating on real data: the model lives in a TOML system file, the record in a CSV log (an
empty cell is a missing sample). The streaming monitor predicts, from the data before each
step, a band that the measurement must lie in; a measurement outside it **proves** a fault
(under the model's assumptions an alarm is never false). Here the angle sensor of the servo
motor gets a bias of 1 rad from step 60 on. The same on the command line:
``ivobs run --system servo.toml --log day1.csv`` and ``ivobs monitor --system servo.toml``.
"""

# %%
import tempfile
from pathlib import Path

import numpy as np

import ivobs
from ivobs.io import read_log, write_log
from ivobs.monitor import Monitor

folder = Path(tempfile.mkdtemp())
sc = ivobs.scenarios.get("servo-motor")
ivobs.save_system(folder / "servo.toml", sc, method="interval-split")
print("\n".join((folder / "servo.toml").read_text().splitlines()[:12]), "\n...")

# %%
# A record with a sensor fault (bias on ``y1`` from step 60) and two missing samples.
traj = sc.simulate(seed=1)
y = traj.y.copy()
y[60:, 0] += 1.0
y[[20, 21], 1] = np.nan
write_log(folder / "day1.csv", traj.u, y)
print("\n".join((folder / "day1.csv").read_text().splitlines()[:4]))

# %%
# Load both files and monitor the record step by step (exactly what ``ivobs monitor`` does
# with one CSV row at a time).
plant = ivobs.load_system(folder / "servo.toml")  # model, prior box, method, options
log = read_log(folder / "day1.csv", plant.system)
mon = Monitor(plant.system, plant.method, x0=plant.x0)
rec = mon.run(log.u, log.y)
print("first alarm at step", rec.first_alarm)
print(rec.reasons[rec.first_alarm])
for fault in rec.faults:
    print(f"fault from step {fault.start} on outputs {fault.names}, {fault.duration} steps")
assert rec.first_alarm is not None and rec.first_alarm >= 60

# %%
# The band of ``y1`` predicted at each step, the measurement, and the alarm. The estimate goes
# on from the fault-free outputs (``y1`` is excluded while the fault is open).
import matplotlib.pyplot as plt

k = np.arange(len(log.y))
fig, ax = plt.subplots(figsize=(8, 3.2))
ax.fill_between(k, rec.band_lower[:, 0], rec.band_upper[:, 0], alpha=0.3, label="predicted band")
ax.plot(k, log.y[:, 0], "k.", ms=3, label="y1 (biased from k = 60)")
ax.vlines(
    np.flatnonzero(rec.alarm), *ax.get_ylim(), color="tab:red", lw=0.4, alpha=0.4, label="alarm"
)
ax.set_xlabel("step k")
ax.legend(loc="upper left")
fig.tight_layout()
