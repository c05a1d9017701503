"""
A continuous-time nonlinear plant: Van der Pol with uncertain damping, sampled
===============================================================================

Most plants are continuous-time and nonlinear. Here a Van der Pol oscillator
``p' = v``, ``v' = mu (1 - p²) v - p + 0.3 d`` whose damping ``mu`` is only known to lie in
``[0.9, 1.1]``, pushed by a force ``d(t)`` with ``|d| <= 1`` that changes sign several times
between two samples, and whose position is measured every ``Ts = 0.1`` s with noise ``|n| <= 0.01``.

``NonlinearSystem(..., dt=0)`` is the plant; ``discretize(Ts)`` encloses its validated flow over
one period for **every** ``d(t)`` in its bounds (a differential inclusion), so the set methods
``nl-constrained-zonotope`` and ``nl-zonotope`` give boxes that contain the state at the samples;
``ivobs.between_samples`` turns them into boxes that contain the state over each whole period
(docs/continuous.md).
"""

# %%
import matplotlib.pyplot as plt
import numpy as np
from scipy.integrate import solve_ivp

import ivobs

plant = ivobs.NonlinearSystem(
    f=["v", "mu*(1 - p**2)*v - p + 0.3*d"],  # x' = f(x, p, d)
    h=["p + n"],  # y[k] = h(x(t_k), n[k])
    states=["p", "v"],
    params={"mu": (0.9, 1.1)},  # unknown constant in its bounds
    d={"d": (-1.0, 1.0), "n": (-0.01, 0.01)},
    dt=0,  # continuous time
)
Ts = 0.1
sampled = plant.discretize(Ts)  # d varies between samples (the default)
sampled

# %%
# A record, simulated here (not by ivobs): ``mu = 1.07``, the force switches sign 8 times per
# period against the velocity (the hardest kind of signal for a model that would hold ``d``),
# 70 samples (7 s, about one cycle of the oscillator). ``fine`` keeps the path between samples.
rng = np.random.default_rng(0)
T, pieces, mu = 70, 8, 1.07


def rhs(t, z, d):
    return [z[1], mu * (1 - z[0] ** 2) * z[1] - z[0] + 0.3 * d]


x = np.empty((T, 2))
x[0] = [1.0, 0.5]
fine_t, fine_x = [], []
for k in range(T - 1):
    z = x[k]
    for j in range(pieces):
        d = 1.0 if z[1] >= 0 else -1.0
        t0 = (k + j / pieces) * Ts
        sol = solve_ivp(rhs, (t0, t0 + Ts / pieces), z, args=(d,), rtol=1e-10, atol=1e-12,
                        dense_output=True)  # fmt: skip
        tt = np.linspace(t0, t0 + Ts / pieces, 5)
        fine_t.append(tt)
        fine_x.append(sol.sol(tt).T)
        z = sol.y[:, -1]
    x[k + 1] = z
fine_t, fine_x = np.concatenate(fine_t), np.concatenate(fine_x)
y = (x[:, 0] + rng.uniform(-0.01, 0.01, T))[:, None]

# %%
# Estimate with both set methods from a prior box on ``x(0)``; every box contains the true
# state at its sample.
x0 = ivobs.Box([0.9, 0.4], [1.1, 0.6])
results = {}
for method in ["nl-constrained-zonotope", "nl-zonotope"]:
    res = ivobs.make_estimator(method, sampled, x0=x0).run(None, y)
    assert res.contains(x).all()
    results[method] = res
    print(
        f"{method:24s} mean widths (p, v) after 10 samples:",
        np.round(res.mean_width(burn_in=10), 4),
    )

# %%
# Between the samples: the boxes of ``between_samples`` contain ``x(t)`` for every ``t`` in
# ``[t_k, t_k + Ts]`` (every path from the sample box, for every ``d(t)`` in its bounds). Checked
# here on the simulated path.
res = results["nl-constrained-zonotope"]
tube = ivobs.between_samples(sampled, res)
k_of = np.minimum((fine_t / Ts + 1e-9).astype(int), T - 1)
inside = (tube.lower[k_of] <= fine_x) & (fine_x <= tube.upper[k_of])
assert inside.all()
print("mean widths of the period boxes (p, v):", np.round(tube.mean_width(burn_in=10), 4))

# %%
# The velocity (not measured): the true path, the boxes at the samples of both methods (the
# constrained zonotope's inside the zonotope's), and the boxes over each period of
# ``nl-constrained-zonotope``.
fig, ax = plt.subplots(figsize=(8, 4))
t = np.arange(T) * Ts
for k in range(T):
    ax.fill_between([t[k], t[k] + Ts], tube.lower[k, 1], tube.upper[k, 1], color="C0",
                    alpha=0.15, lw=0, label="between samples" if k == 0 else None)  # fmt: skip
for i, method in enumerate(["nl-zonotope", "nl-constrained-zonotope"]):
    r = results[method]
    ax.errorbar(t, (r.lower[:, 1] + r.upper[:, 1]) / 2,
                yerr=(r.upper[:, 1] - r.lower[:, 1]) / 2, fmt="none", ecolor=f"C{i + 1}",
                capsize=2, label=f"{method} at the samples")  # fmt: skip
ax.plot(fine_t, fine_x[:, 1], "k", lw=1, label="true v(t)")
ax.set_xlabel("t (s)")
ax.set_ylabel("velocity v")
ax.set_ylim(-3.5, 3.5)
ax.legend(loc="upper left", fontsize=8)
fig.tight_layout()
