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

import json
from collections.abc import Callable, Iterable, Iterator, Sized
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lburst import methods, store
from lburst.burst.io import BurstError, file_sha1, read_features_npz
from lburst.cluster.models import WorkerExtractor, extractor_request, set_threads
from lburst.cluster.runner import Runner
from lburst.errors import LBurstFileNotFoundError, LBurstValueError
from lburst.features import Features, check_features, check_inside
from lburst.methods import Method
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


@dataclass(frozen=True)
class Extracted:
    """The features of one keyframe burst, and whether they were computed now."""

    burst: KeyframeBurst
    features: Features
    computed: bool


def stored(layout: Layout, name: str, key: Any) -> Features | None:
    """The features of ``name`` stored in ``layout`` under ``key``, when its image is there and
    is the one they describe (its SHA-1 recorded with them) and they pass the checks of
    :func:`load_checked`; else ``None`` (computed again)."""
    path, image = layout.features_path(name), layout.image_path(name)
    try:
        features = load_checked(path, key)
    except ValueError:
        return None
    meta = store.read_meta(path) if features is not None else None
    if meta is None or not image.is_file() or meta.get("image_sha1") != file_sha1(image):
        return None
    return features


def _same(a: Any, b: Any) -> bool:
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True)


def load_checked(path: Path, key: Any, size: tuple[int, int] | None = None) -> Features | None:
    """The features stored at ``path`` under ``key`` (with their ``image_size``), or ``None`` when
    the file is missing or holds another key.  A file that holds ``key`` but features that cannot
    be right (unreadable, wrong shapes, NaN, keypoints off the image, or an image other than the
    burst's common frame of ``size`` (W, H)) is ``LBurstValueError`` naming it, never used."""
    meta = store.read_meta(path)
    if meta is None or not _same(meta.get("key"), key):
        return None
    try:
        features = read_features_npz(path)
        stored_size = tuple(int(v) for v in features.pop("imsize"))
        check_inside(check_features(features), stored_size)
        if size is not None and stored_size != tuple(size):
            raise LBurstValueError(
                f"they describe a {stored_size[0]}x{stored_size[1]} image, the burst's common frame is "
                f"{size[0]}x{size[1]}"
            )
    except (OSError, ValueError, KeyError, IndexError, TypeError, EOFError) as exc:
        raise LBurstValueError(
            f"{path}: stored features of this burst and method that cannot be right ({exc}); remove the file, "
            "or extract the bursts again"
        ) from None
    return features


def stored_elsewhere(layout: Layout, name: str, key: Any, size: tuple[int, int]) -> Features | None:
    """The features of ``name`` under ``key`` at its place in ``layout`` (a file there that cannot
    be right is replaced), else in ``layout.elsewhere`` (such a file there is an error naming it:
    :func:`load_checked`), else ``None``."""
    try:
        own = load_checked(layout.features_path(name), key, size)
    except ValueError:
        own = None  # ours, to be replaced
    if own is not None:
        return own
    for folder in layout.elsewhere:
        found = load_checked(folder / f"{name}.npz", key, size)
        if found is not None:
            return found
    return None


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
    size = (frames.shape[2], frames.shape[1])
    found = stored_elsewhere(layout, burst.name, burst.key, size) if job.reuse else None
    features = job.compute(frames) if found is None else found
    store.save(target, features, size, burst.key, image_sha1=file_sha1(image))
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
    skipped (by default its error ends the loop).  ``progress``: a bar over the bursts to compute,
    with their count when ``bursts`` is a sequence (then checked for stored features first)."""
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

    todo = list(jobs()) if isinstance(bursts, Sized) else jobs()  # a list: the bar knows its total
    total = len(todo) if isinstance(todo, list) else None
    for job, result in runner.map(compute_burst, todo, desc, progress, total=total):
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


def extracted_folders(features: str | Path | None, out: Path, folder: str) -> tuple[Path, ...]:
    """Where a reconstruction into ``out`` looks for the features that another run stored of the
    same bursts (:attr:`Layout.elsewhere`): in ``features`` (``None``: ``out``) under ``folder``,
    where ``lburst extract --out`` puts them (a recording's name, else none), and in
    ``features/features``, where ``lburst reconstruct --out`` keeps them.  A ``features`` that is
    missing or not a folder is an error naming it."""
    if features is None:
        return (out / folder,)
    root = Path(features)
    if not root.exists():
        raise LBurstFileNotFoundError(f"--features {root}: no such folder")
    if not root.is_dir():
        raise LBurstValueError(
            f"--features {root}: not a folder; give the --out folder of lburst extract or lburst reconstruct"
        )
    return tuple(dict.fromkeys((root / folder, root / "features")))


def _method_text(method: dict[str, Any], wanted: dict[str, Any]) -> str:
    options = ",".join(f"{k}={v}" for k, v in sorted(method.get("options", {}).items()))
    older = " by other extraction code" if method.get("revision") != wanted.get("revision") else ""
    return f"{method.get('spec')!r}{' with ' + options if options else ''}{older}"


def why_not_stored(folders: tuple[Path, ...], method: dict[str, Any], most: int = 200) -> str:
    """Why bursts were not found in ``folders`` (where ``--features`` pointed) for ``method``
    (:func:`lburst.store.method_key`): no lburst features there, features of other methods (named,
    from the first ``most`` files), or of this method but for other bursts or frames."""
    files = [path for folder in folders if folder.is_dir() for path in sorted(folder.glob("*.npz"))][:most]
    stored_methods = [m["key"]["method"] for m in map(store.read_meta, files) if _has_method(m)]
    if not stored_methods:
        return f"it holds no lburst features ({' or '.join(str(f) for f in folders)}: no .npz with lburst's key)"
    if any(_same(m, method) for m in stored_methods):
        return f"its features of {_method_text(method, method)} are of other bursts, or of other frames or cuts"
    others = sorted({_method_text(m, method) for m in stored_methods})
    listed = ", ".join(others[:3]) + (" ..." if len(others) > 3 else "")
    return f"it holds features of {listed}, not of {_method_text(method, method)}"


def _has_method(meta: Any) -> bool:
    return isinstance(meta, dict) and isinstance(meta.get("key"), dict) and isinstance(meta["key"].get("method"), dict)


def compute_for(
    method: str | Method,
    runner: Runner,
    extractor: Callable | None = None,
    options: dict[str, Any] | None = None,
    threads: int | None = None,
) -> Callable[[np.ndarray], Features]:
    """The per-burst ``compute`` of ``method`` (created with ``options``) for ``runner``: in this
    process ``extractor`` or one created on first use (:class:`LazyExtractor`), with torch at
    ``threads``; on a cluster each worker's own (:class:`lburst.cluster.models.WorkerExtractor`),
    at ``threads`` or the runner's count (one).  A method or option that :meth:`Method.create`
    would refuse is refused here, before any burst (:meth:`Method.check`)."""
    method = Method.of(method)
    if extractor is None:
        method.check(**(options or {}))
    if runner.remote:
        return WorkerExtractor(extractor_request(method, options, threads or runner.threads))
    set_threads(threads)
    return LazyExtractor(method, extractor, options)


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
    from ``method`` on first use only, so a run whose features are all stored never loads a network."""

    def __init__(self, method: str | Method, extractor=None, options: dict[str, Any] | None = None) -> None:
        self.method, self.extractor, self.options = Method.of(method), extractor, dict(options or {})

    def __call__(self, burst) -> Features:
        if self.extractor is None:  # torch, for a learned method: only when a burst needs it
            self.extractor = methods.create(self.method, **self.options)
        return check_features(self.extractor(burst))
