"""Sylvester (KKL) transformations for interval observers ([Dinh2024]).

A target pair ``(A_z, B_z)`` — Schur and nonnegative in discrete time, Hurwitz and Metzler in
continuous time, ``(A_z, B_z)`` controllable, ``eig(A_z)`` disjoint from ``eig(A)`` — and the
solution ``T`` of the Sylvester equation ([Dinh2024, eq. (4)], ``F = A``, ``H = C``, the paper's
``(A, B)`` = ``(A_z, B_z)``)::

    T A = A_z T + B_z C

turn ``z = T x`` into a cooperative system ``z+ = A_z z + B_z y + ...`` for which interval bounds
are immediate ([Dinh2024, Proposition 1]). Nothing here loops over time.

* :mod:`.equation`: the equation (4), the conditions of Proposition 1 on a target pair, the
  predicted width of the bounds;
* :mod:`.flow`: the flow of ``T`` in the continuous-time observer (the default target's rule);
* :mod:`.targets`: the default diagonal target of a time-invariant system and the block targets
  of time-varying systems.
"""

from .equation import check_target, predicted_width, solve_transform
from .flow import CT_RANGE, FLOW_MARGIN, check_flow, flow_cap, flow_gap
from .targets import DT_RANGE, TargetChoice, block_target, default_target

__all__ = [
    "CT_RANGE",
    "DT_RANGE",
    "FLOW_MARGIN",
    "TargetChoice",
    "block_target",
    "check_flow",
    "check_target",
    "default_target",
    "flow_cap",
    "flow_gap",
    "predicted_width",
    "solve_transform",
]
