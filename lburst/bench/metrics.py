"""Matching metrics under a known homography (pixel centres at integer coordinates).

- MMA@t: fraction of mutual matches (p1, p2) with ``||H(p1) - p2|| <= t`` (0 if none).
- repeatability@t: among keypoints that project inside the other image, the fraction
  with a keypoint of the other image within ``t`` px; both directions averaged.
- matching score: matches correct at 3 px / mean number of keypoints of the two images.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

THRESHOLDS = tuple(range(1, 11))


def project(h: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Points (N, 2) mapped by the 3x3 homography ``h``."""
    p = np.c_[points, np.ones(len(points))] @ np.asarray(h).T
    return p[:, :2] / p[:, 2:]


def match_errors(h: np.ndarray, kp1: np.ndarray, kp2: np.ndarray, matches: np.ndarray) -> np.ndarray:
    """Reprojection error (M,) of matches (M, 2) of keypoints ``kp1`` -> ``kp2``."""
    if len(matches) == 0:
        return np.zeros(0)
    return np.linalg.norm(project(h, kp1[matches[:, 0]]) - kp2[matches[:, 1]], axis=1)


def mma(errors: np.ndarray, thresholds=THRESHOLDS) -> np.ndarray:
    """MMA at each threshold."""
    if len(errors) == 0:
        return np.zeros(len(thresholds))
    return np.array([(errors <= t).mean() for t in thresholds])


def _inside(points: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    h, w = shape[:2]
    return (points[:, 0] >= -0.5) & (points[:, 0] <= w - 0.5) & (points[:, 1] >= -0.5) & (points[:, 1] <= h - 0.5)


def repeatability(h: np.ndarray, kp1: np.ndarray, kp2: np.ndarray, shape1, shape2, threshold: float = 3.0) -> float:
    """Repeatability at ``threshold`` px (see the module docstring); 0 with no keypoints."""
    scores = []
    for a, b, hab, shape_b in ((kp1, kp2, h, shape2), (kp2, kp1, np.linalg.inv(h), shape1)):
        if len(a) == 0 or len(b) == 0:
            scores.append(0.0)
            continue
        pa = project(hab, a)
        pa = pa[_inside(pa, shape_b)]
        if len(pa) == 0:
            scores.append(0.0)
            continue
        dist, _ = cKDTree(b).query(pa)
        scores.append(float((dist <= threshold).mean()))
    return float(np.mean(scores))


def rotation_deg(h: np.ndarray, shape: tuple[int, int]) -> float:
    """In-plane rotation of ``h`` at the centre of image 1 (from its local affine), degrees."""
    cy, cx = (shape[0] - 1) / 2, (shape[1] - 1) / 2
    eps = 1.0
    c = project(h, np.array([[cx, cy], [cx + eps, cy]]))
    d = c[1] - c[0]
    return float(abs(np.degrees(np.arctan2(d[1], d[0]))))
