"""``ivobs scenarios`` and ``ivobs methods``: what is available."""

from __future__ import annotations

import argparse
from typing import Any


def add_parser(sub: Any) -> argparse.ArgumentParser:
    p: argparse.ArgumentParser = sub.add_parser(
        "scenarios",
        help="list the papers' example systems",
        description="List the scenarios (paper examples) by name.",
    )
    return p


def main(args: argparse.Namespace) -> int:
    from .. import scenarios

    width = max(len(n) for n in scenarios.names())
    for name, summary in scenarios.summaries().items():
        print(f"{name:<{width}}  {summary}")
    return 0
