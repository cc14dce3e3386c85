"""SIFT and ORB (OpenCV) on the grayscale common frame of a burst.

Registered as ``sift`` (options ``max_features`` = 5000, ``root`` = false: RootSIFT,
``contrast_threshold`` = 0.04) and ``orb`` (``max_features`` = 5000).  uint16 bursts are
scaled to 8 bit first.  Keypoints use OpenCV's convention, which is lburst's (pixel
centres at integer coordinates).  ``scales`` is OpenCV's keypoint ``size`` (the
diameter of the described region), ``scores`` its ``response`` and ``orientations``
its ``angle`` in radians.  SIFT descriptors are float32 (L2); ORB's stay packed uint8
(32 bytes, Hamming).  ``image_size`` is the frame's (width, height).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from lburst.burst.frames import check_burst, to_gray8
from lburst.features import Features, empty_features, image_size
from lburst.memory import check_memory
from lburst.methods import register
from lburst.numbers import check_integer, check_real

#: bytes per pixel of the common frame that OpenCV's SIFT holds at its peak (its float32 scale
#: space, from an image doubled in size): 236 measured (peak resident memory, 2000x2000 and
#: 4000x4000 frames); ORB's pyramid needs far less, so the figure bounds both
DETECT_BYTES_PER_PIXEL = 240


def keypoints_to_features(
    keypoints: tuple[cv2.KeyPoint, ...], descriptors: np.ndarray | None, dim: int, binary: bool
) -> Features:
    """Convert OpenCV keypoints and descriptors to a features dict (with ``orientations``)."""
    if not keypoints or descriptors is None:
        features = empty_features(dim, binary)
        features["orientations"] = np.zeros(0, np.float32)
        return features
    return {
        "keypoints": np.array([kp.pt for kp in keypoints], np.float32).reshape(-1, 2),
        "scales": np.array([kp.size for kp in keypoints], np.float32),
        "scores": np.array([kp.response for kp in keypoints], np.float32),
        "orientations": np.deg2rad(np.array([kp.angle for kp in keypoints], np.float32)),
        "descriptors": descriptors.astype(np.uint8 if binary else np.float32),
    }


def root_sift(descriptors: np.ndarray, eps: float = 1e-7) -> np.ndarray:
    """RootSIFT (Arandjelovic & Zisserman 2012): L1-normalise, then element-wise square root.

    The result has unit L2 norm, so L2 distances between RootSIFT vectors compare
    the original descriptors by the Hellinger kernel.
    """
    d = descriptors.astype(np.float32)
    d /= np.abs(d).sum(axis=1, keepdims=True) + eps
    return np.sqrt(d)


class OpenCVExtractor:
    """An OpenCV ``Feature2D`` detector/descriptor run on the burst's common frame."""

    def __init__(self, detector: cv2.Feature2D, dim: int, binary: bool, root: bool = False) -> None:
        self.detector = detector
        self.dim = dim
        self.binary = binary
        self.root = root
        self.name = "opencv"

    def __call__(self, burst: np.ndarray) -> Features:
        burst = check_burst(burst)
        height, width = burst.shape[1:3]
        detector = self.detector.getDefaultName().rsplit(".", 1)[-1]  # SIFT, ORB
        check_memory(
            height * width * DETECT_BYTES_PER_PIXEL, f"{detector} on a {width}x{height} frame", "resize the images"
        )
        image = to_gray8(burst[len(burst) // 2])
        keypoints, descriptors = self.detector.detectAndCompute(image, None)
        features = keypoints_to_features(keypoints, descriptors, self.dim, self.binary)
        if self.root and len(features["descriptors"]):
            features["descriptors"] = root_sift(features["descriptors"])
        return {**features, "image_size": image_size(image.shape[1], image.shape[0])}


@dataclass(frozen=True)
class SiftOptions:
    """OpenCV's SIFT: ``max_features`` kept, ``contrast_threshold``, and ``root`` for RootSIFT descriptors."""

    max_features: int = 5000
    root: bool = False
    contrast_threshold: float = 0.04

    def __post_init__(self) -> None:
        check_integer(self.max_features, "sift max_features (0: all)", 0)
        check_real(self.contrast_threshold, "sift contrast_threshold", 0, low_open=True)


@register("sift", SiftOptions)
def sift(arg: None, options: SiftOptions) -> OpenCVExtractor:
    """SIFT (OpenCV's defaults) on the common frame; root=true gives RootSIFT."""
    detector = cv2.SIFT_create(nfeatures=options.max_features, contrastThreshold=options.contrast_threshold)
    return OpenCVExtractor(detector, 128, binary=False, root=options.root)


@dataclass(frozen=True)
class OrbOptions:
    """OpenCV's ORB: ``max_features`` kept."""

    max_features: int = 5000

    def __post_init__(self) -> None:
        check_integer(self.max_features, "orb max_features", 1)


@register("orb", OrbOptions)
def orb(arg: None, options: OrbOptions) -> OpenCVExtractor:
    """ORB (OpenCV's defaults) on the common frame; descriptors are 32 packed bytes."""
    return OpenCVExtractor(cv2.ORB_create(nfeatures=options.max_features), 32, binary=True)
