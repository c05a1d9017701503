"""The CORA benchmark systems of [Althoff2021], shipped as scenarios (``cora-*``).

Numeric data only (matrices, sets, signals, trajectories), extracted from CORA v2026.0.1; see
``ivobs/data/CORA_README.md`` for the provenance, the time convention and known defects. Credit
CORA ([Althoff2021]) when you use them; for ``cora-2dim`` also [Alamo2005, Section 7.1].

Mapping onto ivobs' model: CORA's ``x+ = A x + B u + w``, ``y = C x + v`` with zonotopes
``w ∈ <W_c, W_G>``, ``v ∈ <V_c, V_G>``, ``x0 ∈ <R0_c, R0_G>`` becomes ``d = (β_w, β_v) ∈
[-1, 1]^(m_w + m_v)``, ``E = [W_G 0]``, ``F = [0 V_G]`` (all centers are zero in these files), and
the prior box is the interval hull of ``R0`` (a box in every file). ``y[k]`` measures ``x[k]``;
``u[k]`` acts on the step ``k -> k+1`` (CORA's convention, as ivobs').

Disturbance kinds: ``"recorded"`` gives CORA's own record (``x`` is NaN where CORA stores none,
``cora-2dim``); ``"paper"`` is a uniform random disturbance in the bounds (seed 0; CORA sampled
Gaussian noise truncated to its sets); ``"vertex"``, ``"uniform"``, ``"sinusoidal"`` as usual.
Known defect: CORA's pedestrian record leaves its own bounds at 3 samples (k = 185, 230 for W,
k = 217 for V; by at most 3.2e-3), so a guaranteed method may legitimately miss that record.
"""

from __future__ import annotations

import functools
from importlib import resources

import numpy as np

from ..model import LinearSystem
from ..sets import Box
from ..simulate import Trajectory
from .registry import Scenario, paper_signal, register_scenario

_FILES = {
    "cora-2dim": ("cora_2dim.npz", "CORA/Alamo 2005 2-D example: 2 states, 1 output, 20 steps"),
    "cora-vehicle6": ("cora_vehicle6.npz", "CORA vehicle model: 6 states, 4 outputs, 350 steps"),
    "cora-pedestrian4": (
        "cora_pedestrian4.npz",
        "CORA pedestrian (double integrator): 4 states, 2 outputs, 240 steps",
    ),
    "cora-slip4": ("cora_slip4.npz", "CORA side-slip model: 4 states, 3 outputs, 700 steps"),
    "cora-tank30": (
        "cora_tank30.npz",
        "CORA linearised 30-tank cascade of [Althoff2021]: 30 states, 21 outputs, 235 steps",
    ),
}


def _load(fname: str) -> dict[str, np.ndarray]:
    with resources.files("ivobs.data").joinpath(fname).open("rb") as fh:
        z = np.load(fh)
        return {k: np.array(z[k]) for k in z.files}


def _build(name: str) -> Scenario:
    fname, summary = _FILES[name]
    z = _load(fname)
    A, B, C, D = z["A"], z["B"], z["C"], z["D"]
    WG, VG = z["W_G"], z["V_G"]
    nx, ny = A.shape[0], C.shape[0]
    mw, mv = WG.shape[1], VG.shape[1]
    E = np.hstack([WG, np.zeros((nx, mv))])
    F = np.hstack([np.zeros((ny, mw)), VG])
    sys = LinearSystem(
        A, B, C, D=D, E=E, F=F, d=Box(-np.ones(mw + mv), np.ones(mw + mv)), dt=float(z["dt"])
    )
    r0 = np.abs(z["R0_G"]).sum(axis=1)
    x0 = Box(z["R0_c"] - r0, z["R0_c"] + r0)
    u, y = z["u"], z["y"]
    T = y.shape[0]
    x_rec = z["x"] if "x" in z else np.full((T, nx), np.nan)
    recorded = Trajectory(
        x=x_rec, y=y, u=u, d=np.full((T, mw + mv), np.nan), t=np.arange(T) * float(z["dt"])
    )

    return Scenario(
        name=name,
        system=sys,
        x0=x0,
        x_true0=x_rec[0] if np.all(np.isfinite(x_rec[0])) else np.asarray(z["R0_c"], float),
        u=u,
        horizon=T,
        source=f"CORA v2026.0.1 benchmark data ({fname}); see ivobs/data/CORA_README.md",
        description=summary,
        recorded=recorded,
        _disturbance=paper_signal("uniform", sys),
        reference={"W_G": WG, "V_G": VG, "R0_G": z["R0_G"]},
        notes="x_true0 for simulations is CORA's recorded x[0] (R0's center when none is stored)",
    )


for _name in _FILES:  # a builder without options (options(name) == [])
    register_scenario(_name, _FILES[_name][1])(functools.partial(_build, _name))
