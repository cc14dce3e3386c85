"""SIFT orientation and descriptor (Lowe 2004, as in OpenCV) from patches sampled by a callback.

The callback decouples *what* image is described from *how* it is sampled: BuFF samples
the slope-merged Gaussian image of a burst, a plain image would sample itself.  It is
called as ``sample(grid)`` with ``grid`` ``(C, P, Q, 2)`` float32 x, y positions in the
image's pixel grid (one patch per keypoint) and returns ``(C, P, Q)`` float32 values.

Angles are radians in image coordinates (x right, y down), measured from +x towards +y,
the direction of the dominant intensity gradient; this equals OpenCV's
``KeyPoint.angle`` converted to radians.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

Sampler = Callable[[np.ndarray], np.ndarray]

ORI_BINS = 36
ORI_RADIUS = 3 * 1.5  # in units of the keypoint's sigma
ORI_SIGMA = 1.5
ORI_PEAK_RATIO = 0.8
DESC_WIDTH = 4  # spatial bins per axis
DESC_BINS = 8  # orientation bins
DESC_SCALE = 3.0  # one spatial bin spans DESC_SCALE * sigma pixels
DESC_SAMPLES = 4  # samples per spatial bin and axis
DESC_MAG_CLIP = 0.2


def orientations(sample: Sampler, centres: np.ndarray, sigmas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Dominant gradient orientations (SIFT): 36-bin histogram, peaks within 80% of the highest.

    Args:
        sample: the patch sampler (see the module docstring).
        centres: ``(C, 2)`` integer-valued x, y where the histograms are centred.
        sigmas: ``(C,)`` keypoint sigma in the image's pixels.

    Returns:
        ``index`` ``(M,)`` into the keypoints (a keypoint appears once per peak) and
        ``angle`` ``(M,)`` radians in [0, 2 pi).
    """
    if len(centres) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.float32)
    radii = np.rint(ORI_RADIUS * sigmas).astype(np.int64)
    r = int(radii.max())
    offsets = np.arange(-r - 1, r + 2, dtype=np.float32)
    grid = np.stack(np.meshgrid(offsets, offsets, indexing="xy"), -1)  # (P, P, 2) x, y
    patches = sample(centres[:, None, None, :].astype(np.float32) + grid[None])
    gx = patches[:, 1:-1, 2:] - patches[:, 1:-1, :-2]
    gy = patches[:, 2:, 1:-1] - patches[:, :-2, 1:-1]  # y down
    inner = offsets[1:-1]
    dist2 = inner[None, :] ** 2 + inner[:, None] ** 2
    weight = np.exp(-dist2[None] / (2 * (ORI_SIGMA * sigmas[:, None, None]) ** 2))
    inside = (np.abs(inner)[None, None, :] <= radii[:, None, None]) & (
        np.abs(inner)[None, :, None] <= radii[:, None, None]
    )
    magnitude = np.hypot(gx, gy) * weight * inside
    bins = np.rint(np.arctan2(gy, gx) % (2 * np.pi) * (ORI_BINS / (2 * np.pi))).astype(np.int64) % ORI_BINS
    c = len(centres)
    flat = (np.arange(c)[:, None, None] * ORI_BINS + bins).ravel()
    hist = np.bincount(flat, magnitude.ravel(), minlength=c * ORI_BINS).reshape(c, ORI_BINS)
    smooth = sum(w * np.roll(hist, s, axis=1) for s, w in zip(range(-2, 3), (1, 4, 6, 4, 1))) / 16.0
    left, right = np.roll(smooth, 1, axis=1), np.roll(smooth, -1, axis=1)
    peak = (smooth > left) & (smooth > right) & (smooth >= ORI_PEAK_RATIO * smooth.max(1, keepdims=True))
    index, b = np.nonzero(peak)
    lo, m, rr = left[index, b], smooth[index, b], right[index, b]
    offset = 0.5 * (lo - rr) / (lo - 2 * m + rr)
    angle = ((b + offset) * (2 * np.pi / ORI_BINS)) % (2 * np.pi)
    return index, angle.astype(np.float32)


def descriptors(sample: Sampler, points: np.ndarray, sigmas: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """128-D SIFT descriptors ``(C, 128)`` float32 (OpenCV's scale: unit norm x 512, clipped to 255).

    A 4x4 grid of 8-bin gradient histograms over a square of side 4 x 3 sigma rotated
    by ``angles``, sampled at 4x4 points per cell (plus a half-cell margin for the
    trilinear spread), Gaussian-weighted (sigma = half the grid), normalised, clipped
    at 0.2 and renormalised.

    Args:
        points: ``(C, 2)`` x, y keypoint positions (sub-pixel).
        sigmas: ``(C,)`` keypoint sigma in the image's pixels.
        angles: ``(C,)`` keypoint orientations in radians.
    """
    c = len(points)
    if c == 0:
        return np.zeros((0, DESC_WIDTH * DESC_WIDTH * DESC_BINS), np.float32)
    half = DESC_WIDTH / 2 + 0.5  # bins covered on each side of the centre
    n = int(2 * half * DESC_SAMPLES)
    step = 1.0 / DESC_SAMPLES
    coords = (np.arange(-1, n + 1, dtype=np.float32) + 0.5) * step - half  # bin units, one extra each side
    a, b = np.meshgrid(coords, coords, indexing="xy")  # a along the keypoint's axis, b across it
    cos, sin = np.cos(angles)[:, None, None], np.sin(angles)[:, None, None]
    scale = (DESC_SCALE * sigmas)[:, None, None]
    x = points[:, 0, None, None] + scale * (a * cos - b * sin)
    y = points[:, 1, None, None] + scale * (a * sin + b * cos)
    patches = sample(np.stack([x, y], -1).astype(np.float32))
    ga = patches[:, 1:-1, 2:] - patches[:, 1:-1, :-2]
    gb = patches[:, 2:, 1:-1] - patches[:, :-2, 1:-1]
    a, b = a[1:-1, 1:-1], b[1:-1, 1:-1]
    weight = np.exp(-(a**2 + b**2) / (2 * (DESC_WIDTH / 2) ** 2))
    magnitude = np.hypot(ga, gb) * weight[None]
    obin = (np.arctan2(gb, ga) % (2 * np.pi)) * (DESC_BINS / (2 * np.pi))
    xbin = np.broadcast_to(a + DESC_WIDTH / 2 - 0.5, magnitude.shape)
    ybin = np.broadcast_to(b + DESC_WIDTH / 2 - 0.5, magnitude.shape)
    x0, y0, o0 = np.floor(xbin), np.floor(ybin), np.floor(obin)
    fx, fy, fo = xbin - x0, ybin - y0, obin - o0
    x0, y0, o0 = x0.astype(np.int64), y0.astype(np.int64), o0.astype(np.int64)
    base = np.arange(c)[:, None, None] * (DESC_WIDTH * DESC_WIDTH * DESC_BINS)
    size = c * DESC_WIDTH * DESC_WIDTH * DESC_BINS
    hist = np.zeros(size, np.float64)
    for dy in (0, 1):
        wy = fy if dy else 1 - fy
        yy = y0 + dy
        for dx in (0, 1):
            wx = fx if dx else 1 - fx
            xx = x0 + dx
            ok = (xx >= 0) & (xx < DESC_WIDTH) & (yy >= 0) & (yy < DESC_WIDTH)
            for do in (0, 1):
                wo = fo if do else 1 - fo
                oo = (o0 + do) % DESC_BINS
                idx = base + (yy * DESC_WIDTH + xx) * DESC_BINS + oo
                hist += np.bincount(idx[ok], (magnitude * wy * wx * wo)[ok], minlength=size)
    hist = hist.reshape(c, -1)
    norm = np.linalg.norm(hist, axis=1, keepdims=True) + 1e-12
    hist = np.minimum(hist, DESC_MAG_CLIP * norm)
    hist /= np.linalg.norm(hist, axis=1, keepdims=True) + 1e-12
    return np.minimum(np.rint(hist * 512), 255).astype(np.float32)
