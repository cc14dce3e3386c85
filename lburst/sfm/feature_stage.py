"""The features stage of a reconstruction: the features of each burst's common frame (a
scene's bursts: :func:`scene_features`; a recording's keyframes, read once:
:func:`recording_features`), with any method spec, and the common frames written as
``OUT/images/<name>.png`` for COLMAP.  Features are cached in ``OUT/features/<name>.npz``
under the store's key (:func:`lburst.store.key`), so an interrupted run resumes; features
that ``lburst extract --out DIR`` stored for the same burst by the same method are taken
from ``DIR`` (:func:`stored_paths`), by default ``OUT``, and not computed again.
"""

from __future__ import annotations

import os
from pathlib import Path

from tqdm import tqdm

from lburst import store
from lburst.burst.io import BurstError, file_sha1
from lburst.burst.sources import RecordingOptions, open_recording
from lburst.features import Features, check_features
from lburst.sfm import recording as rec
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.outputs import IMAGES, write_common_frame
from lburst.sfm.result import ReconstructionError
from lburst.sfm.scene import Scene, load_item


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


def stored_paths(out: Path, name: str, extracted: Path | None, recording: Path | None = None) -> list[Path]:
    """Where the features of burst ``name`` may be stored: reconstruct's own cache
    ``OUT/features/<name>.npz``, then where ``lburst extract --out EXTRACTED`` puts them
    (``EXTRACTED/<name>.npz``; a recording's keyframe: ``EXTRACTED/<recording>/<name>.npz``)."""
    folder = out if extracted is None else Path(extracted)
    own = [out / "features" / f"{safe_name(name)}.npz"]
    if recording is not None:
        recording = Path(os.path.abspath(recording))  # named as lburst extract names it
        stem = recording.stem if recording.is_file() else recording.name
        return own + [folder / stem / f"{name}.npz"]
    return own + [folder / f"{name}.npz"]


class LazyExtractor:
    """``extractor(burst)``, checked (:func:`lburst.features.check_features`), the method created
    from ``spec`` on first use only, so a run whose features are all stored never loads a network."""

    def __init__(self, spec: str, extractor=None) -> None:
        self.spec, self.extractor = spec, extractor

    def __call__(self, burst) -> Features:
        if self.extractor is None:
            from lburst.methods import create

            self.extractor = create(self.spec)
        return check_features(self.extractor(burst))


def scene_features(
    scene: Scene, spec: str, out: Path, progress: bool = True, extractor=None, extracted: Path | None = None
) -> list[Features]:
    """Features of each item's common frame (with their ``image_size`` (W, H)); writes
    ``out/images/<name>.png`` too.  Stored features under the same key
    (:func:`stored_paths`) are used, not computed again."""
    features = []
    method = store.method_key(spec)
    extract = LazyExtractor(spec, extractor)
    for item in tqdm(scene.items, desc=f"features {spec}", disable=not progress, leave=False):
        paths = stored_paths(out, item.name, extracted)
        cache = paths[0]
        image_path = out / IMAGES / f"{item.name}.png"
        key = store.key(method, item.path)  # the burst's content and the weights: no stale features
        cached = store.load(cache, key)
        if cached is not None and image_path.is_file() and cached[2].get("image_sha1") == file_sha1(image_path):
            features.append(cached[0])
            continue
        burst = load_item(item)
        write_common_frame(image_path, burst)
        found = cached or store.find(paths[1:], key)
        feats = found[0] if found is not None else extract(burst)
        store.save(cache, feats, (burst.shape[2], burst.shape[1]), key, image_sha1=file_sha1(image_path))
        features.append(store.load(cache, key)[0])  # as stored, so a rerun gives the same
    return features


def recording_features(
    path: str | Path, spec: str, out: Path, opts: ReconstructOptions, extractor=None
) -> tuple[Scene, list[Features], str | None]:
    """The keyframe scene of a recording (:mod:`lburst.sfm.recording`), the features of each
    keyframe (with their ``image_size`` (W, H)), and why reading stopped early (or ``None``).
    Features are stored as for bursts, under the store's key of the keyframe (the method,
    the recording's content and options, the keyframe's name: :func:`lburst.store.key`), the
    key ``lburst extract`` gives them too, so those it stored are used (:func:`stored_paths`)."""
    try:
        recording = open_recording(path, opts.recording or RecordingOptions())
    except BurstError as err:
        raise ReconstructionError(str(err)) from err
    method, content = store.method_key(spec), store.recording_content(recording)
    extract = LazyExtractor(spec, extractor)

    def key(name: str) -> dict:
        return store.key(method, path, content, keyframe=name)

    def paths(name: str) -> list[Path]:
        return stored_paths(out, name, opts.features, Path(path))

    def cached(name: str) -> bool:
        return store.load(paths(name)[0], key(name)) is not None and (out / IMAGES / f"{name}.png").is_file()

    keyframes = rec.load_keyframes(out, store.key(method, path, content))
    error = None
    if keyframes is None or not all(cached(k.name) for k in keyframes):
        keyframes = []
        stream = rec.stream_keyframes(recording, cached, keyframes)
        try:
            for keyframe, burst in tqdm(stream, desc=f"keyframes {spec}", disable=not opts.progress, leave=False):
                if burst is None:
                    continue
                write_common_frame(out / IMAGES / f"{keyframe.name}.png", burst)
                found = store.find(paths(keyframe.name), key(keyframe.name))
                feats = found[0] if found is not None else extract(burst)
                store.save(paths(keyframe.name)[0], feats, (burst.shape[2], burst.shape[1]), key(keyframe.name))
        except BurstError as err:
            error = str(err)
        rec.save_keyframes(out, store.key(method, path, content), recording, keyframes, error)
    features = [store.load(paths(k.name)[0], key(k.name))[0] for k in keyframes]
    return rec.keyframe_scene(recording, keyframes, out), features, error
