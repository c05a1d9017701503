"""A model matrix given as a constant, a stack over the steps, a callable or a sparse matrix,
with its shape checked once (what :class:`~ivobs.LinearSystem` holds for each of A, ..., F)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from .._validate import as_float_array, as_matrix, check_finite
from ..errors import IvobsError

__all__ = ["Matrix", "MatrixLike", "is_scipy_sparse"]

MatrixLike = Any  # array_like, (T, r, c) stacked array, or callable k -> array_like


def is_scipy_sparse(value: Any) -> bool:
    """Whether ``value`` is a ``scipy.sparse`` matrix (SciPy's sparse module imported here)."""
    try:
        from scipy.sparse import issparse
    except ImportError:  # pragma: no cover
        return False
    return bool(issparse(value))


class Matrix:
    """A constant, stacked, callable or sparse matrix with a checked shape; :meth:`at` gives it
    at a step as a dense array (a sparse one densified once, on demand)."""

    __slots__ = ("const", "fn", "given", "name", "shape", "sp", "stack", "vector")

    def __init__(
        self, name: str, value: MatrixLike, rows: int | None, cols: int | None, vector: str
    ) -> None:
        self.name, self.vector = name, vector
        self.const: np.ndarray | None = None
        self.stack: np.ndarray | None = None
        self.fn: Callable[[Any], Any] | None = None
        self.sp: Any = None
        if is_scipy_sparse(value):
            self._init_sparse(value, rows, cols)
        elif callable(value):
            self.fn = value
            try:
                first = value(0)
            except Exception as exc:  # the user's function failed: say which and where
                raise IvobsError(f"{name}: calling {name}(0) failed: {exc!r}") from None
            m = as_matrix(f"{name}(0)", first, rows, cols, vector=vector)
            self.shape = m.shape
            self.given = np.shape(first)
        else:
            arr = as_float_array(name, value)
            self.given = arr.shape
            if arr.ndim == 3:
                check_finite(name, arr)
                if (rows is not None and arr.shape[1] != rows) or (
                    cols is not None and arr.shape[2] != cols
                ):
                    raise IvobsError(
                        f"{name}: expected stacked matrices of shape (T, {rows}, {cols}), "
                        f"got {arr.shape}"
                    )
                self.stack = arr
                self.shape = arr.shape[1:]
            else:
                self.const = as_matrix(name, arr, rows, cols, vector=vector)
                self.shape = self.const.shape

    def _init_sparse(self, value: Any, rows: int | None, cols: int | None) -> None:
        sp = value.tocsr().astype(float)
        if not np.all(np.isfinite(sp.data)):
            raise IvobsError(f"{self.name}: expected finite numbers in the sparse matrix")
        if (rows is not None and sp.shape[0] != rows) or (cols is not None and sp.shape[1] != cols):
            raise IvobsError(
                f"{self.name}: expected shape ({rows if rows is not None else 'any'}, "
                f"{cols if cols is not None else 'any'}), got {sp.shape}"
            )
        self.sp = sp
        self.shape = self.given = sp.shape

    @property
    def is_constant(self) -> bool:
        return self.const is not None or self.sp is not None

    def at(self, k: Any) -> np.ndarray:
        if self.const is not None:
            return self.const
        if self.sp is not None:  # dense view on demand (methods that do not exploit sparsity)
            self.const = self.sp.toarray()
            return self.const
        if self.stack is not None:
            ki = int(k)
            if not 0 <= ki < self.stack.shape[0]:
                raise IvobsError(
                    f"{self.name}: step {ki} is beyond the {self.stack.shape[0]} stacked matrices"
                )
            out: np.ndarray = self.stack[ki]
            return out
        assert self.fn is not None
        return as_matrix(f"{self.name}({k})", self.fn(k), *self.shape, vector=self.vector)

    def public(self) -> Any:
        if self.const is not None or self.sp is not None:
            return self.at(0)
        return self.stack if self.stack is not None else self.fn
