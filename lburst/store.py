"""The features store: one ``.npz`` per burst that records what made it.

Used by ``lburst extract``, ``lburst reconstruct`` (and so by the reconstruction
benchmark) and the homography benchmark.  Each file has the layout of :func:`lburst.burst.io.write_features_npz` plus
``_meta``, a JSON object whose ``key`` says what the features depend on.  Every caller
gets its key from :func:`key`, the one key builder, so that the same burst by the same
method has the same key wherever it was computed (``lburst extract`` of a recording and
``lburst reconstruct`` of it share the features of its keyframes):

- ``method`` (:func:`method_key`): the method spec and the SHA-1 of the weights it loads
  (:meth:`lburst.methods.Method.results_key`), so retrained weights are not served
  old features, plus the options given besides the spec (``precision``, ``runtime``), an
  option left out when it has the method's default value (``lburst extract`` and
  ``lburst reconstruct`` both write a learned method's ``top_k`` into the spec, so they key
  it alike), and the
  revision of the extraction code (:data:`REVISION`), so a change of it is not served old
  features either;
- ``source``: the burst's absolute ``path`` and ``sha1``, the SHA-1 of its content
  (:func:`content_sha1`), so changed frames are computed again; for a recording's keyframe,
  the recording's path, ``sha1`` its content and cut (:func:`recording_content`) and
  ``keyframe`` the keyframe's name; a benchmark's generated burst gives the SHA-1 of what it
  was made from.

Image sizes are (W, H) at the store's edge, in and out, as a features dict's
``image_size`` (and LightGlue's ``image_size``) has them.

Stored features are used only when the stored key equals the wanted one
(:func:`load`).  :func:`same_source` tells a stale file of the same burst (to replace)
from the features of another burst that has the same name (a collision).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from lburst.burst.io import read_features_npz, write_features_npz
from lburst.features import Features, check_features
from lburst.methods import Method


def files_sha1(files: list[Path] | tuple[Path, ...], root: Path | None = None) -> str:
    """SHA-1 over ``files`` in the given order: each file's name (its path under ``root`` when
    given) and every byte, read in 1 MiB blocks."""
    digest = hashlib.sha1()
    for file in files:
        digest.update(os.fsencode(file.relative_to(root) if root is not None else file.name) + b"\0")
        with open(file, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        digest.update(b"\0")
    return digest.hexdigest()


def content_sha1(path: str | Path) -> str:
    """SHA-1 over a burst's bytes: a file's, or a folder's non-hidden files (names and bytes, sorted)."""
    path = Path(path)
    files = (
        [path]
        if not path.is_dir()
        else sorted((p for p in path.iterdir() if p.is_file() and not p.name.startswith(".")), key=lambda p: p.name)
    )
    return files_sha1(files)


def recording_content(recording: Any) -> str:
    """What the features of a recording's keyframes depend on besides the method: the SHA-1 of
    its whole content (a video's bytes, or every frame file's name and bytes, :func:`files_sha1`)
    and how it is cut into keyframe bursts (:meth:`lburst.burst.sources.RecordingOptions.signature`).

    Every byte counts, so a change anywhere (frames re-encoded in the middle of a video, a
    frame file rewritten at the same size) computes the keyframes again.  Sampling the
    file (its size and first and last MiB) missed such changes and served stale features;
    trusting ``(size, mtime_ns)`` misses them too where a copy keeps the times (``cp -p``,
    ``rsync -a``, ``tar``) or a clock goes back.  Reading costs about a second per GB from a
    warm disk, once per run, far less than decoding the recording.
    """
    sha1 = files_sha1([recording.path] if recording.is_video else recording.files)
    return f"{sha1}|{recording.options.signature()}"


#: the revision of the code that turns a burst into features, raised when it changes what a
#: method returns for the same burst and weights, so that no stored file of the old code is
#: served (2: bursts that turn are aligned with their rotation, :mod:`lburst.burst.turning`)
REVISION = 2


def method_key(method: str | Method, **options: Any) -> dict[str, Any]:
    """The ``method`` part of a key: the method's spec with its weights' SHA-1
    (:meth:`lburst.methods.Method.results_key`), the options given besides it (less those that
    are ``None`` or the method's default), and :data:`REVISION`."""
    method = Method.of(method)
    defaults = method.default_options()
    given = {k: str(v) for k, v in sorted(options.items()) if v is not None and defaults.get(k) != str(v)}
    return {"spec": method.results_key(), "options": given, "revision": REVISION}


def key(
    method: dict[str, Any], source: str | Path, content: str | None = None, keyframe: str | None = None
) -> dict[str, Any]:
    """The key of one burst's features, the only one the store knows (module docstring):
    ``method`` (:func:`method_key`) on the burst at ``source``, whose content has the SHA-1
    ``content`` (``None``: :func:`content_sha1` of ``source``); for a recording's keyframe,
    ``source`` is the recording, ``content`` its :func:`recording_content` and ``keyframe``
    the keyframe's name."""
    where = {"path": os.fsdecode(os.path.abspath(source)), "sha1": content or content_sha1(source)}
    if keyframe is not None:
        where["keyframe"] = keyframe
    return {"method": method, "source": where}


def _canonical(value: Any) -> str:
    return json.dumps(value, sort_keys=True)


def read_meta(path: str | Path) -> dict[str, Any] | None:
    """The ``_meta`` of a stored file, or ``None`` (missing, unreadable, or written without one)."""
    try:
        with np.load(path) as data:
            return json.loads(str(data["_meta"])) if "_meta" in data.files else None
    except (OSError, ValueError, KeyError, EOFError):
        return None


def load(path: str | Path, key: Any) -> tuple[Features, tuple[int, int], dict[str, Any]] | None:
    """Features (with their ``image_size``), image size (W, H) and ``_meta`` stored under
    ``key`` at ``path``; ``None`` when the file is missing, unreadable or holds another key."""
    meta = read_meta(path)
    if meta is None or _canonical(meta.get("key")) != _canonical(key):
        return None
    try:
        features = read_features_npz(path)
        size = tuple(int(v) for v in features.pop("imsize"))
        features = {k: v for k, v in features.items() if not k.startswith("_")}
        return check_features(features), size, meta
    except (OSError, ValueError, KeyError, EOFError):
        return None


def find(paths: list[Path], key: Any) -> tuple[Features, tuple[int, int], dict[str, Any]] | None:
    """What :func:`load` gives for the first of ``paths`` that holds features under ``key``, or
    ``None``: the same features wherever they were stored (``lburst reconstruct`` finds those
    of ``lburst extract``)."""
    for path in paths:
        found = load(path, key)
        if found is not None:
            return found
    return None


def save(path: str | Path, features: Features, image_size: tuple[int, int] | None, key: Any, **info: Any) -> Path:
    """Store ``features`` of an image of ``image_size`` (W, H; ``None``: the features' own
    ``image_size``) under ``key`` (and ``info``), atomically."""
    return write_features_npz(path, features, image_size, meta={"key": key, **info})


def is_foreign(path: str | Path) -> bool:
    """True if ``path`` is a readable ``.npz`` that lburst did not write (no ``_meta``): a file
    of someone else's, which lburst must not overwrite unasked."""
    try:
        with np.load(path) as data:
            return "_meta" not in data.files
    except (OSError, ValueError, EOFError):
        return False  # unreadable (a torn write of ours, or not an npz): recomputed as before


def same_source(meta: dict[str, Any] | None, key: dict[str, Any]) -> bool:
    """True if the file with ``meta`` holds (possibly stale) features of the burst of ``key``:
    the same path, or the same content.  A file without a key counts as the same."""
    try:
        old = meta["key"]["source"]
    except (TypeError, KeyError):
        return True
    new = key["source"]
    return old.get("path") == new["path"] or old.get("sha1") == new["sha1"]
