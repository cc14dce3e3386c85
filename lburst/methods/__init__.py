"""Every feature method is an *extractor*: a callable taking a burst and returning features.

An extractor is called as ``extractor(burst)`` with ``burst`` a uint8 or uint16 array
``(N, H, W, 3)`` in temporal order (N odd; single-image methods use the middle
frame) and returns a features dict (see :mod:`lburst.features`) for the common frame.
It has a ``name`` attribute.

A method is a :class:`Method` value, parsed once from its *spec* string (:meth:`Method.parse`)::

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
``lburst methods`` lists every method with its options.  Only this package reads the spec's
grammar: everything else takes the :class:`Method` (or a spec, turned into one at the edge by
:meth:`Method.of`) and asks it (its store key, its weights, its options, its extractor).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from lburst.features import Extractor
from lburst.methods.method import Method, method_slug
from lburst.methods.registry import MethodInfo, available, methods, register

__all__ = [
    "Extractor",
    "Method",
    "MethodInfo",
    "accepts",
    "available",
    "check",
    "create",
    "method_slug",
    "methods",
    "register",
    "weights_file",
]


def accepts(method: str | Method, option: str) -> bool:
    """Whether the method that ``method`` runs on the burst (inside any wrappers) has ``option``."""
    return Method.of(method).accepts(option)


def weights_file(method: str | Method) -> Path | None:
    """The checkpoint file that ``method`` loads (inside any wrappers), or ``None``."""
    return Method.of(method).weights_file()


def check(method: str | Method, **options: Any) -> None:
    """Raise ``LBurstValueError`` (one line) where :func:`create` would refuse ``method`` with
    ``options``, without creating anything (:meth:`Method.check`)."""
    Method.of(method).check(**options)


def create(method: str | Method, **options: Any) -> Extractor:
    """Create the extractor of ``method`` (a :class:`Method` or its spec, see the module docstring).

    Keyword ``options`` (strings or typed values, for example ``device``) are added to
    those in the spec of the method that runs on the burst (inside any wrappers).
    """
    return Method.of(method).create(**options)
