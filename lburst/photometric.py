"""Photometric changes between views: one random colour change of a whole burst or image.

R2D2 trains with ``ColorJitter(0.2, 0.2, 0.2, 0.1)`` on its second image; lburst's training
pairs (``lburst train --color-jitter``) and the homography benchmark (``lburst bench homography
--color-jitter``) change colours the same way.
"""

from __future__ import annotations

import numpy as np

from lburst.errors import LBurstValueError

#: RGB to YIQ: luma, then the two chroma axes a hue shift turns.
_YIQ = np.array([[0.299, 0.587, 0.114], [0.596, -0.274, -0.322], [0.211, -0.523, 0.312]])


def color_jitter(frames: np.ndarray, rng: np.random.Generator, jitter: tuple[float, float, float, float]) -> np.ndarray:
    """The burst ``frames`` (N, H, W, 3), or one image (H, W, 3), on 0..255, with one random
    brightness, contrast, saturation and hue change for all its frames: factors drawn in
    ``1 +- jitter[0..2]``, a hue turn of up to ``jitter[3]`` of the circle (in YIQ), the contrast
    about the (common) frame's mean luma.  Float32, clipped to 0..255."""
    brightness, contrast, saturation, hue = jitter
    if not any(jitter):
        return frames
    f_b, f_c, f_s = (rng.uniform(1 - j, 1 + j) for j in (brightness, contrast, saturation))
    angle = 2 * np.pi * rng.uniform(-hue, hue)
    turn = np.array([[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]])
    # YIQ: scale the luma by brightness, the chroma by saturation, turn the chroma by the hue angle
    mix = np.linalg.inv(_YIQ) @ turn @ np.diag([f_b, f_b * f_s, f_b * f_s]) @ _YIQ
    out = np.asarray(frames, np.float32) @ mix.T.astype(np.float32)
    common = out if out.ndim == 3 else out[len(out) // 2]
    mean = float((common @ _YIQ[0].astype(np.float32)).mean())
    out = (out - mean) * f_c + mean
    return np.clip(out, 0, 255).astype(np.float32)


def check_jitter(jitter: tuple[float, ...]) -> tuple[float, float, float, float]:
    """``jitter`` as four numbers in [0, 1] (brightness, contrast, saturation, hue), or ``LBurstValueError``."""
    values = tuple(float(v) for v in jitter)
    if len(values) != 4 or not all(0.0 <= v <= 1.0 for v in values):
        raise LBurstValueError(
            f"color_jitter {jitter} must be four numbers in [0, 1]: brightness, contrast, saturation, hue"
        )
    return values
