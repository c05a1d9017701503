"""ivobs: guaranteed interval state estimation for linear systems (exact or interval matrices,
discrete or continuous time) and nonlinear systems with uncertain parameters.

Given a model, bounds on disturbances and noise, the inputs and the measurements, every method
returns at each step a box that is certain to contain the true state.

>>> import ivobs
>>> sc = ivobs.scenarios.get("servo-motor")
>>> traj = sc.simulate()
>>> est = ivobs.make_estimator("interval-split", sc.system, x0=sc.x0)   # doctest: +SKIP
>>> res = est.run(traj.u, traj.y)                                       # doctest: +SKIP
"""

from . import config, io, linalg, monitor, nlmath, scenarios
from .between import between_samples
from .errors import (
    DesignError,
    DesignWarning,
    DivergenceError,
    InconsistentDataError,
    IvobsError,
)
from .estimators import Design, Estimator, make_estimator, methods
from .io import equal_systems, load_system, save_system
from .model import LinearSystem, NonlinearSystem
from .monitor import Monitor, MonitorStep
from .result import Estimate
from .sets import Box, Zonotope, image_bounds
from .simulate import (
    Trajectory,
    disturbance,
    simulate,
    sinusoidal_disturbance,
    uniform_disturbance,
    vertex_disturbance,
)
from .simulate_batch import simulate_batch
from .simulate_nonlinear import simulate_nonlinear

__version__ = "0.1.0"

__all__ = [
    "Box",
    "Design",
    "DesignError",
    "DesignWarning",
    "DivergenceError",
    "Estimate",
    "Estimator",
    "InconsistentDataError",
    "IvobsError",
    "LinearSystem",
    "Monitor",
    "MonitorStep",
    "NonlinearSystem",
    "Trajectory",
    "Zonotope",
    "__version__",
    "between_samples",
    "config",
    "disturbance",
    "equal_systems",
    "image_bounds",
    "io",
    "linalg",
    "load_system",
    "make_estimator",
    "methods",
    "monitor",
    "nlmath",
    "save_system",
    "scenarios",
    "simulate",
    "simulate_batch",
    "simulate_nonlinear",
    "sinusoidal_disturbance",
    "uniform_disturbance",
    "vertex_disturbance",
]
