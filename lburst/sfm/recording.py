"""A recording (video or frame folder, :mod:`lburst.burst.sources`) as a reconstruction scene.

The keyframes are known only once the recording has been read (a video's frame count
is a promise of its container), so :func:`stream_keyframes` reads it once, yielding each
keyframe's burst, or ``None`` for a keyframe the caller has cached, and
:func:`keyframe_scene` turns the keyframes that were read into a :class:`Scene`.
``OUT/keyframes.json`` records them with the store's key of the recording (its content and
options, :func:`lburst.store.recording_content`; :func:`save_keyframes`); a rerun whose keyframes are all cached skips reading the
recording.  With a ground truth (``gt.txt``), ``OUT/reference.json`` holds the true
poses of the keyframes (the ground-truth pose within 1 ms of each keyframe's timestamp)
and the camera of ``meta.json``, so the usual metrics apply.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Iterator

import numpy as np

from lburst.burst.io import atomic_path
from lburst.burst.sources import Keyframe, Recording
from lburst.sfm.poses import path_length
from lburst.sfm.reference import Reference
from lburst.sfm.scene import Scene, SceneItem
from lburst.tum import lookup, read_tum

KEYFRAMES_FILE = "keyframes.json"


def load_keyframes(out: Path, key: dict) -> list[Keyframe] | None:
    """The keyframes of a finished earlier read with the same ``key`` (the store's key of the
    recording, :func:`lburst.store.key`, without a keyframe), else ``None``."""
    path = out / KEYFRAMES_FILE
    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None
    if data.get("key") != key or not data.get("complete"):
        return None
    return [Keyframe(k["index"], k["time"], k["filled"]) for k in data["keyframes"]]


def save_keyframes(out: Path, key: dict, recording: Recording, keyframes: list[Keyframe], error: str | None) -> None:
    data = {
        "recording": str(recording.path),
        "key": key,
        "complete": error is None,
        "error": error,
        "fps": recording.fps,
        "gain": recording.gain,
        "options": recording.options.signature(),
        "frames_read": recording.frames_read,
        "read_seconds": round(recording.read_seconds, 3),
        "read_fps": round(recording.frames_read / recording.read_seconds, 1) if recording.read_seconds else None,
        "keyframes": [{"name": k.name, "index": k.index, "time": k.time, "filled": k.filled} for k in keyframes],
    }
    with atomic_path(out / KEYFRAMES_FILE) as tmp:
        tmp.write_text(json.dumps(data, indent=1))


def stream_keyframes(
    recording: Recording, cached, found: list[Keyframe]
) -> Iterator[tuple[Keyframe, np.ndarray | None]]:
    """``(keyframe, burst)`` for every keyframe, ``burst`` ``None`` when ``cached(name)``; each keyframe
    is appended to ``found`` as it comes (so the caller keeps them when the recording fails later)."""
    for keyframe, burst in recording.bursts():
        found.append(keyframe)
        yield keyframe, (None if cached(keyframe.name) else burst)


def keyframe_scene(recording: Recording, keyframes: list[Keyframe], out: Path) -> Scene:
    """The scene of ``keyframes`` (items named by :attr:`Keyframe.name`), with ``OUT/reference.json``
    from the ground truth when the recording has one."""
    items = tuple(SceneItem(k.name, recording.path, "keyframe") for k in keyframes)
    reference_path = None
    if recording.ground_truth is not None and recording.camera is not None:
        times, poses = read_tum(recording.ground_truth)
        matched = {k.name: lookup(times, poses, k.time) for k in keyframes}
        matched = {name: pose for name, pose in matched.items() if pose is not None}
        if matched:
            centres = np.array([-R.T @ t for R, t in matched.values()])
            reference = Reference(
                source=f"ground truth {recording.ground_truth.name}",
                camera=dict(recording.camera),
                poses=matched,
                length=path_length(centres),
            )
            reference_path = out / "reference.json"
            reference.save(reference_path)
    return Scene(recording.path, items, reference_path, camera=recording.camera, camera_source=recording.camera_source)
