"""Bursts that turn: the in-plane rotation of each frame about the common frame, on top of the
translation of :func:`lburst.burst.align.pyramid_shifts`, on the same pyramid levels.

A drone that yaws while it takes a burst (in a turn between survey lines, or in a gust) turns
its frames against each other: at 24 degrees per second and 20 frames per second the ends of a
5-frame burst are turned by 2.4 degrees, 13 px at the corners of a 640x480 frame, more than the
translation the networks were trained to take.  :func:`euclidean_warps` fits a rotation and a
translation per frame (OpenCV's ECC with its Euclidean motion) and returns ``None`` when the
fitted rotation moves no corner by :data:`ROTATION_MIN_PX` or more: such a burst is aligned by
its translation alone, exactly as before.  It costs two ECC fits on a quarter of the pixels for
a burst that does not turn (6 ms at 1024x768), and eight more at the pyramid's fine level for
one that does (0.10 s at 1024x768, whose fine level is half-resolution; 0.35 s at 640x480, whose
is full resolution; one core, docs/speed.md).

Warp convention (that of the shifts, extended): ``warps[k]`` is a 2x3 matrix ``W`` with
``frame_k(W @ (x, y, 1)) ~ common(x, y)``; the common frame's is the identity.
"""

from __future__ import annotations

import cv2
import numpy as np

from lburst.burst.frames import inner_mask, time_offsets

#: a fitted rotation that moves every corner of the frame by less than this many pixels reads as
#: none: the networks take that much (they are trained on bursts moving up to 12 px per frame),
#: and below it the fit is near its noise (the simulated flight's wobble of 0.2 degrees, 1.5 px at
#: the corners of 640x480, is found in some bursts and not in others)
ROTATION_MIN_PX = 3.0


def warp_matrix(angle: float, centre_shift: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """The 2x3 warp that turns by ``angle`` (radians) about ``centre`` and then moves ``centre``
    by ``centre_shift``: ``W p = R (p - centre) + centre + centre_shift`` (OpenCV's rotation
    matrix, whose positive angles turn the other way in image coordinates)."""
    warp = cv2.getRotationMatrix2D((float(centre[0]), float(centre[1])), -float(np.degrees(angle)), 1.0)
    warp[:, 2] += centre_shift
    return warp


def euclidean_ecc(
    reference: np.ndarray,
    image: np.ndarray,
    start: np.ndarray,
    smoothing: int,
    iterations: int,
    eps: float,
    pad: int,
) -> tuple[float, np.ndarray | None]:
    """OpenCV's ECC with Euclidean motion from the 2x3 ``start``, ignoring ``pad`` px at the borders:
    ``(correlation, warp)``, ``(-1, None)`` where it fails."""
    mask = inner_mask(*reference.shape, pad)
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, iterations, eps)
    try:
        rho, warp = cv2.findTransformECC(
            reference, image, np.float32(start), cv2.MOTION_EUCLIDEAN, criteria, mask, smoothing
        )
    except cv2.error:
        return -1.0, None
    return (float(rho), warp.astype(np.float64)) if np.all(np.isfinite(warp)) else (-1.0, None)


#: ``(angle in radians, shift of the frame's centre in full pixels)``
Turn = tuple[float, np.ndarray]
#: one level of :func:`lburst.burst.align.pyramid_levels`: ``(factor, grey frames downsampled by it)``
Level = tuple[int, list[np.ndarray]]


def euclidean_warps(
    fine: Level,
    coarse: Level,
    shifts: np.ndarray,
    smoothing: int = 7,
    iterations: int = 50,
    eps: float = 1e-4,
    margin: int = 8,
) -> np.ndarray | None:
    """Warps ``(N, 2, 3)`` float64 in full-resolution pixels, or ``None`` for a burst that does not turn.

    The end frames are first turned against the common frame on the ``coarse`` level (a quarter
    of the pixels or fewer), from no motion and from their ``shifts``; only if one of them turns
    are all frames fitted on the ``fine`` level, each from its share of the ends' turn and from
    its shift, keeping the fit of higher correlation (phase correlation, which gives the shifts,
    can fail on a turning frame).  Each frame keeps its own fit, with no motion model: a turn
    starts and ends within a burst (the ECC fits of a 640x480 moonless burst differ from a
    steady turn by about 0.05 degrees).

    Args:
        fine, coarse: the burst's levels (:func:`lburst.burst.align.pyramid_levels`; pixel ``i``
            of a level covers full pixels ``factor * i .. factor * i + factor - 1``).
        shifts: ``(N, 2)`` full-resolution translations.
    """
    n = len(shifts)
    middle = n // 2
    h, w = fine[1][middle].shape
    half_diagonal = fine[0] * np.hypot(w, h) / 2.0
    shifts = np.asarray(shifts, np.float64)

    def fit(level: Level, k: int, starts: list[Turn]) -> Turn:
        factor, frames = level
        lh, lw = frames[middle].shape
        centre = np.array([(lw - 1) / 2.0, (lh - 1) / 2.0])
        best, best_rho = starts[0], -1.0
        for angle, shift in starts:
            pad = max(margin // factor, 2) + int(np.ceil(np.abs(shift).max() / factor))
            # fitted about the level's centre, so that the translation is that of the frame's
            # centre, whose velocity is constant in a steady turn
            rho, warp = euclidean_ecc(
                frames[middle], frames[k], warp_matrix(angle, shift / factor, centre), smoothing, iterations, eps, pad
            )
            if warp is not None and rho > best_rho:
                turned = float(np.arctan2(warp[1, 0], warp[0, 0]))
                best, best_rho = (turned, (warp[:, :2] @ centre + warp[:, 2] - centre) * factor), rho
        return best

    still = np.zeros(2)
    ends = {k: fit(coarse, k, [(0.0, still), (0.0, shifts[k])]) for k in (0, n - 1)}
    if max(abs(angle) for angle, _ in ends.values()) * half_diagonal < ROTATION_MIN_PX:
        return None
    t = time_offsets(n).astype(np.float64)
    angles = np.zeros(n)
    centre_shifts = np.zeros((n, 2))
    for k in range(n):
        if k != middle:
            end = 0 if t[k] < 0 else n - 1
            share = t[k] / t[end]
            start = (ends[end][0] * share, ends[end][1] * share)
            angles[k], centre_shifts[k] = fit(fine, k, [start, (0.0, shifts[k])])
    if np.abs(angles).max() * half_diagonal < ROTATION_MIN_PX:
        return None
    offset = (fine[0] - 1) / 2.0  # full pixel = factor * level pixel + (factor - 1) / 2
    centre = fine[0] * np.array([(w - 1) / 2.0, (h - 1) / 2.0]) + offset
    return np.stack([warp_matrix(a, s, centre) for a, s in zip(angles, centre_shifts)])
