"""A disturbance that varies between samples: the held model loses the state, the default
(varying) model keeps it (docs/continuous.md). Writes docs/img/continuous_held_vs_varying.png.

A lightly damped oscillator ``x'' = -x - 0.04 x' + d`` sampled every quarter period, its
position measured (noise ±0.01), the force ``|d| <= 1`` switching sign eight times per sample
to pump energy in. The simulator is written here: exact matrix exponentials per constant piece.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.linalg import expm

import ivobs

A = np.array([[0.0, 1.0], [-1.0, -0.04]])
Ts, switches, T = np.pi / 2, 8, 40
plant = ivobs.LinearSystem(
    A, None, [[1.0, 0.0]], E=[[0.0, 0.0], [1.0, 0.0]], F=[[0.0, 1.0]],
    d=ivobs.Box([-1.0, -0.01], [1.0, 0.01]), dt=0,
)  # fmt: skip

rng = np.random.default_rng(1)
Ph = expm(A * Ts / switches)
gh = np.linalg.solve(A, Ph - np.eye(2)) @ np.array([0.0, 1.0])
x, xs, ys = np.array([0.5, -0.3]), [], []
for _ in range(T):
    xs.append(x.copy())
    ys.append([x[0] + 0.01 * rng.choice([-1.0, 1.0])])
    for _ in range(switches):
        x = Ph @ x + gh * (1.0 if x[1] >= 0 else -1.0)
xs, ys = np.array(xs), np.array(ys)

x0 = ivobs.Box([0.0, -1.0], [1.0, 1.0])
held = ivobs.make_estimator("exact", plant.discretize(Ts, disturbances="held"), x0=x0).run(y=ys)
varying = ivobs.make_estimator("exact", plant.discretize(Ts), x0=x0).run(y=ys)


def outside(res: ivobs.Estimate) -> int:
    return int(np.sum(np.any((xs < res.lower) | (xs > res.upper), axis=1)))


print(f"held model:    true state outside the box at {outside(held)} of {T} samples")
print(f"varying model: true state outside the box at {outside(varying)} of {T} samples")

if __name__ == "__main__":
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.4), sharey=True)
    k = np.arange(T)
    for ax, res, title in [
        (axes[0], held, 'disturbances="held"'),
        (axes[1], varying, 'disturbances="varying" (default)'),
    ]:
        ax.fill_between(k, res.lower[:, 1], res.upper[:, 1], step="mid", alpha=0.3,
                        label="exact: velocity box")  # fmt: skip
        miss = (xs[:, 1] < res.lower[:, 1]) | (xs[:, 1] > res.upper[:, 1])
        ax.plot(k, xs[:, 1], "k.-", lw=0.8, label="true velocity")
        ax.plot(k[miss], xs[miss, 1], "rx", ms=8, label="outside the box")
        ax.set_title(title)
        ax.set_xlabel("sample k (Ts = quarter period)")
        ax.set_ylim(-1.2 * np.abs(xs[:, 1]).max(), 1.2 * np.abs(xs[:, 1]).max())
    axes[0].set_ylabel("velocity")
    axes[1].legend(loc="lower left", fontsize=8)
    fig.tight_layout()
    out = Path(__file__).resolve().parents[1] / "docs" / "img" / "continuous_held_vs_varying.png"
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")
