"""Burst input shared by the alignment and the non-learned methods: validation, dtype scale,
grayscale.

A burst is a uint8 or uint16 array ``(N, H, W, 3)`` (RGB) in temporal order with N odd;
frame ``N // 2`` is the common frame whose pixel grid all features refer to.  Frame
``k`` is at time offset ``t = k - N // 2``.
"""

from __future__ import annotations

import cv2
import numpy as np

from lburst.burst.io import to_uint8
from lburst.errors import LBurstValueError

#: pixels: the smallest side of a burst that lburst aligns, merges or extracts features from
MIN_BURST_SIDE = 8


def check_burst(burst: np.ndarray) -> np.ndarray:
    """Return ``burst`` as an array after checking its shape ``(N, H, W, 3)``, N odd, at least
    :data:`MIN_BURST_SIDE` pixels a side, and its dtype."""
    burst = np.asarray(burst)
    if burst.ndim != 4 or burst.shape[-1] != 3:
        raise LBurstValueError(f"expected a burst (N, H, W, 3), got shape {burst.shape}")
    if burst.shape[0] % 2 != 1:
        raise LBurstValueError(f"a burst needs an odd number of frames, got {burst.shape[0]}")
    if min(burst.shape[1:3]) < MIN_BURST_SIDE:
        raise LBurstValueError(
            f"a {burst.shape[2]}x{burst.shape[1]} burst is too small (at least {MIN_BURST_SIDE} px a side)"
        )
    if burst.dtype not in (np.uint8, np.uint16):
        raise LBurstValueError(f"a burst must be uint8 or uint16, got {burst.dtype}")
    return burst


def dtype_max(dtype: np.dtype) -> float:
    """The white level of an integer image type: 255 for uint8, 65535 for uint16."""
    return float(np.iinfo(dtype).max)


def time_offsets(n: int) -> np.ndarray:
    """Time offsets ``k - n // 2`` of the ``n`` frames, float32 ``(n,)``."""
    return np.arange(n, dtype=np.float32) - n // 2


def inner_mask(height: int, width: int, pad: int, min_inner: int = 0) -> np.ndarray:
    """uint8 ``(height, width)`` mask for OpenCV's ECC: 1 more than ``pad`` px from every border,
    or everywhere where that leaves no more than ``min_inner`` px a side."""
    mask = np.zeros((height, width), np.uint8)
    if height > 2 * pad + min_inner and width > 2 * pad + min_inner:
        mask[pad : height - pad, pad : width - pad] = 1
    else:
        mask[:] = 1
    return mask


def gray(frames: np.ndarray) -> np.ndarray:
    """Luma (ITU-R 601 weights, as OpenCV) of RGB ``(..., 3)`` images, float32 in the input's scale."""
    weights = np.array([0.299, 0.587, 0.114], np.float32)
    return frames.astype(np.float32) @ weights


def gray_unit(burst: np.ndarray) -> np.ndarray:
    """Grayscale frames ``(N, H, W)`` float32 in [0, 1] (divided by the dtype's white level)."""
    burst = check_burst(burst)
    return gray(burst) / np.float32(dtype_max(burst.dtype))


def to_gray8(image: np.ndarray) -> np.ndarray:
    """One RGB image ``(H, W, 3)`` uint8 or uint16 as 8-bit grayscale ``(H, W)`` (uint16 scaled by 255/65535)."""
    if image.dtype not in (np.uint8, np.uint16) or image.ndim != 3 or image.shape[-1] != 3:
        raise LBurstValueError(f"expected an RGB image (H, W, 3) uint8 or uint16, got {image.shape} {image.dtype}")
    luma = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    return to_uint8(luma)
