"""``ivobs methods``: the estimation methods, their papers and what each supports.

Everything printed comes from the estimator classes' attributes (``name``, ``order``,
``summary``, ``reference``, ``data_used``, ``needs_x0``, ``supports_*``): the one source of
the README's methods table too (``ivobs methods --markdown`` prints it).
"""

from __future__ import annotations

import argparse
import re
from typing import Any

__all__ = ["COLUMNS", "add_parser", "main", "markdown_table", "paper_keys", "rows"]

COLUMNS = ("method", "paper", "data used", "needs x0", "time-varying", "continuous")
"""The table's columns (``--markdown`` adds the one-line summary after ``method``)."""


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "methods",
        help="list the estimation methods",
        description="List the estimation methods in the papers' order: the papers they come "
        "from (reference keys of docs/references.md), the data the box of x[k] uses (filter: "
        "u[0..k], y[0..k]; prediction: u[0..k-1], y[0..k-1]), whether a prior box x0 is "
        "needed, and whether time-varying and continuous-time systems are supported.",
    )
    p.add_argument(
        "--markdown",
        action="store_true",
        help="print the README's methods table (Markdown) instead",
    )
    return p


_KEY = re.compile(r"\[([A-Z][A-Za-z]+[0-9]{4})")


def _yes(flag: bool) -> str:
    return "yes" if flag else "no"


def paper_keys(reference: str) -> str:
    """The reference keys a ``reference`` attribute cites (``"[Tang2019, Algorithm 1]"`` ->
    ``"Tang2019"``), comma-separated; ``"—"`` when it cites none."""
    keys = list(dict.fromkeys(_KEY.findall(reference)))
    return ", ".join(keys) if keys else "—"


def rows() -> list[dict[str, str]]:
    """One row per method, in ``ivobs.methods()`` order, read from the estimator classes."""
    from ..estimators import get, methods

    out = []
    for name in methods():
        cls = get(name)
        out.append(
            {
                "method": name,
                "summary": cls.summary,
                "paper": paper_keys(cls.reference),
                "reference": cls.reference,
                "data used": cls.data_used,
                "needs x0": _yes(cls.needs_x0),
                "time-varying": _yes(cls.supports_time_varying),
                "continuous": _yes(cls.supports_continuous),
            }
        )
    return out


def markdown_table() -> str:
    """The README's methods table (the ``paper`` column holds the whole ``reference``)."""
    head = ["method", "what it does", *COLUMNS[1:]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows():
        cells = [f"`{row['method']}`", row["summary"], row["reference"]]
        cells += [row[c] for c in COLUMNS[2:]]
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines)


def _text_table(table: list[dict[str, str]]) -> str:
    """Aligned columns, each method's summary and reference indented on the line below."""
    widths = {c: max(len(c), *(len(r[c]) for r in table)) for c in COLUMNS}
    lines = ["  ".join(c.ljust(widths[c]) for c in COLUMNS).rstrip()]
    for row in table:
        lines.append("  ".join(row[c].ljust(widths[c]) for c in COLUMNS).rstrip())
        lines.append(f"    {row['summary']}  {row['reference']}")
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    table = rows()
    if not table:
        print("(no methods installed)")
        return 0
    print(markdown_table() if args.markdown else _text_table(table))
    return 0
