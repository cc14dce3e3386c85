"""Mip-mapped textures and the photos they are made from.

Texture coordinates ``(u, v)`` are in level-0 texels: texel ``(row r, column c)`` covers
``u in [c, c + 1)``, ``v in [r, r + 1)``; sampling wraps around at the borders.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np

from lburst.errors import LBurstValueError
from lburst.extras import require

# scikit-image sample photos (bundled with the package, no download); ``cat`` is ``chelsea``
PHOTOS = (
    "astronaut",
    "coffee",
    "chelsea",
    "rocket",
    "immunohistochemistry",
    "hubble_deep_field",
    "retina",
    "camera",
    "brick",
    "grass",
    "gravel",
    "moon",
    "coins",
    "clock",
    "cell",
    "text",
)


@functools.cache
def load_photo(name: str) -> np.ndarray:
    """A scikit-image sample photo as uint8 (H, W, 3) (cached: do not modify it)."""
    img = np.asarray(getattr(require("skimage.data", "the scenes' photo textures"), name)())
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    return np.ascontiguousarray(img[..., :3].astype(np.uint8))


@functools.cache
def photo_patches(names: tuple[str, ...] = PHOTOS, size: int = 256, min_std: float = 25.0) -> tuple[np.ndarray, ...]:
    """Non-overlapping ``size x size`` uint8 (size, size, 3) patches of the photos at their
    own resolution, leaving out flat ones (grey-level std below ``min_std``).  Distinct
    patches keep a mosaic from repeating the same picture close by."""
    out = []
    for name in names:
        img = load_photo(name)
        for y in range(0, img.shape[0] - size + 1, size):
            for x in range(0, img.shape[1] - size + 1, size):
                patch = img[y : y + size, x : x + size]
                if patch.mean(-1).std() >= min_std:
                    out.append(patch)
    return tuple(out)


def mosaic(
    height: int, width: int, rng: np.random.Generator, patches: tuple[np.ndarray, ...] | None = None
) -> np.ndarray:
    """A uint8 (height, width, 3) grid of photo patches, each rotated by a multiple of
    90 degrees, maybe mirrored, with a random colour gain.  Patches are dealt in a
    shuffled order, so a patch comes back only after all the others."""
    patches = photo_patches() if patches is None else patches
    tile = patches[0].shape[0]
    out = np.empty((height, width, 3), np.uint8)
    order: list[int] = []
    for y in range(0, height, tile):
        for x in range(0, width, tile):
            if not order:
                order = list(rng.permutation(len(patches)))
            t = np.rot90(patches[order.pop()], rng.integers(4))
            if rng.random() < 0.5:
                t = t[:, ::-1]
            t = np.clip(t * rng.uniform(0.6, 1.2, size=3).astype(np.float32), 0, 255)
            out[y : y + tile, x : x + tile] = t[: height - y, : width - x]
    return out


def noise_field(
    height: int, width: int, rng: np.random.Generator, scales: tuple[float, ...] = (1.0, 4.0, 16.0)
) -> np.ndarray:
    """Float32 (height, width) random texture, a sum of Gaussian noise smoothed at each
    of ``scales`` (texels), each normalised to unit standard deviation: never repeats."""
    out = np.zeros((height, width), np.float32)
    for scale in scales:
        step = max(int(scale), 1)
        small = rng.standard_normal((height // step + 2, width // step + 2)).astype(np.float32)
        if step > 1:
            small = cv2.GaussianBlur(small, (0, 0), 1.0)
            small /= small.std() + 1e-6
        out += cv2.resize(small, (width + 2 * step, height + 2 * step), interpolation=cv2.INTER_CUBIC)[:height, :width]
    return out / np.sqrt(len(scales))


def scatter_shapes(img: np.ndarray, count: int, size: tuple[int, int], rng: np.random.Generator) -> None:
    """Draw ``count`` random filled circles, rectangles and strokes (``size`` = min, max
    extent in texels, random colours) into ``img`` (H, W, 3) uint8, in place."""
    h, w = img.shape[:2]
    for _ in range(count):
        x, y = int(rng.integers(w)), int(rng.integers(h))
        r = int(rng.integers(size[0], size[1] + 1)) // 2
        colour = tuple(int(c) for c in rng.integers(0, 256, size=3))
        kind = rng.integers(3)
        if kind == 0:
            cv2.circle(img, (x, y), r, colour, -1, cv2.LINE_AA)
        elif kind == 1:
            dx, dy = (int(v) for v in rng.integers(-r, r + 1, size=2))
            cv2.rectangle(img, (x - abs(dx) - 1, y - abs(dy) - 1), (x + abs(dx) + 1, y + abs(dy) + 1), colour, -1)
        else:
            dx, dy = (int(v) for v in rng.integers(-2 * r, 2 * r + 1, size=2))
            cv2.line(img, (x, y), (x + dx, y + dy), colour, max(r // 3, 1), cv2.LINE_AA)


class MipTexture:
    """An RGB texture with an area-averaged mip pyramid, sampled trilinearly.

    Level ``l`` is about ``2**l`` times smaller than level 0 (the image given, stored
    as uint8 with values 0..255).
    """

    def __init__(self, image: np.ndarray, min_size: int = 4):
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[2] != 3:
            raise LBurstValueError(f"texture must be (H, W, 3), got shape {image.shape}")
        levels = [np.ascontiguousarray(np.clip(np.round(image), 0, 255).astype(np.uint8))]
        while min(levels[-1].shape[:2]) >= 2 * min_size:
            h, w = levels[-1].shape[:2]
            levels.append(cv2.resize(levels[-1], (w // 2, h // 2), interpolation=cv2.INTER_AREA))
        self.levels = levels

    @classmethod
    def constant(cls, colour: tuple[float, float, float], size: int = 8) -> "MipTexture":
        return cls(np.broadcast_to(np.asarray(colour, np.float32), (size, size, 3)))

    @property
    def shape(self) -> tuple[int, int]:
        return self.levels[0].shape[:2]

    def _bilinear(self, level: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Bilinear samples (N, 3) float32 of one level, wrapping around (OpenCV remap)."""
        img = self.levels[level]
        h, w = img.shape[:2]
        x = np.mod(u * (w / self.shape[1]) - 0.5, w).astype(np.float32)
        y = np.mod(v * (h / self.shape[0]) - 0.5, h).astype(np.float32)
        n = len(x)
        cols = 1024  # remap needs maps smaller than 32767 on each side
        pad = -n % cols
        x = np.pad(x, (0, pad)).reshape(-1, cols)
        y = np.pad(y, (0, pad)).reshape(-1, cols)
        out = cv2.remap(img, x, y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
        return out.reshape(-1, 3)[:n].astype(np.float32)

    def sample(self, u: np.ndarray, v: np.ndarray, lod: np.ndarray) -> np.ndarray:
        """Colours (N, 3) float32 at texel coordinates ``u, v`` (N,) and level of detail
        ``lod`` (N,) = log2 of the pixel footprint in level-0 texels (clipped)."""
        top = len(self.levels) - 1
        lod = np.clip(lod, 0.0, top)
        base = np.minimum(np.floor(lod).astype(np.int64), max(top - 1, 0))
        frac = (lod - base)[:, None].astype(np.float32)
        out = np.empty((len(u), 3), np.float32)
        for level in np.flatnonzero(np.bincount(base, minlength=1)):
            m = base == level
            a = self._bilinear(int(level), u[m], v[m])
            if level < top:
                a += (self._bilinear(int(level) + 1, u[m], v[m]) - a) * frac[m]
            out[m] = a
        return out
