"""Method options: typed dataclasses, and converting the strings of a spec (``NAME,KEY=VALUE``) to them."""

from __future__ import annotations

import dataclasses
import types
import typing
from typing import Any

from lburst.errors import LBurstValueError


def as_bool(value: str | bool) -> bool:
    """``'1'/'true'/'yes'`` -> True, ``'0'/'false'/'no'`` -> False (case-insensitive)."""
    if isinstance(value, bool):
        return value
    if str(value).lower() in ("1", "true", "yes"):
        return True
    if str(value).lower() in ("0", "false", "no"):
        return False
    raise LBurstValueError(f"expected a boolean, got {value!r}")


def as_floats(value: str | tuple | list, count: int | None = None) -> tuple[float, ...]:
    """``'a:b'`` or ``'a;b'`` (colon/semicolon separated, since commas separate options) or a sequence -> floats."""
    if isinstance(value, str):
        parts = value.replace(";", ":").split(":")
        values = tuple(float(p) for p in parts if p.strip())
    else:
        values = tuple(float(v) for v in value)
    if count is not None and len(values) != count:
        raise LBurstValueError(f"expected {count} numbers, got {value!r}")
    return values


# --- typed method options -------------------------------------------------------------
#
# Each method declares its options as a dataclass; a spec string's ``KEY=VALUE`` pairs
# (strings) and keyword options from code (strings or typed values) become one instance
# of it through :func:`parse_options`, the one place that converts and checks them.


def _convert(value: Any, tp: Any, where: str) -> Any:
    """``value`` (a string from a spec, or already typed) as type ``tp``."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None or (isinstance(value, str) and value.lower() == "none" and type(None) in args):
            return None
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                return _convert(value, arg, where)
            except ValueError as exc:
                errors.append(str(exc))
        raise LBurstValueError(errors[0] if errors else f"{where}: bad value {value!r}")
    if origin is typing.Literal:
        if value not in args:
            raise LBurstValueError(f"{where}: expected one of {', '.join(map(str, args))}, got {value!r}")
        return value
    if origin is tuple:
        count = None if (len(args) == 2 and args[1] is Ellipsis) else len(args)
        try:
            return as_floats(value, count)
        except ValueError as exc:
            raise LBurstValueError(f"{where}: {exc} (write a:b)") from None
    if tp is bool:
        try:
            return as_bool(value)
        except ValueError:
            raise LBurstValueError(f"{where}: expected a boolean (true or false), got {value!r}") from None
    if tp in (int, float):
        if isinstance(value, bool):
            raise LBurstValueError(f"{where}: expected {tp.__name__}, got {value!r}")
        try:
            out = tp(value)
        except (TypeError, ValueError):
            raise LBurstValueError(f"{where}: expected {tp.__name__}, got {value!r}") from None
        if tp is int and isinstance(value, float) and out != value:
            raise LBurstValueError(f"{where}: expected int, got {value!r}")
        return out
    if tp is str:
        return str(value)
    raise TypeError(f"{where}: unsupported option type {tp!r}")


def _type_name(tp: Any) -> str:
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        return " | ".join(_type_name(a) for a in args)
    if origin is typing.Literal:
        return "|".join(map(str, args))
    if origin is tuple:
        return ":".join("float" for a in args if a is not Ellipsis) if Ellipsis not in args else "float:..."
    return "none" if tp is type(None) else getattr(tp, "__name__", str(tp))


def option_table(cls: type | None) -> list[tuple[str, str, Any]]:
    """``(name, type, default)`` of every option of the dataclass ``cls``."""
    if cls is None:
        return []
    hints = typing.get_type_hints(cls)
    return [
        (f.name, _type_name(hints[f.name]), f.default if f.default is not dataclasses.MISSING else None)
        for f in dataclasses.fields(cls)
    ]


def format_default(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, tuple):
        return ":".join(f"{v:g}" for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return "none" if value is None else str(value)


def describe_options(cls: type | None) -> str:
    """``name: type = default, ...`` for error messages and ``lburst methods``."""
    table = option_table(cls)
    return ", ".join(f"{n}: {t} = {format_default(d)}" for n, t, d in table) if table else "none"


def parse_pairs(pairs: list[str], spec: str, kind: str = "method") -> dict[str, str]:
    """The ``KEY=VALUE`` items of a method or matcher spec (``pairs``: the spec split at its
    commas, after the name) as strings by key; ``LBurstValueError`` for an item without ``=``
    or a key given twice.  The one parser of spec options, for methods and matchers alike."""
    options: dict[str, str] = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        if not eq or not key.strip():
            raise LBurstValueError(f"bad option {pair!r} in {kind} spec {spec!r}: expected KEY=VALUE")
        if key.strip() in options:
            raise LBurstValueError(f"option {key.strip()!r} given twice in {kind} spec {spec!r}")
        options[key.strip()] = value.strip()
    return options


def parse_options(cls: type | None, given: dict[str, Any], method: str, kind: str = "method") -> Any:
    """An instance of the options dataclass ``cls`` from ``given`` (strings or values).

    Raises ``ValueError`` naming the method, the bad option and every valid option with
    its type and default.
    """
    if cls is None:
        if given:
            raise LBurstValueError(f"{kind} {method!r} takes no options, got {', '.join(sorted(given))}")
        return None
    hints = typing.get_type_hints(cls)
    names = [f.name for f in dataclasses.fields(cls)]
    unknown = sorted(set(given) - set(names))
    if unknown:
        raise LBurstValueError(
            f"unknown options for {kind} {method!r}: {', '.join(unknown)}; valid: {describe_options(cls)}"
        )
    values = {}
    for key, value in given.items():
        try:
            values[key] = _convert(value, hints[key], f"option {key} of {kind} {method!r}")
        except ValueError as exc:
            raise LBurstValueError(f"{exc}; valid: {describe_options(cls)}") from None
    try:
        return cls(**values)
    except ValueError as exc:  # checks in __post_init__
        raise LBurstValueError(f"{kind} {method!r}: {exc}") from None
