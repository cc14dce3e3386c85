"""In-plane rotation of images and bursts about their centre, and the pixel map it makes.

Angles are in degrees, counter-clockwise as the image is displayed (y down), as
``np.rot90`` turns an image.  Pixel centres are at integer coordinates (as lburst
keypoints).  The rotated image is the bounding box of the turned one, so nothing is
cropped; a multiple of 90 degrees is an exact permutation of the pixels.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from lburst.errors import LBurstValueError


def _cos_sin(deg: float) -> tuple[float, float]:
    if float(deg) % 90 == 0:  # exact, so that quarter turns map pixel centres onto pixel centres
        k = int(round(float(deg) / 90)) % 4
        return ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))[k]
    rad = math.radians(deg)
    return math.cos(rad), math.sin(rad)


def rotation_map(deg: float, shape: tuple[int, ...]) -> tuple[np.ndarray, tuple[int, int]]:
    """The 3x3 map from pixels of an image of ``shape`` (H, W, ...) to pixels of the image
    turned by ``deg``, and the turned image's (H, W)."""
    if not math.isfinite(deg):
        raise LBurstValueError(f"rotation must be a finite number of degrees, got {deg!r}")
    h, w = shape[:2]
    c, s = _cos_sin(deg)
    new_w = int(round(abs(w * c) + abs(h * s)))
    new_h = int(round(abs(w * s) + abs(h * c)))
    turn = np.array([[c, s], [-s, c]])
    centre = np.array([(w - 1) / 2, (h - 1) / 2])
    new_centre = np.array([(new_w - 1) / 2, (new_h - 1) / 2])
    m = np.eye(3)
    m[:2, :2] = turn
    m[:2, 2] = new_centre - turn @ centre
    return m, (new_h, new_w)


def rotate_image(image: np.ndarray, deg: float, reflect: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``image`` (H, W[, C]) turned by ``deg`` and the 3x3 pixel map from ``image`` to it.
    Quarter turns are exact; other angles are bilinear, with black corners (or, with
    ``reflect``, the image mirrored into them, which makes no false edges)."""
    m, (new_h, new_w) = rotation_map(deg, image.shape)
    if float(deg) % 90 == 0:
        return np.ascontiguousarray(np.rot90(image, int(round(float(deg) / 90)) % 4)), m
    turned = cv2.warpAffine(
        image,
        m[:2],
        (new_w, new_h),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REFLECT_101 if reflect else cv2.BORDER_CONSTANT,
        borderValue=0,
    )
    return turned, m


def turn_burst(burst: np.ndarray, quarter_turns: int) -> np.ndarray:
    """A burst (N, H, W, C) with every frame turned by ``quarter_turns`` x 90 degrees (exact)."""
    return np.ascontiguousarray(np.rot90(burst, quarter_turns % 4, axes=(1, 2)))


def map_points(points: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Points (K, 2) mapped by the affine 3x3 ``m``."""
    return (np.asarray(points, np.float64) @ m[:2, :2].T + m[:2, 2]).astype(np.float32)
