"""Estimates as tables and labelled arrays (pandas, xarray) and as rich notebook output.

pandas and xarray are optional (``pip install "ivobs[pandas]"`` / ``"ivobs[xarray]"``) and
imported only when these functions are called. The tidy layout is one row per (step, state)
— the form ``seaborn``, ``groupby`` and ``pivot`` expect:

====== ===== ===== ======= ======= ======= ======= ============ ============
stream  k     t     state   lower   upper   width   missing      inconsistent
====== ===== ===== ======= ======= ======= ======= ============ ============

(``stream`` only for a batch, ``t`` only when sample times are known, ``truth`` and
``contained`` when a true trajectory is given).
"""

from __future__ import annotations

import base64
import io
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from ._html import summary_html
from .errors import IvobsError

if TYPE_CHECKING:  # annotations only: result.py imports this module lazily
    from .result import Estimate

__all__ = ["estimate_html", "estimate_to_pandas", "estimate_to_xarray", "state_labels"]


def state_labels(nx: int, names: Sequence[str] | None) -> list[str]:
    """``names`` checked against ``nx``, or ``x1..xn``."""
    if names is None:
        return [f"x{i + 1}" for i in range(nx)]
    labels = [str(n) for n in names]
    if len(labels) != nx:
        raise IvobsError(f"names: expected {nx} state names, got {len(labels)}: {labels!r}")
    return labels


def _truth(est: Estimate, truth: Any) -> np.ndarray | None:
    if truth is None:
        return None
    x = getattr(truth, "x", truth)  # a Trajectory or an array
    x = np.asarray(x, dtype=float)
    if x.shape != est.lower.shape:
        raise IvobsError(
            f"truth: expected the true states with the estimate's shape {est.lower.shape}, "
            f"got {x.shape}"
        )
    return x


def _import(name: str, extra: str) -> Any:
    try:
        return __import__(name)
    except ImportError:
        raise IvobsError(
            f'{name} is not installed; install it with: pip install "ivobs[{extra}]"'
        ) from None


def estimate_to_pandas(est: Estimate, truth: Any = None, names: Sequence[str] | None = None) -> Any:
    """The tidy ``pandas.DataFrame`` of :meth:`ivobs.Estimate.to_pandas`."""
    pd = _import("pandas", "pandas")
    labels = state_labels(est.nx, est.names if names is None else names)
    x = _truth(est, truth)
    lo, hi = est.lower.reshape(-1, est.T, est.nx), est.upper.reshape(-1, est.T, est.nx)
    B, T, n = lo.shape
    cols: dict[str, Any] = {}
    if est.is_batch:
        cols["stream"] = np.repeat(np.arange(B), T * n)
    cols["k"] = np.tile(np.repeat(np.arange(T), n), B)
    if est.t is not None:
        cols["t"] = np.tile(np.repeat(np.asarray(est.t, dtype=float), n), B)
    cols["state"] = pd.Categorical(np.tile(labels, B * T), categories=labels)
    cols["lower"], cols["upper"] = lo.ravel(), hi.ravel()
    cols["width"] = cols["upper"] - cols["lower"]
    if x is not None:
        cols["truth"] = x.reshape(-1)
        with np.errstate(invalid="ignore"):
            inside = (cols["lower"] <= cols["truth"]) & (cols["truth"] <= cols["upper"])
        cols["contained"] = inside | np.isnan(cols["lower"])  # no claim before valid_from
    assert est.missing is not None and est.inconsistent is not None  # by __post_init__
    cols["missing"] = np.repeat(np.broadcast_to(est.missing, (B, T)).ravel(), n)
    cols["inconsistent"] = np.repeat(np.broadcast_to(est.inconsistent, (B, T)).ravel(), n)
    frame = pd.DataFrame(cols)
    frame.attrs.update(method=est.method, valid_from=est.valid_from)
    if est.units is not None:
        frame.attrs["units"] = dict(zip(labels, est.units))
    return frame


def estimate_to_xarray(est: Estimate, truth: Any = None, names: Sequence[str] | None = None) -> Any:
    """The ``xarray.Dataset`` of :meth:`ivobs.Estimate.to_xarray`."""
    xr = _import("xarray", "xarray")
    labels = state_labels(est.nx, est.names if names is None else names)
    dims = (["stream"] if est.is_batch else []) + ["k", "state"]
    coords: dict[str, Any] = {"k": np.arange(est.T), "state": labels}
    if est.t is not None:
        coords["t"] = ("k", np.asarray(est.t, dtype=float))
    data: dict[str, Any] = {"lower": (dims, est.lower), "upper": (dims, est.upper)}
    x = _truth(est, truth)
    if x is not None:
        data["truth"] = (dims, x)
    flag_dims = dims[:-1]
    assert est.missing is not None and est.inconsistent is not None
    data["missing"] = (flag_dims, np.broadcast_to(est.missing, est.lower.shape[:-1]))
    data["inconsistent"] = (flag_dims, np.broadcast_to(est.inconsistent, est.lower.shape[:-1]))
    attrs = {"method": est.method, "valid_from": est.valid_from}
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    if est.units is not None:
        ds["state"].attrs["units"] = list(est.units)
    return ds


def _png(est: Estimate) -> str:
    """A small figure of the bounds' widths over time, as a base64 PNG."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.0, 2.2), dpi=80)
    try:
        first = est.width if not est.is_batch else est.width[0]
        time = np.arange(est.T) if est.t is None else np.asarray(est.t, dtype=float)
        for i in range(min(est.nx, 8)):
            ax.plot(time, first[:, i], lw=1.0, label=est.state_labels[i])
        ax.set_xlabel("step k" if est.t is None else "time")
        ax.set_ylabel("width")
        ax.set_yscale("log" if np.nanmin(first, initial=np.inf) > 0 else "linear")
        if est.nx <= 8:
            ax.legend(fontsize=7, ncol=min(est.nx, 4))
        fig.tight_layout()
        buf = io.BytesIO()
        fig.savefig(buf, format="png")
    finally:
        plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def estimate_html(est: Estimate) -> str:
    """A short HTML summary (method, sizes, mean widths, flags) and an inline width figure."""
    assert est.missing is not None and est.inconsistent is not None
    mean = est.mean_width(burn_in=est.valid_from) if est.T > est.valid_from else None
    rows = [
        ("method", est.method or "(unnamed)"),
        ("steps", f"{est.T}" + (f" × {est.lower.shape[0]} streams" if est.is_batch else "")),
        ("states", str(est.nx) if est.names is None else ", ".join(est.state_labels)),
        ("valid from", f"step {est.valid_from}"),
        ("missing samples", str(int(np.count_nonzero(est.missing)))),
        ("inconsistent steps", str(int(np.count_nonzero(est.inconsistent)))),
    ]
    if mean is not None:
        shown = ", ".join(f"{w:.4g}" for w in np.ravel(mean)[:8])
        rows.append(("mean width", shown + (" …" if est.nx > 8 else "")))
    img = ""
    if est.T > est.valid_from:
        img = f"<img alt='widths over time' src='data:image/png;base64,{_png(est)}'/>"
    return summary_html("ivobs Estimate", rows, img)
