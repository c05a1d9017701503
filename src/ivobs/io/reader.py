"""The TOML reader behind system files and campaign specs: errors that name the file, the line
and the key (``tomllib`` gives values without positions; :class:`KeyLines` finds them).

What a file may hold is bounded before anything is built from it: integers within TOML's
64-bit range ([TOML 1.0]: larger ones "must" be an error; beyond the float range they would
not convert), values nested at most :data:`MAX_DEPTH` deep. A UTF-8 byte-order mark is
skipped, as in logs."""

from __future__ import annotations

import re
import tomllib
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import IvobsError

__all__ = ["MAX_DEPTH", "KeyLines", "TomlReader", "check_toml_values"]

MAX_DEPTH = 20
"""Deepest nesting of tables and arrays a system file or a campaign spec may hold (theirs is at
most 6: ``method.options.NAME.lower`` of a box, a time-varying matrix's 3-D array)."""

_INT64 = 2**63


class KeyLines:
    """Line numbers of the keys of a TOML text (for semantic errors: tomllib has no positions)."""

    _HEADER = re.compile(r"^\s*\[\s*([^\[\]]+?)\s*\]\s*(#.*)?$")
    _PART = r'(?:[A-Za-z0-9_-]+|"[^"]*"|\'[^\']*\')'
    _KEY = re.compile(rf"^\s*({_PART}(?:\s*\.\s*{_PART})*)\s*=")
    _INLINE = re.compile(rf"({_PART})\s*=")

    def __init__(self, text: str):
        self.lines = text.splitlines()
        self.where: dict[tuple[str, ...], int] = {}
        table: tuple[str, ...] = ()
        for i, line in enumerate(self.lines, start=1):
            m = self._HEADER.match(line)
            if m:
                table = self._split(m.group(1))
                self.where.setdefault(table, i)
                continue
            m = self._KEY.match(line)
            if m:
                key = table + self._split(m.group(1))
                self.where.setdefault(key, i)
                brace = line.find("{", m.end())
                if brace >= 0:  # keys of an inline table on the same line
                    for sub in self._INLINE.finditer(line, brace):
                        self.where.setdefault(key + self._split(sub.group(1)), i)

    @staticmethod
    def _split(dotted: str) -> tuple[str, ...]:
        parts = re.findall(r'"[^"]*"|\'[^\']*\'|[^.\s]+', dotted)
        return tuple(p[1:-1] if p[:1] in "\"'" else p for p in parts)

    def line(self, key: tuple[str, ...]) -> int | None:
        for n in range(len(key), -1, -1):
            if key[:n] in self.where:
                return self.where[key[:n]]
        return None


class TomlReader:
    """A parsed TOML text and its key -> line map; :meth:`fail` builds the error of a key.

    Subclasses validate one kind of file (system files, campaign specs)."""

    def __init__(self, text: str, source: str):
        self.source = source
        text = text.removeprefix("\ufeff")  # a byte-order mark (Windows editors), as in logs
        self.lines = KeyLines(text)
        try:
            self.doc: dict[str, Any] = tomllib.loads(text)
        except RecursionError:
            raise IvobsError(
                f"{source}: not valid TOML here: arrays or tables nested too deeply (at most "
                f"{MAX_DEPTH} levels)"
            ) from None
        except ValueError as exc:  # e.g. an integer of more than 4300 digits (int(str) limit)
            if isinstance(exc, tomllib.TOMLDecodeError):
                raise self._syntax(exc) from None
            raise IvobsError(f"{source}: not valid TOML ({exc})") from None
        check_toml_values(self.doc, self.fail)

    def _syntax(self, exc: tomllib.TOMLDecodeError) -> IvobsError:
        """The error of a syntax error, with the line it is on (this file's own line)."""
        m = re.search(r"line (\d+)", str(exc))
        shown = ""
        if m and 1 <= int(m.group(1)) <= len(self.lines.lines):
            shown = f": {self.lines.lines[int(m.group(1)) - 1].strip()[:200]!r}"
        where = f", line {m.group(1)}" if m else ""
        return IvobsError(f"{self.source}{where}: not valid TOML ({exc}){shown}")

    def fail(self, key: tuple[str, ...], msg: str) -> IvobsError:
        """The error of ``key``: ``source, line N: dotted.key: msg``."""
        line = self.lines.line(key)
        where = f", line {line}" if line else ""
        label = ".".join(key) if key else "(top level)"
        return IvobsError(f"{self.source}{where}: {label}: {msg}")

    # -- values ---------------------------------------------------------------------------
    def numbers(self, key: tuple[str, ...], value: Any, ndims: tuple[int, ...]) -> np.ndarray:
        """A rectangular array of numbers whose dimension is one of ``ndims``."""
        shape = self._shape(key, value, ())
        if len(shape) not in ndims:
            what = {1: "a list of numbers", 2: "an array of rows (e.g. [[1.0, 0.0]])"}
            exp = " or ".join(what.get(n, f"a {n}-D array") for n in ndims)
            raise self.fail(key, f"expected {exp}, got a {len(shape)}-D value of shape {shape}")
        return np.array(value, dtype=float).reshape(shape)

    def _shape(self, key: tuple[str, ...], value: Any, index: tuple[int, ...]) -> tuple[int, ...]:
        at = "".join(f"[{i}]" for i in index)
        if isinstance(value, bool) or isinstance(value, (str, dict)) or value is None:
            raise self.fail(key, f"entry {at or '(value)'}: expected a number, got {value!r}")
        if isinstance(value, (int, float)):
            return ()
        if not isinstance(value, list):  # pragma: no cover - tomllib gives no other types
            raise self.fail(key, f"entry {at}: unexpected {type(value).__name__}")
        if not value:
            return (0,)
        shapes = [self._shape(key, v, (*index, i)) for i, v in enumerate(value)]
        for i, s in enumerate(shapes):
            if s != shapes[0]:
                raise self.fail(
                    key,
                    f"ragged array: row {at}[{i}] has shape {s}, row {at}[0] has {shapes[0]}",
                )
        return (len(value), *shapes[0])


def check_toml_values(doc: dict[str, Any], fail: Callable[..., IvobsError]) -> None:
    """Refuse integers outside TOML's 64-bit range and values nested more than
    :data:`MAX_DEPTH` deep (walked without recursion: a deep file cannot exhaust the stack);
    ``fail(key, msg)`` builds the error of a key."""
    todo: list[tuple[tuple[str, ...], Any, int]] = [((), doc, 0)]
    while todo:
        key, value, depth = todo.pop()
        if depth > MAX_DEPTH:
            raise fail(key, f"nested more than {MAX_DEPTH} levels deep")
        if isinstance(value, dict):
            todo.extend(((*key, str(k)), v, depth + 1) for k, v in value.items())
        elif isinstance(value, list):
            todo.extend((key, v, depth + 1) for v in value)
        elif isinstance(value, int) and not isinstance(value, bool):
            if not -_INT64 <= value < _INT64:
                raise fail(
                    key,
                    f"an integer of {value.bit_length()} bits, beyond TOML's 64-bit range "
                    f"(-2**63 to 2**63 - 1)",
                )
