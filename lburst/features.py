"""The one output shape shared by every feature method.

A *features* dict describes the keypoints of a burst's common (middle) frame:

- ``keypoints`` (K, 2) float32: x, y in pixels of the common frame, pixel centres at
  integer coordinates ((0, 0) is the centre of the top-left pixel; COLMAP wants +0.5);
- ``scales`` (K,) float32: the keypoint's scale (detector-specific units, larger = coarser);
- ``scores`` (K,) float32: detection confidence, larger is better;
- ``descriptors`` (K, D): float32 (compared with L2) or uint8 packed bits (binary,
  compared with Hamming distance, e.g. ORB);

and optionally ``orientations`` (K,) float32 radians and ``slopes`` (K, 2) float32
apparent motion in pixels per frame (BuFF).

Every extractor also gives ``image_size`` (2,) int64: (width, height) of the common frame
in pixels, as LightGlue's ``image_size``.  It describes the image, not the keypoints:
:func:`select` and :func:`concatenate` keep it whole (:data:`PER_IMAGE`).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from lburst.errors import LBurstValueError

Features = dict[str, np.ndarray]


class Extractor(Protocol):
    """A feature method: ``extractor(burst)`` with ``burst`` uint8/uint16 ``(N, H, W, 3)`` in
    temporal order (N odd) returns the features of its common frame; ``name`` is its spec."""

    name: str

    def __call__(self, burst: np.ndarray) -> Features: ...


REQUIRED = ("keypoints", "scales", "scores", "descriptors")
PER_IMAGE = ("image_size",)  # keys that describe the image, not one entry per keypoint


def image_size(width: int, height: int) -> np.ndarray:
    """The ``image_size`` entry of a features dict: ``[width, height]`` int64."""
    return np.array([width, height], np.int64)


def select(features: Features, index: np.ndarray) -> Features:
    """The keypoints ``index`` (indices or a boolean mask) of ``features``: every per-keypoint
    array indexed, the per-image entries (:data:`PER_IMAGE`) kept as they are."""
    return {key: value if key in PER_IMAGE else value[index] for key, value in features.items()}


def concatenate(parts: list[Features]) -> Features:
    """The keypoints of several features dicts of one image, one after the other (the
    per-image entries taken from the first)."""
    return {
        key: parts[0][key] if key in PER_IMAGE else np.concatenate([part[key] for part in parts]) for key in parts[0]
    }


def is_binary(features: Features) -> bool:
    """True if the descriptors are packed bits, to be compared with Hamming distance."""
    return features["descriptors"].dtype == np.uint8


def check_features(features: Features) -> Features:
    """Raise ``ValueError`` if ``features`` does not have the shape documented above."""
    missing = [k for k in REQUIRED if k not in features]
    if missing:
        raise LBurstValueError(f"features lack {missing}")
    k = len(features["keypoints"])
    if features["keypoints"].shape != (k, 2):
        raise LBurstValueError(f"keypoints must be (K, 2), got {features['keypoints'].shape}")
    for key in ("scales", "scores", "orientations"):
        if key in features and features[key].shape != (k,):
            raise LBurstValueError(f"{key} must be ({k},), got {features[key].shape}")
    d = features["descriptors"]
    if d.ndim != 2 or len(d) != k:
        raise LBurstValueError(f"descriptors must be (K, D) with K={k}, got {d.shape}")
    if d.dtype not in (np.float32, np.uint8):
        raise LBurstValueError(f"descriptors must be float32 or uint8, got {d.dtype}")
    if not np.isfinite(features["keypoints"]).all() or (d.dtype == np.float32 and not np.isfinite(d).all()):
        raise LBurstValueError("keypoints and descriptors must be finite (no NaN or inf)")
    size = features.get("image_size")
    if size is not None and (np.shape(size) != (2,) or not np.issubdtype(np.asarray(size).dtype, np.integer)):
        raise LBurstValueError(f"image_size must be (2,) integers (width, height), got {np.asarray(size).tolist()}")
    if size is not None and min(size) < 1:
        raise LBurstValueError(f"image_size must be positive (width, height), got {tuple(int(v) for v in size)}")
    return features


def check_inside(features: Features, size: tuple[int, int]) -> Features:
    """Raise ``ValueError`` if a keypoint lies off the image of ``size`` (W, H): its pixels span
    -0.5 to W - 0.5 (pixel centres at integers), and a keypoint may lie up to half a pixel
    beyond that edge; else return ``features``."""
    kp = np.asarray(features["keypoints"], np.float64).reshape(-1, 2)
    width, height = size
    off = (kp[:, 0] < -1) | (kp[:, 0] > width) | (kp[:, 1] < -1) | (kp[:, 1] > height)
    if off.any():
        x, y = kp[off][np.argmax(np.abs(kp[off]).max(axis=1))]
        raise LBurstValueError(
            f"{int(off.sum())} of {len(kp)} keypoints lie outside the {width}x{height} image (one at x={x:g}, y={y:g})"
        )
    return features


def empty_features(dim: int = 128, binary: bool = False) -> Features:
    """Features with no keypoints."""
    return {
        "keypoints": np.zeros((0, 2), np.float32),
        "scales": np.zeros(0, np.float32),
        "scores": np.zeros(0, np.float32),
        "descriptors": np.zeros((0, dim), np.uint8 if binary else np.float32),
    }


def spread_top_k(features: Features, top_k: int, image_size: tuple[int, int], cells: int) -> Features:
    """The ``top_k`` keypoints of ``features`` spread over the image: first the best
    ``top_k // cells**2`` of each cell of a ``cells`` x ``cells`` grid over ``image_size``
    (W, H), then the best of the rest, all sorted by decreasing score.  A detector whose
    scores fade towards the borders leaves the periphery of the image nearly empty under
    a plain top-k; a camera model fitted to such keypoints is free to bend there."""
    k = len(features["scores"])
    if k <= top_k:
        return features
    order = np.argsort(-features["scores"], kind="stable")
    width, height = image_size
    x, y = features["keypoints"][order].T
    cell = np.clip((x + 0.5) * cells / width, 0, cells - 1).astype(int) * cells + np.clip(
        (y + 0.5) * cells / height, 0, cells - 1
    ).astype(int)
    rank = np.empty(k, np.int64)  # rank of each keypoint within its cell, by score
    by_cell = np.argsort(cell, kind="stable")
    starts = np.searchsorted(cell[by_cell], cell[by_cell], side="left")
    rank[by_cell] = np.arange(k) - starts
    first = rank < top_k // cells**2
    chosen = np.concatenate([np.flatnonzero(first), np.flatnonzero(~first)])[:top_k]
    keep = order[np.sort(chosen)]  # back in score order
    return select(features, keep)
