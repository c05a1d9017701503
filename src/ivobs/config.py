"""The defaults of the methods' options, in one registry (python-control's ``config.defaults``
is the model).

Each method's options and their defaults are those of its class's ``__init__`` signature (the
one source: nothing here copies them); :func:`defaults` lists them. :func:`set_defaults`
changes a default for the whole process (a session, a campaign, a test), :func:`using` for a
``with`` block, :func:`reset_defaults` undoes them. A changed default applies wherever the
option is not passed (``make_estimator``, a class called directly, ``intersect``'s members,
``ivobs.report.compare``, the commands run from Python, a campaign's jobs); an option passed
explicitly always wins. Values are checked by the method when it is built, as if passed there.
The registry belongs to the process (not to a thread). Examples: docs/options.md.

What each option does and when to change it: :func:`describe`, ``ivobs methods --options``
and docs/options.md (one text, :mod:`ivobs.estimators.option_notes`).
"""

from __future__ import annotations

import inspect
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any, NamedTuple

from .errors import IvobsError
from .estimators import Estimator, checked_options, get, methods
from .estimators._overrides import OVERRIDES

__all__ = [
    "OptionDoc",
    "defaults",
    "describe",
    "overrides",
    "reset_defaults",
    "set_defaults",
    "using",
]


class OptionDoc(NamedTuple):
    """One option of one method: its ``default`` (the class's signature), what it does,
    ``when`` to change it, and whether it is ``common`` to every method (declared by the base
    class and not redeclared by the method)."""

    method: str
    option: str
    default: Any
    what: str
    when: str
    common: bool


def defaults(method: str | None = None) -> dict[str, Any]:
    """The defaults in effect: the class's signature with this process's changes.

    ``method``: that method's ``{option: value}``, in the order of
    :meth:`Estimator.options`. ``None``: every method's, as ``{"method.option": value}`` (this
    imports every method's module). ``None`` as a value usually means "chosen by the design"
    (:func:`describe` says how)."""
    if method is None:
        return {f"{name}.{k}": v for name in methods() for k, v in defaults(name).items()}
    cls = get(method)
    return {**cls.option_defaults(), **OVERRIDES.get(cls.name, {})}


def overrides(method: str | None = None) -> dict[str, Any]:
    """Only what :func:`set_defaults` changed: ``{option: value}`` of ``method``, or
    ``{method: {option: value}}`` of every method changed (``None``). Copies."""
    if method is None:
        return {name: dict(opts) for name, opts in OVERRIDES.items() if opts}
    return dict(OVERRIDES.get(get(method).name, {}))


def set_defaults(method: str, **options: Any) -> None:
    """Change the defaults of ``method``'s options for this process, until
    :func:`reset_defaults`. Every name must be an option of the method
    (:class:`~ivobs.IvobsError` listing the accepted ones otherwise); the values are checked by
    the method when it is built, as if passed there."""
    cls = get(method)
    checked = checked_options(cls, options)
    if checked:
        OVERRIDES.setdefault(cls.name, {}).update(checked)


def reset_defaults(method: str | None = None, *options: str) -> None:
    """Back to the classes' defaults: every method's (``None``), one method's, or only the
    named ``options`` of one method."""
    if method is None:
        if options:
            raise IvobsError(
                f"options: name the method whose options to reset, got method=None and "
                f"{', '.join(map(repr, options))}"
            )
        OVERRIDES.clear()
        return
    cls = get(method)
    if not options:
        OVERRIDES.pop(cls.name, None)
        return
    checked_options(cls, dict.fromkeys(options))
    current = OVERRIDES.get(cls.name, {})
    for name in options:
        current.pop(name, None)
    if not current:
        OVERRIDES.pop(cls.name, None)


@contextmanager
def using(method: str, **options: Any) -> Iterator[dict[str, Any]]:
    """:func:`set_defaults` for the ``with`` block only: on leaving it (an exception too) the
    method's defaults are what they were before. Yields the method's defaults in effect."""
    cls = get(method)
    saved = dict(OVERRIDES[cls.name]) if cls.name in OVERRIDES else None
    set_defaults(cls.name, **options)
    try:
        yield defaults(cls.name)
    finally:
        if saved is None:
            OVERRIDES.pop(cls.name, None)
        else:
            OVERRIDES[cls.name] = saved


def describe(method: str | None = None) -> list[OptionDoc]:
    """Every option of ``method`` (of every method: ``None``), with the class's default, what
    it does and when to change it (:mod:`ivobs.estimators.option_notes`; empty texts for an
    option of a method defined outside ivobs that no note covers)."""
    from .estimators.option_notes import note

    names = methods() if method is None else [get(method).name]
    base = Estimator.option_defaults()
    out = []
    for name in names:
        cls = get(name)
        for option, default in cls.option_defaults().items():
            text = note(name, option)
            what, when = (text.what, text.when) if text else ("", "")
            common = option in base and _declared_by(cls, option) is Estimator
            out.append(OptionDoc(name, option, default, what, when, common))
    return out


def _declared_by(cls: type[Estimator], option: str) -> type:
    """The nearest class along ``cls``'s bases whose own ``__init__`` declares ``option``."""
    for klass in cls.__mro__:
        init = vars(klass).get("__init__")
        if init is not None and option in inspect.signature(init).parameters:
            return klass
    return Estimator  # pragma: no cover - option_defaults lists declared options only
