"""Translational alignment of burst frames to the common (middle) frame: the shifts
(:func:`estimate_shifts`) and the aligned burst (:func:`align_burst`), used by the
``merge`` and ``align`` methods, BuFF, training pairs and :class:`lburst.LBurst` (for
weights run on aligned bursts).

Shift convention:
``shifts[k] = (dx, dy)`` in pixels means the scene point seen at ``(x, y)`` in the
common frame appears at ``(x + dx, y + dy)`` in frame ``k``, i.e.
``frame_k(p + shifts[k]) ~ common(p)``; the common frame's shift is ``(0, 0)``.  A
burst moving at a constant apparent velocity ``(u, v)`` px/frame has
``shifts[k] = (k - N // 2) * (u, v)``.
"""

from __future__ import annotations

from typing import Literal

import cv2
import numpy as np

from lburst.extras import require
from lburst.frames import check_burst, dtype_max, gray_unit, time_offsets

Method = Literal["phase", "ecc"]
Motion = Literal["free", "linear"]


def phase_shift(reference: np.ndarray, image: np.ndarray, window: np.ndarray, upsample: int = 100) -> np.ndarray:
    """Shift ``(dx, dy)`` of ``image`` relative to ``reference`` (both ``(H, W)`` float32).

    Phase correlation of the Hann-windowed images; the peak is refined to
    ``1 / upsample`` px by a matrix-multiply DFT upsampling around it (scikit-image).
    """
    registration = require("skimage.registration", "phase-correlation alignment (merge+...)")
    shift_yx, _, _ = registration.phase_cross_correlation(
        reference * window, image * window, upsample_factor=upsample, normalization=None
    )
    return -np.asarray(shift_yx[::-1], np.float64)


def ecc_shift(
    reference: np.ndarray,
    image: np.ndarray,
    initial: np.ndarray,
    smoothing: int = 5,
    margin: int = 8,
    iterations: int = 100,
) -> np.ndarray:
    """Refine ``initial`` ``(dx, dy)`` by maximising the enhanced correlation coefficient (OpenCV ECC).

    The images are smoothed by a ``smoothing``-pixel Gaussian inside OpenCV; pixels
    within ``margin`` of the border (plus the initial shift) are ignored.  If ECC
    fails to converge the initial shift is returned.
    """
    h, w = reference.shape
    pad = margin + int(np.ceil(np.abs(initial).max()))
    mask = np.zeros((h, w), np.uint8)
    if h > 2 * pad + 8 and w > 2 * pad + 8:
        mask[pad : h - pad, pad : w - pad] = 1
    else:
        mask[:] = 1
    warp = np.array([[1, 0, initial[0]], [0, 1, initial[1]]], np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, iterations, 1e-6)
    try:
        _, warp = cv2.findTransformECC(reference, image, warp, cv2.MOTION_TRANSLATION, criteria, mask, smoothing)
    except cv2.error:
        return np.asarray(initial, np.float64)
    return warp[:, 2].astype(np.float64)


def fit_linear(shifts: np.ndarray) -> np.ndarray:
    """Least-squares constant-velocity fit ``shifts[k] ~ t_k * (u, v)`` (through zero at the common frame)."""
    t = time_offsets(len(shifts)).astype(np.float64)
    if not np.any(t):
        return np.zeros_like(shifts)
    velocity = (t[:, None] * shifts).sum(0) / (t**2).sum()
    return t[:, None] * velocity[None]


def estimate_shifts(burst: np.ndarray, method: Method = "phase", motion: Motion = "free") -> np.ndarray:
    """Shifts ``(N, 2)`` float64 ``(dx, dy)`` of each frame relative to the common frame.

    Args:
        burst: uint8/uint16 ``(N, H, W, 3)``, temporal order, N odd.
        method: ``'phase'`` (windowed phase correlation with upsampled peak, about
            0.01-0.1 px on textured images up to noise std 50 of 255) or ``'ecc'``
            (phase correlation refined by OpenCV's ECC on smoothed images: slower,
            more accurate and more robust at high noise).
        motion: ``'free'`` estimates every frame on its own; ``'linear'`` then fits a
            constant velocity through them (robotic bursts), which averages the errors.
    """
    if method not in ("phase", "ecc"):
        raise ValueError(f"unknown alignment method {method!r}: use 'phase' or 'ecc'")
    if motion not in ("free", "linear"):
        raise ValueError(f"unknown motion model {motion!r}: use 'free' or 'linear'")
    frames = gray_unit(burst)
    n, h, w = frames.shape
    middle = n // 2
    window = cv2.createHanningWindow((w, h), cv2.CV_32F)
    shifts = np.zeros((n, 2), np.float64)
    for k in range(n):
        if k == middle:
            continue
        shifts[k] = phase_shift(frames[middle], frames[k], window)
        if method == "ecc":
            shifts[k] = ecc_shift(frames[middle], frames[k], shifts[k])
    return fit_linear(shifts) if motion == "linear" else shifts


def warp_frame(frame: np.ndarray, shift: np.ndarray, interpolation: int = cv2.INTER_LINEAR) -> np.ndarray:
    """Resample ``frame`` ``(H, W, C)`` onto the common frame: ``out(p) = frame(p + shift)`` (float32)."""
    matrix = np.array([[1, 0, shift[0]], [0, 1, shift[1]]], np.float32)
    h, w = frame.shape[:2]
    out = cv2.warpAffine(
        frame.astype(np.float32),
        matrix,
        (w, h),
        flags=interpolation | cv2.WARP_INVERSE_MAP,
        borderMode=cv2.BORDER_REPLICATE,
    )
    return out.reshape(frame.shape)


def align_burst(
    burst: np.ndarray, shifts: np.ndarray | None = None, method: Method = "ecc", motion: Motion = "linear"
) -> np.ndarray:
    """Every frame resampled onto the common frame (bilinear, replicated borders), rounded
    to the burst's dtype: the burst as it would be without its motion (the estimated
    shifts unless ``shifts`` are given).  The common frame is returned untouched."""
    burst = check_burst(burst)
    if shifts is None:
        shifts = estimate_shifts(burst, method=method, motion=motion)
    top = dtype_max(burst.dtype)
    out = burst.copy()
    for k in range(len(burst)):
        if np.any(shifts[k] != 0):
            out[k] = np.clip(np.rint(warp_frame(burst[k], np.asarray(shifts[k]))), 0, top).astype(burst.dtype)
    return out
