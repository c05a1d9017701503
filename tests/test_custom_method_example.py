"""The worked example of docs/architecture.md (examples/custom_method.py) is a real method: it
registers, is sound under vertex disturbances (checked with this test's own simulator), keeps
its online state typed and round-trips it. Run in a subprocess so that its registration does not
leak into the other tests' list of methods."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parents[1] / "examples"

SCRIPT = r"""
import json, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
import custom_method  # registers "measured-state-predictor"
import ivobs
import ivobs.testing

assert "measured-state-predictor" in ivobs.methods()
report = ivobs.testing.check_estimator(custom_method.MeasuredStatePredictor, steps=60)
assert report.checked, report.skipped
rng = np.random.default_rng(7)
A = np.array([[0.9, 0.2, 0.0], [-0.1, 0.8, 0.3], [0.0, 0.1, 0.7]])
B = np.array([[0.0], [1.0], [0.5]])
C = np.array([[2.0, 0.0, 0.0], [0.0, 1.0, 1.0]])
E, F = np.eye(3)[:, :2], np.array([[0.0, 0.0], [0.0, 0.0]])
sys_ = ivobs.LinearSystem(A, B, C, E=np.hstack([E, np.zeros((3, 1))]),
                          F=np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.5]]),
                          d=ivobs.Box([-0.1, -0.2, -0.05], [0.1, 0.3, 0.05]))
x0 = ivobs.Box([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0])
T = 300
d_lo, d_hi = sys_.d.lo, sys_.d.hi
x = rng.choice([-1.0, 1.0], 3)  # a vertex of x0
X, Y, U = [], [], rng.uniform(-1, 1, (T, 1))
for k in range(T):  # independent simulator, disturbances on the vertices of their box
    d = np.where(rng.random(3) < 0.5, d_lo, d_hi)
    X.append(x.copy())
    Y.append(C @ x + sys_.F @ d)
    x = A @ x + B @ U[k] + sys_.E @ d
X, Y = np.array(X), np.array(Y)
est = ivobs.make_estimator("measured-state-predictor", sys_, x0=x0)
assert est.design.rows == ((0, 0, 2.0),)
res = est.run(U, Y)
assert np.all(res.lower <= X) and np.all(X <= res.upper), "missed the true state"
assert np.all(res.width[:, 0] <= 0.3 + 1e-9)  # the measured state: |F d| / 2 at most
est.reset()
for k in range(150):
    est.step(U[k], Y[k])
saved = json.loads(json.dumps(est.state()))
assert saved["version"] == 2 and saved["state"]["k"] == 150
other = ivobs.make_estimator("measured-state-predictor", sys_, x0=x0)
other.restore(saved)
rest = np.array([other.step(U[k], Y[k]).hi for k in range(150, T)])
assert np.array_equal(rest, res.upper[150:]), "restore does not continue identically"
print("ok")
"""


def test_worked_example_is_a_sound_method_with_a_typed_state() -> None:
    out = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(EXAMPLE)], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().endswith("ok")
