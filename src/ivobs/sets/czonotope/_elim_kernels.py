"""Whether the elimination loop uses the compiled kernels of :mod:`._elim_nb` (numba, optional:
``ivobs[fast]``), kept apart from them so that deciding does not import numba.

The kernels give the same numbers as the NumPy code of :func:`~.elimination._propagate` and
:func:`~.elimination._overshoot`, bit for bit, for the memory layouts whose order of row sums
they reproduce (:func:`layout`); they are used from :data:`KERNEL_MIN` entries on.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np

__all__ = ["KERNEL_MIN", "kernels", "layout"]

_KERNELS: Any = False  # not looked up yet
KERNEL_MIN = 1 << 14
"""Entries of ``A`` from which the kernels are used (tank30's 81 x 552 is 44712): below it
(the servo's ~12 x 50) NumPy takes tens of µs and importing numba and loading the kernels
(~0.5 s of CPU once per process) would not pay."""


def kernels() -> Any:
    """The module :mod:`._elim_nb`, or None: numba missing, or disabled by the environment
    variable ``IVOBS_NUMBA=0`` (as the other kernels) when first asked."""
    global _KERNELS
    if _KERNELS is False:
        _KERNELS = None
        if os.environ.get("IVOBS_NUMBA", "") != "0":
            try:
                from . import _elim_nb
            except ImportError:  # numba not installed (or broken): NumPy
                pass
            else:
                _KERNELS = _elim_nb
    return _KERNELS


def layout(A: np.ndarray, b: np.ndarray) -> bool | None:
    """``pairwise`` for the kernels: True when ``A`` is C-contiguous (NumPy sums a contiguous
    row pairwise), False when it is Fortran-ordered (NumPy adds the columns in turn, every row
    at once); the temporaries NumPy sums have ``A``'s layout. ``None``: use NumPy's code (a
    small ``A``, no numba, not float64, or another layout; rows over 8192 entries, which NumPy
    may sum in buffered chunks)."""
    if A.size < KERNEL_MIN or A.ndim != 2 or A.dtype != np.float64 or b.dtype != np.float64:
        return None
    if b.shape != (A.shape[0],):
        return None
    if A.flags.c_contiguous:
        if A.shape[1] > 8192:
            return None
        pairwise = True
    elif A.flags.f_contiguous:
        pairwise = False
    else:
        return None
    return pairwise if kernels() is not None else None
