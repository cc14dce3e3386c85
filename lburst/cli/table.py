"""Argument tables: a command's options as rows (:class:`Option`), each the flag of one field of
an options dataclass, added to a parser by :func:`add_options` and read back as that
dataclass's keywords by :func:`given`, so that a flag, its field and its conversion are written
once and two commands that share options share their rows."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class Option:
    """``flag`` sets the dataclass field ``name`` (``None``: a flag of the command alone, read by
    its own code); ``kwargs`` are :meth:`argparse.ArgumentParser.add_argument`'s (``type``,
    ``help``, ``default``, ...); ``read`` turns the parsed value into the field's (it gets
    ``None`` when the flag is not given)."""

    flag: str
    name: str | None
    kwargs: dict[str, Any] = field(default_factory=dict)
    read: Callable[[Any], Any] | None = None
    group: str | None = None  # options of one mutually exclusive group share its name

    @property
    def dest(self) -> str:
        return self.kwargs.get("dest", self.flag.lstrip("-").replace("-", "_"))


def add_options(parser, options: Iterable[Option]) -> None:
    """Each of ``options`` on ``parser`` (or an argument group), in order; the options of one
    ``group`` in one mutually exclusive group."""
    groups: dict[str, Any] = {}
    for option in options:
        target = parser
        if option.group is not None:
            if option.group not in groups:
                groups[option.group] = parser.add_mutually_exclusive_group()
            target = groups[option.group]
        target.add_argument(option.flag, **option.kwargs)


def given(args: argparse.Namespace, options: Iterable[Option]) -> dict[str, Any]:
    """``{field: value}`` of ``options`` as parsed in ``args`` (each through its ``read``), one
    entry per field."""
    values = {}
    for option in options:
        if option.name is not None:
            value = getattr(args, option.dest)
            values[option.name] = option.read(value) if option.read is not None else value
    return values


def optional_tuple(value) -> tuple | None:
    """A list of ``nargs`` values as a tuple (``None`` or empty: not given)."""
    return tuple(value) if value else None


def true_or_none(value: bool) -> bool | None:
    """A ``store_true`` flag: ``True`` when given, else ``None`` (not given)."""
    return value or None
