"""Mip-mapped textures and the photos they are made from.

Texture coordinates ``(u, v)`` are in level-0 texels: texel ``(row r, column c)`` covers
``u in [c, c + 1)``, ``v in [r, r + 1)``; sampling wraps around at the borders.
"""

from __future__ import annotations

import functools

import cv2
import numpy as np
import skimage.data

# scikit-image sample photos (bundled with the package, no download)
COLOUR_PHOTOS = ("astronaut", "coffee", "chelsea", "rocket", "cat", "immunohistochemistry")
GREY_PHOTOS = ("camera", "brick", "grass", "gravel", "moon", "coins", "clock", "cell", "text")


@functools.lru_cache(maxsize=None)
def load_photo(name: str) -> np.ndarray:
    """A scikit-image sample photo as uint8 (H, W, 3) (cached: do not modify it)."""
    img = np.asarray(getattr(skimage.data, name)())
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=-1)
    return np.ascontiguousarray(img[..., :3].astype(np.uint8))


def random_tile(names: tuple[str, ...], size: int, rng: np.random.Generator) -> np.ndarray:
    """A ``size x size`` uint8 tile: a random crop of a random photo, rotated by a
    multiple of 90 degrees, maybe mirrored, with a random colour gain."""
    img = load_photo(names[rng.integers(len(names))])
    h, w = img.shape[:2]
    crop = int(rng.uniform(0.5, 1.0) * min(h, w))
    y, x = rng.integers(0, h - crop + 1), rng.integers(0, w - crop + 1)
    tile = cv2.resize(img[y : y + crop, x : x + crop], (size, size), interpolation=cv2.INTER_AREA)
    tile = np.rot90(tile, rng.integers(4))
    if rng.random() < 0.5:
        tile = tile[:, ::-1]
    gain = rng.uniform(0.6, 1.2, size=3)
    return np.clip(tile * gain.astype(np.float32), 0, 255).astype(np.uint8)


def mosaic(names: tuple[str, ...], height: int, width: int, tile: int, rng: np.random.Generator) -> np.ndarray:
    """A uint8 (height, width, 3) grid of :func:`random_tile` tiles."""
    out = np.empty((height, width, 3), np.uint8)
    for y in range(0, height, tile):
        for x in range(0, width, tile):
            t = random_tile(names, tile, rng)
            out[y : y + tile, x : x + tile] = t[: height - y, : width - x]
    return out


class MipTexture:
    """An RGB texture with an area-averaged mip pyramid, sampled trilinearly.

    Level ``l`` is about ``2**l`` times smaller than level 0 (the image given, stored
    as uint8 with values 0..255).
    """

    def __init__(self, image: np.ndarray, min_size: int = 4):
        image = np.asarray(image)
        if image.ndim != 3 or image.shape[2] != 3:
            raise ValueError(f"texture must be (H, W, 3), got shape {image.shape}")
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
