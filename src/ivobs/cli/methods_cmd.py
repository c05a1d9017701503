"""``ivobs methods``: the estimation methods and their papers."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub: Any) -> argparse.ArgumentParser:
    return sub.add_parser(
        "methods",
        help="list the estimation methods",
        description="List the estimation methods and where they come from.",
    )


def main(args: argparse.Namespace) -> int:
    from ..estimators import get, methods

    names = methods()
    if not names:
        print("(no methods installed)")
        return 0
    width = max(len(n) for n in names)
    for name in names:
        cls = get(name)
        print(f"{name:<{width}}  {cls.summary}  [{cls.reference}]")
    return 0
