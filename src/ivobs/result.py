"""``Estimate``: guaranteed bounds over time, with the metrics users compare methods by.

Time convention (all methods): ``lower[k], upper[k]`` bound ``x[k]`` using ``u[0..k]`` and
``y[0..k]`` at most. Rows before ``valid_from`` are NaN: the method makes no claim there
(fixed-time estimators need ``s + 1`` measurements, time-varying KKL observers a left-invertible
transformation). A batch of streams has bounds of shape ``(B, T, nx)``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import IvobsError
from .sets import Box

__all__ = ["Estimate"]


@dataclass
class Estimate:
    """Bounds ``lower <= x[k] <= upper`` for every step ``k >= valid_from``.

    Attributes
    ----------
    lower, upper : (T, nx) or (B, T, nx) arrays (NaN before ``valid_from``)
    valid_from : first step with a guaranteed box
    method : name of the method that produced it
    t : sample times (optional; filled from the model's sampling period by ``run()`` for a
        sampled system, ``k dt``)
    missing : (T,) bool, steps where (part of) the measurement was missing (NaN) and predicted over
    inconsistent : (T,) bool, steps where the measurement contradicted the model and bounds
        (a fault under the model's assumptions); the method then predicted without it
    info : free-form extras (design time, run time, ...)
    names : the states' names (from the model's ``names``; None: ``x1..xn``)
    units : the states' units (``"rad"``, ``"m/s"``; None or ``""``: none)
    """

    lower: np.ndarray
    upper: np.ndarray
    valid_from: int = 0
    method: str = ""
    t: np.ndarray | None = None
    missing: np.ndarray | None = None
    inconsistent: np.ndarray | None = None
    info: dict[str, Any] = field(default_factory=dict)
    names: tuple[str, ...] | None = None
    units: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        self.lower = np.asarray(self.lower, dtype=float)
        self.upper = np.asarray(self.upper, dtype=float)
        if self.lower.shape != self.upper.shape or self.lower.ndim not in (2, 3):
            raise IvobsError(
                f"Estimate: lower and upper must share a (T, nx) or (B, T, nx) shape, got "
                f"{self.lower.shape} and {self.upper.shape}"
            )
        T = self.T
        if self.missing is None:
            self.missing = np.zeros(T, dtype=bool)
        if self.inconsistent is None:
            self.inconsistent = np.zeros(T, dtype=bool)
        for key in ("names", "units"):
            value = getattr(self, key)
            if value is not None:
                value = tuple(str(v) for v in value)
                if len(value) != self.nx:
                    raise IvobsError(
                        f"Estimate: {key}: expected {self.nx} entries (one per state), got "
                        f"{len(value)}: {list(value)!r}"
                    )
                setattr(self, key, value)

    @property
    def state_labels(self) -> list[str]:
        """``"name (unit)"`` per state (``x1..xn`` for unnamed states): plots and tables."""
        names = self.names or tuple(f"x{i + 1}" for i in range(self.nx))
        units = self.units or ("",) * self.nx
        return [f"{n} ({u})" if u else n for n, u in zip(names, units)]

    # -- shape ---------------------------------------------------------------------------
    @property
    def T(self) -> int:
        """Number of steps."""
        return int(self.lower.shape[-2])

    @property
    def nx(self) -> int:
        return int(self.lower.shape[-1])

    @property
    def is_batch(self) -> bool:
        return self.lower.ndim == 3

    def __len__(self) -> int:
        return self.T

    # -- metrics -------------------------------------------------------------------------
    @property
    def width(self) -> np.ndarray:
        """``upper - lower`` (NaN before ``valid_from``)."""
        width: np.ndarray = self.upper - self.lower
        return width

    @property
    def valid(self) -> np.ndarray:
        """``(T,)`` bool: steps with a guaranteed box."""
        return np.arange(self.T) >= self.valid_from

    def box(self, k: int) -> Box:
        """The box at step ``k`` (``Box.unknown`` before ``valid_from``)."""
        if self.is_batch:
            raise IvobsError("box: not available for a batch estimate; index lower/upper")
        if k < self.valid_from:
            return Box.unknown(self.nx)
        return Box._trusted(self.lower[k].copy(), self.upper[k].copy())

    def contains(self, x: Any, tol: float = 0.0) -> np.ndarray:
        """``(T,)`` (or ``(B, T)``) bool: whether each true state lies in its box.

        Steps before ``valid_from`` count as contained (no claim is made there); a NaN bound at
        or after ``valid_from`` counts as not containing.
        """
        x = np.asarray(x, dtype=float)
        if x.shape != self.lower.shape:
            raise IvobsError(f"contains: expected x of shape {self.lower.shape}, got {x.shape}")
        ok = np.all((x >= self.lower - tol) & (x <= self.upper + tol), axis=-1)
        ok[..., : self.valid_from] = True
        contained: np.ndarray = ok
        return contained

    def mean_width(self, burn_in: int = 0) -> np.ndarray:
        """Mean width per state over steps ``>= max(valid_from, burn_in)`` (shape ``(nx,)``)."""
        start = max(self.valid_from, int(burn_in))
        if start >= self.T:
            raise IvobsError(f"mean_width: no valid step at or after {start} (T = {self.T})")
        w = self.width[..., start:, :]
        mean: np.ndarray = w.reshape(-1, self.nx).mean(axis=0)
        return mean

    def tightness_ratio(self, reference: Estimate, burn_in: int = 0) -> np.ndarray:
        """Mean width per state divided by the reference's (e.g. the ``exact`` hull): ``>= 1``
        for any guaranteed method when the reference is the exact hull."""
        if reference.lower.shape != self.lower.shape:
            raise IvobsError("tightness_ratio: the two estimates have different shapes")
        start = max(self.valid_from, reference.valid_from, int(burn_in))
        w, wr = self.mean_width(start), reference.mean_width(start)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(wr > 0, w / wr, np.where(w > 0, np.inf, 1.0))

    # -- files ---------------------------------------------------------------------------
    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write ``k, [t,] lower_1.., upper_1.., missing, inconsistent`` atomically: bounds with
        full precision, ``k`` and the flags as integers (``missing``/``inconsistent``: 0 or 1).
        ``k`` counts from ``info["first_step"]`` (the step of the prior box; default 0)."""
        if self.is_batch:
            raise IvobsError("to_csv: batch estimates are not written as CSV; save lower/upper")
        path = Path(path)
        cols = ["k"] + (["t"] if self.t is not None else [])
        cols += [f"{b}_{i + 1}" for b in ("lower", "upper") for i in range(self.nx)]
        cols += ["missing", "inconsistent"]
        times = [np.asarray(self.t, dtype=float)[:, None]] if self.t is not None else []
        data = np.hstack([*times, self.lower, self.upper])
        assert self.missing is not None and self.inconsistent is not None  # by __post_init__
        flags = np.column_stack([self.missing, self.inconsistent]).astype(int)
        header = f"# ivobs estimate\n# method: {self.method}\n# valid_from: {self.valid_from}\n"
        if self.names is not None:
            header += f"# states: {_listed(self.names)}\n"
        if self.units is not None:
            header += f"# units: {_listed(self.units)}\n"
        header += ",".join(cols)
        from .io.atomic import atomic_path  # the umask's file mode, like open(path, "w")
        from .io.logs import csv_cell

        with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8") as fh:
            fh.write(header + "\n")
            first = int(self.info.get("first_step", 0))
            for k, (row, flag) in enumerate(zip(data, flags), start=first):
                cells = [str(k), *(csv_cell(v, "nan") for v in row), *(str(int(f)) for f in flag)]
                fh.write(",".join(cells) + "\n")

    @classmethod
    def from_csv(cls, path: str | os.PathLike[str]) -> Estimate:
        """Read what :meth:`to_csv` wrote."""
        meta: dict[str, str] = {}
        path = Path(path)
        if not path.exists():
            raise IvobsError(f"from_csv: no such file {str(path)!r}")
        with open(path, encoding="utf-8") as fh:
            lines = fh.read().splitlines()
        body = []
        for line in lines:
            if line.startswith("#"):
                if ":" in line:
                    key, val = line[1:].split(":", 1)
                    meta[key.strip()] = val.strip()
            elif line.strip():
                body.append(line)
        if not body or not body[0].startswith("k"):
            raise IvobsError(
                f"from_csv: {str(path)!r} is not an ivobs estimate (no 'k,...' header)"
            )
        cols = body[0].split(",")
        try:
            data = np.array([[float(v) for v in r.split(",")] for r in body[1:]]).reshape(
                -1, len(cols)
            )
        except ValueError as exc:
            raise IvobsError(f"from_csv: malformed row in {str(path)!r}: {exc}") from None
        lo_idx = [i for i, c in enumerate(cols) if c.startswith("lower_")]
        hi_idx = [i for i, c in enumerate(cols) if c.startswith("upper_")]
        t = data[:, cols.index("t")] if "t" in cols else None
        names, units = (
            tuple(v.strip() for v in meta[key].split(";")) if key in meta else None
            for key in ("states", "units")
        )
        return cls(
            lower=data[:, lo_idx],
            upper=data[:, hi_idx],
            valid_from=int(meta.get("valid_from", 0)),
            method=meta.get("method", ""),
            t=t,
            missing=data[:, cols.index("missing")].astype(bool) if "missing" in cols else None,
            inconsistent=(
                data[:, cols.index("inconsistent")].astype(bool) if "inconsistent" in cols else None
            ),
            names=names,
            units=units,
        )

    def equals(self, other: Estimate) -> bool:
        """Same bounds (NaN equal to NaN), same ``valid_from`` and method."""
        return (
            self.valid_from == other.valid_from
            and self.method == other.method
            and np.array_equal(self.lower, other.lower, equal_nan=True)
            and np.array_equal(self.upper, other.upper, equal_nan=True)
        )

    # -- figures -------------------------------------------------------------------------
    def plot(self, truth: Any = None, states: Any = None, ax: Any = None, **kwargs: Any) -> Any:
        """Bands per state (and the true trajectory when given); returns the figure
        (:func:`ivobs.report.plot.plot_estimates`)."""
        # the plotting layer imports this module for its annotations only: no import cycle
        from .report.plot import plot_estimates

        return plot_estimates(
            {self.method or "estimate": self}, truth=truth, states=states, axes=ax, **kwargs
        )

    # -- tables and notebooks (ivobs.frames) ------------------------------------------------
    def to_pandas(self, truth: Any = None, names: Any = None) -> Any:
        """A tidy ``pandas.DataFrame``: one row per step and state with columns ``k``, ``t``
        (when sample times are known), ``state``, ``lower``, ``upper``, ``width``, ``missing``,
        ``inconsistent`` (``stream`` first for a batch; ``truth`` and ``contained`` when the
        true trajectory ``truth`` — a :class:`~ivobs.Trajectory` or an array — is given).
        ``names``: state labels (default ``x1..xn``). Needs pandas (``ivobs[pandas]``)."""
        from .frames import estimate_to_pandas

        return estimate_to_pandas(self, truth, names)

    def to_xarray(self, truth: Any = None, names: Any = None) -> Any:
        """An ``xarray.Dataset`` with variables ``lower``, ``upper`` (and ``truth``) over
        dimensions ``(stream,) k, state`` and the flags over ``(stream,) k``; ``t`` as a
        coordinate when known. Needs xarray (``ivobs[xarray]``)."""
        from .frames import estimate_to_xarray

        return estimate_to_xarray(self, truth, names)

    def _repr_html_(self) -> str:
        """Jupyter: a short summary and an inline figure of the widths."""
        from .frames import estimate_html

        return estimate_html(self)

    def __repr__(self) -> str:
        shape = "x".join(str(s) for s in self.lower.shape)
        return f"Estimate(method={self.method!r}, shape={shape}, valid_from={self.valid_from})"


def _listed(values: tuple[str, ...]) -> str:
    """Names or units on one header line, ``;``-separated (a name cannot hold ``;`` or a
    line break there: they are replaced)."""
    return "; ".join(v.replace(";", ",").replace("\n", " ") for v in values)
