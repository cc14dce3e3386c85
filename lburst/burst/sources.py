"""Recordings as burst sources: a video or a folder of consecutive frames, cut into keyframe bursts.

A *recording* is a video file (decoded with PyAV, one frame at a time), a ROS bag's image
topic (:mod:`lburst.burst.rosbag`: frames numbered in bag order, timed by their header
stamps) or a folder of consecutive frames (PNG/JPEG/TIFF, 8 or 16 bit, or DNG), sorted naturally.  A folder is
one when it has a ``meta.json`` or DNG frames, or, with
:attr:`RecordingOptions.frame_folders` (the command line's ``--every`` or ``--motion``),
any folder with frame files in it (:func:`is_recording`); without them a folder of
plain frames is one burst.  Frame
*indices* count frames from the start: for a video ``round((time - t0) * fps)`` from
the frames' timestamps, for a folder the last number in each file name (so a gap in the
numbering is a dropped frame), or the position when the names carry no distinct
numbers.  Timestamps are the video's, or ``index / fps`` for a folder.  Video frames are
turned as the stream's rotation metadata (display matrix) says, as a player shows them; a
camera in ``meta.json`` describes the frames so turned.

Keyframes are frames ``start, start + every, start + 2 every, ...``, or, with
``motion``, the frames from ``start`` on where the view has moved that fraction of the
image width since the last keyframe (:mod:`lburst.burst.keyframes`); the burst of
keyframe ``k`` is frames ``k - N//2 .. k + N//2`` (``N = burst``, odd), in temporal
order, keyframe in the middle.  A frame of the window the recording lacks (before its
first frame, after its last, or dropped) is replaced by the nearest frame of the window
it has (:attr:`Keyframe.filled` counts them); a keyframe whose own frame is missing is
skipped.  Frames are read as a stream and only those of the bursts being assembled are
held, at most ``N + 1`` at once, so a long recording never sits in memory.

Linear 16-bit frames (DNG, 16-bit PNG/TIFF) are normalised to uint8 with one gain
for the recording (:mod:`lburst.burst.raw`); 8-bit frames pass unchanged.

Sidecar files (optional), next to a video ``X.mp4`` or inside a folder ``X/``:

- ``X.meta.json`` / ``X/meta.json``: ``{"fps": ..., "camera": COLMAP camera dict}``
  (fps of a frame folder, default 30; the camera's intrinsics, taken as the calibration;
  without them COLMAP estimates the camera), checked when the recording is opened
  (:mod:`lburst.burst.meta`);
- ``X.gt.txt`` / ``X/gt.txt``: ground-truth camera poses per frame, TUM format
  (:mod:`lburst.tum`), timestamps on the recording's clock;
- ``X.SRT`` / ``X.srt`` beside a video: a DJI drone's per-frame position
  (:mod:`lburst.geo.srt`); a folder's frames may carry theirs in EXIF (:mod:`lburst.geo.exif`).

Every problem raises :class:`lburst.burst.io.BurstError` naming the file; bursts yielded
before it stay valid.
"""

from __future__ import annotations

import re
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

import numpy as np

from lburst.burst.io import IMAGE_SUFFIXES, VIDEO_SUFFIXES, BurstError, natural_key, read_image
from lburst.burst.keyframes import MotionGate, MotionTracker, thumbnail
from lburst.burst.meta import check_fps, read_meta
from lburst.burst.raw import RAW_SUFFIXES, Normalisation, normalise, read_dng
from lburst.burst.rosbag import BagReader, is_bag
from lburst.errors import LBurstValueError
from lburst.extras import require
from lburst.geo.exif import frames_track
from lburst.geo.fixes import GnssTrack
from lburst.geo.srt import read_srt, srt_path
from lburst.numbers import check_integer

DEFAULT_FPS = 30.0


@dataclass(frozen=True)
class RecordingOptions:
    """How a recording is cut into bursts (module docstring).

    Attributes:
        burst: frames per burst (odd).
        every: a keyframe every this many frames (without ``motion``).
        motion: take keyframes by motion instead (:class:`lburst.burst.keyframes.MotionGate`).
        start: index of the first keyframe.
        fps: frame rate of a frame folder (default: its ``meta.json``, else 30).
        normalisation: brightness normalisation of linear 16-bit frames.
        max_frames: stop reading after this many frames (``None``: all).
        frame_folders: a folder of plain frames (PNG/JPEG/TIFF, without ``meta.json``) is
            a recording too (:func:`is_recording`); the command line sets it when
            ``--every`` or ``--motion`` is given.  It changes no burst (not in :meth:`signature`).
        topic: the image topic of a ROS bag (:mod:`lburst.burst.rosbag`); ``None``: its only one.
    """

    burst: int = 5
    every: int = 10
    start: int = 0
    fps: float | None = None
    normalisation: Normalisation = field(default_factory=Normalisation)
    max_frames: int | None = None
    motion: MotionGate | None = None
    frame_folders: bool = False
    topic: str | None = None

    def __post_init__(self) -> None:
        check_integer(self.burst, "--burst", 1, 99)
        if self.burst % 2 == 0:
            raise LBurstValueError(
                f"--burst must be odd and positive (the middle frame is the keyframe), got {self.burst}"
            )
        check_integer(self.every, "--every", 1)
        check_integer(self.start, "--start", 0)
        if self.fps is not None:
            check_fps(self.fps)
        if self.max_frames is not None:
            check_integer(self.max_frames, "max_frames", 1)

    def signature(self) -> str:
        """What changes the bursts (for caches): burst, every or motion, start, fps, normalisation."""
        n = self.normalisation
        spacing = f"every={self.every}" if self.motion is None else f"motion={self.motion.threshold}/{self.motion.size}"
        return (
            f"burst={self.burst},{spacing},start={self.start},fps={self.fps},"
            f"gain={n.gain},p={n.percentile},target={n.target},max_gain={n.max_gain},"
            f"curve={n.curve},binning={n.binning}"
        ) + (f",topic={self.topic}" if self.topic is not None else "")


@dataclass(frozen=True)
class Frame:
    """One decoded frame: index (module docstring), timestamp (s), RGB ``(H, W, 3)`` uint8/uint16, file."""

    index: int
    time: float
    image: np.ndarray
    source: str


@dataclass(frozen=True)
class Keyframe:
    """A keyframe: its frame index, timestamp (s) and how many burst frames were filled in."""

    index: int
    time: float
    filled: int = 0

    @property
    def name(self) -> str:
        """``f<index>_t<seconds>s``, e.g. ``f000064_t3.200s``: file-safe, in natural order."""
        return f"f{self.index:06d}_t{self.time:.3f}s"


def _sidecar(path: Path, name: str) -> Path:
    return path / name if path.is_dir() else path.with_name(f"{path.stem}.{name}")


def meta_path(path: str | Path) -> Path:
    return _sidecar(Path(path), "meta.json")


def ground_truth_path(path: str | Path) -> Path:
    return _sidecar(Path(path), "gt.txt")


def _as_displayed(frame) -> np.ndarray:
    """A decoded video frame (RGB) turned as its stream's display matrix says (phone videos
    shot upright are stored on their side), so that frames are what a player shows."""
    image = frame.to_ndarray(format="rgb24")
    turns = int(round((getattr(frame, "rotation", 0) or 0) / 90)) % 4
    return np.ascontiguousarray(np.rot90(image, turns)) if turns else image


def frame_files(folder: Path) -> list[Path]:
    """The frame files of a recording folder (images and DNG), naturally sorted."""
    suffixes = IMAGE_SUFFIXES + RAW_SUFFIXES
    for p in folder.iterdir():
        if p.suffix.lower() in suffixes and p.is_symlink() and not p.exists():
            raise BurstError(f"{p}: a broken link (its target is missing, or the link loops); fix or remove it")
    return sorted(
        (p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in suffixes and not p.name.startswith(".")),
        key=lambda p: natural_key(p.name),
    )


def is_recording(path: str | Path, options: RecordingOptions | None = None) -> bool:
    """A video file, a ROS bag (:func:`lburst.burst.rosbag.is_bag`), or a folder with a ``meta.json`` or with DNG frames; with
    ``options.frame_folders`` also a folder with frame files (PNG/JPEG/TIFF) in it.  Other
    folders are scenes or bursts."""
    path = Path(path)
    if (path.suffix.lower() in VIDEO_SUFFIXES and not path.is_dir()) or is_bag(path):
        return True
    if not path.is_dir():
        return False
    if (path / "meta.json").is_file() or any(p.suffix.lower() in RAW_SUFFIXES for p in path.iterdir()):
        return True
    return bool(options is not None and options.frame_folders) and any(
        p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".") for p in path.iterdir()
    )


def read_frame(path: Path) -> np.ndarray:
    """A frame file as RGB uint8/uint16 (DNG: linear uint16, :func:`lburst.burst.raw.read_dng`)."""
    return read_dng(path) if path.suffix.lower() in RAW_SUFFIXES else read_image(path)


class Recording:
    """A video or a frame folder (module docstring): ``frames()`` streams its frames."""

    def __init__(self, path: str | Path, options: RecordingOptions = RecordingOptions()):
        self.path = Path(path)
        self.options = options
        if not self.path.exists():
            raise BurstError(f"{self.path}: no such file or folder")
        self.meta = read_meta(meta_path(self.path))
        self.bag = BagReader(self.path, options.topic) if is_bag(self.path) else None
        self.is_video = self.path.is_file() and self.bag is None
        if self.bag is not None:
            self.files = sorted(self.path.iterdir()) if self.path.is_dir() else [self.path]  # its content's key
            self.fps, self.frame_count = self._bag_rate(), self.bag.count
        elif self.is_video:
            if self.path.stat().st_size == 0:
                raise BurstError(f"{self.path}: empty file (zero-length video)")
            self.files: list[Path] = []
            self.fps, self.frame_count = self._probe_video()
        else:
            self.files = frame_files(self.path)
            if not self.files:
                raise BurstError(f"{self.path}: no frames ({', '.join(IMAGE_SUFFIXES + RAW_SUFFIXES)})")
            self.fps = float(options.fps or self.meta.get("fps") or DEFAULT_FPS)
            if options.fps is None and "fps" not in self.meta:  # its times, in keyframes.json and the trajectory
                warnings.warn(
                    f'{self.path}: no frame rate (--fps, or "fps" in meta.json): its frames are timed at '
                    f"{DEFAULT_FPS:g} fps",
                    stacklevel=2,
                )
            self.indices = self._file_indices()
            self.frame_count = self.indices[-1] + 1
        self.gain: float | None = None  # set by bursts() from the first burst of linear frames
        self.frames_read, self.read_seconds, self.last_index = 0, 0.0, -1

    @property
    def camera(self) -> dict | None:
        """The camera of ``meta.json`` (a COLMAP camera dict), else a bag's ``CameraInfo``, if any."""
        if self.bag is not None and "camera" not in self.meta:
            return self.bag.camera()
        return self.meta.get("camera")

    @property
    def camera_source(self) -> str:
        """Where :attr:`camera` comes from, as the report says it."""
        if self.bag is not None and "camera" not in self.meta:
            return f"the CameraInfo of {self.bag.path.name}"
        return "meta.json"

    def _bag_rate(self) -> float:
        """A bag's frame rate: its frames over the time from the first to the last (30 for one frame)."""
        span = self.bag.span()
        return (self.bag.count - 1) / span if span > 0 else DEFAULT_FPS

    @property
    def ground_truth(self) -> Path | None:
        path = ground_truth_path(self.path)
        return path if path.is_file() else None

    def gnss_track(self) -> GnssTrack | None:
        """The GNSS fixes the recording carries, on its clock (:mod:`lburst.geo`): a video's DJI
        ``.SRT`` beside it, or the EXIF GPS of a folder's frames; ``None`` when it has none."""
        if self.bag is not None:
            return self.bag.gnss_track()
        if self.is_video:
            srt = srt_path(self.path)
            return None if srt is None else read_srt(srt)
        times = [index / self.fps for index in self.indices]
        return frames_track(((path, t, None) for path, t in zip(self.files, times)), str(self.path))

    def _open_video(self):
        av = require("av", "reading a video")

        try:
            container = av.open(str(self.path))
        except (av.FFmpegError, OSError) as err:
            raise BurstError(f"{self.path}: not a readable video ({err}); truncated or not a video file?") from err
        if not container.streams.video:
            container.close()
            raise BurstError(
                f"{self.path}: no video stream found (a truncated MP4 whose index was at the end, or not a video)"
            )
        demuxer = container.format.name
        if demuxer.endswith("_pipe") or demuxer.startswith("image2"):
            container.close()
            raise BurstError(
                f"{self.path}: a still image ({demuxer.removesuffix('_pipe')}), not a video; "
                "to read images as a recording, put the frames in a folder"
            )
        return container

    def _probe_video(self) -> tuple[float, int | None]:
        container = self._open_video()
        try:
            stream = container.streams.video[0]
            rate = stream.average_rate or stream.guessed_rate
            if not rate:
                raise BurstError(f"{self.path}: the video stream has no frame rate")
            return float(rate), (int(stream.frames) or None)
        finally:
            container.close()

    def _file_indices(self) -> list[int]:
        numbers = [re.findall(r"\d+", p.stem) for p in self.files]
        if all(numbers):
            indices = [int(n[-1]) for n in numbers]
            if len(set(indices)) == len(indices):
                first = indices[0]
                return [i - first for i in indices]
        return list(range(len(self.files)))

    def frames(self) -> Iterator[Frame]:
        """Frames in temporal order, one at a time (module docstring).  ``frames_read`` and
        ``read_seconds`` count them and the time spent reading and decoding them."""
        limit = self.options.max_frames
        source = self._bag_frames() if self.bag else self._video_frames() if self.is_video else self._folder_frames()
        while limit is None or self.frames_read < limit:
            start = time.perf_counter()
            frame = next(source, None)
            self.read_seconds += time.perf_counter() - start
            if frame is None:
                return
            self.frames_read += 1
            self.last_index = frame.index
            yield frame

    def _bag_frames(self) -> Iterator[Frame]:
        for frame in self.bag.frames():
            yield Frame(frame.index, frame.time, frame.image, f"{self.path}: {self.bag.topic} message {frame.index}")

    def _folder_frames(self) -> Iterator[Frame]:
        for path, index in zip(self.files, self.indices):
            yield Frame(index, index / self.fps, read_frame(path), str(path))

    def _video_frames(self) -> Iterator[Frame]:
        av = require("av", "reading a video")

        container = self._open_video()
        decoded, t0, last = 0, None, -1
        try:
            stream = container.streams.video[0]
            stream.thread_type = "AUTO"
            try:
                for frame in container.decode(stream):
                    stamp = float(frame.time) if frame.time is not None else decoded / self.fps
                    t0 = stamp if t0 is None else t0
                    index = int(round((stamp - t0) * self.fps))
                    if index <= last:  # a repeated timestamp: keep the frames in decode order
                        index = last + 1
                    last = index
                    decoded += 1
                    yield Frame(index, stamp, _as_displayed(frame), str(self.path))
            except av.FFmpegError as err:
                raise BurstError(
                    f"{self.path}: decoding stopped after {decoded} frames ({err}); the file is truncated or corrupt"
                ) from err
        finally:
            container.close()
        if decoded == 0:
            raise BurstError(f"{self.path}: no frames could be decoded (zero-length or truncated video)")
        if self.frame_count and decoded < self.frame_count and self.options.max_frames is None:
            raise BurstError(
                f"{self.path}: only {decoded} of its {self.frame_count} frames could be decoded; the file is truncated"
            )

    def bursts(self) -> Iterator[tuple[Keyframe, np.ndarray]]:
        """``(keyframe, burst (N, H, W, 3))`` in temporal order (module docstring); the burst is
        normalised (uint8) when the frames are linear 16-bit and the normalisation asks for it.
        A ``start`` past the last frame is an error that names both."""
        emitted = 0
        for item in self._motion_bursts(self.options.motion) if self.options.motion is not None else self._bursts():
            emitted += 1
            yield item
        if not emitted and self.frames_read and self.options.start > self.last_index:
            raise BurstError(
                f"{self.path}: --start {self.options.start} is past the last frame ({self.last_index}) of the recording"
            )

    def _bursts(self) -> Iterator[tuple[Keyframe, np.ndarray]]:
        o = self.options
        half = o.burst // 2
        buffer: dict[int, Frame] = {}
        next_key = o.start
        for frame in self._checked_frames():
            while next_key + half < frame.index:
                yield from self._emit(next_key, buffer)
                next_key = self._next_key(next_key + o.every, [*buffer, frame.index])
                for i in [i for i in buffer if i < next_key - half]:
                    del buffer[i]
            if frame.index >= next_key - half:
                buffer[frame.index] = frame
        while buffer and next_key <= max(buffer):
            yield from self._emit(next_key, buffer)
            next_key += o.every

    def _next_key(self, key: int, present: list[int]) -> int:
        """The first keyframe of the schedule (``start + k * every``) from ``key`` on whose own frame
        may be there, given the indices ``present`` of the frames read that may still be needed:
        keyframes whose frame is missing are skipped anyway, so a gap in the numbering is crossed at
        once, not one missing index at a time (a frame numbered 999999999 after 30 frames took 10^9 steps)."""
        later = [i for i in present if i >= key]
        if not later or min(later) <= key:
            return key
        every = self.options.every
        return key + -(-(min(later) - key) // every) * every

    def _motion_bursts(self, gate: MotionGate) -> Iterator[tuple[Keyframe, np.ndarray]]:
        """Every frame from ``start`` on is a candidate once its window is read; a keyframe when ``gate`` says so."""
        half = self.options.burst // 2
        buffer: dict[int, Frame] = {}
        thumbs: dict[int, np.ndarray] = {}
        tracker = MotionTracker(gate)

        def consider(candidate: int) -> Iterator[tuple[Keyframe, np.ndarray]]:
            if candidate < self.options.start or candidate not in buffer:
                return
            if tracker.is_keyframe([thumbs[i] for i in range(candidate - half, candidate + half + 1) if i in thumbs]):
                yield from self._emit(candidate, buffer)

        newest = None
        for frame in self._checked_frames():
            buffer[frame.index] = frame
            thumbs[frame.index] = thumbnail(frame.image, gate.size)
            first_new = frame.index if newest is None else newest + 1  # frames read since the last one
            for candidate in sorted(i for i in buffer if first_new - half <= i <= frame.index - half):
                yield from consider(candidate)  # frames read, not every index between: numbers may jump
            newest = frame.index
            for i in [i for i in buffer if i < frame.index - 2 * half]:
                del buffer[i], thumbs[i]
        if newest is not None:
            for candidate in range(newest - half + 1, newest + 1):
                yield from consider(candidate)

    def _checked_frames(self) -> Iterator[Frame]:
        """:meth:`frames`, refusing a frame whose size or type differs from the first one's."""
        first: Frame | None = None
        for frame in self.frames():
            if first is None:
                first = frame
            elif frame.image.shape != first.image.shape or frame.image.dtype != first.image.dtype:
                raise BurstError(
                    f"{frame.source}: frame {frame.index} is {_describe(frame.image)}, "
                    f"the first frame ({first.source}) {_describe(first.image)}; mixed frame sizes"
                )
            yield frame

    def _emit(self, key: int, buffer: dict[int, Frame]) -> Iterator[tuple[Keyframe, np.ndarray]]:
        if key not in buffer:
            return  # the keyframe itself was dropped
        half = self.options.burst // 2
        window = [i for i in range(key - half, key + half + 1) if i in buffer]
        frames, filled = [], 0
        for i in range(key - half, key + half + 1):
            if i not in buffer:
                filled += 1
                i = min(window, key=lambda j: (abs(j - i), abs(j - key)))
            frames.append(buffer[i].image)
        burst = np.stack(frames)
        if burst.dtype == np.uint16:
            if self.gain is None:
                self.gain = self.options.normalisation.estimate_gain(burst)
            burst = normalise(burst, self.gain, self.options.normalisation.curve)
        yield Keyframe(key, buffer[key].time, filled), burst


def _describe(image: np.ndarray) -> str:
    return f"{image.shape[1]}x{image.shape[0]} {image.dtype}"


def open_recording(path: str | Path, options: RecordingOptions = RecordingOptions()) -> Recording:
    """The recording at ``path`` (module docstring); ``BurstError`` naming the file if it cannot be used."""
    return Recording(path, options)
