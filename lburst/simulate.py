"""Robotic bursts simulated from one image.

Frame ``k`` (``k = -N//2 .. N//2``) of a burst shows the image translated by
``k * (dx, dy)``: content at ``(x, y)`` of the image appears at ``(x + k dx, y + k dy)``
in frame ``k`` (pixel centres at integer coordinates), resampled with sub-pixel
bilinear interpolation.  The middle frame (``k = 0``) is the image itself, untouched
by interpolation.  Noise (see :mod:`lburst.noise`) is drawn independently per frame
and channel, then every frame is rounded and clipped to the image's dtype.

Training pairs (two bursts of one photo related by a homography, with the flow
between their common frames) are made by :func:`lburst.train.pairs.training_pair`.
"""

from __future__ import annotations

import hashlib
from typing import Sequence

import cv2
import numpy as np

from lburst.burst.motion import BurstMotion
from lburst.errors import LBurstValueError
from lburst.noise import NoiseModel

_BORDERS = {"reflect": cv2.BORDER_REFLECT_101, "replicate": cv2.BORDER_REPLICATE, "constant": cv2.BORDER_CONSTANT}


def stable_seed(*parts: object) -> int:
    """A seed that depends only on ``parts`` (their ``str``), the same in every run and
    on every machine (unlike Python's ``hash``)."""
    digest = hashlib.sha256("\x1f".join(str(p) for p in parts).encode()).digest()
    return int.from_bytes(digest[:8], "little")


def as_generator(rng: np.random.Generator | int | None) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


def random_motion(rng: np.random.Generator | int | None, max_shift: float) -> tuple[float, float]:
    """Per-frame motion (dx, dy) uniform in ``[-max_shift, max_shift]^2``."""
    dx, dy = as_generator(rng).uniform(-max_shift, max_shift, 2)
    return float(dx), float(dy)


def translate(image: np.ndarray, dx: float, dy: float, border: str = "reflect") -> np.ndarray:
    """``image`` (H, W[, C]) translated by (dx, dy), bilinear, as float32."""
    if border not in _BORDERS:
        raise LBurstValueError(f"unknown border {border!r}: use {', '.join(_BORDERS)}")
    h, w = image.shape[:2]
    matrix = np.array([[1, 0, dx], [0, 1, dy]], np.float64)
    out = cv2.warpAffine(image.astype(np.float32), matrix, (w, h), flags=cv2.INTER_LINEAR, borderMode=_BORDERS[border])
    return out.reshape(image.shape[:2] + image.shape[2:])


def simulate_burst(
    image: np.ndarray,
    frames: int = 5,
    motion: tuple[float, float] | Sequence[tuple[float, float]] | BurstMotion = (0.0, 0.0),
    noise: NoiseModel | None = None,
    rng: np.random.Generator | int | None = None,
    border: str = "reflect",
) -> np.ndarray:
    """A robotic burst ``(N, H, W, 3)`` of ``image`` (H, W, 3) or (H, W), uint8 or uint16.

    ``motion`` is the per-frame translation (dx, dy) in pixels, one (dx, dy) per
    frame (absolute offsets, the middle one (0, 0)), or a :class:`lburst.burst.motion.BurstMotion`
    (translation, rotation, zoom and smooth non-uniform flow).  Returns the image's dtype.
    """
    image = np.asarray(image)
    if image.dtype not in (np.uint8, np.uint16):
        raise LBurstValueError(f"image must be uint8 or uint16, got {image.dtype}")
    if image.ndim == 2:
        image = np.repeat(image[..., None], 3, axis=2)
    if image.ndim != 3 or image.shape[2] != 3:
        raise LBurstValueError(f"image must be (H, W) or (H, W, 3), got shape {image.shape}")
    if frames < 1 or frames % 2 == 0:
        raise LBurstValueError(f"frames must be odd and positive, got {frames}")
    half = frames // 2
    if isinstance(motion, BurstMotion):
        if motion.is_translation:
            motion = motion.shift
        else:
            return _simulate_general(image, frames, motion, noise, as_generator(rng), border)
    offsets = np.asarray(motion, np.float64)
    if offsets.shape == (2,):
        offsets = np.arange(-half, half + 1)[:, None] * offsets[None]
    if offsets.shape != (frames, 2):
        raise LBurstValueError(f"motion must be (dx, dy) or {frames} (dx, dy) pairs, got shape {offsets.shape}")
    generator = as_generator(rng)
    top = float(np.iinfo(image.dtype).max)
    burst = np.empty((frames,) + image.shape, image.dtype)
    for i, (dx, dy) in enumerate(offsets):
        frame = image.astype(np.float32) if dx == 0 and dy == 0 else translate(image, dx, dy, border)
        if noise is not None:
            frame = noise(frame * (255.0 / top), generator) * (top / 255.0)
        burst[i] = np.clip(np.round(frame), 0, top)
    return burst


def _simulate_general(
    image: np.ndarray,
    frames: int,
    motion: BurstMotion,
    noise: NoiseModel | None,
    generator: np.random.Generator,
    border: str,
) -> np.ndarray:
    """:func:`simulate_burst` for a motion beyond a translation: frame k is one remap of
    ``image`` at ``motion.source_points(k)``."""
    if border not in _BORDERS:
        raise LBurstValueError(f"unknown border {border!r}: use {', '.join(_BORDERS)}")
    h, w = image.shape[:2]
    top = float(np.iinfo(image.dtype).max)
    source = image.astype(np.float32)
    burst = np.empty((frames,) + image.shape, image.dtype)
    for i, k in enumerate(range(-(frames // 2), frames // 2 + 1)):
        if k == 0:
            frame = source
        else:
            pts = motion.source_points(k, (w, h))
            frame = cv2.remap(source, pts[..., 0], pts[..., 1], cv2.INTER_LINEAR, borderMode=_BORDERS[border])
        if noise is not None:
            frame = noise(frame * (255.0 / top), generator) * (top / 255.0)
        burst[i] = np.clip(np.round(frame), 0, top)
    return burst
