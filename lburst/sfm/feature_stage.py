"""The features stage: one loop (:func:`keyframe_features`) over the named keyframe bursts
(:class:`KeyframeBurst`) that any source yields (:mod:`lburst.sfm.inputs`: a burst, a scene
of bursts, a recording's keyframes), with any method as its per-burst ``compute``.

Each burst's features go to ``<features>/<name>.npz`` under the key its source gave it
(:func:`lburst.store.key`), with the SHA-1 of its common frame, written as
``<images>/<name>.png`` (:class:`Layout`).  Features stored there under that key, beside the
image they describe, are used as they are; features stored under the same key elsewhere
(``lburst reconstruct`` finds those of ``lburst extract``: :attr:`Layout.elsewhere`) are
copied, not computed again.  The loop never asks what kind of input it reads: it takes
bursts one at a time, so a cluster map can take its place.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lburst import methods, store
from lburst.burst.io import BurstError, file_sha1
from lburst.features import Features, check_features
from lburst.sfm.outputs import write_common_frame
from lburst.sfm.result import ReconstructionError


@dataclass(frozen=True)
class KeyframeBurst:
    """A named burst of a source: ``name`` names its image (``<name>.png``) and its features
    (``<name>.npz``), ``key`` is the store's key of its features (the source decides it;
    ``None`` when no method is given), ``load()`` reads the burst ``(N, H, W, 3)``, and a
    recording's keyframe has its frame ``index`` and ``time`` (s)."""

    name: str
    key: dict[str, Any] | None
    load: Callable[[], np.ndarray]
    index: int | None = None
    time: float | None = None


@dataclass(frozen=True)
class Layout:
    """Where the loop keeps a burst's features (``features/<name>.npz``) and common frame
    (``images/<name>.png``), and the folders where the same features may be stored already."""

    features: Path
    images: Path
    elsewhere: tuple[Path, ...] = ()

    def features_path(self, name: str) -> Path:
        return self.features / f"{name}.npz"

    def image_path(self, name: str) -> Path:
        return self.images / f"{name}.png"

    def stored_paths(self, name: str) -> list[Path]:
        return [self.features_path(name)] + [folder / f"{name}.npz" for folder in self.elsewhere]


@dataclass(frozen=True)
class Extracted:
    """The features of one keyframe burst, and whether they were computed now."""

    burst: KeyframeBurst
    features: Features
    computed: bool


def stored(layout: Layout, name: str, key: Any) -> Features | None:
    """The features of ``name`` stored in ``layout`` under ``key``, when its image is there and
    is the one they describe (its SHA-1 recorded with them); else ``None``."""
    found = store.load(layout.features_path(name), key)
    image = layout.image_path(name)
    if found is None or not image.is_file() or found[2].get("image_sha1") != file_sha1(image):
        return None
    return found[0]


def check_target(path: Path, key: dict[str, Any]) -> None:
    """Refuse to replace ``path`` when lburst did not write it, or when it holds the features
    of another burst with the same name (:func:`lburst.store.same_source`)."""
    if not path.exists():
        return
    where = key["source"]["path"]
    if store.is_foreign(path):
        raise BurstError(
            f"{where}: {path} exists and was not written by lburst; use another --out, or --overwrite to replace it"
        )
    meta = store.read_meta(path)
    if not store.same_source(meta, key):
        raise BurstError(
            f"{where}: {path} holds the features of another burst with the same name "
            f"({meta['key']['source']['path']}); use another --out, or --overwrite to replace them"
        )


def keyframe_features(
    bursts: Iterable[KeyframeBurst],
    compute: Callable[[np.ndarray], Features],
    layout: Layout,
    *,
    reuse: bool = True,
    protect: bool = False,
) -> Iterator[Extracted]:
    """The features of each burst, in order, as they are done (module docstring).  ``reuse``:
    take stored features (``False``: compute every burst again); ``protect``: refuse to
    replace a file of someone else's or of another burst (:func:`check_target`)."""
    for burst in bursts:
        target, image = layout.features_path(burst.name), layout.image_path(burst.name)
        if reuse and (features := stored(layout, burst.name, burst.key)) is not None:
            yield Extracted(burst, features, computed=False)
            continue
        if protect and reuse:
            check_target(target, burst.key)
        frames = burst.load()
        write_common_frame(image, frames)
        found = store.find(layout.stored_paths(burst.name), burst.key) if reuse else None
        features = compute(frames) if found is None else found[0]
        store.save(target, features, (frames.shape[2], frames.shape[1]), burst.key, image_sha1=file_sha1(image))
        yield Extracted(burst, store.load(target, burst.key)[0], computed=found is None)  # as stored


def safe_name(name: str) -> str:
    """``name`` if COLMAP can store it: no ``/``, not hidden, valid UTF-8."""
    if "/" in name or name.startswith(".") or not name.isprintable() or not utf8(name):
        raise ReconstructionError(f"image name {name!r} cannot be used as a COLMAP image name (rename it)")
    return name


def utf8(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


class LazyExtractor:
    """``extractor(burst)``, checked (:func:`lburst.features.check_features`), the method created
    from ``spec`` on first use only, so a run whose features are all stored never loads a network."""

    def __init__(self, spec: str, extractor=None) -> None:
        self.spec, self.extractor = spec, extractor

    def __call__(self, burst) -> Features:
        if self.extractor is None:
            self.extractor = methods.create(self.spec)  # torch, for a learned method: only when a burst needs it
        return check_features(self.extractor(burst))
