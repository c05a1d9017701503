"""The ``ivobs`` command. Each subcommand is a module of this package defining
``add_parser(subparsers)`` and ``main(args) -> int``; modules are discovered automatically."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
from typing import Any

from ..errors import IvobsError

__all__ = ["main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ivobs",
        description="Guaranteed interval state estimation for linear systems.",
    )
    from .. import __version__

    parser.add_argument("--version", action="version", version=f"ivobs {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if mod.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{mod.name}")
        p = module.add_parser(sub)
        p.set_defaults(_main=module.main)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "_main", None):
        parser.print_help()
        return 2
    try:
        return int(args._main(args) or 0)
    except IvobsError as exc:
        print(f"ivobs: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # pragma: no cover
        return 130


def use_agg() -> Any:
    """Headless figures."""
    import matplotlib

    matplotlib.use("Agg")
    return matplotlib


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
