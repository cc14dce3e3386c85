"""Vectorised ray casting against a ground plane ``z = 0`` and axis-aligned boxes.

Conventions (COLMAP's, as in :mod:`lburst.sfm.reference`): world z is up; a camera
``(K, R, t)`` maps ``x_cam = R @ x_world + t`` and looks along +z with x right, y down;
pixel ``(row i, column j)`` has its centre at image coordinates ``(j + 0.5, i + 0.5)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

GROUND = -1  # value of ``Hits.box`` for rays that hit the ground plane
SKY = -2  # value of ``Hits.box`` for rays that hit nothing


def intrinsics(width: int, height: int, hfov_deg: float) -> np.ndarray:
    """Pinhole K (3, 3) with square pixels, horizontal field of view ``hfov_deg`` and
    the principal point at the image centre ``(W / 2, H / 2)`` (COLMAP pixel centres)."""
    f = 0.5 * width / np.tan(np.radians(hfov_deg) / 2)
    return np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])


def transfer(
    K: np.ndarray, uv: np.ndarray, depth: np.ndarray, pose_from: tuple, pose_to: tuple
) -> tuple[np.ndarray, np.ndarray]:
    """Image points ``uv`` (N, 2) of a camera at ``pose_from`` whose surface lies at z-depth
    ``depth`` (N,), seen by a camera at ``pose_to`` (both ``(R, t)`` world-to-camera, intrinsics
    ``K``): their image points there (N, 2) and their z-depth there (N,; negative behind it)."""
    (r0, t0), (r1, t1) = pose_from, pose_to
    cam = np.c_[np.asarray(uv, np.float64), np.ones(len(uv))] @ np.linalg.inv(K).T * np.asarray(depth)[:, None]
    seen = ((cam - t0) @ r0) @ np.asarray(r1).T + t1
    p = seen @ K.T
    return p[:, :2] / p[:, 2:3], seen[:, 2]


def rays_through(K: np.ndarray, R: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Unit world-space directions (..., 3) of the rays through image points ``uv`` (..., 2)."""
    uv = np.asarray(uv, dtype=np.float64)
    cam = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1) @ np.linalg.inv(K).T
    world = cam @ R  # R^T applied to each row vector
    return world / np.linalg.norm(world, axis=-1, keepdims=True)


def pixel_rays(K: np.ndarray, R: np.ndarray, width: int, height: int) -> np.ndarray:
    """Unit world-space directions (H, W, 3) float64 of the rays through the pixel centres."""
    uu, vv = np.meshgrid(np.arange(width) + 0.5, np.arange(height) + 0.5)
    return rays_through(K, R, np.stack([uu, vv], axis=-1))


@dataclass
class Hits:
    """Nearest intersection of each pixel's ray, all arrays (H, W).

    Attributes:
        t: distance along the unit ray (``inf`` for sky); box hits have float32
            precision (relative error ~1e-7).
        box: index of the box hit, ``GROUND`` or ``SKY``.
        axis: axis (0, 1, 2) of the face's normal; 2 for the ground.
        points: (H, W, 3) world points hit (undefined for sky).
        dirs: (H, W, 3) unit world directions of the rays.
    """

    t: np.ndarray
    box: np.ndarray
    axis: np.ndarray
    points: np.ndarray
    dirs: np.ndarray


def box_windows(
    lo: np.ndarray, hi: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int
) -> list[tuple[int, int, int, int] | None]:
    """Pixel rectangle ``(row0, row1, col0, col1)`` (exclusive ends) that may see each box.

    A box entirely behind the camera or outside the image gets ``None``; a box that
    straddles the camera plane gets the whole image.
    """
    corners = np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1).reshape(-1, 3)
    pts = lo[:, None, :] + corners[None] * (hi - lo)[:, None, :]  # (B, 8, 3)
    cam = pts @ R.T + t
    z = cam[..., 2]
    windows: list[tuple[int, int, int, int] | None] = []
    for b in range(len(lo)):
        if np.all(z[b] <= 1e-6):
            windows.append(None)
            continue
        if np.any(z[b] <= 1e-6):
            windows.append((0, height, 0, width))
            continue
        uv = cam[b, :, :2] / z[b, :, None] * np.diag(K)[:2] + K[:2, 2]
        c0 = max(int(np.floor(uv[:, 0].min() - 0.5)) - 1, 0)
        c1 = min(int(np.ceil(uv[:, 0].max() - 0.5)) + 2, width)
        r0 = max(int(np.floor(uv[:, 1].min() - 0.5)) - 1, 0)
        r1 = min(int(np.ceil(uv[:, 1].max() - 0.5)) + 2, height)
        windows.append((r0, r1, c0, c1) if r0 < r1 and c0 < c1 else None)
    return windows


def cast(K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int, lo: np.ndarray, hi: np.ndarray) -> Hits:
    """Nearest hit of every pixel ray against the ground ``z = 0`` and boxes ``[lo, hi]``.

    Args:
        K, R, t: camera (3, 3), (3, 3), (3,), world-to-camera.
        lo, hi: (B, 3) box corners with ``lo < hi``.
    """
    origin = -R.T @ t
    dirs = pixel_rays(K, R, width, height)
    safe = np.where(np.abs(dirs) < 1e-12, 1e-12, dirs)
    inv = [np.ascontiguousarray(1.0 / safe[..., a], dtype=np.float32) for a in range(3)]  # float32: 2x faster
    best = np.full((height, width), np.inf)
    box = np.full((height, width), SKY, dtype=np.int32)
    axis = np.full((height, width), 2, dtype=np.int8)

    down = dirs[..., 2] < 0
    best[down] = -origin[2] / dirs[..., 2][down]
    box[down] = GROUND

    for b, win in enumerate(box_windows(lo, hi, K, R, t, width, height)):
        if win is None:
            continue
        r0, r1, c0, c1 = win
        slabs = []
        for a in range(3):
            iv = inv[a][r0:r1, c0:c1]
            t1 = np.float32(lo[b, a] - origin[a]) * iv
            t2 = np.float32(hi[b, a] - origin[a]) * iv
            slabs.append((np.minimum(t1, t2), np.maximum(t1, t2)))
        near = np.maximum(np.maximum(slabs[0][0], slabs[1][0]), slabs[2][0])
        far = np.minimum(np.minimum(slabs[0][1], slabs[1][1]), slabs[2][1])
        sub = best[r0:r1, c0:c1]
        hit = (near <= far) & (near > 0) & (near < sub)
        if not hit.any():
            continue
        sub[hit] = near[hit]
        box[r0:r1, c0:c1][hit] = b
        # the face hit is the slab that entered last
        face = np.where(slabs[2][0] == near, 2, np.where(slabs[1][0] == near, 1, 0))
        axis[r0:r1, c0:c1][hit] = face[hit]

    finite = np.where(np.isfinite(best), best, 0.0)
    points = origin + finite[..., None] * dirs
    return Hits(t=best, box=box, axis=axis, points=points, dirs=dirs)
