"""Writing a Bayer mosaic as a minimal DNG (tifffile), readable by LibRaw (``rawpy``).

The file is one uncompressed 16-bit CFA image (``PhotometricInterpretation`` 32803)
with the tags a raw converter needs: ``CFARepeatPatternDim``/``CFAPattern`` (RGGB by
default), ``BlackLevel``, ``WhiteLevel``, ``AsShotNeutral`` (1, 1, 1: the mosaic is
white-balanced), and ``ColorMatrix1`` (XYZ to camera) set to the inverse of the sRGB
primaries at D65, so that the camera's colour space *is* linear sRGB and a converter's
colour step is the identity.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lburst.burst.io import atomic_path
from lburst.errors import LBurstValueError
from lburst.extras import require

# XYZ (D65) -> linear sRGB, IEC 61966-2-1
XYZ_TO_SRGB = np.array(
    [[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560], [0.0556434, -0.2040259, 1.0572252]]
)
PATTERNS = {"RGGB": (0, 1, 1, 2), "BGGR": (2, 1, 1, 0), "GRBG": (1, 0, 2, 1), "GBRG": (1, 2, 0, 1)}


def mosaic(image: np.ndarray, pattern: str = "RGGB") -> np.ndarray:
    """Sample an RGB image ``(H, W, 3)`` through a Bayer filter: ``(H, W)`` of the same dtype."""
    colours = np.array(PATTERNS[pattern]).reshape(2, 2)
    h, w = image.shape[:2]
    rows, cols = np.indices((h, w))
    return image[rows, cols, colours[rows % 2, cols % 2]]


def _rational(values, denominator: int = 10000) -> list[int]:
    out = []
    for v in np.ravel(values):
        out += [int(round(float(v) * denominator)), denominator]
    return out


def write_dng(
    path: str | Path,
    cfa: np.ndarray,
    black_level: int,
    white_level: int,
    pattern: str = "RGGB",
    model: str = "lburst synthetic camera",
) -> Path:
    """Write the Bayer mosaic ``cfa`` (H, W) uint16 (raw counts, black level included) as a DNG, atomically."""
    tifffile = require("tifffile", "writing DNG frames")

    cfa = np.ascontiguousarray(cfa, dtype=np.uint16)
    if cfa.ndim != 2 or cfa.shape[0] % 2 or cfa.shape[1] % 2:
        raise LBurstValueError(f"a Bayer mosaic must be (H, W) with even H and W, got {cfa.shape}")
    if pattern not in PATTERNS:
        raise LBurstValueError(f"unknown CFA pattern {pattern!r}; use one of {', '.join(PATTERNS)}")
    tags = [
        (50706, 1, 4, (1, 4, 0, 0), True),  # DNGVersion
        (50707, 1, 4, (1, 1, 0, 0), True),  # DNGBackwardVersion
        (50708, 2, 0, model, True),  # UniqueCameraModel
        (271, 2, 0, "lburst", True),  # Make
        (272, 2, 0, model, True),  # Model
        (33421, 3, 2, (2, 2), True),  # CFARepeatPatternDim
        (33422, 1, 4, PATTERNS[pattern], True),  # CFAPattern
        (50710, 1, 3, (0, 1, 2), True),  # CFAPlaneColor
        (50711, 3, 1, 1, True),  # CFALayout: rectangular
        (50714, 4, 1, int(black_level), True),  # BlackLevel
        (50717, 4, 1, int(white_level), True),  # WhiteLevel
        (50721, 10, 9, _rational(XYZ_TO_SRGB), True),  # ColorMatrix1
        (50778, 3, 1, 21, True),  # CalibrationIlluminant1: D65
        (50728, 5, 3, _rational([1.0, 1.0, 1.0]), True),  # AsShotNeutral
    ]
    path = Path(path)
    with atomic_path(path) as tmp:
        tifffile.imwrite(
            tmp,
            cfa,
            photometric=32803,
            subfiletype=0,
            bitspersample=16,
            compression=None,
            extratags=tags,
            metadata=None,
        )
    return path
