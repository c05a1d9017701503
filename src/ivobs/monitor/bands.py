"""The monitor's own model prediction and output band, per model class.

* **Linear, exactly known** ([Efimov2013, Lemma 1]): ``P_k = A[X_{k-1}] + B u + E[d]`` and the
  band ``C[P_k] + D u + F[d]`` (:func:`ivobs.image_bounds`, rounding included).
* **Linear with interval matrices** (docs/uncertain.md): the same with ``|ΔM| <= R_M`` for
  ``M = A, B, C, D``: ``[M] [x] ⊆ M₀ [x] ± R_M max(|x_lo|, |x_hi|)`` and ``[M] u ⊆ M₀ u ± R_M |u|``
  (each realisation's product lies there; the sums rounded up).
* **Nonlinear** (:class:`~ivobs.NonlinearSystem`, or the sampled model of a continuous-time
  one): ``P_k = f([X_{k-1}], u, [w])`` and the band ``h([P_k], u, [w])``, the model's natural ∩
  mean-value inclusions, outward rounded (:mod:`ivobs.model.nonlinear`).

Each contains every value the model allows from the box, so the monitor's guarantee (an alarm
is never false under the model's assumptions) holds for every class.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..model import LinearSystem
from ..sets import image_bounds, neg, pos
from ..sets.rounding import product_error, up, upper

__all__ = ["LinearBands", "NonlinearBands", "bands_for"]

Pair = tuple[np.ndarray, np.ndarray]


def bands_for(sys: Any) -> LinearBands | NonlinearBands:
    """The prediction and band of ``sys``'s class."""
    return LinearBands(sys) if isinstance(sys, LinearSystem) else NonlinearBands(sys)


class LinearBands:
    """[Efimov2013, Lemma 1] with the model's matrices (interval ones by their radii)."""

    def __init__(self, sys: LinearSystem):
        self.sys = sys
        self.unc = sys.uncertainty if sys.is_uncertain else None
        self._split: dict[str, Pair] = {}
        self._dimg: dict[str, Pair] = {}

    def predict(self, k: int, prev: dict[str, Any]) -> Pair | None:
        """``A[X_{k-1}] + B u[k-1] + E[d[k-1]]``."""
        if self.sys.is_continuous:
            return None
        lo, hi = self._image("A", k - 1, prev["lo"], prev["hi"])
        e_lo, e_hi = self._disturbance("E", k - 1, prev["y"])
        b_lo, b_hi = self._input("B", k - 1, prev["u"])
        return lo + b_lo + e_lo, hi + b_hi + e_hi

    def band(self, k: int, key: Any, pred: Pair, u: np.ndarray, y: np.ndarray) -> Pair:
        """``C[P_k] + D u[k] + F[d[k]]`` (``key``: the step, or the time in continuous time)."""
        lo, hi = self._image("C", key, pred[0], pred[1])
        f_lo, f_hi = self._disturbance("F", k, y)
        d_lo, d_hi = self._input("D", key, u)
        return lo + d_lo + f_lo, hi + d_hi + f_hi

    def _image(self, name: str, k: Any, lo: np.ndarray, hi: np.ndarray) -> Pair:
        if name in self._split:
            Mp, Mn = self._split[name]
        else:
            M = self.sys.A_at(k) if name == "A" else self.sys.C_at(k)
            Mp, Mn = pos(M), neg(M)
            if not self.sys.is_time_varying:
                self._split[name] = (Mp, Mn)
        if self.unc is not None or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            out_lo, out_hi = image_bounds(Mp - Mn, lo, hi)
        else:
            out_lo, out_hi = Mp @ lo - Mn @ hi, Mp @ hi - Mn @ lo
        R = None if self.unc is None else (self.unc.RA if name == "A" else self.unc.RC)
        if R is not None and R.any():
            with np.errstate(invalid="ignore"):
                mag = np.maximum(np.abs(lo), np.abs(hi))
                spread = upper(np.nan_to_num(R @ mag, nan=np.inf), R.shape[1] + 1)
            out_lo, out_hi = out_lo - spread, out_hi + spread
        return out_lo, out_hi

    def _input(self, name: str, k: Any, u: np.ndarray) -> Pair:
        M = self.sys.B_at(k) if name == "B" else self.sys.D_at(k)
        v = M @ u
        R = None if self.unc is None else (self.unc.RB if name == "B" else self.unc.RD)
        if R is None or not R.any():
            return v, v
        spread = up(
            upper(R @ np.abs(u), R.shape[1] + 1) + product_error(np.abs(M) @ np.abs(u), M.shape[1])
        )
        return v - spread, v + spread

    def _disturbance(self, name: str, k: Any, y: np.ndarray) -> Pair:
        if name in self._dimg:
            return self._dimg[name]
        M = self.sys.E_at(k) if name == "E" else self.sys.F_at(k)
        d = self.sys.d_at(k, y)
        out = image_bounds(M, d.lo, d.hi)
        if not self.sys.is_time_varying and self.sys.has_constant_bounds:
            self._dimg[name] = out
        return out


class NonlinearBands:
    """``f`` and ``h`` over boxes, with the unknowns ``w`` over their whole box."""

    def __init__(self, sys: Any):
        self.sys = sys
        self.wl, self.wh = sys.w_box.lo, sys.w_box.hi

    def predict(self, k: int, prev: dict[str, Any]) -> Pair | None:
        lo, hi = prev["lo"], prev["hi"]
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            return None
        out: Pair = self.sys.f_tight_box(lo, hi, prev["u"], self.wl, self.wh)
        return out

    def band(self, k: int, key: Any, pred: Pair, u: np.ndarray, y: np.ndarray) -> Pair:
        if not (np.all(np.isfinite(pred[0])) and np.all(np.isfinite(pred[1]))):
            n = self.sys.ny
            return np.full(n, -np.inf), np.full(n, np.inf)
        out: Pair = self.sys.h_tight_box(pred[0], pred[1], u, self.wl, self.wh)
        return out
