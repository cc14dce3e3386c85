"""The night flight placed on the Earth, and written as a drone or robot records it: JPEG
frames with their GPS in EXIF, a video's DJI ``.SRT`` subtitles, a ROS 2 (or ROS 1) bag with
compressed images, camera info and GNSS fixes.  Every position is the exact camera centre.

The flight's frame (:mod:`lburst.scenes.night_flight`: x, y on the ground, z up, metres) is
taken as east, north, up around :data:`FLIGHT_ORIGIN` (:class:`lburst.geo.frame.GeoOrigin`),
so a frame's latitude, longitude and altitude are its camera centre's, exactly; a reader
that puts its local frame on the first fix gets the flight's frame shifted by the first
camera centre (and turned by the curvature of the Earth over the shift: below 1e-5 rad).

- :func:`write_flight_jpg`: the PNG recording's frames (:func:`lburst.scenes.flight_recording.write_flight_png`)
  as JPEG with EXIF GPS, ``meta.json`` and ``gt.txt`` in the folder;
- :func:`write_flight_srt`: ``X.SRT`` beside the video ``X.mp4``, one subtitle per frame;
- :func:`write_flight_bag`: ``/camera/image_raw/compressed`` (JPEG ``CompressedImage``),
  ``/camera/camera_info`` (the exact camera, with each frame) and ``/gps/fix``
  (``NavSatFix`` at :data:`GNSS_RATE` Hz, so positions are interpolated to the frames), header
  stamps from :data:`BAG_EPOCH`; ``gt.txt`` in the bag's folder (``X.gt.txt`` beside a ROS 1
  ``X.bag``), timed from the first frame.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path
from lburst.burst.rosbag import BagWriter
from lburst.burst.sources import ground_truth_path
from lburst.errors import LBurstFileExistsError
from lburst.geo.exif import write_gps_jpeg
from lburst.geo.frame import GeoOrigin
from lburst.geo.srt import write_srt
from lburst.scenes import flight_recording as recording
from lburst.scenes.night_flight import NightFlightConfig, camera_pose
from lburst.tum import write_tum

#: where the flight's frame lies: latitude, longitude (degrees, WGS 84) and altitude (m) of its origin
FLIGHT_ORIGIN = GeoOrigin(47.3769, 8.5417, 408.0)
#: the simulated receiver's rate in a bag (Hz)
GNSS_RATE = 5.0
#: the header stamp of a bag's first frame (s since 1970)
BAG_EPOCH = 1_700_000_000.0
IMAGE_TOPIC = "/camera/image_raw/compressed"
INFO_TOPIC = "/camera/camera_info"
GNSS_TOPIC = "/gps/fix"


def frame_fixes(cfg: NightFlightConfig, times: np.ndarray) -> np.ndarray:
    """``(N, 3)`` latitude, longitude and altitude of the camera centre at each of ``times``."""
    centres = np.array([-R.T @ t for R, t in (camera_pose(cfg, float(time)) for time in times)]).reshape(-1, 3)
    return FLIGHT_ORIGIN.to_geodetic(centres)


def write_flight_jpg(folder: str | Path, cfg: NightFlightConfig, progress: bool = True, quality: int = 95) -> Path:
    """Render the flight as JPEG frames with EXIF GPS in ``folder`` (module docstring); frames
    already there are kept (resume), a folder made with another configuration is refused."""
    folder = recording._frame_folder(folder, cfg, "jpg")
    todo = [j for j in range(recording.frame_count(cfg)) if not (folder / f"frame_{j:06d}.jpg").is_file()]
    fixes = frame_fixes(cfg, recording.frame_times(cfg))
    if todo:
        for j, _, radiance in recording._rendered(cfg, progress, f"JPEG {folder.name}", todo):
            with atomic_path(folder / f"frame_{j:06d}.jpg") as tmp:
                write_gps_jpeg(tmp, recording.camera_frame(cfg, radiance, j), *fixes[j], quality=quality)
    return folder


def write_flight_srt(video: str | Path, cfg: NightFlightConfig) -> Path:
    """``X.SRT`` beside the video ``X.mp4`` of the flight: the camera centre of every frame."""
    times = recording.frame_times(cfg)
    path = Path(video).with_suffix(".SRT")
    with atomic_path(path) as tmp:
        write_srt(tmp, list(times), [tuple(f) for f in frame_fixes(cfg, times)], recording.fps(cfg))
    return path


def write_flight_bag(path: str | Path, cfg: NightFlightConfig, storage: str = "sqlite3", progress: bool = True) -> Path:
    """Render the flight into a bag at ``path`` (module docstring): ROS 1 for ``X.bag``, else a
    ROS 2 folder with ``storage`` ``'sqlite3'`` or ``'mcap'``; an existing one is refused."""
    path = Path(path)
    if path.exists():
        raise LBurstFileExistsError(f"{path}: exists; remove it or give another path for the bag")
    times = recording.frame_times(cfg)
    fixes = frame_fixes(cfg, times)
    camera = recording.camera(cfg)
    every = max(1, int(round(recording.fps(cfg) / GNSS_RATE)))
    with BagWriter(path, storage) as bag:
        for j, time, radiance in recording._rendered(cfg, progress, f"bag {path.name}"):
            stamp = BAG_EPOCH + time
            bag.compressed(IMAGE_TOPIC, stamp, recording.camera_frame(cfg, radiance, j))
            bag.camera_info(INFO_TOPIC, stamp, camera)
            if j % every == 0:
                bag.navsat(GNSS_TOPIC, stamp, *fixes[j])
    write_tum(
        ground_truth_path(path),
        times,
        [camera_pose(cfg, t) for t in times],
        header="ground truth of the synthetic night flight (ROS bag), camera-to-world, metres, from the first frame",
    )
    return path
