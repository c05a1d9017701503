"""Method options in files: the ``[method]`` table of a system file, the method grids of a
campaign spec, and how option values are written back.

An option value in TOML is a number, a string, a boolean, an array of numbers (read as a NumPy
array) or a table; a table ``{ lower = [...], upper = [...] }`` is a :class:`~ivobs.Box`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..errors import IvobsError
from ..sets import Box

if TYPE_CHECKING:
    from .reader import TomlReader

__all__ = ["method_class", "read_method", "read_option", "same_method"]


def method_class(reader: TomlReader, key: tuple[str, ...], name: str) -> Any:
    """The estimator class registered as ``name``; an unknown name is an error of ``key``."""
    from ..estimators import get

    try:
        return get(name)
    except IvobsError as exc:
        if str(exc).startswith(reader.source):
            raise
        raise reader.fail(key, str(exc).removeprefix("method: ")) from None


def check_option(reader: TomlReader, key: tuple[str, ...], cls: Any, option: str) -> None:
    """``option`` must be one of the keyword options of the method ``cls``."""
    allowed = cls.options()
    if option not in allowed:
        raise reader.fail(
            (*key, option),
            f"{cls.name} has no option {option!r}; accepted: {', '.join(allowed) or '(none)'}",
        )


def read_method(reader: TomlReader, tab: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The ``[method]`` table of a system file: ``name`` and the ``options`` table."""
    name = tab.get("name")
    if not isinstance(name, str):
        raise reader.fail(("method", "name"), f"expected a method name, got {name!r}")
    cls = method_class(reader, ("method", "name"), name)
    opts = tab.get("options", {})
    if not isinstance(opts, dict):
        raise reader.fail(("method", "options"), f"expected a table, got {opts!r}")
    out: dict[str, Any] = {}
    for k, v in opts.items():
        check_option(reader, ("method", "options"), cls, k)
        out[k] = read_option(reader, ("method", "options", k), v)
    return name, out


def read_option(reader: TomlReader, key: tuple[str, ...], v: Any) -> Any:
    """One option value: boxes and arrays of numbers as ivobs objects, the rest as given."""
    if isinstance(v, dict):
        if set(v) == {"lower", "upper"}:
            try:
                return Box(
                    reader.numbers((*key, "lower"), v["lower"], (1,)),
                    reader.numbers((*key, "upper"), v["upper"], (1,)),
                )
            except IvobsError as exc:
                raise reader.fail(key, str(exc)) from None
        return {k: read_option(reader, (*key, k), x) for k, x in v.items()}
    if (
        isinstance(v, list)
        and v
        and all(isinstance(x, (int, float, list)) and not isinstance(x, bool) for x in v)
    ):
        return reader.numbers(key, v, (1, 2, 3))
    return v


def same_method(a: str, b: str) -> bool:
    """Whether two spellings name the same method (case, ``_`` or ``-``)."""
    return a.strip().lower().replace("_", "-") == b.strip().lower().replace("_", "-")
