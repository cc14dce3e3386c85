"""Every feature method is an *extractor*: a callable taking a burst and returning features.

An extractor is called as ``extractor(burst)`` with ``burst`` a uint8 or uint16 array
``(N, H, W, 3)`` in temporal order (N odd; single-image methods use the middle
frame) and returns a features dict (see :mod:`lburst.features`) for the common frame.
It has a ``name`` attribute.

Methods are created from a *spec* string::

    NAME[:ARG][,KEY=VALUE...]        a method
    WRAPPER[,KEY=VALUE...]+SPEC      a method that wraps the extractor of SPEC

``NAME`` picks a method from the registry, ``ARG`` is its positional argument (a
checkpoint path for learned methods; it may hold commas: it runs to the first
``,KEY=`` with KEY a name) and ``KEY=VALUE`` pairs are its options.  Each
method declares its options as a dataclass (:func:`register`); :func:`create` converts
and checks them in one place (:func:`lburst.methods.options.parse_options`), and an
error lists the valid options with their types and defaults.  A wrapper such as
``merge`` (align and average the burst, then run SPEC on the merged image) is a
registered method too.  Examples: ``lburst``, ``lburst:weights.pt,frame_order=published``,
``sift``, ``orb,max_features=2000``, ``merge+sift``, ``merge,reduce=median+orb``, ``buff``.
``lburst methods`` lists every method with its options.
"""

from __future__ import annotations

import hashlib
import importlib
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from lburst.errors import LBurstValueError
from lburst.features import Extractor
from lburst.methods.options import parse_options, parse_pairs

__all__ = [
    "Extractor",
    "MethodInfo",
    "Spec",
    "accepts",
    "available",
    "check",
    "create",
    "methods",
    "parse_spec",
    "register",
    "weights_file",
    "with_default",
    "with_given",
]

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


def _load_providers() -> None:
    for module in _PROVIDERS:
        try:
            importlib.import_module(module)
        except ModuleNotFoundError as exc:
            if exc.name != module:  # a provider that exists but fails to import is a bug
                raise


def methods() -> list[MethodInfo]:
    """Every registered method, by name."""
    _load_providers()
    return [_METHODS[n] for n in sorted(_METHODS)]


def available() -> list[str]:
    """Names of the registered methods."""
    return [m.name for m in methods()]


@dataclass(frozen=True)
class Spec:
    """A parsed method spec: ``name``, ``arg``, ``options`` (strings) and, for a wrapper, the ``inner`` spec."""

    text: str
    name: str
    arg: str | None
    options: dict[str, str]
    inner: Spec | None = None


_OPTION = re.compile(r"\s*[A-Za-z_]\w*\s*=")


def _split(head: str, spec: str) -> tuple[str, str | None, dict[str, str]]:
    first, *pairs = head.split(",")
    name, colon, arg = first.partition(":")
    while colon and pairs and not _OPTION.match(pairs[0]):  # a comma inside the checkpoint path
        arg += "," + pairs.pop(0)
    if colon and not arg.strip():
        raise LBurstValueError(
            f"method spec {spec!r}: nothing after {name.strip() + ':'!r} (a checkpoint file or a shipped name)"
        )
    return name.strip(), (arg or None), parse_pairs(pairs, spec)


def method_slug(spec: str) -> str:
    """A file or folder name for a method spec: its readable characters plus a short hash of
    the whole spec (specs may hold paths, and two specs never share a name)."""
    readable = re.sub(r"[^A-Za-z0-9+._=-]+", "_", spec.replace("../", "")).strip("_")[-40:]
    return f"{readable}-{hashlib.sha1(spec.encode()).hexdigest()[:6]}"


def parse_spec(spec: str) -> Spec:
    """Parse ``NAME[:ARG][,KEY=VALUE...]`` or ``WRAPPER[,KEY=VALUE...]+SPEC`` (module docstring)."""
    if not isinstance(spec, str):
        raise LBurstValueError(f"a method spec is a string such as 'lburst' or 'merge+sift', got {spec!r}")
    _load_providers()
    head, plus, rest = spec.partition("+")
    if plus:
        name, arg, options = _split(head, spec)
        info = _METHODS.get(name)
        if info is not None and info.wraps:
            if arg is not None:
                raise LBurstValueError(f"method {name!r} takes no argument, got {arg!r} in {spec!r}")
            return Spec(spec, name, None, options, parse_spec(rest))
    name, arg, options = _split(spec, spec)
    return Spec(spec, name, arg, options)


def _info(name: str, spec: str) -> MethodInfo:
    if name not in _METHODS:
        raise LBurstValueError(f"unknown method {name!r} in {spec!r}; available: {', '.join(available())}")
    return _METHODS[name]


def _innermost(spec: Spec) -> Spec:
    while spec.inner is not None:
        spec = spec.inner
    return spec


def accepts(spec: str, option: str) -> bool:
    """Whether the method that ``spec`` runs on the burst (inside any wrappers) has ``option``."""
    inner = _innermost(parse_spec(spec))
    options = _info(inner.name, spec).options
    return options is not None and option in options.__dataclass_fields__


def with_default(spec: str, option: str, value: Any) -> str:
    """``spec`` with ``option=value`` for the method it runs on the burst (inside any wrappers),
    where that method has ``option`` and ``spec`` does not set it: a default that depends on
    the input (:attr:`lburst.sfm.inputs.InputSource.keypoints`).  Otherwise, or with ``value``
    ``None``, ``spec`` itself."""
    if value is None or not accepts(spec, option) or option in _innermost(parse_spec(spec)).options:
        return spec
    return f"{spec},{option}={value}"  # the innermost method's options end the spec


def weights_file(spec: str) -> Path | None:
    """The checkpoint file that ``spec`` loads (inside any wrappers), or ``None``."""
    inner = _innermost(parse_spec(spec))
    info = _info(inner.name, spec)
    return info.weights(inner.arg) if info.weights is not None else None


def _options(spec: Spec, runtime: dict[str, Any]) -> Any:
    """The typed options of one level of ``spec`` (``runtime`` joins those of the method that
    runs on the burst, overriding the spec's); ``LBurstValueError`` for a bad name, argument or option."""
    info = _info(spec.name, spec.text)
    if info.wraps:
        return parse_options(info.options, spec.options, spec.name)
    if spec.arg is not None and info.arg is None:
        raise LBurstValueError(f"method {spec.name!r} takes no argument, got {spec.arg!r}")
    return parse_options(info.options, {**spec.options, **runtime}, spec.name)


def _build(spec: Spec, runtime: dict[str, Any]) -> Extractor:
    info = _info(spec.name, spec.text)
    options = _options(spec, runtime)
    extractor = info.factory(_build(spec.inner, runtime) if info.wraps else spec.arg, options)
    extractor.name = spec.text
    return extractor


def check(spec: str, **options: Any) -> None:
    """Raise ``LBurstValueError`` (one line) where :func:`create` would refuse ``spec`` with
    ``options`` for its names, arguments or option values, without creating anything (no weights
    are read): a bad spec is refused before any work, where the extractor is created later or
    elsewhere (on first use, on a cluster's workers)."""
    level: Spec | None = parse_spec(spec)
    while level is not None:
        _options(level, options)
        level = level.inner


def with_given(spec: str, option: str, value: Any, flag: str) -> str:
    """``spec`` with ``option=value`` given outside it (``flag``, a command-line option) for the
    method it runs on the burst (inside any wrappers); ``spec`` itself when ``value`` is ``None``,
    when that method has no such option, or when the spec sets the same value.  A spec that sets
    another value is refused (``LBurstValueError`` naming both): neither silently wins."""
    if value is None or not accepts(spec, option):
        return spec
    inner = _innermost(parse_spec(spec))
    if option not in inner.options:
        return f"{spec},{option}={value}"  # the innermost method's options end the spec
    cls = _info(inner.name, spec).options
    own = getattr(parse_options(cls, {option: inner.options[option]}, inner.name), option)
    if own != getattr(parse_options(cls, {option: value}, inner.name), option):
        raise LBurstValueError(
            f"{flag} {value} and {option}={inner.options[option]} in method spec {spec!r} disagree; give one of them"
        )
    return spec


def create(spec: str, **options: Any) -> Extractor:
    """Create the extractor described by ``spec`` (see the module docstring).

    Keyword ``options`` (strings or typed values, for example ``device``) are added to
    those in the spec of the method that runs on the burst (inside any wrappers).
    """
    return _build(parse_spec(spec), options)
