"""In-burst motion: how frame ``k`` of a robotic burst sees the common frame.

A :class:`BurstMotion` says, for every pixel ``p`` of frame ``k``
(``k = -N//2 .. N//2``), which position ``S_k(p)`` of the common frame (``k = 0``) it
shows, pixel centres at integer coordinates::

    S_k(p) = A_k^-1(p) - k * D(p)
    A_k(x) = c + (1 + zoom)^k R(k * rotation_deg) (x - c) + k * (dx, dy)

with ``c`` the image centre and ``D`` a smooth random displacement field (the
non-uniform, parallax-like part: a ``grid x grid`` lattice of Gaussian vectors of std
``flow_px``, upsampled bicubically to the image).  ``S_0`` is the identity, so the
common frame is never resampled.  With only ``(dx, dy)`` this is the pure translation
of :func:`lburst.simulate.simulate_burst`: content at ``x`` appears at ``x + k (dx, dy)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass(frozen=True)
class BurstMotion:
    """Per-frame motion of a burst (see the module docstring).

    Attributes:
        shift: translation per frame (dx, dy), pixels.
        rotation_deg: rotation per frame about the image centre, degrees.
        zoom: relative scale change per frame (0.01: 1% per frame).
        flow_px: std of the smooth random displacement per frame, pixels.
        flow_seed: seed of that field (the same field for every frame, scaled by ``k``).
        grid: lattice size of the field (coarser is smoother).
    """

    shift: tuple[float, float] = (0.0, 0.0)
    rotation_deg: float = 0.0
    zoom: float = 0.0
    flow_px: float = 0.0
    flow_seed: int = 0
    grid: int = 3

    @property
    def is_translation(self) -> bool:
        return self.rotation_deg == 0 and self.zoom == 0 and self.flow_px == 0

    def affine(self, k: int, size: tuple[int, int]) -> np.ndarray:
        """``A_k`` as a 3x3 matrix for an image of ``size`` (width, height)."""
        w, h = size
        c = np.array([(w - 1) / 2, (h - 1) / 2])
        angle = np.deg2rad(k * self.rotation_deg)
        s = (1.0 + self.zoom) ** k
        r = s * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        t = c - r @ c + k * np.asarray(self.shift, np.float64)
        return np.array([[r[0, 0], r[0, 1], t[0]], [r[1, 0], r[1, 1], t[1]], [0, 0, 1]], np.float64)

    def field(self, size: tuple[int, int]) -> np.ndarray:
        """``D``: (height, width, 2) float32 displacement per frame step, pixels."""
        w, h = size
        if self.flow_px == 0:
            return np.zeros((h, w, 2), np.float32)
        lattice = np.random.default_rng(self.flow_seed).standard_normal((self.grid, self.grid, 2)) * self.flow_px
        return cv2.resize(lattice.astype(np.float32), (w, h), interpolation=cv2.INTER_CUBIC)

    def source_points(self, k: int, size: tuple[int, int]) -> np.ndarray:
        """``S_k(p)`` for every pixel ``p``: (height, width, 2) float32 x, y in the common frame."""
        w, h = size
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
        inv = np.linalg.inv(self.affine(k, size))
        x = inv[0, 0] * xs + inv[0, 1] * ys + inv[0, 2]
        y = inv[1, 0] * xs + inv[1, 1] * ys + inv[1, 2]
        pts = np.stack([x, y], -1).astype(np.float32)
        if self.flow_px:
            pts -= k * self.field(size)
        return pts

    def frame_points(self, k: int, size: tuple[int, int], iterations: int = 4) -> np.ndarray:
        """The inverse of :meth:`source_points`: for every common-frame pixel ``x``, the
        position ``p`` in frame ``k`` that shows it (``S_k(p) = x``), (height, width, 2)
        float32.  Exact for the affine part; the flow is inverted by fixed-point
        iteration ``p = A_k(x + k D(p))`` (converges since ``D`` is smooth)."""
        w, h = size
        ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
        a = self.affine(k, size)
        grid = np.stack([xs, ys], -1)
        if not self.flow_px or k == 0:
            return (grid @ a[:2, :2].T.astype(np.float32) + a[:2, 2].astype(np.float32)).astype(np.float32)
        d = self.field(size)
        p = grid.copy()
        for _ in range(iterations):
            dp = cv2.remap(d, p[..., 0], p[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            q = grid + k * dp
            p = (q @ a[:2, :2].T.astype(np.float32) + a[:2, 2].astype(np.float32)).astype(np.float32)
        return p


def sample_motion(
    rng: np.random.Generator,
    max_shift: float,
    max_rotation_deg: float = 0.0,
    max_zoom: float = 0.0,
    max_flow_px: float = 0.0,
) -> BurstMotion:
    """A random :class:`BurstMotion`: shift uniform in ``[-max_shift, max_shift]^2``,
    rotation and zoom uniform in ``[-max, max]``, field std uniform in ``[0, max_flow_px]``."""
    shift = rng.uniform(-max_shift, max_shift, 2) if max_shift else np.zeros(2)
    rotation = rng.uniform(-max_rotation_deg, max_rotation_deg) if max_rotation_deg else 0.0
    zoom = rng.uniform(-max_zoom, max_zoom) if max_zoom else 0.0
    flow = rng.uniform(0, max_flow_px) if max_flow_px else 0.0
    return BurstMotion(
        (float(shift[0]), float(shift[1])),
        float(rotation),
        float(zoom),
        float(flow),
        int(rng.integers(2**31)) if flow else 0,
    )
