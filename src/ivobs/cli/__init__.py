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
        description=(
            "Guaranteed interval state estimation for linear systems (exact or interval "
            "matrices, discrete or continuous time) and nonlinear systems."
        ),
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


def check_disturbance(kind: str) -> str:
    """``--disturbance``: one of the scenario disturbance kinds."""
    from ..scenarios import DISTURBANCES

    if kind not in (*DISTURBANCES, "center"):
        raise IvobsError(
            f"--disturbance: unknown kind {kind!r}; expected one of {', '.join(DISTURBANCES)}"
        )
    return kind


def check_seed(seed: int) -> int:
    """``--seed``: a non-negative integer (NumPy's random generators refuse negative seeds)."""
    if seed < 0:
        raise IvobsError(f"--seed: expected an integer >= 0, got {seed}")
    return seed


def check_out_dir(path: str, what: str) -> None:
    """An output folder (created if needed): refuse an existing file, or a missing parent."""
    import os

    if os.path.exists(path) and not os.path.isdir(path):
        raise IvobsError(f"{what}: {path!r} exists and is not a folder; give a folder name")
    parent = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(path) and not os.path.isdir(parent):
        raise IvobsError(f"{what}: cannot create {path!r}: the folder {parent!r} does not exist")


def check_outputs(args: argparse.Namespace, names: tuple[str, ...]) -> dict[str, Any]:
    """The output options ``names`` (``csv``, ``plot``, ``html``, ``json``) checked before any
    work, a bad path failing fast (``--plot``: a figure's, ``.png`` added without extension);
    returns the files written by option, for :func:`~ivobs.io.atomic.check_distinct`
    (``--json -``, ``--html -``: standard output, not a file)."""
    from ..io.atomic import check_output_path
    from ..report.plot import figure_path

    for opt in names:
        value = getattr(args, opt)
        if value and not (value == "-" and opt in ("html", "json")):
            check = figure_path if opt == "plot" else check_output_path
            setattr(args, opt, str(check(value, f"--{opt}")))
    return {f"--{o}": None if o == "json" and args.json == "-" else getattr(args, o) for o in names}


def add_trust_option(p: argparse.ArgumentParser) -> None:
    """``--allow-code``: let a system file or a campaign spec run Python code (callables
    ``{ python = "module:function" }`` outside ``ivobs.scenarios``, ``imports = [...]``)."""
    p.add_argument(
        "--allow-code",
        action="store_true",
        help='trust the file: allow the Python code it names (python = "module:function" '
        "callables outside ivobs.scenarios, a spec's imports); off by default, loading a file "
        "runs no code",
    )


def parse_states(text: str, nx: int) -> list[int]:
    """``--states 1,3``: 1-based state numbers -> 0-based indices, each in ``1..nx``."""
    out: list[int] = []
    for part in text.split(","):
        s = part.strip()
        try:
            i = int(s)
        except ValueError:
            raise IvobsError(
                f"--states: expected comma-separated state numbers 1..{nx}, got {s!r}"
            ) from None
        if not 1 <= i <= nx:
            raise IvobsError(f"--states: expected state numbers 1..{nx} (nx = {nx}), got {i}")
        out.append(i - 1)
    return out


def use_agg() -> None:
    """Headless figures."""
    import matplotlib

    matplotlib.use("Agg")


def add_option_argument(p: argparse.ArgumentParser, *, per_method: bool) -> None:
    """``--option [METHOD.]KEY=VALUE``, repeatable: a design option of a method, as in the API
    and in a system file's ``[method.options]``."""
    what = "METHOD.KEY=VALUE" if per_method else "KEY=VALUE"
    p.add_argument(
        "--option",
        action="append",
        default=[],
        metavar=what,
        help=f"a method's design option ({what}; repeatable), as make_estimator(..., KEY=VALUE) "
        "takes it and a system file's [method.options] holds it; VALUE is a Python literal "
        "(2, 0.5, true, 'radius', [1, 2]) or else a string",
    )


def parse_options(items: list[str], methods: list[str] | None) -> dict[str, dict[str, Any]]:
    """``[METHOD.]KEY=VALUE`` items as ``{method: {key: value}}`` (``methods``: the methods
    the command runs; a single method takes ``KEY=VALUE`` alone). Values are literals read by
    :func:`ast.literal_eval` (never executed), ``true``/``false`` as booleans, else strings."""
    import ast

    out: dict[str, dict[str, Any]] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip():
            raise IvobsError(f"--option: expected [METHOD.]KEY=VALUE, got {item!r}")
        method, dot, name = key.strip().rpartition(".")
        if not dot:
            if methods is None or len(methods) != 1:
                raise IvobsError(
                    f"--option: {item!r} names no method; write METHOD.{key.strip()}=VALUE"
                )
            method = methods[0]
        elif methods is not None and method not in methods:
            raise IvobsError(
                f"--option: {item!r} is for {method!r}, which this command does not run "
                f"({', '.join(methods)})"
            )
        text = text.strip()
        lowered = text.lower()
        if lowered in ("true", "false"):
            value: Any = lowered == "true"
        else:
            try:
                value = ast.literal_eval(text)
            except (ValueError, SyntaxError):
                value = text
        out.setdefault(method, {})[name] = value
    return out
