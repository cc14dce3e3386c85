"""Keyframes by motion: take a keyframe once the view has moved far enough.

A drone that hovers, then flies, then turns should get keyframes where the view changes,
not every ``K`` frames.  :class:`MotionTracker` decides that from the frames alone:

- each frame becomes a *thumbnail*: its luminance, area-averaged to ``size`` pixels on
  the long side (a 640x480 frame to 96x72: every thumbnail pixel is the mean of about 44
  pixels, which averages a dark frame's noise away);
- a candidate keyframe's thumbnail is the mean of its burst's thumbnails (the noise falls
  by another ``sqrt(N)``);
- the *motion* of a candidate is how far the median thumbnail pixel has moved since the
  last keyframe, as a fraction of the thumbnail's width: the last keyframe's thumbnail is
  registered to the candidate's by an affine warp (OpenCV's ECC, which maximises their
  correlation, so neither the noise nor a change of gain moves it), started from the warp found for
  the previous candidate; a translation of a tenth of the image is 0.1, and a rotation or
  zoom counts by how far the median pixel moves.

A candidate becomes a keyframe when its motion reaches ``threshold``, or when it can no
longer be registered to the last keyframe but can be to the candidate before it (the view
changed too much to measure).  A candidate that registers to neither (a black or
featureless view, or one lost in noise) is not a keyframe: nothing in it can be measured,
so a lens cap or a dark stretch makes no keyframes.  Every frame is a candidate, in
temporal order, the first one always a keyframe, so the warp only ever has to follow one
frame's motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lburst.errors import LBurstValueError

MIN_CORRELATION = 0.5
"""A registration counts when the warped thumbnails correlate at least this much: 0.8-1.0
between views of the moonless flight up to 32 frames apart, at most 0.15 between two
thumbnails of pure noise."""


def thumbnail(image: np.ndarray, size: int) -> np.ndarray:
    """Luminance of an RGB ``(H, W, 3)`` uint8/uint16 frame, area-averaged to ``size`` on the long side, float32."""
    h, w = image.shape[:2]
    scale = size / max(h, w)
    shape = (max(1, round(w * scale)), max(1, round(h * scale)))
    luma = cv2.cvtColor(image, cv2.COLOR_RGB2GRAY).astype(np.float32)  # 0.299 R + 0.587 G + 0.114 B, per pixel rounded
    return cv2.resize(luma, shape, interpolation=cv2.INTER_AREA)


def register(reference: np.ndarray, view: np.ndarray, start: np.ndarray | None = None) -> np.ndarray | None:
    """The affine warp ``(2, 3)`` from ``reference``'s pixels to where they are in ``view`` (ECC, started
    from ``start``, else from the translation phase correlation finds), or ``None`` if it does not
    converge or the two correlate less than :data:`MIN_CORRELATION` under it."""
    if reference.shape != view.shape:
        raise LBurstValueError(f"thumbnails of different shapes: {reference.shape} and {view.shape}")
    a, b = _standard(reference), _standard(view)
    if start is None:
        (dx, dy), _ = cv2.phaseCorrelate(a, b, cv2.createHanningWindow(a.shape[::-1], cv2.CV_32F))
        warp = np.array([[1, 0, dx], [0, 1, dy]], np.float32)
    else:
        warp = start.astype(np.float32).copy()
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-5)
    try:
        correlation, warp = cv2.findTransformECC(a, b, warp, cv2.MOTION_AFFINE, criteria, None, 3)
    except cv2.error:
        return None
    return warp if correlation >= MIN_CORRELATION and np.all(np.isfinite(warp)) else None


def displacement(warp: np.ndarray, shape: tuple[int, int]) -> float:
    """Median distance a pixel of a ``shape`` thumbnail moves under ``warp``, as a fraction of its width."""
    ys, xs = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float32)
    moved = np.stack([xs, ys, np.ones_like(xs)], -1) @ warp.T
    return float(np.median(np.hypot(moved[..., 0] - xs, moved[..., 1] - ys))) / shape[1]


def apparent_motion(a: np.ndarray, b: np.ndarray) -> float:
    """How far the view moved from thumbnail ``a`` to ``b`` (module docstring); ``inf`` if they do not register."""
    warp = register(a, b)
    return float("inf") if warp is None else displacement(warp, a.shape)


def _standard(t: np.ndarray) -> np.ndarray:
    return ((t - t.mean()) / (t.std() + 1e-6)).astype(np.float32)


@dataclass(frozen=True)
class MotionGate:
    """When the view has moved far enough for a new keyframe (module docstring).

    Attributes:
        threshold: motion since the last keyframe, as a fraction of the image width.
        size: long side of the thumbnails, pixels.
    """

    threshold: float = 0.1
    size: int = 96

    def __post_init__(self) -> None:
        if not 0 < self.threshold < 0.5:
            raise LBurstValueError(f"--motion must be in (0, 0.5) of the image width, got {self.threshold}")
        if self.size < 16:
            raise LBurstValueError(f"thumbnail size must be at least 16 pixels, got {self.size}")


class MotionTracker:
    """Follows the motion since the last keyframe, one candidate after the other (module docstring)."""

    def __init__(self, gate: MotionGate):
        self.gate = gate
        self.reference: np.ndarray | None = None
        self.warp: np.ndarray | None = None
        self.previous: np.ndarray | None = None

    def is_keyframe(self, burst_thumbnails: list[np.ndarray]) -> bool:
        """Whether the candidate whose burst has these frame thumbnails is a keyframe; if so it
        becomes the reference."""
        view = np.mean(burst_thumbnails, axis=0)
        previous, self.previous = self.previous, view
        if self.reference is not None:
            warp = register(self.reference, view, self.warp)
            if warp is None and self.warp is not None:
                warp = register(self.reference, view)
            if warp is not None and displacement(warp, view.shape) < self.gate.threshold:
                self.warp = warp
                return False
            if warp is None and (previous is None or register(previous, view) is None):
                return False  # nothing in the view can be measured
        self.reference, self.warp = view, None
        return True
