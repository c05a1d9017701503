"""The strip method's compiled step (issue 17): optional, with numba (``pip install ivobs[fast]``).

The recursion of :class:`~ivobs.estimators.strip.StripEstimator` is written once in NumPy
(``strip.py``, ``_strip_hull.py``, ``sets/zonotope.py``): that is the reference. At the servo's
size each of its ~40 array operations per step costs more in NumPy's dispatch than in
arithmetic, so when numba is importable the step runs as one compiled call,
:func:`._strip_kernel_nb.strip_step`, the same operations written as loops with the same
rounding margins (its docstring says why they hold for its order of operations). The two are
tested against each other, bound for bound, in tests/test_strip_kernel.py.

The NumPy path runs instead (the fallback) when numba is not installed, when the environment
variable ``IVOBS_NUMBA=0`` is set or :data:`ENABLED` is False when the estimator is built, and
for what the kernel does not do: interval matrices (``sys.uncertainty``) and
``reduction="box"`` (its weighted norms). numba is imported here, when the first strip
estimator is built, never by ``import ivobs``; the first call compiles the kernel (a few
seconds) or loads it from numba's cache (``cache=True``).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np

__all__ = ["ENABLED", "ENV", "as_c", "kernel_structure", "load"]

ENABLED = True
"""False: strip estimators built from now on take the NumPy path."""
ENV = "IVOBS_NUMBA"
"""The environment variable that disables the kernel when ``"0"``."""


def load() -> Callable[..., Any] | None:
    """The compiled step, or None (the NumPy path) when disabled or numba is missing."""
    if not ENABLED or os.environ.get(ENV, "") == "0":
        return None
    try:
        from . import _strip_kernel_nb
    except ImportError:  # numba not installed (or broken): the NumPy path
        return None
    step: Callable[..., Any] = _strip_kernel_nb.strip_step
    return step


def kernel_structure(st: Any) -> tuple[np.ndarray, ...]:
    """The arrays of a ``strip._Structure`` the kernel reads, C-contiguous float64 (int64
    for the index arrays) so that one compiled specialisation serves every system."""
    out = [np.ascontiguousarray(a, dtype=np.float64) for a in (st.D, st.aD, st.h, st.ah)]
    idx = [np.ascontiguousarray(a, dtype=np.int64) for a in (st.jc, st.pc, st.mc)]
    mats = [st.M, st.aM, st.Ep, st.aEp, st.B, st.aB]
    return (*out, *idx, *(np.ascontiguousarray(a, dtype=np.float64) for a in mats))


def as_c(a: np.ndarray) -> np.ndarray:
    """``a`` as a C-contiguous, writeable float64 array (a copy only when it is not one)."""
    if a.dtype == np.float64 and a.flags.c_contiguous and a.flags.writeable:
        return a
    return np.array(a, dtype=np.float64, order="C")
