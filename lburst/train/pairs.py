"""Self-supervised training pairs: two synthetic bursts of one photo and the flow between them.

Coordinates: pixel centres at integer coordinates.  Both bursts are ``crop x crop``
crops; ``G`` is the 3x3 homography mapping pixels of burst A's common frame to
pixels of burst B's common frame.  Frame ``k`` (k = -N//2 .. N//2) of a burst shows
the common frame's content displaced by ``k * motion`` (as in
:func:`lburst.simulate.simulate_burst`).  Every frame is one ``cv2.warpPerspective``
of the (rescaled) photo, so no frame is resampled twice.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lburst.burst.align import warp_frame
from lburst.burst.motion import BurstMotion
from lburst.errors import LBurstValueError
from lburst.noise import IMAGENET_STD, LowLightNoise, sensor_from_spec
from lburst.photometric import check_jitter, color_jitter

#: The calibrated sensors of ``sensor_prob``: the phone-class IMX686 (a small drone's camera)
#: at its calibrated ISO, and the full-frame A7S2 on both sides of its dual-gain switch and at
#: its highest ISO (:data:`lburst.noise.SENSORS`).
SENSOR_MIX = ("imx686@6400", "a7s2@1600", "a7s2@6400", "a7s2@25600")


@dataclass(frozen=True)
class PairConfig:
    """How training pairs are drawn.  Defaults follow the paper unless noted.

    Attributes:
        frames: frames per burst N (odd; 1 gives single-image pairs).
        crop: side of the square crops, in pixels.
        long_side: range of the photo's long side after random rescaling.
        max_burst_motion: largest total in-burst translation (first to last frame), px.
        max_rotation_deg, max_tilt, scale_range: the random homography between the
            bursts (rotation about the crop centre, perspective tilt as a fraction of
            the crop moving a corner pair, isotropic scale).
        max_pair_shift: largest random translation between the bursts, px.
        noise_variance: paper noise, variance on ImageNet-normalised values, drawn
            uniformly per burst; ``None`` to use ``noise_std`` instead.
        noise_std: Gaussian std range on the 0..255 scale, drawn per burst (lburst's
            wider-range recipe, used when ``noise_variance`` is None).
        dark_prob, dark_range: probability and range of a per-burst exposure factor
            applied before the noise (darker images, same noise: lower SNR).
        gamma_range: per-burst gamma jitter applied before the exposure factor.
        color_jitter: largest change of brightness, contrast and saturation (relative) and of
            hue (a fraction of the colour circle) of burst B against burst A, drawn per pair,
            as R2D2's ``ColorJitter(0.2, 0.2, 0.2, 0.1)`` changes its second image; zeros
            (the presets) leave the colours alone.
        burst_rotation_deg, burst_zoom, burst_flow_px: in-burst motion beyond the
            translation (:class:`lburst.burst.motion.BurstMotion`): largest rotation per frame,
            largest relative zoom per frame, largest std of the smooth non-uniform flow
            per frame (drawn uniformly per burst).
        align_error_px: if not None, every noisy frame is warped back onto the common
            frame by the translation part of its motion plus a Gaussian error of this std
            (bilinear, replicated borders), as ``align+SPEC`` does with estimated shifts
            at inference: the network then learns to fuse and detect, not to align.
        lowlight_prob, lowlight_photons: probability of physical low-light noise
            (:class:`lburst.noise.LowLightNoise`, photons at white drawn log-uniformly
            in the range) instead of the Gaussian noise.
        sensor_prob, sensors: probability of a calibrated sensor's noise instead
            (:class:`lburst.noise.SensorNoise`: one of ``sensors``, each ``NAME@ISO`` as in
            ``sensor:NAME@ISO``, drawn uniformly per burst, exposed with photons at white drawn
            log-uniformly in ``lowlight_photons``); the three kinds of noise are drawn with
            one number, so ``lowlight_prob + sensor_prob`` is at most 1.
    """

    frames: int = 5
    crop: int = 192
    long_side: tuple[int, int] = (256, 1024)
    max_burst_motion: float = 30.0
    max_rotation_deg: float = 15.0
    max_tilt: float = 0.15
    scale_range: tuple[float, float] = (0.8, 1.25)
    max_pair_shift: float = 24.0
    noise_variance: tuple[float, float] | None = (0.3, 0.6)
    noise_std: tuple[float, float] = (5.0, 110.0)
    dark_prob: float = 0.0
    dark_range: tuple[float, float] = (0.15, 1.0)
    gamma_range: tuple[float, float] = (1.0, 1.0)
    color_jitter: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    burst_rotation_deg: float = 0.0
    burst_zoom: float = 0.0
    burst_flow_px: float = 0.0
    lowlight_prob: float = 0.0
    lowlight_photons: tuple[float, float] = (3.0, 60.0)
    sensor_prob: float = 0.0
    sensors: tuple[str, ...] = SENSOR_MIX
    align_error_px: float | None = None

    def __post_init__(self) -> None:
        low, high = self.noise_std
        if not 0.0 <= low <= high:
            raise LBurstValueError(f"noise_std ({low:g}, {high:g}) must be a range LOW <= HIGH of stds >= 0")
        low, high = self.scale_range
        if not 0.0 < low <= high:
            raise LBurstValueError(f"scale_range ({low:g}, {high:g}) must be a range 0 < LOW <= HIGH")
        check_jitter(self.color_jitter)
        if not 0.0 <= self.max_tilt < 1.0:
            raise LBurstValueError(f"max_tilt {self.max_tilt:g} must lie in [0, 1)")
        if not 0.0 <= self.sensor_prob <= 1.0 - self.lowlight_prob:
            raise LBurstValueError(
                f"sensor_prob {self.sensor_prob} must lie in [0, 1 - lowlight_prob] = [0, {1.0 - self.lowlight_prob:g}]"
            )
        if self.sensor_prob:
            if not self.sensors:
                raise LBurstValueError("sensor_prob > 0 needs at least one sensor (NAME@ISO)")
            for sensor in self.sensors:
                sensor_from_spec(sensor)


@dataclass
class TrainingPair:
    """``burst_a``, ``burst_b``: (N, crop, crop, 3) float32 on the 0..255 scale, noisy,
    rounded and clipped; ``clean_a``: burst A before the noise (rounded and clipped), the
    target of self-distillation; ``flow``: (crop, crop, 2) float32, the absolute position (x, y)
    in B's common frame of every pixel of A's common frame; ``mask``: (crop, crop) bool,
    where that position lies inside B; ``homography``: the 3x3 ``G`` (A to B)."""

    burst_a: np.ndarray
    burst_b: np.ndarray
    clean_a: np.ndarray
    flow: np.ndarray
    mask: np.ndarray
    homography: np.ndarray


def _translation(tx: float, ty: float) -> np.ndarray:
    return np.array([[1, 0, tx], [0, 1, ty], [0, 0, 1]], np.float64)


def random_homography(rng: np.random.Generator, cfg: PairConfig) -> np.ndarray:
    """A random homography of the crop (rotation, scale, tilt about its centre, then a shift)."""
    c = (cfg.crop - 1) / 2
    angle = np.deg2rad(rng.uniform(-cfg.max_rotation_deg, cfg.max_rotation_deg))
    scale = np.exp(rng.uniform(*np.log(cfg.scale_range)))
    rot = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    similarity = np.diag([scale, scale, 1.0]) @ rot
    # tilt: move the four corners inwards/outwards by up to max_tilt * crop/2 along one random axis
    half = cfg.crop / 2
    src = np.array([[-half, -half], [half, -half], [half, half], [-half, half]], np.float32)
    t = rng.uniform(-cfg.max_tilt, cfg.max_tilt) * half
    dst = src.copy()
    if rng.random() < 0.5:  # horizontal tilt: the left edge shrinks, the right one grows (or vice versa)
        dst[[0, 3], 1] *= 1 - t / half
        dst[[1, 2], 1] *= 1 + t / half
    else:  # vertical tilt
        dst[[0, 1], 0] *= 1 - t / half
        dst[[2, 3], 0] *= 1 + t / half
    tilt = cv2.getPerspectiveTransform(src, dst).astype(np.float64)
    shift = rng.uniform(-cfg.max_pair_shift, cfg.max_pair_shift, 2)
    g = _translation(c + shift[0], c + shift[1]) @ tilt @ similarity @ _translation(-c, -c)
    return g / g[2, 2]


def _burst_motion(rng: np.random.Generator, cfg: PairConfig) -> BurstMotion:
    """In-burst motion: a translation of total length up to ``max_burst_motion`` over the
    burst, plus (when configured) rotation, zoom and a smooth non-uniform flow."""
    if cfg.frames == 1:
        return BurstMotion()
    length = rng.uniform(0, cfg.max_burst_motion) / (cfg.frames - 1)
    angle = rng.uniform(0, 2 * np.pi)
    shift = (float(length * np.cos(angle)), float(length * np.sin(angle)))
    rotation = float(rng.uniform(-cfg.burst_rotation_deg, cfg.burst_rotation_deg)) if cfg.burst_rotation_deg else 0.0
    zoom = float(rng.uniform(-cfg.burst_zoom, cfg.burst_zoom)) if cfg.burst_zoom else 0.0
    flow = float(rng.uniform(0, cfg.burst_flow_px)) if cfg.burst_flow_px else 0.0
    return BurstMotion(shift, rotation, zoom, flow, int(rng.integers(2**31)) if flow else 0)


def _exposure(frames: np.ndarray, rng: np.random.Generator, cfg: PairConfig) -> np.ndarray:
    """Per-burst gamma and exposure factor (the clean, darkened burst)."""
    gamma = rng.uniform(*cfg.gamma_range)
    if gamma != 1.0:
        frames = 255.0 * (frames / 255.0) ** gamma
    if rng.random() < cfg.dark_prob:
        frames = frames * rng.uniform(*cfg.dark_range)
    return frames


def _noise(frames: np.ndarray, rng: np.random.Generator, cfg: PairConfig) -> np.ndarray:
    """Per-frame, per-channel noise (Gaussian, physical low light or a calibrated sensor's),
    rounded and clipped."""
    kind = rng.random() if cfg.lowlight_prob or cfg.sensor_prob else 1.0
    if kind < cfg.lowlight_prob:
        photons = float(np.exp(rng.uniform(*np.log(cfg.lowlight_photons))))
        noisy = LowLightNoise(photons)(frames, rng)
    elif kind < cfg.lowlight_prob + cfg.sensor_prob:
        sensor = cfg.sensors[int(rng.integers(len(cfg.sensors)))]
        photons = float(np.exp(rng.uniform(*np.log(cfg.lowlight_photons))))
        noisy = sensor_from_spec(f"{sensor},photons={photons!r}")(frames, rng)
    else:
        if cfg.noise_variance is not None:
            variance = rng.uniform(*cfg.noise_variance)
            std = np.sqrt(variance) * np.array(IMAGENET_STD) * 255.0
        else:
            std = np.full(3, rng.uniform(*cfg.noise_std))
        noisy = frames + rng.standard_normal(frames.shape, dtype=np.float32) * std.astype(np.float32)
    return np.clip(np.round(noisy), 0, 255).astype(np.float32)


def _rescale(photo: np.ndarray, rng: np.random.Generator, cfg: PairConfig) -> np.ndarray:
    h, w = photo.shape[:2]
    lo, hi = cfg.long_side
    # the rescaled photo must hold a crop with margin for the in-burst motion
    lo = max(lo, int(np.ceil((cfg.crop + 2 * cfg.max_burst_motion) * max(h, w) / min(h, w))))
    target = rng.uniform(lo, max(lo, hi))
    s = target / max(h, w)
    size = (max(1, round(w * s)), max(1, round(h * s)))
    interp = cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR
    return cv2.resize(photo, size, interpolation=interp)


def _render(photo: np.ndarray, to_photo: np.ndarray, crop: int, motion: BurstMotion, frames: int) -> np.ndarray:
    """Frames whose common frame maps pixel p to photo pixel ``to_photo @ p``; frame k
    shows the common frame at ``motion.source_points(k)``."""
    out = np.empty((frames, crop, crop, 3), np.float32)
    for i, k in enumerate(range(-(frames // 2), frames // 2 + 1)):
        if motion.is_translation:  # one exact homography per frame
            m = to_photo @ _translation(-k * motion.shift[0], -k * motion.shift[1])
            out[i] = cv2.warpPerspective(
                photo,
                m,
                (crop, crop),
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_REFLECT_101,
            )
            continue
        pts = motion.source_points(k, (crop, crop)).astype(np.float64)
        q = pts @ to_photo[:2, :2].T + to_photo[:2, 2]
        z = pts @ to_photo[2, :2] + to_photo[2, 2]
        q = (q / z[..., None]).astype(np.float32)
        out[i] = cv2.remap(photo, q[..., 0], q[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
    return out


def _estimated_shifts(motion: BurstMotion, cfg: PairConfig, rng: np.random.Generator) -> np.ndarray:
    """``(N, 2)`` shifts of the frames as an aligner would find them: the translation
    part of ``motion`` plus a Gaussian error (none for the common frame)."""
    k = np.arange(cfg.frames) - cfg.frames // 2
    shifts = k[:, None] * np.asarray(motion.shift)[None] + rng.normal(0, cfg.align_error_px, (cfg.frames, 2))
    shifts[cfg.frames // 2] = 0
    return shifts


def _align(frames: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Frames warped back by ``shifts`` (``out(p) = frame(p + shift)``), rounded and clipped."""
    out = frames.copy()
    for i, shift in enumerate(shifts):
        if np.any(shift != 0):
            out[i] = np.clip(np.round(warp_frame(frames[i], shift)), 0, 255)
    return out


def training_pair(photo: np.ndarray, rng: np.random.Generator, cfg: PairConfig = PairConfig()) -> TrainingPair:
    """Draw one training pair from ``photo`` (H, W, 3) uint8 RGB."""
    if photo.ndim != 3 or photo.shape[2] != 3:
        raise LBurstValueError(f"expected an RGB photo (H, W, 3), got {photo.shape}")
    photo = _rescale(photo, rng, cfg).astype(np.float32)
    h, w = photo.shape[:2]
    crop = cfg.crop
    margin = cfg.max_burst_motion
    ox = rng.uniform(margin, max(margin, w - crop - margin))
    oy = rng.uniform(margin, max(margin, h - crop - margin))
    a_to_photo = _translation(ox, oy)
    g = random_homography(rng, cfg)
    b_to_photo = a_to_photo @ np.linalg.inv(g)
    motion_a, motion_b = _burst_motion(rng, cfg), _burst_motion(rng, cfg)
    burst_a = _render(photo, a_to_photo, crop, motion_a, cfg.frames)
    burst_b = _render(photo, b_to_photo, crop, motion_b, cfg.frames)
    clean_a = _exposure(burst_a, rng, cfg)
    burst_a = _noise(clean_a, rng, cfg)
    burst_b = _noise(_exposure(color_jitter(burst_b, rng, cfg.color_jitter), rng, cfg), rng, cfg)
    if cfg.align_error_px is not None:
        shifts_a = _estimated_shifts(motion_a, cfg, rng)
        clean_a = _align(np.clip(np.round(clean_a), 0, 255), shifts_a)
        burst_a = _align(burst_a, shifts_a)
        burst_b = _align(burst_b, _estimated_shifts(motion_b, cfg, rng))
    ys, xs = np.mgrid[0:crop, 0:crop].astype(np.float64)
    pts = np.stack([xs, ys, np.ones_like(xs)], -1) @ g.T
    flow = (pts[..., :2] / pts[..., 2:]).astype(np.float32)
    mask = (flow[..., 0] >= 0) & (flow[..., 0] <= crop - 1) & (flow[..., 1] >= 0) & (flow[..., 1] <= crop - 1)
    clean_a = np.clip(np.round(clean_a), 0, 255).astype(np.float32)
    return TrainingPair(burst_a, burst_b, clean_a, flow, mask, g)
