"""Fast evaluation of the linear recursions that every observer's time loop reduces to.

For constant bounds and complete measurements, the vectorised path of every recursive method is
a *data-dependent centre* that follows a linear time-invariant recursion, plus a radius that does
not depend on the data. Both are the state of one discrete LTI system driven by the record,

    x[k+1] = M x[k] + Σ_s W_s v_s[k] + g

(``v_s``: the signals, e.g. ``y`` and ``u``), which :class:`LinearFilter` evaluates over whole
records and batches of records at memory speed:

* **Small state** (``n <=`` :data:`BLOCK_MAX_STATES`): the record is cut into blocks of ``K``
  steps. Inside a block ``x[qK + j] = M^j s_q + Σ_{i<j} M^(j-1-i) (W v[qK+i] + g)``, so the
  states of every block are one row of a single matrix product ``[v_q, 1, s_q] @ Op`` with a
  block-Toeplitz ``Op`` built once (``M^(j-1-i) W`` below the diagonal, ``M^j`` on the block
  start ``s_q``). The block starts follow ``s_(q+1) = M^K s_q + e_q`` (``e_q`` from
  one more product), a recursion ``K`` times shorter, solved by a loop over blocks (batches) or
  by the same method again (long single records). The products run in the stream-major layout
  of the data, so there is no transposition and no per-step Python work.
* **Large or sparse state**: a loop over time, one (sparse) product per step, with all input
  terms precomputed in one matrix product and written into the state buffer beforehand.

Results agree with the step-by-step recursion up to rounding (sums in another order): a method
that uses a filter bounds that difference itself (e.g. by the defect of the computed sequence,
:mod:`ivobs.estimators.interval.vectorised`).

The package: :mod:`.kernels` (reusable temporaries, batch helpers),
:mod:`.linear_filter` (:class:`LinearFilter`), :mod:`.split_filter`
(:class:`SplitFilter`: the per-stream and shared parts of a batch).
"""

from __future__ import annotations

from .kernels import abs_max, is_shared, matrix_product, norm_inf, redo_streams, scratch
from .linear_filter import BLOCK_MAX_STATES, LinearFilter
from .split_filter import SplitFilter

__all__ = [
    "BLOCK_MAX_STATES",
    "LinearFilter",
    "SplitFilter",
    "abs_max",
    "is_shared",
    "matrix_product",
    "norm_inf",
    "redo_streams",
    "scratch",
]
