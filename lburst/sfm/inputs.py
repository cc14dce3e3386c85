"""The inputs of a reconstruction, each a source of keyframes: a scene (a folder of bursts or
photos) or a recording (a video, a frame or DNG folder: :mod:`lburst.burst.sources`).

:func:`open_input` is the one place that asks which kind an input is
(:func:`lburst.burst.sources.is_recording`); the pipeline (:func:`lburst.sfm.reconstruct.reconstruct_scene`)
then reads :class:`Keyframes` from it and takes the input's defaults from its attributes:
``time_ordered`` (a recording's keyframes come in time order: sequential pairs with loop
candidates, :func:`lburst.sfm.pairs.pair_plan`) and ``one_camera`` (one camera shot it:
one COLMAP camera by default, :mod:`lburst.sfm.cameras`).  Both leave the same files:
``OUT/images/``, the features, ``OUT/keyframes.json`` (times) and ``OUT/reference.json``
when there is a reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from lburst.burst.sources import RecordingOptions, is_recording
from lburst.features import Features
from lburst.sfm.cameras import CameraPlan, camera_origin
from lburst.sfm.feature_stage import recording_features, scene_features
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.outputs import copy_reference, write_scene_times
from lburst.sfm.scene import Scene, list_scene


@dataclass
class Keyframes:
    """What an input gives the pipeline: its scene (items named as their images), the features
    of each item's common frame, and why reading stopped early (``None``: it did not)."""

    scene: Scene
    features: list[Features]
    error: str | None = None

    def unpack(self) -> tuple[Scene, list[Features], str | None]:
        return self.scene, self.features, self.error


class SceneInput:
    """A folder of bursts or photos (:func:`lburst.sfm.scene.list_scene`), timed by index."""

    time_ordered = False
    one_camera = False

    def __init__(self, path: str | Path):
        self.path = path

    def read(self, spec: str, out: Path, opts: ReconstructOptions, extractor=None) -> Keyframes:
        scene = list_scene(self.path)
        if len(scene.items) < 2:
            return Keyframes(scene, [])
        features = scene_features(scene, spec, out, opts.progress, extractor, opts.features)
        write_scene_times(out, str(self.path), scene.names)
        copy_reference(scene.reference_path, out / "reference.json")
        return Keyframes(scene, features)

    def camera_origin(self, scene: Scene, plan: CameraPlan, opts: ReconstructOptions) -> str | None:
        return None  # a scene's report has no camera line


class RecordingInput(SceneInput):
    """A video or a frame/DNG folder read once into keyframe bursts (:mod:`lburst.sfm.recording`)."""

    time_ordered = True
    one_camera = True

    def read(self, spec: str, out: Path, opts: ReconstructOptions, extractor=None) -> Keyframes:
        return Keyframes(*recording_features(self.path, spec, out, opts, extractor))

    def camera_origin(self, scene: Scene, plan: CameraPlan, opts: ReconstructOptions) -> str | None:
        return camera_origin(scene, plan, opts)  # where the intrinsics came from (result.json, report.md)


def open_input(path: str | Path, options: RecordingOptions | None = None) -> SceneInput:
    """The input at ``path``: a :class:`RecordingInput` when it is a recording
    (:func:`lburst.burst.sources.is_recording` with ``options``), else a :class:`SceneInput`."""
    return RecordingInput(path) if is_recording(path, options) else SceneInput(path)
