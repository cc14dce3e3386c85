"""A feature method as a value: :class:`Method`, parsed once from its spec (``NAME[:ARG][,KEY=VALUE...]``,
``WRAPPER[,KEY=VALUE...]+SPEC``: :mod:`lburst.methods`), and everything a run derives from it.

A command parses its ``--method`` into a :class:`Method` (an argparse ``type``), the Python API
takes a spec or a :class:`Method` (:meth:`Method.of`); from then on the value travels: it gives
the features store its key (:meth:`Method.results_key`), names a benchmark's results
(:meth:`Method.slug`) and a demo's (:meth:`Method.label`), ships to cluster workers (it pickles)
and creates the extractor (:meth:`Method.create`).  ``str(method)`` is its canonical spec, the
text the store and the results have always been keyed by: for a spec written without spaces
around its names, ``=`` and commas, the spec itself.
"""

from __future__ import annotations

import hashlib
import re
from dataclasses import MISSING, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from lburst.burst.io import file_sha1
from lburst.errors import LBurstValueError
from lburst.features import Extractor
from lburst.methods.options import parse_options, parse_pairs
from lburst.methods.registry import MethodInfo, method_info, registered

_OPTION = re.compile(r"\s*[A-Za-z_]\w*\s*=")


def _split(head: str, spec: str) -> tuple[str, str | None, dict[str, str]]:
    """``NAME[:ARG][,KEY=VALUE...]`` of ``spec`` (``head``: one level of it) as its name, argument and options."""
    first, *pairs = head.split(",")
    name, colon, arg = first.partition(":")
    while colon and pairs and not _OPTION.match(pairs[0]):  # a comma inside the checkpoint path
        arg += "," + pairs.pop(0)
    if colon and not arg.strip():
        raise LBurstValueError(
            f"method spec {spec!r}: nothing after {name.strip() + ':'!r} (a checkpoint file or a shipped name)"
        )
    return name.strip(), (arg or None), parse_pairs(pairs, spec)


def method_slug(text: str) -> str:
    """A file or folder name for a method's text (:meth:`Method.results_key`): its readable characters
    plus a short hash of the whole text (it may hold paths, and two texts never share a name)."""
    readable = re.sub(r"[^A-Za-z0-9+._=-]+", "_", text.replace("../", "")).strip("_")[-40:]
    return f"{readable}-{hashlib.sha1(text.encode()).hexdigest()[:6]}"


@dataclass(frozen=True, repr=False)
class Method:
    """A feature method: ``name`` (a registered method), its ``arg`` (a checkpoint; ``None``: none),
    its ``options`` as given (``(KEY, VALUE)`` strings in the spec's order; a dict is taken too) and,
    for a wrapper such as ``merge``, the ``inner`` method it runs on the burst it makes.

    Frozen, hashable and picklable; two methods are equal when their specs are.  Options are
    kept as their spec's text, so that the store's key and the results' names stay those of the
    spec; :meth:`check` and :meth:`create` convert them (:func:`lburst.methods.options.parse_options`).
    """

    name: str
    arg: str | None = None
    options: tuple[tuple[str, str], ...] = field(default=())
    inner: Method | None = None

    def __post_init__(self) -> None:
        pairs = self.options.items() if isinstance(self.options, dict) else self.options
        object.__setattr__(self, "options", tuple((str(k), str(v)) for k, v in pairs))

    # --- the spec -----------------------------------------------------------------------

    @classmethod
    def parse(cls, spec: str) -> Method:
        """The method of ``spec``: ``NAME[:ARG][,KEY=VALUE...]`` or ``WRAPPER[,KEY=VALUE...]+SPEC``
        (:mod:`lburst.methods`); ``LBurstValueError`` (one line) for a spec that breaks the grammar.
        Names and option values are checked by :meth:`check` (or :meth:`create`)."""
        if not isinstance(spec, str):
            raise LBurstValueError(f"a method spec is a string such as 'lburst' or 'merge+sift', got {spec!r}")
        head, plus, rest = spec.partition("+")
        if plus:
            name, arg, options = _split(head, spec)
            info = registered(name)
            if info is not None and info.wraps:
                if arg is not None:
                    raise LBurstValueError(f"method {name!r} takes no argument, got {arg!r} in {spec!r}")
                return cls(name, None, options, cls.parse(rest))
        name, arg, options = _split(spec, spec)
        return cls(name, arg, options)

    @classmethod
    def of(cls, method: str | Method) -> Method:
        """``method`` itself, or the method of a spec (:meth:`parse`): what the Python API takes."""
        return method if isinstance(method, Method) else cls.parse(method)

    def __str__(self) -> str:
        text = self.name + (f":{self.arg}" if self.arg is not None else "")
        text += "".join(f",{key}={value}" for key, value in self.options)
        return text if self.inner is None else f"{text}+{self.inner}"

    def __repr__(self) -> str:
        return f"Method.parse({str(self)!r})"

    # --- what it is ---------------------------------------------------------------------

    @property
    def innermost(self) -> Method:
        """The method that runs on the burst, inside any wrappers (itself without any)."""
        level = self
        while level.inner is not None:
            level = level.inner
        return level

    @property
    def given(self) -> dict[str, str]:
        """This level's options as given, by name."""
        return dict(self.options)

    def info(self) -> MethodInfo:
        """The registered method of this level; ``LBurstValueError`` for an unknown name."""
        return method_info(self.name, str(self))

    def accepts(self, option: str) -> bool:
        """Whether the method that runs on the burst (inside any wrappers) has ``option``."""
        options = method_info(self.innermost.name, str(self)).options
        return options is not None and option in options.__dataclass_fields__

    def weights_file(self) -> Path | None:
        """The checkpoint file the method loads (inside any wrappers), or ``None``."""
        inner = self.innermost
        info = method_info(inner.name, str(self))
        return info.weights(inner.arg) if info.weights is not None else None

    def results_key(self) -> str:
        """The spec, plus ``@`` and 12 hex digits of the SHA-1 of the weights it loads, if any: the
        name under which the store and the benchmarks keep its results, so that retrained weights
        (or new shipped ones) are not served stale results."""
        path = self.weights_file()
        return f"{self}@{file_sha1(path)[:12]}" if path is not None and path.is_file() else str(self)

    def slug(self) -> str:
        """A folder name for its results (:func:`method_slug` of :meth:`results_key`); reads its weights."""
        return method_slug(self.results_key())

    def label(self) -> str:
        """A readable name (a table row, an output folder): a checkpoint becomes its file stem,
        ``lburst:../RoBLo_N16_B5.pt,frame_order=published`` is ``lburst-RoBLo_N16_B5-frame_order=published``."""
        if self.inner is not None:
            own = self.name + "".join(f",{key}={value}" for key, value in self.options)
            return f"{own}+{self.inner.label()}".replace("/", "_").replace(":", "_")
        parts = [self.name] + ([Path(self.arg).stem] if self.arg else []) + [f"{k}={v}" for k, v in self.options]
        return "-".join(parts).replace("/", "_").replace(":", "_")

    def default_options(self) -> dict[str, str]:
        """The options of the method that runs on the burst with their default values (as
        strings), less those it sets itself; none for an unknown method."""
        inner = self.innermost
        info = registered(inner.name)
        if info is None or info.options is None:
            return {}
        return {
            f.name: str(f.default)
            for f in fields(info.options)
            if f.default is not MISSING and f.name not in inner.given
        }

    # --- new methods from it ------------------------------------------------------------

    def _with_innermost(self, **changes: Any) -> Method:
        if self.inner is None:
            return replace(self, **changes)
        return replace(self, inner=self.inner._with_innermost(**changes))

    def with_option(self, option: str, value: Any) -> Method:
        """The method with ``option=value`` added to the method that runs on the burst (as the
        spec ``SPEC,option=value``); ``LBurstValueError`` where it sets ``option`` already."""
        if option in self.innermost.given:
            raise LBurstValueError(f"option {option!r} given twice in method spec {f'{self},{option}={value}'!r}")
        return self._with_innermost(options=(*self.innermost.options, (option, str(value))))

    def with_weights(self, weights: str | None) -> Method:
        """The method that runs on the burst with the checkpoint ``weights`` where it names none
        (``lburst`` and ``--weights W``: ``lburst:W``); itself for ``weights`` ``None``."""
        if not weights or self.innermost.arg is not None:
            return self
        return self._with_innermost(arg=str(weights))

    def with_default(self, option: str, value: Any) -> Method:
        """The method with ``option=value`` for the method it runs on the burst, where that method
        has ``option`` and leaves it unset: a default that depends on the input
        (:attr:`lburst.sfm.inputs.InputSource.keypoints`).  Otherwise, or for ``value`` ``None``, itself."""
        if value is None or not self.accepts(option) or option in self.innermost.given:
            return self
        return self.with_option(option, value)

    def with_given(self, option: str, value: Any, flag: str) -> Method:
        """The method with ``option=value`` given outside its spec (``flag``, a command-line option)
        for the method it runs on the burst; itself when ``value`` is ``None``, when that method has
        no such option, or when the spec sets the same value.  A spec that sets another value is
        refused (``LBurstValueError`` naming both): neither silently wins."""
        if value is None or not self.accepts(option):
            return self
        inner = self.innermost
        if option not in inner.given:
            return self.with_option(option, value)
        cls = method_info(inner.name, str(self)).options
        own = getattr(parse_options(cls, {option: inner.given[option]}, inner.name), option)
        if own != getattr(parse_options(cls, {option: value}, inner.name), option):
            raise LBurstValueError(
                f"{flag} {value} and {option}={inner.given[option]} in method spec {str(self)!r} disagree; "
                "give one of them"
            )
        return self

    # --- its extractor ------------------------------------------------------------------

    def _settings(self, runtime: dict[str, Any]) -> Any:
        """The typed options of this level (``runtime`` joins those of the method that runs on
        the burst, overriding the spec's); ``LBurstValueError`` for a bad name, argument or option."""
        info = self.info()
        if info.wraps and self.inner is None:
            raise LBurstValueError(
                f"method {self.name!r} wraps another method: write {self.name}+SPEC, e.g. {self.name}+sift"
            )
        if info.wraps:
            return parse_options(info.options, self.given, self.name)
        if self.arg is not None and info.arg is None:
            raise LBurstValueError(f"method {self.name!r} takes no argument, got {self.arg!r}")
        return parse_options(info.options, {**self.given, **runtime}, self.name)

    def check(self, **options: Any) -> None:
        """Raise ``LBurstValueError`` (one line) where :meth:`create` would refuse the method with
        ``options`` for its names, arguments or option values, without creating anything (no weights
        are read): a bad method is refused before any work, where the extractor is created later or
        elsewhere (on first use, on a cluster's workers)."""
        level: Method | None = self
        while level is not None:
            level._settings(options)
            level = level.inner

    def create(self, **options: Any) -> Extractor:
        """The extractor; keyword ``options`` (strings or typed values, for example ``device``) join
        those of the method that runs on the burst (inside any wrappers)."""
        info = self.info()
        settings = self._settings(options)
        extractor = info.factory(self.inner.create(**options) if info.wraps else self.arg, settings)
        extractor.name = str(self)
        return extractor
