"""Difference-of-Gaussians scale space of a burst's slope images, for BuFF.

The slope image of slope ``s`` (px/frame) is the mean of the frames resampled at
``p + t_k * s`` (``t_k = k - N // 2``; see :mod:`lburst.burst.align` for the shift
convention).  Shifting, averaging and Gaussian blurring are linear and shift-invariant,
so the DoG of a slope image equals the mean of the frames' own DoGs shifted the same
way: each frame's Gaussian pyramid is built once (OpenCV's SIFT layout: ``layers + 3``
Gaussian levels per octave, the next octave decimated ``[::2, ::2]`` from level
``layers``) and slope DoGs are sums of resampled frame DoGs.  Sub-pixel resampling is
Keys cubic (a = -0.5): bilinear would blur fractional shifts more than whole ones and
bias the slope search towards whole-pixel shifts.

Octave ``o`` has pixel ``(x, y)`` at ``(x, y) * 2**o`` in the full-resolution frame,
and shifts there are the full-resolution ones divided by ``2**o``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import cv2
import numpy as np

KEYS_A = -0.5


def cubic_weights(f: float) -> np.ndarray:
    """Keys cubic weights ``(4,)`` of the samples at offsets -1, 0, 1, 2 for a position ``f`` in [0, 1)."""
    a = KEYS_A
    d = np.array([1 + f, f, 1 - f, 2 - f])
    near = ((a + 2) * d - (a + 3)) * d * d + 1
    far = ((a * d - 5 * a) * d + 8 * a) * d - 4 * a
    return np.where(d <= 1, near, far)


@dataclass
class OctaveStack:
    """One octave of every frame.

    Attributes:
        index: the octave number ``o``.
        gauss: ``(N, layers + 3, h, w)`` float32 Gaussian levels of each frame.
        dog_padded: ``(N, layers + 2, h + 2 pad, w + 2 pad)`` the frames' DoGs divided by
            N (summing frames gives the mean), edge-padded by ``pad`` pixels.
        cache_limit: bytes of resampled DoG stacks kept for reuse.
    """

    index: int
    gauss: np.ndarray
    dog_padded: np.ndarray
    pad: int
    cache_limit: int
    cache: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        return self.gauss.shape[2:]

    def fraction(self, k: int, fx: float, fy: float) -> np.ndarray:
        """Frame ``k``'s padded DoG stack resampled at ``+ (1 + fx, 1 + fy)``, 0 <= f < 1:
        ``out[:, r, c] = dog_padded[k][:, r + 1 + fy, c + 1 + fx]`` (cubic), shape (L, Hp - 3, Wp - 3)."""
        key = (k, fx, fy)
        if key in self.cache:
            return self.cache[key]
        a = self.dog_padded[k]
        hp, wp = a.shape[1:]
        if fx:
            xkey = (k, fx, None)
            if xkey in self.cache:
                a = self.cache[xkey]
            else:
                wx = cubic_weights(fx).astype(np.float32)
                out = a[:, :, 0 : wp - 3] * wx[0]
                for i in range(1, 4):
                    out += a[:, :, i : wp - 3 + i] * wx[i]
                a = out
                self._store(xkey, a)
        else:
            a = a[:, :, 1 : wp - 2]
        if fy:
            wy = cubic_weights(fy).astype(np.float32)
            out = a[:, 0 : hp - 3] * wy[0]
            for j in range(1, 4):
                out += a[:, j : hp - 3 + j] * wy[j]
            a = out
        else:
            a = a[:, 1 : hp - 2]
        self._store(key, a)
        return a

    def _store(self, key: tuple, value: np.ndarray) -> None:
        used = sum(v.nbytes for v in self.cache.values() if v.base is None)
        if used + value.nbytes <= self.cache_limit:
            self.cache[key] = value

    def frame_shift(self, k: int, shift: np.ndarray) -> tuple[np.ndarray, int, int]:
        """(resampled stack, row offset, column offset) such that frame ``k``'s DoG at octave pixel
        ``p + shift`` is ``stack[:, p_y + row, p_x + col]``.  Fractions are rounded to ``quantum``
        octave px (1/8 at octave 0, 1/4 beyond: a misalignment of at most 1/16 or 1/8 px against a
        blur of at least 1.6 px), which bounds the number of resampled stacks per octave."""
        dx, dy = (float(v) for v in shift)
        ix, iy = int(np.floor(dx)), int(np.floor(dy))
        steps = 8 if self.index == 0 else 4
        fx, fy = round((dx - ix) * steps) / steps, round((dy - iy) * steps) / steps
        if fx == 1.0:
            ix, fx = ix + 1, 0.0
        if fy == 1.0:
            iy, fy = iy + 1, 0.0
        return self.fraction(k, fx, fy), self.pad + iy - 1, self.pad + ix - 1

    def slope_extrema(self, shifts: np.ndarray, band_bytes: int = 160 << 10) -> tuple[np.ndarray, np.ndarray]:
        """Maximum and minimum over slopes of the slope DoGs, each ``(layers + 2, h, w)``.

        ``shifts`` ``(S, N, 2)``: per-slope, per-frame shifts (octave px).  Streams over
        slopes band by band (rows chosen so a band is about ``band_bytes``: it stays in
        cache across the slopes, which memory-bound sums otherwise are not).
        """
        levels = self.dog_padded.shape[1]
        h, w = self.shape
        dmax = np.empty((levels, h, w), np.float32)
        dmin = np.empty((levels, h, w), np.float32)
        plan = [[self.frame_shift(k, shift) for k, shift in enumerate(per_frame)] for per_frame in shifts]
        rows = max(1, band_bytes // (4 * levels * w))
        buf = np.empty((levels, rows, w), np.float32)
        for r0 in range(0, h, rows):
            r1 = min(h, r0 + rows)
            b = buf[:, : r1 - r0]
            hi, lo = dmax[:, r0:r1], dmin[:, r0:r1]
            for s, frames in enumerate(plan):
                for k, (stack, y0, x0) in enumerate(frames):
                    view = stack[:, y0 + r0 : y0 + r1, x0 : x0 + w]
                    if k == 0:
                        np.copyto(b, view)
                    else:
                        b += view
                if s == 0:
                    np.copyto(hi, b)
                    np.copyto(lo, b)
                else:
                    np.maximum(hi, b, out=hi)
                    np.minimum(lo, b, out=lo)
        return dmax, dmin

    def gather(self, shifts: np.ndarray, level: np.ndarray, y: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Mean DoG at integer ``(level, y, x)`` (equal shapes) for one slope's per-frame shifts ``(N, 2)``."""
        out = np.zeros(level.shape, np.float32)
        for k, shift in enumerate(shifts):
            stack, y0, x0 = self.frame_shift(k, shift)
            out += stack[level, y + y0, x + x0]
        return out

    def gather_slopes(
        self, shifts: np.ndarray, slope: np.ndarray, level: np.ndarray, y: np.ndarray, x: np.ndarray
    ) -> np.ndarray:
        """Mean DoG at ``(level, y, x)`` (shape ``(C, ...)``) where point c uses slope ``slope[c]``
        of the per-slope, per-frame shifts ``shifts`` ``(S, N, 2)``."""
        out = np.zeros(level.shape, np.float32)
        for s in np.unique(slope):
            sel = np.nonzero(slope == s)[0]
            out[sel] = self.gather(shifts[s], level[sel], y[sel], x[sel])
        return out


def frame_pyramids(
    frames: np.ndarray, sigma: float, init_sigma: float, layers: int, octaves: int, max_shift: float, cache_limit: int
) -> Iterator[OctaveStack]:
    """Yield :class:`OctaveStack` for octaves 0.. of grayscale ``frames`` ``(N, H, W)`` in [0, 1].

    ``max_shift`` (full-resolution px) sizes the padding so any slope shift stays inside.
    """
    n = len(frames)
    levels = layers + 3
    k = 2.0 ** (1.0 / layers)
    increments = [np.sqrt((sigma * k**i) ** 2 - (sigma * k ** (i - 1)) ** 2) for i in range(1, levels)]
    first = np.sqrt(max(sigma**2 - init_sigma**2, 0.01))
    base = [cv2.GaussianBlur(f, (0, 0), first) for f in frames]
    for o in range(octaves):
        gauss = np.empty((n, levels) + base[0].shape, np.float32)
        for j in range(n):
            gauss[j, 0] = base[j]
            for i, inc in enumerate(increments, start=1):
                gauss[j, i] = cv2.GaussianBlur(gauss[j, i - 1], (0, 0), inc)
        pad = int(np.ceil(max_shift / 2**o)) + 3
        dog = (gauss[:, 1:] - gauss[:, :-1]) * np.float32(1.0 / n)
        dog_padded = np.pad(dog, ((0, 0), (0, 0), (pad, pad), (pad, pad)), mode="edge")
        yield OctaveStack(o, gauss, dog_padded, pad, cache_limit)
        base = [np.ascontiguousarray(gauss[j, layers, ::2, ::2]) for j in range(n)]
        if min(base[0].shape) < 8:
            return
