"""Nonlinear models: :class:`NonlinearSystem` (expressions or traced callables) and its
generated guaranteed interval functions. docs/nonlinear.md."""

from __future__ import annotations

from .system import NonlinearSystem

__all__ = ["NonlinearSystem"]
