"""Whether the elimination loop uses the compiled kernels of :mod:`._elim_nb` (numba, optional:
``ivobs[fast]``), kept apart from them so that deciding does not import numba.

The kernels give the same numbers as the NumPy code of :func:`~.elimination._propagate` and
:func:`~.elimination._overshoot`, bit for bit, for the memory layouts whose order of row sums
they reproduce (:func:`select`); they are used from :data:`KERNEL_MIN` entries on.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

__all__ = ["KERNEL_MIN", "Kernels", "kernels", "load_compiled", "select"]


class Kernels(NamedTuple):
    """The compiled :func:`._elim_nb.propagate` and :func:`._elim_nb.overshoot`."""

    propagate: Callable[..., tuple[bool, np.ndarray, np.ndarray]]
    overshoot: Callable[..., np.ndarray]


_KERNELS: Any = False  # not looked up yet
KERNEL_MIN = 1 << 14
"""Entries of ``A`` from which the kernels are used (tank30's 81 x 552 is 44712): below it
(the servo's ~12 x 50) NumPy takes tens of µs and importing numba and loading the kernels
(~0.5 s of CPU once per process) would not pay."""


def load_compiled(module: str, *names: str) -> tuple[Any, ...] | None:
    """``names`` from the compiled module ``module`` of this package (``"_elim_nb"``,
    ``"_loss_nb"``), or None: numba missing (or broken), or disabled by the environment
    variable ``IVOBS_NUMBA=0`` (as the strip kernel). Imported by name, when first asked: only
    then is numba imported."""
    if os.environ.get("IVOBS_NUMBA", "") == "0":
        return None
    try:
        mod = importlib.import_module(f".{module}", __package__)
    except ImportError:  # numba not installed (or broken): NumPy
        return None
    return tuple(getattr(mod, name) for name in names)


def kernels() -> Kernels | None:
    """The kernels, or None (:func:`load_compiled`) when first asked."""
    global _KERNELS
    if _KERNELS is False:
        found = load_compiled("_elim_nb", "propagate", "overshoot")
        _KERNELS = None if found is None else Kernels(*found)
    out: Kernels | None = _KERNELS
    return out


def select(A: np.ndarray, b: np.ndarray) -> tuple[Kernels, bool] | None:
    """The kernels and their ``pairwise`` for ``A``: True when ``A`` is C-contiguous (NumPy sums
    a contiguous row pairwise), False when it is Fortran-ordered (NumPy adds the columns in
    turn, every row at once); the temporaries NumPy sums have ``A``'s layout. ``None``: use
    NumPy's code (a small ``A``, no numba, not float64, or another layout; rows over 8192
    entries, which NumPy may sum in buffered chunks)."""
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
    nb = kernels()
    return None if nb is None else (nb, pairwise)
