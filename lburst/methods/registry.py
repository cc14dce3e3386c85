"""The registry of feature methods: each method's name, factory, options and weights (:func:`register`)."""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from lburst.errors import LBurstValueError
from lburst.features import Extractor

Factory = Callable[..., Extractor]

_METHODS: dict[str, MethodInfo] = {}

# modules that register methods when imported
_PROVIDERS = ("lburst.methods.learned", "lburst.methods.opencv", "lburst.methods.merge", "lburst.methods.buff")


@dataclass(frozen=True)
class MethodInfo:
    """A registered method.

    Attributes:
        name: its name in specs.
        factory: ``factory(arg, options)`` (``factory(inner_extractor, options)`` for a
            wrapper) returning the extractor; ``options`` is an instance of ``options``.
        options: the options dataclass (``None``: no options).
        arg: what the spec's ``ARG`` is (e.g. ``'checkpoint'``); ``None``: it takes none.
        wraps: a wrapper, written ``NAME+SPEC``.
        weights: ``weights(arg)``: the checkpoint file a spec with this ``arg`` loads
            (results are cached by its content); ``None`` for methods without weights.
        summary: one line for ``lburst methods``.
    """

    name: str
    factory: Callable[..., Extractor]
    options: type | None = None
    arg: str | None = None
    wraps: bool = False
    weights: Callable[[str | None], Path | None] | None = None
    summary: str = ""


def register(
    name: str,
    options: type | None = None,
    *,
    arg: str | None = None,
    wraps: bool = False,
    weights: Callable[[str | None], Path | None] | None = None,
) -> Callable[[Factory], Factory]:
    """Decorator: register ``factory`` as method ``name`` (see :class:`MethodInfo`)."""

    def wrap(factory: Factory) -> Factory:
        summary = (factory.__doc__ or "").strip().splitlines()[0] if factory.__doc__ else ""
        _METHODS[name] = MethodInfo(name, factory, options, arg, wraps, weights, summary)
        return factory

    return wrap


def load_providers() -> None:
    """Import the modules that register the methods (once; a provider whose optional extra is missing is skipped)."""
    for module in _PROVIDERS:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:  # a provider that exists but fails to import is a bug
                raise


def methods() -> list[MethodInfo]:
    """Every registered method, by name."""
    load_providers()
    return [_METHODS[n] for n in sorted(_METHODS)]


def available() -> list[str]:
    """Names of the registered methods."""
    return [m.name for m in methods()]


def registered(name: str) -> MethodInfo | None:
    """The registered method ``name``, or ``None``."""
    load_providers()
    return _METHODS.get(name)


def method_info(name: str, spec: str) -> MethodInfo:
    """The registered method ``name`` of the spec ``spec``; ``LBurstValueError`` listing the known ones."""
    info = registered(name)
    if info is None:
        raise LBurstValueError(f"unknown method {name!r} in {spec!r}; available: {', '.join(available())}")
    return info
