"""The night flight as a continuous recording: an MP4 video or a DNG frame sequence, with
ground-truth poses of every frame.

The drone flies the trajectory of :mod:`lburst.scenes.night_flight` (``(n_bursts - 1) *
burst_spacing`` metres, an arc or a survey, whose ``n_bursts`` its path sets) and the camera records a frame every ``frame_interval`` seconds:
frame ``j`` is rendered from the pose at time ``j / fps`` (``fps = 1 / frame_interval``),
so the bursts of the scene version are the frames around ``j = i * burst_spacing /
(speed * frame_interval)``.  Ground truth is written per frame in TUM format
(:mod:`lburst.tum`) with the frame's timestamp, and the camera (PINHOLE, exact) and frame
rate in the recording's ``meta.json`` (see :mod:`lburst.burst.sources` for where they go).

- **Video** (:func:`write_flight_video`): encoded with H.264 (``crf``, one x264 thread,
  so that the file is the same on every machine), ``yuv420p``, ``faststart``.  With a sensor
  noise model (``lowlight:...`` or ``sensor:...``) a frame is what a drone's camera makes
  of the very raw frame the DNG version stores (same Bayer sensor, same noise draw):
  :func:`camera_isp` subtracts the black level, demosaics (bilinear), scales white
  to 255 and rounds to 8 bits.  A Bayer sensor samples one colour per pixel, so it has a
  third of the photo-electrons of per-channel noise at every pixel; the video and the DNG
  of a flight thus hold the same light.  With any other noise (``gaussian:...``,
  ``none``) a frame is the scene version's: scaled by ``exposure``, the noise added on
  the 0..255 scale per pixel and channel, rounded to 8 bits.
- **PNG frames** (:func:`write_flight_png`): the video's frames before H.264, one 8-bit
  PNG per frame, ``frame_000000.png ...``, with ``meta.json`` and ``gt.txt`` inside the
  folder (as a camera's frame dump).
- **DNG** (:func:`write_flight_dng`): the rendered radiance (0..255 taken as linear,
  white at 255, times ``exposure``) is sampled through an RGGB Bayer filter and converted
  by the sensor of ``cfg.noise`` (``lowlight:...``, :class:`lburst.noise.LowLightNoise`:
  shot noise, read noise, a 12-bit ADC) to raw counts above a black level of
  ``BLACK_LEVEL``; one DNG per frame, ``frame_000000.dng ...``, white level
  ``2**adc_bits - 1``.  These frames are very dark: at ``lowlight:moonless`` white is
  about 6 counts above black.  A calibrated sensor (``sensor:NAME@ISO``,
  :class:`lburst.noise.SensorNoise`) writes its own raw values: its bit depth, black level
  (with its black bias, row and Tukey-lambda or Gaussian read noise) and white level.

Frame noise is seeded by ``(cfg.seed, 3, j)`` (DNG, and a sensor-noise video) and
``(cfg.seed, 2, j)`` (any other video).
"""

from __future__ import annotations

import json
from fractions import Fraction
from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path, write_image
from lburst.burst.sources import ground_truth_path, meta_path
from lburst.errors import LBurstValueError
from lburst.extras import require
from lburst.noise import LowLightNoise, SensorNoise, noise_from_spec
from lburst.scenes.dng import mosaic, write_dng
from lburst.scenes.night_flight import NightFlightConfig, camera_pose, make_city, render_view
from lburst.scenes.raycast import intrinsics
from lburst.tum import write_tum

BLACK_LEVEL = 256  # of a lowlight:... sensor; a calibrated sensor (sensor:...) has its own
#: Noise models that simulate a raw sensor (a Bayer mosaic of raw counts for the DNG and the camera's video)
RAW_SENSORS = (LowLightNoise, SensorNoise)


def frame_count(cfg: NightFlightConfig) -> int:
    """Frames of the continuous flight: from time 0 to the last burst's centre."""
    duration = (cfg.n_bursts - 1) * cfg.burst_spacing / cfg.speed
    return int(round(duration / cfg.frame_interval)) + 1


def fps(cfg: NightFlightConfig) -> float:
    return 1.0 / cfg.frame_interval


def frame_times(cfg: NightFlightConfig) -> np.ndarray:
    return np.arange(frame_count(cfg)) / fps(cfg)


def camera(cfg: NightFlightConfig) -> dict:
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    return {
        "model": "PINHOLE",
        "width": cfg.width,
        "height": cfg.height,
        "params": [float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])],
    }


def write_sidecars(cfg: NightFlightConfig, recording: Path, kind: str) -> None:
    """``meta.json`` (fps, camera, configuration) and ``gt.txt`` (per-frame TUM poses) of a recording."""
    times = frame_times(cfg)
    write_tum(
        ground_truth_path(recording),
        times,
        [camera_pose(cfg, t) for t in times],
        header=f"ground truth of the synthetic night flight ({kind}), camera-to-world, metres",
    )
    meta = {"fps": fps(cfg), "camera": camera(cfg), "kind": kind, "frames": len(times), "night_flight": cfg.to_dict()}
    with atomic_path(meta_path(recording)) as tmp:
        tmp.write_text(json.dumps(meta, indent=1))


def _rendered(cfg: NightFlightConfig, progress: bool, desc: str, indices=None):
    """(index, time, radiance (H, W, 3) float32 0..255 scaled by exposure) of frames ``indices`` (default all)."""
    city = make_city(cfg)
    K = intrinsics(cfg.width, cfg.height, cfg.hfov_deg)
    indices = range(frame_count(cfg)) if indices is None else indices
    if progress:
        from tqdm import tqdm

        indices = tqdm(indices, desc=desc, unit="frame")
    for j in indices:
        time = j / fps(cfg)
        R, t = camera_pose(cfg, time)
        image, _ = render_view(city, K, R, t, cfg.width, cfg.height, cfg.supersample)
        yield j, time, image * np.float32(cfg.exposure)


def write_flight_video(path: str | Path, cfg: NightFlightConfig, crf: int = 16, progress: bool = True) -> Path:
    """Render the flight as an MP4 (module docstring), atomically; sidecars next to it."""
    av = require("av", "writing a video (--video)")

    path = Path(path)
    if cfg.width % 2 or cfg.height % 2:
        raise LBurstValueError(f"an H.264 video needs an even size, got {cfg.width}x{cfg.height}")
    rate = Fraction(fps(cfg)).limit_denominator(1000)
    with atomic_path(path) as tmp:
        with av.open(str(tmp), mode="w", format="mp4", options={"movflags": "+faststart"}) as container:
            stream = container.add_stream("libx264", rate=rate)
            stream.width, stream.height, stream.pix_fmt = cfg.width, cfg.height, "yuv420p"
            # x264's output depends on its thread count, which it takes from the CPUs it may use:
            # one thread makes the video the same on every machine
            stream.options = {"crf": str(crf), "preset": "medium", "threads": "1"}
            for j, _, image in _rendered(cfg, progress, f"video {path.name}"):
                frame = av.VideoFrame.from_ndarray(camera_frame(cfg, image, j), format="rgb24")
                frame.pts = j
                for packet in stream.encode(frame):
                    container.mux(packet)
            for packet in stream.encode(None):
                container.mux(packet)
    write_sidecars(cfg, path, "video")
    return path


def camera_frame(cfg: NightFlightConfig, radiance: np.ndarray, j: int) -> np.ndarray:
    """Frame ``j`` as the camera delivers it, 8-bit RGB ``(H, W, 3)`` (module docstring): with a
    sensor noise model the camera's processing of the raw frame, else the noisy rendering rounded."""
    noise = noise_from_spec(cfg.noise)
    if isinstance(noise, RAW_SENSORS):
        return camera_isp(raw_frame(cfg, radiance, np.random.default_rng([cfg.seed, 3, j]))[0], noise)
    noisy = noise(radiance, np.random.default_rng([cfg.seed, 2, j]))
    return np.clip(np.round(noisy), 0, 255).astype(np.uint8)


def write_flight_png(folder: str | Path, cfg: NightFlightConfig, progress: bool = True) -> Path:
    """Render the flight as 8-bit PNG frames in ``folder``, the video's frames before encoding
    (module docstring); frames already there are kept (resume), a folder made with another
    configuration is refused with ``ValueError``."""
    folder = _frame_folder(folder, cfg, "png")
    todo = [j for j in range(frame_count(cfg)) if not (folder / f"frame_{j:06d}.png").is_file()]
    if todo:
        for j, _, radiance in _rendered(cfg, progress, f"PNG {folder.name}", todo):
            with atomic_path(folder / f"frame_{j:06d}.png") as tmp:
                write_image(tmp, camera_frame(cfg, radiance, j))
    return folder


def _frame_folder(folder: str | Path, cfg: NightFlightConfig, kind: str) -> Path:
    """``folder`` made (or resumed) for a frame recording of ``cfg``, with its sidecars."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    meta = meta_path(folder)
    if meta.is_file():
        old = json.loads(meta.read_text()).get("night_flight")
        if old != json.loads(json.dumps(cfg.to_dict())):
            raise LBurstValueError(f"{meta}: {folder} was made with another configuration; use a new folder")
    write_sidecars(cfg, folder, kind)
    return folder


def raw_frame(cfg: NightFlightConfig, radiance: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, int]:
    """Bayer raw counts ``(H, W)`` uint16 (black level included) of a radiance image, and the white level."""
    sensor = noise_from_spec(cfg.noise)
    if not isinstance(sensor, RAW_SENSORS):
        raise LBurstValueError(
            f"a DNG recording needs a sensor noise model (lowlight:... or sensor:...), got {cfg.noise!r}"
        )
    if isinstance(sensor, SensorNoise):
        return sensor.raw_dn(mosaic(radiance), rng, bayer=True).astype(np.uint16), sensor.white_level
    white = 2**sensor.adc_bits - 1
    counts = sensor.raw_counts(mosaic(radiance), rng) + BLACK_LEVEL
    return np.clip(counts, 0, white).astype(np.uint16), white


def black_level(sensor: LowLightNoise | SensorNoise) -> int:
    """The black level of ``sensor``'s raw frames: a calibrated sensor's own, else ``BLACK_LEVEL``."""
    return sensor.black_level if isinstance(sensor, SensorNoise) else BLACK_LEVEL


def camera_isp(cfa: np.ndarray, sensor: LowLightNoise | SensorNoise) -> np.ndarray:
    """The 8-bit RGB ``(H, W, 3)`` a camera makes of raw counts ``cfa`` (``raw_frame``'s RGGB mosaic,
    black level included) from ``sensor`` (a ``LowLightNoise`` or a calibrated ``SensorNoise``): bilinear
    demosaicing (of the counts scaled up to 16 bits, so that interpolation does not round to whole
    counts), the nominal black level subtracted, white radiance (the sensor's counts at white) scaled
    to 255, rounded, clipped."""
    import cv2

    code = getattr(cv2, "COLOR_BayerRGGB2RGB", cv2.COLOR_BayerBG2RGB)  # OpenCV calls RGGB 'BG'
    up = 2 ** max(0, 16 - sensor.adc_bits)
    scaled = np.ascontiguousarray(cfa, np.uint16) * np.uint16(up)
    rgb = cv2.cvtColor(scaled, code).astype(np.float32) / np.float32(up) - black_level(sensor)
    return np.clip(np.round(rgb * np.float32(255.0 / sensor.counts_at_white)), 0, 255).astype(np.uint8)


def write_flight_dng(folder: str | Path, cfg: NightFlightConfig, progress: bool = True) -> Path:
    """Render the flight as DNG frames in ``folder`` (module docstring); frames already there are kept
    (resume), a folder made with another configuration is refused with ``ValueError``."""
    sensor = noise_from_spec(cfg.noise)
    if not isinstance(sensor, RAW_SENSORS):
        raise LBurstValueError(
            f"a DNG recording needs a sensor noise model (lowlight:... or sensor:...), got {cfg.noise!r}"
        )
    folder = _frame_folder(folder, cfg, "dng")
    todo = [j for j in range(frame_count(cfg)) if not (folder / f"frame_{j:06d}.dng").is_file()]
    if todo:
        for j, _, radiance in _rendered(cfg, progress, f"DNG {folder.name}", todo):
            cfa, white = raw_frame(cfg, radiance, np.random.default_rng([cfg.seed, 3, j]))
            write_dng(folder / f"frame_{j:06d}.dng", cfa, black_level(sensor), white)
    return folder
