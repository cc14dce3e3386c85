"""Burst with Merge (Ravendran et al., RA-L 2021): align the frames, average them, then
run any single-image method on the merged image.

``merge_burst`` returns float32 ``(H, W, 3)`` on the burst dtype's scale (0..255 for
uint8, 0..65535 for uint16); :class:`MergeThen` rounds and clips it back to the burst's
dtype and hands it to the inner extractor as a 1-frame burst.  Specs ``merge+sift``,
``merge+orb``, ``merge+r2d2:CKPT``, ``merge,reduce=median+sift`` build a
:class:`MergeThen` through :func:`lburst.methods.create` (``merge`` is a registered
wrapper with :class:`MergeOptions`).  Shift convention: see :mod:`lburst.burst.align`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from lburst.burst.align import Method, Motion, align_burst, estimate_shifts, warp_frame
from lburst.burst.frames import check_burst, dtype_max
from lburst.errors import LBurstValueError
from lburst.features import Extractor, Features
from lburst.methods import register

Reduce = Literal["mean", "median"]


def valid_mask(shape: tuple[int, int], shift: np.ndarray) -> np.ndarray:
    """``(H, W)`` bool: where ``p + shift`` falls inside the frame (no border extrapolation)."""
    h, w = shape
    x = np.arange(w) + shift[0]
    y = np.arange(h) + shift[1]
    return ((y >= 0) & (y <= h - 1))[:, None] & ((x >= 0) & (x <= w - 1))[None, :]


def merge_burst(
    burst: np.ndarray,
    shifts: np.ndarray | None = None,
    reduce: Reduce = "mean",
    method: Method = "phase",
    motion: Motion = "free",
) -> np.ndarray:
    """Warp every frame onto the common frame (bilinear, sub-pixel) and average.

    Args:
        burst: uint8/uint16 ``(N, H, W, 3)``, temporal order, N odd.
        shifts: ``(N, 2)`` ``(dx, dy)`` per frame (see :mod:`lburst.burst.align`); given
            (e.g. the true ones, the "oracle" merge), nothing is estimated; otherwise
            :func:`estimate_shifts` with ``method`` and ``motion``.
        reduce: ``'mean'`` or ``'median'`` over the frames that cover each pixel.

    Returns:
        float32 ``(H, W, 3)`` on the burst dtype's scale (0..255 for uint8).  Pixels
        that no frame covers (only possible when the common frame's shift is not 0)
        take the mean of the border-replicated values.
    """
    burst = check_burst(burst)
    n, h, w, _ = burst.shape
    if shifts is None:
        shifts = estimate_shifts(burst, method=method, motion=motion)
    shifts = np.asarray(shifts, np.float64)
    if shifts.shape != (n, 2):
        raise LBurstValueError(f"shifts must be ({n}, 2) for a {n}-frame burst, got {shifts.shape}")
    if reduce not in ("mean", "median"):
        raise LBurstValueError(f"unknown reduction {reduce!r}: use 'mean' or 'median'")
    warped = np.stack([warp_frame(burst[k], shifts[k]) for k in range(n)])
    valid = np.stack([valid_mask((h, w), shifts[k]) for k in range(n)])
    none = ~valid.any(0)
    valid[:, none] = True
    if reduce == "mean":
        weights = valid[..., None].astype(np.float32)
        return (warped * weights).sum(0) / weights.sum(0)
    if valid.all():
        return np.median(warped, axis=0).astype(np.float32)
    warped[~valid] = np.nan
    return np.nanmedian(warped, axis=0).astype(np.float32)


class MergeThen:
    """Extractor: merge the burst (:func:`merge_burst`), round/clip to its dtype, run ``inner`` on it.

    Defaults suit robotic bursts: ECC alignment and a constant-velocity (``'linear'``)
    fit.  ``extractor(burst, shifts=true_shifts)`` skips estimation (oracle merge).
    """

    def __init__(
        self, inner: Extractor, method: Method = "ecc", motion: Motion = "linear", reduce: Reduce = "mean"
    ) -> None:
        self.inner = inner
        self.method = method
        self.motion = motion
        self.reduce = reduce
        self.name = f"merge+{getattr(inner, 'name', type(inner).__name__)}"

    def __call__(self, burst: np.ndarray, shifts: np.ndarray | None = None) -> Features:
        burst = check_burst(burst)
        merged = merge_burst(burst, shifts, reduce=self.reduce, method=self.method, motion=self.motion)
        image = np.clip(np.rint(merged), 0, dtype_max(burst.dtype)).astype(burst.dtype)
        return self.inner(image[None])


@dataclass(frozen=True)
class MergeOptions:
    """Alignment ``method`` (phase correlation, or refined by ECC), ``motion`` model of the
    shifts (``linear``: constant velocity) and the ``reduce`` over frames."""

    method: Literal["phase", "ecc", "pyramid"] = "ecc"
    motion: Literal["free", "linear"] = "linear"
    reduce: Literal["mean", "median"] = "mean"


@register("merge", MergeOptions, wraps=True)
def merge(inner: Extractor, options: MergeOptions) -> MergeThen:
    """Burst with Merge: align and average the frames, then run SPEC on the merged image."""
    return MergeThen(inner, method=options.method, motion=options.motion, reduce=options.reduce)


class AlignThen:
    """Extractor: align the burst's frames onto the common frame (:func:`align_burst`),
    then run the burst method ``inner`` on the aligned burst.

    The burst is aligned once, with these options: an ``inner`` network whose weights
    align the burst themselves (:attr:`lburst.LBurst.align`) has that turned off."""

    def __init__(self, inner: Extractor, method: Method = "pyramid", motion: Motion = "linear") -> None:
        model = getattr(inner, "model", None)
        if getattr(model, "align", False):
            model.align = False
        self.inner = inner
        self.method = method
        self.motion = motion
        self.name = f"align+{getattr(inner, 'name', type(inner).__name__)}"

    def __call__(self, burst: np.ndarray) -> Features:
        return self.inner(align_burst(burst, method=self.method, motion=self.motion))


@dataclass(frozen=True)
class AlignOptions:
    """Alignment ``method`` and ``motion`` model of the shifts, as for ``merge``."""

    method: Literal["phase", "ecc", "pyramid"] = "pyramid"
    motion: Literal["free", "linear"] = "linear"


@register("align", AlignOptions, wraps=True)
def align(inner: Extractor, options: AlignOptions) -> AlignThen:
    """Align the burst's frames onto the common frame, then run the burst method SPEC on it."""
    return AlignThen(inner, method=options.method, motion=options.motion)
