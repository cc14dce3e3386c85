"""Every feature method is an *extractor*: a callable taking a burst and returning features.

An extractor is called as ``extractor(burst)`` with ``burst`` a uint8 or uint16 array
``(N, H, W, 3)`` in temporal order (N odd; single-image methods use the middle
frame) and returns a features dict (see :mod:`lburst.features`) for the common frame.
It has a ``name`` attribute.

Methods are created from a *spec* string::

    NAME[:ARG][,KEY=VALUE...]

``NAME`` picks a factory from the registry, ``ARG`` is the factory's positional
argument (a checkpoint path for learned methods) and ``KEY=VALUE`` pairs are passed
as keyword arguments (as strings; each factory converts its own).  A spec starting
with ``merge+`` aligns and averages the burst first, then runs the rest of the spec
on the merged image (see :mod:`lburst.methods.merge`).  Examples: ``lburst``,
``lburst:weights.pt,frame_order=published``, ``sift``, ``orb,max_features=2000``,
``merge+sift``, ``buff``.
"""

from __future__ import annotations

import importlib
from typing import Callable

from lburst.features import Extractor

__all__ = ["Extractor", "Factory", "available", "create", "parse_spec", "register"]

Factory = Callable[..., Extractor]

_FACTORIES: dict[str, Factory] = {}

# modules that register factories when imported
_PROVIDERS = ("lburst.methods.learned", "lburst.methods.opencv", "lburst.methods.merge", "lburst.methods.buff")


def register(name: str) -> Callable[[Factory], Factory]:
    """Decorator: register ``factory(arg: str | None, **options: str) -> Extractor`` as ``name``."""

    def wrap(factory: Factory) -> Factory:
        _FACTORIES[name] = factory
        return factory

    return wrap


def _load_providers() -> None:
    for module in _PROVIDERS:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:  # a provider that exists but fails to import is a bug
                raise


def available() -> list[str]:
    """Names of the registered methods."""
    _load_providers()
    return sorted(_FACTORIES)


def parse_spec(spec: str) -> tuple[str, str | None, dict[str, str]]:
    """Split ``NAME[:ARG][,KEY=VALUE...]`` into its parts."""
    head, *pairs = spec.split(",")
    name, _, arg = head.partition(":")
    options = {}
    for pair in pairs:
        key, eq, value = pair.partition("=")
        if not eq or not key:
            raise ValueError(f"bad option {pair!r} in method spec {spec!r}: expected KEY=VALUE")
        options[key.strip()] = value.strip()
    return name.strip(), (arg or None), options


def create(spec: str, **options) -> Extractor:
    """Create the extractor described by ``spec`` (see the module docstring).

    Keyword ``options`` are added to those in the spec (for example ``device``).
    """
    _load_providers()
    if spec.startswith("merge+"):
        from lburst.methods.merge import MergeThen

        return MergeThen(create(spec[len("merge+") :], **options))
    name, arg, spec_options = parse_spec(spec)
    if name not in _FACTORIES:
        raise ValueError(f"unknown method {name!r} in {spec!r}; available: {', '.join(available())}")
    extractor = _FACTORIES[name](arg, **{**spec_options, **options})
    extractor.name = spec
    return extractor
