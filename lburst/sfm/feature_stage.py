"""The features stage: one loop (:func:`keyframe_features`) over the named keyframe bursts
(:class:`KeyframeBurst`) that any source yields (:mod:`lburst.sfm.inputs`: a burst, a scene
of bursts, a recording's keyframes), with any method as its per-burst ``compute``.

Each burst's features go to ``<features>/<name>.npz`` under the key its source gave it
(:func:`lburst.store.key`), with the SHA-1 of its common frame, written as
``<images>/<name>.png`` (:class:`Layout`).  Features stored there under that key, beside the
image they describe, are used as they are; features stored under the same key elsewhere
(``lburst reconstruct`` finds those of ``lburst extract``: :attr:`Layout.elsewhere`) are
copied, not computed again.  The loop never asks what kind of input it reads: it takes
bursts one at a time, and each burst to compute is one task (:class:`BurstJob`) of a runner
(:mod:`lburst.cluster.runner`) that does it in this process or on a Dask cluster worker,
which writes the same files (``--cluster``: docs/large_surveys.md).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lburst import methods, store
from lburst.burst.io import BurstError, file_sha1
from lburst.cluster.models import WorkerExtractor, extractor_request, set_threads
from lburst.cluster.runner import Runner
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


@dataclass(frozen=True)
class BurstJob:
    """One burst whose features are computed (or copied from ``layout.elsewhere``) and stored:
    a task that :func:`compute_burst` does in this process or on a cluster worker, so that its
    parts travel (a burst that a worker can read is loaded there; a recording's keyframe,
    already cut, travels with it)."""

    burst: KeyframeBurst
    compute: Callable[[np.ndarray], Features]
    layout: Layout
    reuse: bool = True


def compute_burst(job: BurstJob) -> bool:
    """Read the burst, write its common frame, take its features stored under its key elsewhere
    (with ``reuse``) or compute them, and store them beside the frame's SHA-1; returns whether
    they were computed."""
    burst, layout = job.burst, job.layout
    target, image = layout.features_path(burst.name), layout.image_path(burst.name)
    frames = burst.load()
    write_common_frame(image, frames)
    found = store.find(layout.stored_paths(burst.name), burst.key) if job.reuse else None
    features = job.compute(frames) if found is None else found[0]
    store.save(target, features, (frames.shape[2], frames.shape[1]), burst.key, image_sha1=file_sha1(image))
    return found is None


#: what a failed burst raises that ``keyframe_features(failed=...)`` reports and skips
BURST_ERRORS = (BurstError, ValueError, OSError, RuntimeError)


def keyframe_features(
    bursts: Iterable[KeyframeBurst],
    compute: Callable[[np.ndarray], Features],
    layout: Layout,
    *,
    reuse: bool = True,
    protect: bool = False,
    runner: Runner | None = None,
    failed: Callable[[KeyframeBurst, Exception], None] | None = None,
    progress: bool = False,
    desc: str = "features",
) -> Iterator[Extracted]:
    """The features of each burst as they are done (module docstring): in order in one process,
    in the order their tasks finish on a cluster (``runner``: :mod:`lburst.cluster.runner`,
    by default this process).  ``reuse``: take stored features (``False``: compute every
    burst again); ``protect``: refuse to replace a file of someone else's or of another burst
    (:func:`check_target`).  ``failed(burst, error)``: a burst that fails is reported there and
    skipped (by default its error ends the loop).  ``progress``: a bar over computed bursts."""
    runner = runner or Runner()
    ready: list[Extracted] = []  # stored ones, given out before the next computed one

    def jobs() -> Iterator[BurstJob]:
        for burst in bursts:
            if reuse and (features := stored(layout, burst.name, burst.key)) is not None:
                ready.append(Extracted(burst, features, computed=False))
                continue
            if protect and reuse:
                try:
                    check_target(layout.features_path(burst.name), burst.key)
                except BurstError as exc:
                    if failed is None:
                        raise
                    failed(burst, exc)
                    continue
            yield BurstJob(burst, compute, layout, reuse)

    for job, result in runner.map(compute_burst, jobs(), desc, progress):
        yield from ready
        ready.clear()
        try:
            computed = result()
        except BURST_ERRORS as exc:
            if failed is None:
                raise
            failed(job.burst, exc)
            continue
        target = layout.features_path(job.burst.name)
        yield Extracted(job.burst, store.load(target, job.burst.key)[0], computed)  # as stored
    yield from ready


def compute_for(
    spec: str,
    runner: Runner,
    extractor: Callable | None = None,
    options: dict[str, Any] | None = None,
    threads: int | None = None,
) -> Callable[[np.ndarray], Features]:
    """The per-burst ``compute`` of ``spec`` (created with ``options``) for ``runner``: in this
    process ``extractor`` or one created on first use (:class:`LazyExtractor`), with torch at
    ``threads``; on a cluster each worker's own (:class:`lburst.cluster.models.WorkerExtractor`),
    at ``threads`` or the runner's count (one).  A spec or option that :func:`lburst.methods.create`
    would refuse is refused here, before any burst (:func:`lburst.methods.check`)."""
    if extractor is None:
        methods.check(spec, **(options or {}))
    if runner.remote:
        return WorkerExtractor(extractor_request(spec, options, threads or runner.threads))
    set_threads(threads)
    return LazyExtractor(spec, extractor, options)


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

    def __init__(self, spec: str, extractor=None, options: dict[str, Any] | None = None) -> None:
        self.spec, self.extractor, self.options = spec, extractor, dict(options or {})

    def __call__(self, burst) -> Features:
        if self.extractor is None:  # torch, for a learned method: only when a burst needs it
            self.extractor = methods.create(self.spec, **self.options)
        return check_features(self.extractor(burst))
