"""Alignment of burst frames to the common (middle) frame: the shifts
(:func:`estimate_shifts`), the warps with the rotation of bursts that turn
(:func:`estimate_warps`, :mod:`lburst.burst.turning`) and the aligned burst
(:func:`align_burst`), used by the
``merge`` and ``align`` methods, BuFF, training pairs and :class:`lburst.LBurst` (for
weights run on aligned bursts).

Shift convention:
``shifts[k] = (dx, dy)`` in pixels means the scene point seen at ``(x, y)`` in the
common frame appears at ``(x + dx, y + dy)`` in frame ``k``, i.e.
``frame_k(p + shifts[k]) ~ common(p)``; the common frame's shift is ``(0, 0)``.  A
burst moving at a constant apparent velocity ``(u, v)`` px/frame has
``shifts[k] = (k - N // 2) * (u, v)``.

Methods: ``'phase'`` (phase correlation at full resolution), ``'ecc'`` (phase
correlation refined by ECC at full resolution: the reference, about 0.5-1 s per
1024x768 5-frame burst on one core) and ``'pyramid'`` (plain cross-correlation on a 4x
downsampled grey image, refined by ECC on a 2x downsampled one: within about 0.02 px
of ``'ecc'`` on simulated bursts, noise up to std 100 of 255 and ``lowlight:night``,
at about 0.03 s per burst; see ``scripts/align_speed.py``).  :func:`align_burst` uses
``'pyramid'`` by default.
"""

from __future__ import annotations

from typing import Literal

import cv2
import numpy as np

from lburst.burst.frames import check_burst, gray_unit, inner_mask, time_offsets
from lburst.burst.turning import Level, euclidean_warps
from lburst.errors import LBurstValueError
from lburst.extras import require

Method = Literal["phase", "ecc", "pyramid"]
Motion = Literal["free", "linear"]
Warp = Literal["rigid", "affine"]
METHODS = ("phase", "ecc", "pyramid")
#: what :func:`estimate_warps` fits to each frame: ``'rigid'``, a translation (with a constant
#: velocity), and a rotation where the burst turns; ``'affine'``, that warp refined to a full
#: affine map per frame (:func:`affine_warps`), which also takes out the zoom of a camera moving
#: along its view and the shear of a tilted one
WARPS = ("rigid", "affine")

#: ``'pyramid'``: ECC runs at the smallest power-of-two downsampling with at most this many pixels
PYRAMID_MAX_PIXELS = 1 << 19
#: ``'pyramid'``: the coarse cross-correlation runs one level below, if its short side keeps this many pixels
PYRAMID_COARSE_MIN_SIDE = 64


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
    eps: float = 1e-6,
) -> np.ndarray:
    """Refine ``initial`` ``(dx, dy)`` by maximising the enhanced correlation coefficient (OpenCV ECC).

    The images are smoothed by a ``smoothing``-pixel Gaussian inside OpenCV; pixels
    within ``margin`` of the border (plus the initial shift) are ignored.  ECC stops
    after ``iterations`` or when an update moves the shift by less than ``eps`` px.  If
    ECC fails to converge the initial shift is returned.
    """
    pad = margin + int(np.ceil(np.abs(initial).max()))
    mask = inner_mask(*reference.shape, pad, min_inner=8)
    warp = np.array([[1, 0, initial[0]], [0, 1, initial[1]]], np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, iterations, eps)
    try:
        _, warp = cv2.findTransformECC(reference, image, warp, cv2.MOTION_TRANSLATION, criteria, mask, smoothing)
    except cv2.error:
        return np.asarray(initial, np.float64)
    return warp[:, 2].astype(np.float64)


def pyramid_scales(height: int, width: int, max_pixels: int = PYRAMID_MAX_PIXELS) -> tuple[int, int]:
    """Downsampling factors ``(fine, coarse)`` of :func:`pyramid_shifts` for ``height x width`` frames.

    ``fine``: the smallest power of two leaving at most ``max_pixels`` pixels (2 for
    1024x768, 1 for 640x480); ``coarse``: ``2 * fine`` if its short side keeps
    :data:`PYRAMID_COARSE_MIN_SIDE` pixels, else ``fine``.
    """
    fine = 1
    while (height // fine) * (width // fine) > max_pixels and min(height, width) // (2 * fine) >= 2:
        fine *= 2
    coarse = 2 * fine if min(height, width) // (2 * fine) >= PYRAMID_COARSE_MIN_SIDE else fine
    return fine, coarse


def _downsample(image: np.ndarray, factor: int) -> np.ndarray:
    """``image`` (H, W) float32 averaged over ``factor x factor`` blocks (the right/bottom remainder
    dropped, so that pixel ``i`` covers ``factor * i .. factor * i + factor - 1`` and shifts scale by
    exactly ``1 / factor``)."""
    if factor == 1:
        return image
    h, w = (image.shape[0] // factor), (image.shape[1] // factor)
    return cv2.resize(image[: h * factor, : w * factor], (w, h), interpolation=cv2.INTER_AREA)


def _gray_float(frame: np.ndarray) -> np.ndarray:
    """Luma of one RGB frame (H, W, 3) uint8/uint16 as float32 on the dtype's scale (OpenCV, rounded to the dtype)."""
    return cv2.cvtColor(np.ascontiguousarray(frame), cv2.COLOR_RGB2GRAY).astype(np.float32)


def _peak_offset(before: float, peak: float, after: float) -> float:
    """Sub-pixel offset of a peak from a parabola through three samples (0 where they are flat)."""
    curvature = before - 2 * peak + after
    return 0.0 if curvature >= 0 else 0.5 * (before - after) / curvature


def coarse_shift(reference: np.ndarray, image: np.ndarray, window: np.ndarray) -> np.ndarray:
    """Shift ``(dx, dy)`` of ``image`` relative to ``reference`` (both ``(H, W)`` float32): the
    peak of the plain cross-correlation of the mean-free, Hann-windowed images (NumPy FFT),
    refined by a parabola through its neighbours (a fraction of a pixel; ECC refines it).

    Plain, not phase correlation: phase correlation weighs every frequency alike, and in a dark
    burst the high ones are noise. On the validation bursts at 5 photons at white
    (``lowlight:5``) OpenCV's phase correlation started 7 of 120 bursts more than 2 px off,
    this 2; without noise the aligned shifts are as before (median error 0.002 px over the same
    120 bursts).  ``(0, 0)`` for flat images."""
    a = (reference - reference.mean()) * window
    b = (image - image.mean()) * window
    corr = np.fft.irfft2(np.fft.rfft2(b) * np.conj(np.fft.rfft2(a)), s=a.shape)
    h, w = corr.shape
    y, x = np.unravel_index(int(np.argmax(corr)), corr.shape)
    if not np.isfinite(corr[y, x]) or corr[y, x] <= 0:
        return np.zeros(2)
    dx = x + _peak_offset(corr[y, (x - 1) % w], corr[y, x], corr[y, (x + 1) % w])
    dy = y + _peak_offset(corr[(y - 1) % h, x], corr[y, x], corr[(y + 1) % h, x])
    return np.array([dx - w if dx > w / 2 else dx, dy - h if dy > h / 2 else dy], np.float64)


def pyramid_levels(burst: np.ndarray, max_pixels: int = PYRAMID_MAX_PIXELS) -> tuple[Level, Level]:
    """The burst's grey frames (OpenCV luma) averaged down by ``fine`` and ``coarse``
    (:func:`pyramid_scales`): ``((fine, fine_frames), (coarse, coarse_frames))``."""
    h, w = burst.shape[1:3]
    fine, coarse = pyramid_scales(h, w, max_pixels)
    fine_frames = [_downsample(_gray_float(frame), fine) for frame in burst]
    coarse_frames = [_downsample(frame, coarse // fine) for frame in fine_frames]
    return (fine, fine_frames), (coarse, coarse_frames)


def pyramid_shifts(
    burst: np.ndarray,
    smoothing: int = 7,
    iterations: int = 50,
    eps: float = 1e-4,
    max_pixels: int = PYRAMID_MAX_PIXELS,
    levels: tuple[Level, Level] | None = None,
) -> np.ndarray:
    """Shifts ``(N, 2)`` float64 of each frame relative to the common frame, coarse to fine.

    Grey frames (OpenCV luma) are averaged down by ``fine`` and ``coarse`` (see
    :func:`pyramid_scales`: 2 and 4 at 1024x768; ``levels``: those of
    :func:`pyramid_levels`, already made); the cross-correlation of the Hann-windowed
    ``coarse`` images (:func:`coarse_shift`) gives a start within a fraction of a pixel, which
    OpenCV's ECC refines on the ``fine`` images (Gaussian ``smoothing`` px there, stop at
    ``eps`` px or ``iterations``).  No motion model: :func:`estimate_shifts` fits one.
    """
    burst = check_burst(burst)
    n = len(burst)
    middle = n // 2
    (fine, fine_frames), (coarse, coarse_frames) = levels or pyramid_levels(burst, max_pixels)
    ch, cw = coarse_frames[middle].shape
    window = cv2.createHanningWindow((cw, ch), cv2.CV_32F)
    shifts = np.zeros((n, 2), np.float64)
    for k in range(n):
        if k == middle:
            continue
        start = coarse_shift(coarse_frames[middle], coarse_frames[k], window) * (coarse / fine)
        refined = ecc_shift(
            fine_frames[middle],
            fine_frames[k],
            start,
            smoothing=smoothing,
            margin=max(8 // fine, 2),
            iterations=iterations,
            eps=eps,
        )
        shifts[k] = refined * fine
    return shifts


#: A frame whose shift lies further than this from a constant-velocity line (px) disagrees with it:
#: above the night flight's shake (its frames lie up to 1 px off their best line), far below a lost
#: frame (tens of px).
AGREE_PX = 3.0


def fit_linear(shifts: np.ndarray, agree_px: float = AGREE_PX) -> np.ndarray:
    """Constant-velocity fit ``shifts[k] ~ t_k * (u, v)`` (through zero at the common frame).

    Least squares over the frames that agree: each moving frame's own velocity ``shift / t``
    is tried as the line, the one within ``agree_px`` of the most frames wins (the smallest
    total distance breaks a tie), and the fit is least squares over those frames.  When every
    frame agrees this is least squares over all of them; when no two frames agree, least
    squares over all too.  A frame that the correlation lost under heavy noise (tens of
    pixels off) then no longer drags every frame's alignment with it."""
    shifts = np.asarray(shifts, np.float64)
    t = time_offsets(len(shifts)).astype(np.float64)
    moving = t != 0
    if not moving.any():
        return np.zeros_like(shifts)
    best, best_key = moving, None
    for j in np.flatnonzero(moving):
        distance = np.linalg.norm(shifts - t[:, None] * (shifts[j] / t[j]), axis=1)
        agree = moving & (distance <= agree_px)
        key = (int(agree.sum()), -float(distance[moving].sum()))
        if agree.sum() >= 2 and (best_key is None or key > best_key):
            best, best_key = agree, key
    velocity = (t[best, None] * shifts[best]).sum(0) / (t[best] ** 2).sum()
    return t[:, None] * velocity[None]


def estimate_shifts(burst: np.ndarray, method: Method = "phase", motion: Motion = "free") -> np.ndarray:
    """Shifts ``(N, 2)`` float64 ``(dx, dy)`` of each frame relative to the common frame.

    Args:
        burst: uint8/uint16 ``(N, H, W, 3)``, temporal order, N odd.
        method: ``'phase'`` (windowed phase correlation with upsampled peak, about
            0.01-0.1 px on textured images up to noise std 50 of 255), ``'ecc'``
            (phase correlation refined by OpenCV's ECC on smoothed images: slower,
            more accurate and more robust at high noise) or ``'pyramid'``
            (:func:`pyramid_shifts`: ECC on half-resolution images started by a
            quarter-resolution cross-correlation; about as accurate as ``'ecc'``,
            about 20x faster).
        motion: ``'free'`` estimates every frame on its own; ``'linear'`` then fits a
            constant velocity through them (robotic bursts), which averages the errors.
    """
    if method not in METHODS:
        raise LBurstValueError(f"unknown alignment method {method!r}: use 'phase', 'ecc' or 'pyramid'")
    if motion not in ("free", "linear"):
        raise LBurstValueError(f"unknown motion model {motion!r}: use 'free' or 'linear'")
    if method == "pyramid":
        shifts = pyramid_shifts(burst)
        return fit_linear(shifts) if motion == "linear" else shifts
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


def translation_warps(shifts: np.ndarray) -> np.ndarray:
    """The shifts ``(N, 2)`` as warps ``(N, 2, 3)`` (:mod:`lburst.burst.turning`'s convention)."""
    shifts = np.asarray(shifts, np.float64)
    warps = np.zeros((len(shifts), 2, 3))
    warps[:, 0, 0] = warps[:, 1, 1] = 1
    warps[:, :, 2] = shifts
    return warps


def check_warp(warp: str) -> str:
    """``warp`` if it is one of :data:`WARPS`; else ``LBurstValueError`` in one line."""
    if warp not in WARPS:
        raise LBurstValueError(f"unknown warp {warp!r}: use {' or '.join(repr(w) for w in WARPS)}")
    return warp


def estimate_warps(burst: np.ndarray, motion: Motion = "linear", turn: bool = True, warp: Warp = "rigid") -> np.ndarray:
    """Warps ``(N, 2, 3)`` float64 of each frame onto the common frame (``frame_k(W_k p) ~ common(p)``):
    the translations of :func:`estimate_shifts` (``'pyramid'``, ``motion``); with ``turn``, where
    the burst turns, a rotation and a translation per frame instead
    (:func:`lburst.burst.turning.euclidean_warps`, no motion model); with ``warp='affine'``,
    either refined to an affine map per frame (:func:`affine_warps`)."""
    if motion not in ("free", "linear"):
        raise LBurstValueError(f"unknown motion model {motion!r}: use 'free' or 'linear'")
    check_warp(warp)
    burst = check_burst(burst)
    levels = pyramid_levels(burst)
    shifts = pyramid_shifts(burst, levels=levels)
    warps = euclidean_warps(*levels, shifts) if turn else None
    if warps is None:
        warps = translation_warps(fit_linear(shifts) if motion == "linear" else shifts)
    return affine_warps(levels[0], warps) if warp == "affine" else warps


def _to_level(warp: np.ndarray, factor: int) -> np.ndarray:
    """A full-resolution 2x3 warp on a level downsampled by ``factor`` (full pixel =
    ``factor`` x level pixel + ``(factor - 1) / 2``)."""
    offset = (factor - 1) / 2.0
    out = warp.copy()
    out[:, 2] = (warp[:, 2] - offset * (1.0 - warp[:, :2].sum(1))) / factor
    return out


def _to_full(warp: np.ndarray, factor: int) -> np.ndarray:
    """The inverse of :func:`_to_level`."""
    offset = (factor - 1) / 2.0
    out = warp.copy()
    out[:, 2] = warp[:, 2] * factor + offset * (1.0 - warp[:, :2].sum(1))
    return out


def _correlation(reference: np.ndarray, image: np.ndarray, warp: np.ndarray, mask: np.ndarray) -> float:
    """ECC's correlation of ``reference`` and ``image`` resampled by ``warp`` (2x3, inverse map)."""
    h, w = reference.shape
    moved = cv2.warpAffine(image, warp, (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
    return float(cv2.computeECC(reference, moved, mask))


def affine_warps(
    fine: Level, warps: np.ndarray, smoothing: int = 7, iterations: int = 50, eps: float = 1e-4, margin: int = 8
) -> np.ndarray:
    """``warps`` ``(N, 2, 3)`` (full resolution) refined to an affine map per frame by OpenCV's
    ECC on the ``fine`` level (:func:`pyramid_levels`), each started from its warp.  A frame keeps
    its start where ECC fails or ends at a lower correlation than the start's (both measured on
    the same smoothed images, inside the same margin): the refinement never makes a frame worse
    by that measure.  No motion model: each frame has its own map."""
    factor, frames = fine
    n = len(warps)
    middle = n // 2
    h, w = frames[middle].shape
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, iterations, eps)
    smooth = [cv2.GaussianBlur(frame, (smoothing, smoothing), 0) for frame in frames]
    out = np.array(warps, np.float64)
    for k in range(n):
        if k == middle:
            continue
        start = _to_level(out[k], factor).astype(np.float32)
        mask = inner_mask(h, w, max(margin // factor, 2) + int(np.ceil(np.abs(start[:, 2]).max())))
        try:
            _, refined = cv2.findTransformECC(
                frames[middle], frames[k], start.copy(), cv2.MOTION_AFFINE, criteria, mask, smoothing
            )
        except cv2.error:
            continue
        if not np.all(np.isfinite(refined)):
            continue
        better = _correlation(smooth[middle], smooth[k], refined, mask) > _correlation(
            smooth[middle], smooth[k], start, mask
        )
        if better:
            out[k] = _to_full(refined.astype(np.float64), factor)
    return out


def align_burst(
    burst: np.ndarray,
    shifts: np.ndarray | None = None,
    method: Method = "pyramid",
    motion: Motion = "linear",
    turn: bool = True,
    warp: Warp = "rigid",
) -> np.ndarray:
    """Every frame resampled onto the common frame (bilinear, replicated borders), in
    the burst's dtype: the burst as it would be without its motion.  ``shifts`` ``(N, 2)``
    or warps ``(N, 2, 3)`` (:func:`estimate_warps`) when given; else the estimated shifts
    (``method``, ``motion``), and with ``'pyramid'`` and ``turn`` the frames' rotation too
    where the burst turns (:mod:`lburst.burst.turning`; a burst that does not turn is
    aligned by its shifts alone), and with ``'pyramid'`` and ``warp='affine'`` an affine map
    per frame (:func:`affine_warps`).  The common frame is returned untouched.

    The warp runs in the burst's dtype (OpenCV, rounded): for uint16 it equals the
    float warp rounded; for uint8 OpenCV's fixed-point weights differ from it by 1 in
    about 0.4% of the values."""
    burst = check_burst(burst)
    n, h, w = burst.shape[:3]
    check_warp(warp)
    if warp != "rigid" and method != "pyramid":
        raise LBurstValueError(f"warp {warp!r} needs the 'pyramid' method, not {method!r}")
    if shifts is None:
        if method == "pyramid":
            warps = estimate_warps(burst, motion, turn, warp)
        else:
            warps = translation_warps(estimate_shifts(burst, method=method, motion=motion))
    else:
        warps = np.asarray(shifts, np.float64)
        if warps.shape == (n, 2):
            warps = translation_warps(warps)
        if warps.shape != (n, 2, 3):
            raise LBurstValueError(
                f"shifts must be ({n}, 2) or warps ({n}, 2, 3) for a {n}-frame burst, got {warps.shape}"
            )
    identity = np.eye(2, 3)
    out = np.empty(burst.shape, burst.dtype)  # C order: every out[k] is a contiguous frame OpenCV writes into
    for k in range(n):
        if np.any(warps[k] != identity):
            warped = cv2.warpAffine(
                np.ascontiguousarray(burst[k]),
                warps[k].astype(np.float32),
                (w, h),
                dst=out[k],
                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                borderMode=cv2.BORDER_REPLICATE,
            )
            if not np.shares_memory(warped, out[k]):
                out[k] = warped.reshape(out[k].shape)
        else:
            out[k] = burst[k]
    return out
