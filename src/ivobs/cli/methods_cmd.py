"""``ivobs methods``: the estimation methods, their papers and what each supports.

Everything printed comes from the estimator classes' attributes (``name``, ``order``,
``summary``, ``reference``, ``data_used``, ``needs_x0``, ``supports_*``): the one source of
the README's methods table too (``ivobs methods --markdown`` prints it).

``ivobs methods --options [METHOD]`` lists every option with its default (the classes'
signatures) and what it does and when to change it (:func:`ivobs.config.describe`);
``--options --markdown`` prints the tables of docs/options.md.
"""

from __future__ import annotations

import argparse
import re
import textwrap
from typing import Any

__all__ = [
    "COLUMNS",
    "add_parser",
    "main",
    "markdown_table",
    "options_markdown",
    "options_text",
    "paper_keys",
    "rows",
    "show_default",
]

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
        help="print the README's methods table (Markdown) instead (with --options: the tables "
        "of docs/options.md)",
    )
    p.add_argument(
        "--options",
        nargs="?",
        const="",
        default=None,
        metavar="METHOD",
        help="list the options of every method (or of METHOD): the default, what it does and "
        "when to change it (ivobs.config.set_defaults changes a default in Python)",
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

    return [
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
        for name, cls in ((name, get(name)) for name in methods())
    ]


def markdown_table() -> str:
    """The README's methods table (the ``paper`` column holds the whole ``reference``)."""
    head = ["method", "what it does", *COLUMNS[1:]]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for row in rows():
        cells = [f"`{row['method']}`", row["summary"], row["reference"]]
        cells += [row[c] for c in COLUMNS[2:]]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return "\n".join(lines)


def _text_table(table: list[dict[str, str]]) -> str:
    """Aligned columns, each method's summary and reference indented on the line below."""
    widths = {c: max(len(c), *(len(r[c]) for r in table)) for c in COLUMNS}
    lines = ["  ".join(c.ljust(widths[c]) for c in COLUMNS).rstrip()]
    for row in table:
        lines.append("  ".join(row[c].ljust(widths[c]) for c in COLUMNS).rstrip())
        lines.append(f"    {row['summary']}  {row['reference']}")
    return "\n".join(lines)


def show_default(value: Any) -> str:
    """A default as Python writes it (``'auto'``, ``None``, ``16``; ``1e+07`` for large
    floats)."""
    if isinstance(value, float) and "e" in format(value, "g"):
        return format(value, "g")
    return repr(value)


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def _table(docs: list[Any]) -> list[str]:
    lines = ["| option | default | what it does | when to change it |", "|---|---|---|---|"]
    for d in docs:
        cells = [f"`{d.option}`", f"`{show_default(d.default)}`", d.what, d.when]
        lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
    return lines


def options_markdown(method: str | None = None) -> str:
    """The tables of docs/options.md: the options every method has, then each method's own
    (:func:`ivobs.config.describe`); for one ``method``, its table of every option."""
    from ..config import describe

    if method is not None:
        return "\n".join(_table(describe(method)))
    docs = describe()
    common = {d.option: d for d in docs if d.common}
    lines = ["## Every method", "", *_table(list(common.values()))]
    for name in dict.fromkeys(d.method for d in docs):
        own = [d for d in docs if d.method == name and not d.common]
        lines += ["", f"## `{name}`", ""]
        lines += _table(own) if own else ["No options of its own (those of every method only)."]
        shared = [d.option for d in docs if d.method == name and d.common]
        if own and shared:
            lines += ["", f"And those of every method: {', '.join(f'`{o}`' for o in shared)}."]
    return "\n".join(lines)


def options_text(method: str | None = None, width: int = 100) -> str:
    """Every option of ``method`` (of every method: ``None``), its default, what it does and
    when to change it, wrapped to ``width`` columns."""
    from ..config import describe

    def wrap(text: str) -> list[str]:
        return textwrap.wrap(text.replace("`", ""), width, initial_indent="      ",
                             subsequent_indent="      ")  # fmt: skip

    lines: list[str] = []
    current = None
    for d in describe(method):
        if d.method != current:
            lines += ([""] if current else []) + [d.method]
            current = d.method
        lines.append(f"  {d.option} = {show_default(d.default)}")
        lines += wrap(d.what) if d.what else []
        lines += wrap(f"When to change it: {d.when}") if d.when else []
    return "\n".join(lines)


def main(args: argparse.Namespace) -> int:
    if args.options is not None:
        method = args.options or None
        print(options_markdown(method) if args.markdown else options_text(method))
        return 0
    table = rows()
    if not table:
        print("(no methods installed)")
        return 0
    print(markdown_table() if args.markdown else _text_table(table))
    return 0
