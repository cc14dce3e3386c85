"""Every input as a source of named keyframe bursts (:class:`lburst.sfm.feature_stage.KeyframeBurst`):
one burst (a folder of frames, an image, a whole video: :class:`BurstInput`), a scene (a
folder of bursts or photos: :class:`SceneInput`) or a recording (a video, a frame or DNG
folder cut into keyframe bursts: :class:`RecordingInput`, :mod:`lburst.burst.sources`).

:func:`open_input` (``lburst reconstruct``: a scene or a recording) and :func:`open_bursts`
(``lburst extract`` and ``lburst show``: a burst or a recording) are the one place that asks
which kind an input is (:func:`lburst.burst.sources.is_recording`).  Every source then
answers the same questions: :meth:`InputSource.keyframe_bursts` (each burst with its name and
the store's key of its features, which the source decides), :attr:`InputSource.folder` (where
``lburst extract --out DIR`` puts its features, under ``DIR``), :meth:`InputSource.finish`
(its scene, once read) and the defaults it gives a reconstruction: ``time_ordered`` (a
recording's keyframes come in time order: sequential pairs with loop candidates,
:func:`lburst.sfm.pairs.pair_plan`), ``one_camera`` (one camera shot it: one COLMAP camera
by default, :mod:`lburst.sfm.cameras`) and ``keypoints`` (a learned method's ``top_k``
where the spec sets none).  :meth:`InputSource.read` runs the features stage
(:func:`lburst.sfm.feature_stage.keyframe_features`) over any source; every input leaves the
same files: ``OUT/images/``, the features, ``OUT/keyframes.json`` (times) and
``OUT/reference.json`` when there is a reference.
"""

from __future__ import annotations

import os
import warnings
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lburst import store
from lburst.burst.io import BurstError, burst_files, load_burst
from lburst.burst.rosbag import is_bag
from lburst.burst.sources import Keyframe, Recording, RecordingOptions, is_recording, open_recording
from lburst.cluster.runner import Runner
from lburst.extras import MissingExtra
from lburst.features import Features
from lburst.geo.exif import frames_track
from lburst.geo.fixes import GnssError, GnssTrack
from lburst.methods import Method
from lburst.sfm import recording as rec
from lburst.sfm.cameras import CameraPlan, camera_origin
from lburst.sfm.feature_stage import (
    KeyframeBurst,
    Layout,
    compute_for,
    extracted_folders,
    keyframe_features,
    safe_name,
    stored,
    why_not_stored,
)
from lburst.sfm.options import ReconstructOptions
from lburst.sfm.outputs import IMAGES, copy_reference, write_scene_times
from lburst.sfm.positions import Priors, track_priors
from lburst.sfm.result import ReconstructionError
from lburst.sfm.scene import Scene, SceneItem, list_scene, load_item

#: keypoints per image for a scene: its views lie farther apart than a recording's keyframes,
#: and twice the 4,000 gave lburst-b5 60-145 % more 3D points on the photo sets, the pose error
#: within the spread of COLMAP's seeds (docs/defaults.md); a recording keeps 4,000, a quarter of
#: the matching time
PHOTO_SET_KEYPOINTS = 8000

#: ``stored(name, key)``: whether the features of ``name`` are stored under ``key``
Stored = Callable[[str, Any], bool]


def burst_name(path: str | Path) -> str:
    """An input's name in outputs: the folder or file name without suffix (``.`` is the
    current folder's name)."""
    path = Path(os.path.abspath(path))
    name = path.stem if path.is_file() else path.name
    if not name or name.startswith("."):
        raise BurstError(f"{path}: no name to give its output (a hidden or root path)")
    return name


@dataclass
class Keyframes:
    """What an input gives the pipeline: its scene (items named as their images), the features
    of each item's common frame, and why reading stopped early (``None``: it did not)."""

    scene: Scene
    features: list[Features]
    error: str | None = None

    def unpack(self) -> tuple[Scene, list[Features], str | None]:
        return self.scene, self.features, self.error


class InputSource(ABC):
    """A source of named keyframe bursts (module docstring); subclasses say how they are read."""

    time_ordered = False
    one_camera = False
    #: its keyframe bursts hold their frames (a recording, read once in order), so they are made
    #: one at a time; others read their frames when loaded, and are listed before the features stage
    frames_held = False
    #: keypoints per image of a learned method whose spec sets no ``top_k`` (``None``: the
    #: method's own default, 4,000)
    keypoints: int | None = None

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.error: str | None = None  # why reading stopped early, once read

    @property
    def folder(self) -> str:
        """Where ``lburst extract --out DIR`` puts the features of this input, under ``DIR``."""
        return ""

    @abstractmethod
    def keyframe_bursts(
        self, method: dict[str, Any] | None = None, stored: Stored | None = None, out: Path | None = None
    ) -> Iterator[KeyframeBurst]:
        """The bursts, each keyed for ``method`` (:func:`lburst.store.method_key`; ``None``: no key).
        ``stored`` says which features are stored already (a source may then skip reading);
        ``out``: the run's folder, where a source records what it read."""

    @abstractmethod
    def finish(self, out: Path) -> Scene:
        """The scene of the bursts read, its times (``OUT/keyframes.json``) and reference
        (``OUT/reference.json``) written."""

    def camera_origin(self, scene: Scene, plan: CameraPlan, opts: ReconstructOptions) -> str | None:
        return None  # a report without a camera line

    def known_names(self) -> list[str] | None:
        """The names of the images before any is read (a scene's), ``None`` where only reading
        tells them (a recording's keyframes)."""
        return None

    def known_scene(self) -> Scene | None:
        """The scene before any image is read (a scene's: its images and positions are known before
        the features stage), ``None`` where only reading tells it (a recording's keyframes)."""
        return None

    def gnss_track(self) -> GnssTrack | None:
        """The GNSS fixes the input carries (:mod:`lburst.geo`), once read; ``None``: none."""
        return None

    def image_times(self, scene: Scene) -> list[float] | None:
        """Each image's time on the clock of :meth:`gnss_track`'s fixes, ``None``: untimed."""
        return None

    def gnss_priors(self, scene: Scene, std: float) -> Priors | None:
        """The position priors of ``scene``'s images from the fixes the input carries
        (:func:`lburst.sfm.positions.track_priors`), ``None`` when it carries none; a missing
        ``geo`` extra or an unreadable file gives priors of no image with a note saying why."""
        try:
            track = self.gnss_track()
            if track is None:
                return None
            return track_priors(track, scene.names, self.image_times(scene), std)
        except (MissingExtra, GnssError) as err:
            return Priors(
                np.full((len(scene.names), 3), np.nan), f"the GNSS of {self.path}", notes=[f"{err}; no priors"]
            )

    def read(
        self, method: str | Method, out: Path, opts: ReconstructOptions, extractor=None, runner: Runner | None = None
    ) -> Keyframes:
        """The features stage of a reconstruction into ``out``: the features of every burst
        (:func:`lburst.sfm.feature_stage.keyframe_features`), in ``OUT/features`` and
        ``OUT/images``, taken from ``opts.features`` (``lburst extract``'s folder, by default
        ``out``) where they are stored, computed in this process or by ``runner`` on a cluster;
        then the scene (:meth:`finish`), its items' features in its order."""
        layout = Layout(out / "features", out / IMAGES, extracted_folders(opts.features, out, self.folder))
        wanted = store.method_key(method)
        runner = runner or Runner()
        bursts = self.keyframe_bursts(wanted, lambda name, key: stored(layout, name, key) is not None, out)
        named = (burst for burst in bursts if safe_name(burst.name))  # names COLMAP can store
        if not self.frames_held:  # bursts that read their frames when loaded: listed, so the bar has a total
            named = list(named)
        compute = compute_for(method, runner, extractor)
        done: dict[str, Features] = {}
        computed = 0
        try:
            for extracted_burst in keyframe_features(named, compute, layout, runner=runner, progress=opts.progress):
                done[extracted_burst.burst.name] = extracted_burst.features
                computed += extracted_burst.computed
        except BurstError as err:  # the input itself cannot be read
            raise ReconstructionError(str(err)) from err
        if opts.features is not None and computed:  # say why the folder given was not used
            warnings.warn(
                f"--features {opts.features}: {computed} of {len(done)} bursts were not stored there and were "
                f"computed: {why_not_stored(layout.elsewhere, wanted)}",
                stacklevel=2,
            )
        scene = self.finish(out)
        return Keyframes(scene, [done[item.name] for item in scene.items if item.name in done], self.error)


#: the most frames a burst folder holds (as ``--burst``): a folder with more is a recording
LONGEST_BURST = 99


class BurstInput(InputSource):
    """One burst: a folder of frames, an image or a whole video (:func:`lburst.burst.io.load_burst`)."""

    def keyframe_bursts(self, method=None, stored=None, out=None) -> Iterator[KeyframeBurst]:
        if not self.path.exists():
            raise BurstError(f"{self.path}: no such file or folder")
        if self.path.is_dir() and (count := len(burst_files(self.path))) > LONGEST_BURST:
            raise BurstError(  # said before its frames are read
                f"{self.path}: {count} frames, more than a burst holds ({LONGEST_BURST}); a recording? "
                "--every K or --motion F cuts it into keyframe bursts"
            )
        key = None if method is None else store.key(method, self.path)
        yield KeyframeBurst(burst_name(self.path), key, lambda: load_burst(self.path))

    def finish(self, out: Path) -> Scene:
        return Scene(self.path, (SceneItem(burst_name(self.path), self.path, "burst"),), None)


class SceneInput(InputSource):
    """A folder of bursts or photos (:func:`lburst.sfm.scene.list_scene`), timed by index."""

    keypoints = PHOTO_SET_KEYPOINTS

    def __init__(self, path: str | Path):
        super().__init__(path)
        self._scene: Scene | None = None

    @property
    def scene(self) -> Scene:
        if self._scene is None:
            self._scene = list_scene(self.path)
        return self._scene

    def keyframe_bursts(self, method=None, stored=None, out=None) -> Iterator[KeyframeBurst]:
        if len(self.scene.items) < 2:
            return  # nothing to reconstruct: no features computed
        for item in self.scene.items:
            key = None if method is None else store.key(method, item.path)  # the burst's content: no stale features
            yield KeyframeBurst(item.name, key, lambda item=item: load_item(item))

    def known_names(self) -> list[str] | None:
        return self.scene.names

    def known_scene(self) -> Scene | None:
        return self.scene

    def gnss_track(self) -> GnssTrack | None:
        """The EXIF GPS of each image (a burst's: of its middle frame), by the image's name."""
        frames = ((_common_file(item), None, item.name) for item in self.scene.items)
        return frames_track(((path, t, name) for path, t, name in frames if path is not None), str(self.path))

    def finish(self, out: Path) -> Scene:
        if len(self.scene.items) >= 2:
            write_scene_times(out, str(self.path), self.scene.names)
            copy_reference(self.scene.reference_path, out / "reference.json")
        return self.scene


class RecordingInput(InputSource):
    """A video or a frame/DNG folder read once into keyframe bursts (:mod:`lburst.sfm.recording`).
    Its keyframes' features are keyed by the recording's content and cut and the keyframe's
    name (:func:`lburst.store.recording_content`), as ``lburst extract`` keys them."""

    time_ordered = True
    one_camera = True
    frames_held = True

    def __init__(self, path: str | Path, options: RecordingOptions | None = None):
        super().__init__(path)
        self.options = options or RecordingOptions()
        self.recording: Recording | None = None
        self.keyframes: list[Keyframe] = []

    @property
    def folder(self) -> str:
        return burst_name(self.path)  # OUT/<recording>/<keyframe>.npz

    def keyframe_bursts(self, method=None, stored=None, out=None) -> Iterator[KeyframeBurst]:
        """The keyframe bursts in time order; reading stops at a bad frame (:attr:`error`), the
        keyframes before it kept.  With ``out``, ``OUT/keyframes.json`` records them
        (:func:`lburst.sfm.recording.save_keyframes`), and a rerun whose keyframes are all
        ``stored`` does not read the recording again."""
        self.recording = recording = open_recording(self.path, self.options)
        content = None if method is None else store.recording_content(recording)
        whole = None if method is None else store.key(method, self.path, content)

        def key(name: str) -> dict[str, Any] | None:
            return None if method is None else store.key(method, self.path, content, keyframe=name)

        listed = rec.load_keyframes(out, whole) if out is not None and stored is not None else None
        if listed is not None and all(stored(k.name, key(k.name)) for k in listed):
            self.keyframes = listed
            for k in listed:
                yield KeyframeBurst(k.name, key(k.name), self._unread(k.name), k.index, k.time)
            return
        self.keyframes, self.error = [], None
        try:
            for keyframe, burst in recording.bursts():
                self.keyframes.append(keyframe)
                yield KeyframeBurst(keyframe.name, key(keyframe.name), lambda b=burst: b, keyframe.index, keyframe.time)
        except BurstError as err:
            self.error = str(err)
        if out is not None and whole is not None:
            rec.save_keyframes(out, whole, recording, self.keyframes, self.error)

    def _unread(self, name: str) -> Callable:
        def load():
            raise BurstError(f"{self.path}: keyframe {name}'s stored features went missing during the run; run again")

        return load

    def finish(self, out: Path) -> Scene:
        return rec.keyframe_scene(self.recording, self.keyframes, out)

    def camera_origin(self, scene: Scene, plan: CameraPlan, opts: ReconstructOptions) -> str | None:
        return camera_origin(scene, plan, opts)  # where the intrinsics came from (result.json, report.md)

    def gnss_track(self) -> GnssTrack | None:
        return None if self.recording is None else self.recording.gnss_track()

    def image_times(self, scene: Scene) -> list[float] | None:
        times = {k.name: k.time for k in self.keyframes}
        return [times[name] for name in scene.names]


def _common_file(item: SceneItem) -> Path | None:
    """The file of an item's common frame (a burst's middle frame), ``None`` if it has none."""
    if item.kind == "image":
        return item.path
    try:
        files = burst_files(item.path)
    except BurstError:
        return None
    return files[len(files) // 2]


def open_input(path: str | Path, options: RecordingOptions | None = None) -> SceneInput | RecordingInput:
    """The input of a reconstruction at ``path``: a :class:`RecordingInput` when it is a recording
    (:func:`lburst.burst.sources.is_recording` with ``options``), else a :class:`SceneInput`."""
    return RecordingInput(path, options) if is_recording(path, options) else SceneInput(path)


def open_bursts(path: str | Path, options: RecordingOptions | None = None) -> BurstInput | RecordingInput:
    """The input of ``lburst extract`` or ``lburst show`` at ``path``: a :class:`RecordingInput`
    when it is a recording that the options cut (a folder with ``meta.json`` or DNG frames, a ROS
    bag; with ``options.frame_folders``, any video or frame folder), else one :class:`BurstInput`
    (a whole video without them is one burst)."""
    path = Path(path)
    cut = options is not None and options.frame_folders
    if is_recording(path, options) and (path.is_dir() or cut or is_bag(path)):
        return RecordingInput(path, options)
    return BurstInput(path)
