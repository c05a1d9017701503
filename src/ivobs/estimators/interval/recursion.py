"""One step of the interval observers, written once for the three methods (package docstring):

    z̄+ = Q⁺ z̄ − Q⁻ z̲ + S(B − L_k D_u) u + S L_k y + (SG)⁺ d_hi − (SG)⁻ d_lo
    z̲+ = Q⁺ z̲ − Q⁻ z̄ + S(B − L_k D_u) u + S L_k y + (SG)⁺ d_lo − (SG)⁻ d_hi

after the consistency test of ``y[k]`` (an inconsistent measurement is not used), widened by
the step's rounding bound. Dense systems evaluate it with ``Q⁺``, ``Q⁻``; sparse ones with one
compiled product of the stacked matrix ``[[Q⁺, −Q⁻], [−Q⁻, Q⁺]]`` on ``[z̄; z̲]``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np

from ...sets import Box
from .. import _uncertain as uncertain
from .._recursion import csr_accumulate
from ..state import Step, evolve
from .operators import FusedStep, FusedTransformed, SplitOperators, hull
from .rounding import largest
from .window import CooperativeState, after_gap

__all__ = [
    "CooperativeState",
    "IntervalState",
    "SplitState",
    "TransformedState",
    "cooperative_step",
]


@dataclass(frozen=True)
class IntervalState(CooperativeState):
    """The state of ``interval``: bounds of ``x[k]`` ([Tang2019, eq. (36)])."""


@dataclass(frozen=True)
class SplitState(CooperativeState):
    """The state of ``interval-split``: bounds of ``x[k]`` ([Efimov2013, eq. (5)])."""


@dataclass(frozen=True)
class TransformedState(CooperativeState):
    """The state of ``interval-transformed``: bounds of ``z[k] = S x[k]`` ([Tang2019,
    eqs. (42)-(43)])."""


S = TypeVar("S", bound=CooperativeState)


def cooperative_step(ops: SplitOperators, state: S, u_k: np.ndarray, y_k: np.ndarray) -> Step[S]:
    """From the bounds of ``z[k]``: the box of ``x[k]`` and the bounds of ``z[k+1]``."""
    if ops.fused is not None and state.fresh < 0:
        fast = _fused_step(ops.fused, state, u_k, y_k)
        if fast is not None:
            return fast
    if ops.fused_z is not None and state.k > 0:
        fast = _fused_transformed(ops, ops.fused_z, state, u_k, y_k)
        if fast is not None:
            return fast
    zlo, zhi = state.lo, state.hi
    xlo, xhi = ops.to_x(state.k, zlo, zhi)
    obs = ~np.isnan(y_k)
    dbox = ops.disturbance(state.k, y_k)
    w = v = None
    if ops.unc is not None:  # interval matrices: w = ΔA x + ΔB u, v = ΔC x + ΔD u (_uncertain)
        w, v = uncertain.terms(ops.unc, xlo, xhi, u_k)
    inconsistent = bool(obs.any()) and not ops.consistent(xlo, xhi, u_k, y_k, obs, dbox, v)
    if inconsistent:
        obs = np.zeros_like(obs)
    if ops.sparse:
        lo, hi = _stacked_update(ops, zlo, zhi, u_k, y_k, obs, dbox)
    else:
        lo, hi = _split_update(ops, zlo, zhi, xlo, xhi, u_k, y_k, obs, dbox)
    if w is not None and v is not None:  # S (w − L_k v) enters z[k+1] as a bounded input
        lo, hi = uncertain.widen(lo, hi, uncertain.observer_term(w, v, ops.matrices(obs).Lz, ops.S))
    new = replace(state, lo=lo, hi=hi)
    if ops.window is not None:
        new = after_gap(ops.window, ops.dmax, new, state, u_k, y_k, bool(obs.all()))
    return Step(new, xlo, xhi, inconsistent)


def _fused_step(fs: FusedStep, state: S, u_k: np.ndarray, y_k: np.ndarray) -> Step[S] | None:
    """:func:`cooperative_step` for a complete ``y[k]`` inside its bounds (``S = I``, dense,
    constant bounds: :attr:`SplitOperators.fused`): the same step in one product; ``None`` (the
    general step) when ``y[k]`` is missing or maybe inconsistent. The rounding bound (the
    largest ``|v_i|`` of each block, their dot product with ``coef``) and the widening in
    Python floats on short vectors: the same IEEE operations in the same order as NumPy's
    ``maximum.reduceat`` and the (sequential) ``dot`` of a few numbers, so the same bits; the
    box of ``x[k]`` as lists (rounded without a conversion back, ``lean_outward``)."""
    zlo, zhi = state.lo, state.hi
    n, ny = zlo.shape[0], y_k.shape[0]
    v = np.concatenate((zhi, zlo, u_k, y_k))
    out = fs.W.dot(v)
    out += fs.w
    if v.shape[0] > _FEW:  # long vectors: NumPy (the same numbers)
        return _fused_long(fs, state, v, out, y_k)
    o = out.tolist()
    vs = v.tolist()
    n2 = 2 * n
    p = o[n2:]
    for hi_, yv, lo_ in zip(p[:ny], vs[-ny:], p[ny:]):
        if not lo_ <= yv <= hi_:  # maybe inconsistent, or missing: the general step decides
            return None
    e = _block_dot(vs, fs.bounds, fs.coef_list) + fs.e_d
    hi, lo = [], []  # (a loop: cheaper than comprehensions, or NumPy, on 3 numbers)
    for zh, zl in zip(o[:n], o[n:n2]):
        hi.append(zh + e)
        lo.append(zl - e)
    new = evolve(state, lo=np.array(lo), hi=np.array(hi))
    return Step(new, vs[n:n2], vs[:n], False)


def _fused_long(
    fs: FusedStep, state: S, v: np.ndarray, out: np.ndarray, y_k: np.ndarray
) -> Step[S] | None:
    """The rest of :func:`_fused_step` in NumPy, for long vectors (``out = W v + w``)."""
    zlo, zhi = state.lo, state.hi
    n, ny = zlo.shape[0], y_k.shape[0]
    p = out[2 * n :].tolist()
    for hi_, yv, lo_ in zip(p[:ny], y_k.tolist(), p[ny:]):
        if not lo_ <= yv <= hi_:  # maybe inconsistent, or missing: the general step decides
            return None
    e = float(fs.coef.dot(np.maximum.reduceat(np.abs(v, out=v), fs.starts))) + fs.e_d
    hi = out[:n]
    hi += e
    lo = out[n : 2 * n]
    lo -= e
    return Step(evolve(state, lo=lo, hi=hi), zlo, zhi, False)


_FEW = 32
"""Longest ``[z̄; z̲; u; y]`` that :func:`_fused_step` finishes in Python floats (beyond,
NumPy's calls cost less than a float loop)."""


def _block_dot(vs: list[float], bounds: list[tuple[int, int]], coef: list[float]) -> float:
    """``coef · maximum.reduceat(|v|, starts)`` (nonempty blocks ``bounds``) one float at a
    time: the largest ``|v_i|`` of each block as NumPy's ``maximum`` (NaN propagates), then
    the sum of the products from ``0.0`` in order, as the BLAS ``ddot`` of a few numbers
    (tests/test_lean_step.py compares them, NaN and infinities included: equal bit for bit on
    this machine; a BLAS kernel with FMA would differ by the rounding of a short dot)."""
    e = 0.0
    for (a, b), c in zip(bounds, coef):
        m = 0.0  # _largest(vs[a:b]), inline (a call per block costs as much as its work)
        for x in vs[a:b]:
            x = abs(x)
            if x > m:
                m = x
            elif x != x:
                m = x
                break
        e = e + c * m
    return e


def _fused_transformed(
    ops: SplitOperators, fs: FusedTransformed, state: S, u_k: np.ndarray, y_k: np.ndarray
) -> Step[S] | None:
    """:func:`cooperative_step` in ``z = S x`` (``k >= 1``) for a complete ``y[k]`` inside its
    bounds (:attr:`SplitOperators.fused_z`): one product, the widening of the ``x`` box for the
    computed inverse (:meth:`SplitOperators.to_x`) and the step error (``StepMatrices.err`` on
    the norms of ``x``, ``z``, ``y``, ``u``, ``d``) in floats; ``None``: the general step."""
    n, ny = state.lo.shape[0], y_k.shape[0]
    out = fs.W.dot(np.concatenate((state.hi, state.lo, u_k, y_k)))
    out += fs.w
    o = out.tolist()  # the rest in Python floats: the same IEEE operations, so the same bits
    ys = y_k.tolist()
    zmax, umax, ymax, xi = (
        _largest(state.hi.tolist() + state.lo.tolist()),  # max |z|, |u|, |y|, |x̂|
        _largest(u_k.tolist()),
        _largest(ys),
        _largest(o[2 * n : 4 * n]),
    )
    g, c = ops.tconv  # type: ignore[misc]
    cz = c * zmax
    ex = cz + g * (xi + cz) / (1.0 - g)  # as to_x
    p = o[4 * n :]
    for hi_, lo_, yv, ca in zip(p[:ny], p[ny:], ys, fs.cabs.tolist()):
        if not lo_ - ca * ex <= yv <= hi_ + ca * ex:  # maybe inconsistent: the general step
            return None
    err = fs.err
    e = err[0] * (xi + ex) + err[1] * zmax + err[2] * ymax + err[3] * umax + err[4] * fs.dmax
    hi, lo, xhi, xlo = [], [], [], []  # (a loop: cheaper than comprehensions, or NumPy, on
    for zh, zl, xh, xl in zip(o, o[n : 2 * n], o[2 * n : 3 * n], o[3 * n : 4 * n]):  # 3 numbers)
        hi.append(zh + e)
        lo.append(zl - e)
        xhi.append(xh + ex)
        xlo.append(xl - ex)
    return Step(evolve(state, lo=np.array(lo), hi=np.array(hi)), xlo, xhi, False)


def _largest(values: list[float]) -> float:
    """``max |v|`` over ``values`` (0 for none; NaN if one is NaN), as NumPy's
    ``maximum.reduce`` of ``abs``, one float at a time (cheaper on a few numbers)."""
    a = 0.0
    for v in values:
        v = abs(v)
        if v > a:
            a = v
        elif v != v:
            return v
    return a


def _split_update(
    ops: SplitOperators,
    zlo: np.ndarray,
    zhi: np.ndarray,
    xlo: np.ndarray,
    xhi: np.ndarray,
    u_k: np.ndarray,
    y_k: np.ndarray,
    obs: np.ndarray,
    dbox: Box,
) -> tuple[np.ndarray, np.ndarray]:
    """The step with dense ``Q⁺``, ``Q⁻``; the rounding bound of the step (``S = I``:
    :meth:`SplitOperators.local_error`; ``S ≠ I``: ``transform_step_error`` on the true ``x``
    and ``z``) inside the new bounds, for any missing pattern."""
    m = ops.matrices(obs)
    y_obs = np.where(obs, y_k, 0.0)
    known = m.Bz @ u_k + m.Lz @ y_obs
    glo, ghi = hull(m.Gp, m.Gn, dbox.lo, dbox.hi)
    hi = m.Qp @ zhi - m.Qn @ zlo + known + ghi
    lo = m.Qp @ zlo - m.Qn @ zhi + known + glo
    if ops.margins is not None:
        e = ops.local_error(np.concatenate([zlo, zhi, y_obs, u_k]), dbox)
        hi += e
        lo -= e
    elif m.err is not None:
        norms = np.array([largest(xlo, xhi), largest(zlo, zhi), largest(y_obs),
                          largest(u_k), largest(dbox.lo, dbox.hi)])  # fmt: skip
        e = float(m.err @ norms)
        hi += e
        lo -= e
    return lo, hi


def _stacked_update(
    ops: SplitOperators,
    zlo: np.ndarray,
    zhi: np.ndarray,
    u_k: np.ndarray,
    y_k: np.ndarray,
    obs: np.ndarray,
    dbox: Box,
) -> tuple[np.ndarray, np.ndarray]:
    """The step for sparse ``A`` (``S = I``): ``[z̄; z̲]+ = S2 [z̄; z̲] + K [y; u] + [ḡ; g̲]``
    with the stacked CSR matrix ``S2 = [[Q⁺, −Q⁻], [−Q⁻, Q⁺]]``, ``K = [[L_k, B_z];
    [L_k, B_z]]`` (sparse): two compiled sparse products per step
    (:func:`~ivobs._recursion.csr_accumulate`)."""
    n = zlo.shape[0]
    full = bool(obs.all())
    if full and ops.full_inputs is not None:
        m, g = ops.full, ops.full_inputs
    else:
        m = ops.matrices(obs)
        g = ops.input_bounds(m, obs, dbox)
    z = np.concatenate([zhi, zlo])
    nz = g.copy()
    csr_accumulate(m.S2, z, nz)
    yo = y_k if full else np.where(obs, y_k, 0.0)
    csr_accumulate(m.K, np.concatenate([yo, u_k]), nz)
    if ops.margins is not None:  # this step's rounding, inside the state (any pattern)
        e = ops.local_error(np.concatenate([z, yo, u_k]), dbox if ops.nd else None)
        nz[:n] += e
        nz[n:] -= e
    return nz[n:], nz[:n]
